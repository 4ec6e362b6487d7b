"""One reader per test-sheet format (:mod:`shpb.lab.sheet`), each giving the existing
:class:`~shpb.lab.records.RawRecord` with the sheet's bars and specimen attached.

* ``freiburg``: the Freiburg DAQ export (:func:`shpb.lab.records.read_freiburg_raw`);
* ``lanl_raw``, ``lanl_minikolsky``: LANL HopPyBar files (:mod:`shpb.lab.other_labs`); their own bridge
  factors are used where the sheet gives none;
* ``yao``: H. Yao's processor exports (``.csv``/``.xls``/``.xlsx``; a time column rounded to a few
  digits is rebuilt uniform there, the record's notes say so);
* ``csv``: any CSV with a header row, the columns and units named in the sheet. Its time axis must
  be uniform (within 1 % of a step) and no value may be missing: the reduction interpolates on the
  sampling step, so a gap or a NaN would silently become a wrong stress. A scope's export starts with
  lines of its own (model, record length, sample interval) before the column names:
  ``signals.skip_rows`` skips that many lines and ``signals.comment`` (one character) drops every
  line starting with it; a file whose first lines do not parse is reported with the line and the
  ``skip_rows`` that would reach the row naming the sheet's columns, when one does.

Every problem raises :class:`~shpb.lab.sheet.SheetError` naming the sheet, the field and what was
expected; a reader's own message (with the signals file's name and line) is kept in it.
"""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from .records import RawRecord, read_freiburg_raw
from .sheet import Sheet, SheetError, load_sheet

__all__ = ["read_sheet_record", "check_sheet", "TIME_UNITS", "SIGNAL_UNITS"]

#: Time units of a csv sheet and their factor to seconds.
TIME_UNITS = {"s": 1.0, "ms": 1.0e-3, "us": 1.0e-6}
#: Signal units of a csv sheet: (RawRecord unit, factor).
SIGNAL_UNITS = {"V": ("V", 1.0), "mV": ("V", 1.0e-3), "strain": ("strain", 1.0), "microstrain": ("strain", 1.0e-6)}
#: A time axis departing from ``t0 + i dt`` by more than this fraction of ``dt`` is not uniform.
UNIFORM_TOL = 0.01
#: Lines of a csv file searched for the row naming the sheet's columns (a scope's header is a few dozen).
HEADER_SEARCH_LINES = 200
#: Sheet fields of the csv reader only: another reader ignoring them would hide a wrong sheet.
CSV_READER_FIELDS = ("skip_rows", "comment")


def _header_line(path: Path, names: list[str], comment: str | None) -> int | None:
    """The 0-based line of ``path`` (among its first :data:`HEADER_SEARCH_LINES`) whose comma-separated
    fields hold every one of ``names``: the column row a scope's own header lines precede."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for i, line in zip(range(HEADER_SEARCH_LINES), fh):
                if comment and line.startswith(comment):
                    continue
                fields = {f.strip().strip('"') for f in line.split(",")}
                if all(n in fields for n in names):
                    return i
    except OSError:
        return None
    return None


def _skip_hint(path: Path, names: list[str], sig: dict) -> str:
    """The fix to name when the sheet's columns were not found where the reader looked."""
    line = _header_line(path, names, sig.get("comment"))
    if line is not None and line != sig.get("skip_rows", 0):
        return (f"; the columns are named on line {line + 1} of {path.name}: set signals.skip_rows: {line} "
                f"(the lines before it)")
    return ("; if the file starts with lines of its own before the column names (a scope's header), set "
            "signals.skip_rows to their number, or signals.comment to the character they start with")


