"""The parse-time check of the measured records, reduced once ever per content.

The Snakefile checks every record of every experiment before any job runs (a bad record stops the
run with the file and the problem, issue 56), on every command, ``snakemake -n`` too. Reducing each record
there costs a dry run most of its time, so the check's verdict rests on a summary of the record's
reduction (:func:`calibration.observations.record_check_summary`: where the reduced record ends,
whether its stress is finite, its validity class and reasons) stored on disk under a SHA-256 of
everything the reduction reads:

* the record file's bytes; a test sheet's signals file; a Freiburg record's specimen spreadsheet
  (``Rae2021/<lith>.xlsx``) and ``PetrophysicalProperties.xlsx`` (where :mod:`shpb.paths` finds it);
* the source of the reduction and the checks (``shpb/lab/*.py``, ``lithologies.csv``,
  ``calibration/observations.py``, this module), so that a changed reduction checks every record again.

A changed file is a new key and is checked again (its error reported); an entry that cannot be read,
or names another key, is ignored and computed again. A record that fails its check leaves no
entry: it is read again on the next command, which reports the problem again. The verdict itself
(:func:`check_summary`) is the same function for a fresh and a stored summary.

This module imports nothing heavy; :func:`calibration.observations.cached_check_record` joins it to the
reduction, whose heavy imports (SciPy under :mod:`enkf`) happen only when an entry is missing.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

__all__ = ["ObservationFileError", "check_summary", "record_key", "code_digest", "cached_summary", "CACHE_DIR",
           "REDUCTIONS"]

#: Where the summaries are kept, relative to the working directory (Snakemake's own folder: a fresh clone
#: or `rm -r .snakemake` starts without them; results/ stays free of files no rule names).
CACHE_DIR = Path(".snakemake") / "fdem-records"
#: How many records this process reduced for the check (a test counts them).
REDUCTIONS = {"count": 0}

_ROOT = Path(__file__).resolve().parents[1]
_CODE = [_ROOT / "calibration" / "observations.py", Path(__file__).resolve()]


class ObservationFileError(ValueError):
    """An observation source or file is malformed; the message names the file and the problem."""


def check_summary(path, summary: dict, t_end: float | None = None, *, refuse_invalid: bool = False) -> None:
    """The check's verdict on a record's summary (:func:`calibration.observations.record_check_summary`):
    :class:`ObservationFileError` when its stress is not finite, it ends before ``t_end``, or it is an
    invalid test and ``refuse_invalid``."""
    if not summary["stress_finite"]:
        raise ObservationFileError(f"observation file {path}: the reduced specimen stress has non-finite values")
    end = float(summary["end_time_s"])
    if t_end is not None and end < t_end - 1e-12:
        raise ObservationFileError(f"observation file {path}: the reduced record ends at {end:.4g} s, "
                                   f"before the observation window's end {t_end:.4g} s")
    validity = summary["validity"]
    if refuse_invalid and validity["class"] == "invalid":
        raise ObservationFileError(f"observation file {path}: the test is invalid as a calibration record ("
                                   + "; ".join(validity["reasons"]) + "): expected a valid or questionable test; "
                                   "set the experiment's observations.allow_invalid: true to use it anyway")


def _file_digest(h, path: Path) -> None:
    h.update(str(path.name).encode() + b"\0")
    try:
        h.update(path.read_bytes())
    except OSError:
        h.update(b"<missing>")
    h.update(b"\0")


def _companions(path: Path) -> list[Path]:
    """The other files the record's reduction reads (module docstring)."""
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            doc = yaml.safe_load(path.read_text())
            sig = Path(str(doc["signals"]["file"]))
        except Exception:  # noqa: BLE001 - a malformed sheet has no companion; its reduction says what is wrong
            return []
        return [sig if sig.is_absolute() else path.parent / sig]
    from shpb.paths import freiburg_data_dir

    parents = path.resolve().parents
    lith = [parents[2] / f"{path.parent.name}.xlsx"] if len(parents) > 2 else []
    return lith + [freiburg_data_dir() / "PetrophysicalProperties.xlsx"]


def _code_digest() -> bytes:
    h = hashlib.sha256()
    lab = _ROOT / "shpb" / "lab"
    for p in sorted(lab.glob("*.py")) + [lab / "lithologies.csv", lab / "sheet_schema.json"] + _CODE:
        _file_digest(h, p)
    return h.digest()


def record_key(path, code: bytes | None = None) -> str:
    """The SHA-256 (hex) of everything the record's reduction reads (module docstring)."""
    path = Path(path)
    h = hashlib.sha256(code if code is not None else _code_digest())
    for p in [path, *_companions(path)]:
        _file_digest(h, p)
    return h.hexdigest()


def _stored(entry: Path, key: str, path: Path) -> dict | None:
    """The entry's summary, None when it is missing, unreadable or under another key. The record's path is
    kept in the entry for a reader, not compared: the key holds its name, its lithology folder's
    spreadsheet and its content, so one record named by two paths (relative, absolute) shares one entry."""
    try:
        doc = json.loads(entry.read_text())
        summary = doc["summary"]
        ok = (doc["key"] == key and isinstance(summary["stress_finite"], bool)
              and isinstance(summary["end_time_s"], float) and summary["validity"]["class"] in
              ("valid", "questionable", "invalid") and isinstance(summary["validity"]["reasons"], list))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return summary if ok else None


def cached_summary(path, code: bytes | None, cache_dir, summarize) -> dict:
    """The record's summary from its entry in ``cache_dir``, or ``summarize(path)`` stored there when there
    is no valid entry (module docstring). ``code``: the source digest (:func:`code_digest`, computed once
    by a caller checking many records; None: computed here)."""
    path = Path(path)
    if not path.is_file():
        raise ObservationFileError(f"observation file {path}: record file not found: {path}")
    key = record_key(path, code)
    entry = Path(cache_dir) / f"{key}.json"
    summary = _stored(entry, key, path)
    if summary is None:
        from shpb.atomic import atomic_write_text

        REDUCTIONS["count"] += 1
        summary = summarize(path)
        try:
            atomic_write_text(entry, json.dumps({"key": key, "record": str(path), "summary": summary}, indent=1))
        except OSError:
            pass  # a read-only checkout checks every time; the verdict does not depend on the cache
    return summary


def code_digest() -> bytes:
    """The source digest of the reduction (module docstring), for :func:`cached_check_record`'s ``code``."""
    return _code_digest()