def _read_csv(sheet: Sheet, names: list[str]):
    import pandas as pd

    where, path, sig = str(sheet.path), sheet.signals_file, sheet.signals
    skip, comment = int(sig.get("skip_rows", 0)), sig.get("comment")
    try:
        return pd.read_csv(path, skiprows=skip, comment=comment, skip_blank_lines=True)
    except pd.errors.ParserError as exc:
        m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(exc))
        what = (f"line {m.group(2)} has {m.group(3)} fields where the header row (after signals.skip_rows: "
                f"{skip}) has {m.group(1)}") if m else str(exc)
        raise SheetError([f"{where}: signals.file: expected a CSV file with one header row then data rows, "
                          f"{path.name}: {what}{_skip_hint(path, names, sig)}"]) from None
    except (pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise SheetError([f"{where}: signals.file: expected a CSV file with a header row, {path} "
                          f"cannot be read ({exc}){_skip_hint(path, names, sig)}"]) from None


def _csv_record(sheet: Sheet) -> RawRecord:
    import pandas as pd

    where, path, sig = str(sheet.path), sheet.signals_file, sheet.signals
    wanted = [("signals.time.column", sig["time"]["column"])]
    wanted += [(f"signals.{bar}.columns", c) for bar in ("incident", "transmitted") for c in sig[bar]["columns"]]
    df = _read_csv(sheet, [c for _, c in wanted])
    have = [str(c) for c in df.columns]
    problems = [f"{where}: {key}: expected a column of {path.name} ({have}), {c!r} not found"
                for key, c in wanted if c not in have]
    if problems:
        raise SheetError([problems[0] + _skip_hint(path, [c for _, c in wanted], sig), *problems[1:]])
    values = {}
    for key, c in wanted:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            problems.append(f"{where}: {key}: expected a number on every row of column {c!r} of {path.name}, "
                            f"got NaN or text in data row(s) {(bad + 1).tolist()[:5]}")
        values[c] = v
    if problems:
        raise SheetError(problems)
    time = values[sig["time"]["column"]] * TIME_UNITS[sig["time"]["unit"]]
    n = time.size
    steps = np.diff(time)
    dt = float(np.median(steps)) if n > 1 else 0.0
    if n < 20 or not dt > 0:
        raise SheetError([f"{where}: signals.time.column: expected an increasing time axis of at least 20 "
                          f"samples in {path.name}, got {n} samples"])
    bad = np.flatnonzero(np.abs(steps - dt) > UNIFORM_TOL * dt)
    if bad.size:
        i = int(bad[0])
        raise SheetError([f"{where}: signals.time.column: expected a uniform time axis (step {dt:.6g} s within "
                          f"{UNIFORM_TOL:.0%}) in {path.name}, the step from data row {i + 1} to {i + 2} is "
                          f"{steps[i]:.6g} s ({bad.size} uneven step(s))"])
    unit_i, f_i = SIGNAL_UNITS[sig["incident"]["unit"]]
    _, f_t = SIGNAL_UNITS[sig["transmitted"]["unit"]]
    return RawRecord(
        name=sheet.name, source=str(path), time=time,
        incident=np.vstack([values[c] * f_i for c in sig["incident"]["columns"]]),
        transmitted=np.vstack([values[c] * f_t for c in sig["transmitted"]["columns"]]),
        unit=unit_i, sample_rate=1.0 / dt,
        incident_channels=tuple(sig["incident"]["columns"]),
        transmitted_channels=tuple(sig["transmitted"]["columns"]),
        header={"columns": ",".join(have)})


def _lab_record(sheet: Sheet) -> RawRecord:
    """The formats with a reader of their own; a reader's ValueError is kept, prefixed by the field."""
    from .other_labs import read_lanl_minikolsky, read_lanl_raw, read_yao_record

    path = sheet.signals_file
    if sheet.format == "freiburg":
        return read_freiburg_raw(path, bar=sheet.bar)
    if sheet.format == "lanl_raw":
        return read_lanl_raw(path)
    if sheet.format == "lanl_minikolsky":
        return read_lanl_minikolsky(path)
    spv = sheet.bar.strain_per_volt_incident if sheet.strain_per_volt_given else None
    return read_yao_record(path, strain_per_volt=spv)


def read_sheet_record(sheet: Sheet) -> RawRecord:
    """The sheet's signals as a :class:`RawRecord` carrying the sheet's name, bars and specimen.

    The bars are the sheet's; only the volts-to-strain factors of a LANL file are taken from the file
    when the sheet gives none (HopPyBar writes its gains and gauge factors into each test).
    """
    where = str(sheet.path)
    if sheet.format == "csv":
        raw = _csv_record(sheet)
    elif any(k in sheet.signals for k in CSV_READER_FIELDS):
        key = next(k for k in CSV_READER_FIELDS if k in sheet.signals)
        raise SheetError([f"{where}: signals.{key}: only format csv takes it (format {sheet.format!r} has a "
                          f"reader of its own that knows the file's layout), got {sheet.signals[key]!r}"])
    else:
        try:
            raw = _lab_record(sheet)
        except (ValueError, FileNotFoundError, OSError) as exc:
            field = "signals.strain_per_volt" if "strain_per_volt" in str(exc) else "signals.file"
            raise SheetError([f"{where}: {field}: the {sheet.format} reader could not read it: {exc}"]) from None
    bar = sheet.bar
    if not sheet.strain_per_volt_given and raw.unit == "V":
        if raw.bar is None or sheet.format not in ("lanl_raw", "lanl_minikolsky"):
            raise SheetError([f"{where}: signals.bridge: missing; the signals are volts and need the bridge "
                              f"constants or signals.strain_per_volt"])
        bar = replace(bar, strain_per_volt_incident=raw.bar.strain_per_volt_incident,
                      strain_per_volt_transmitted=raw.bar.strain_per_volt_transmitted)
        raw.notes.append("volts-to-strain factors from the signals file (the sheet gives none)")
    raw.name = sheet.name
    raw.bar = bar
    raw.specimen_length = sheet.specimen_length if sheet.geometry == "cylinder" else None
    raw.specimen_diameter = sheet.specimen_diameter
    return raw


def check_sheet(path: str | Path) -> tuple[Sheet, RawRecord]:
    """Load, validate and read a test sheet: ``(sheet, raw record)``; :class:`SheetError` otherwise."""
    sheet = load_sheet(path)
    return sheet, read_sheet_record(sheet)
