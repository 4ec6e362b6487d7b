"""Runs made once across experiments: an index from a run's request (:func:`calibration.batch.request_key`)
to a folder whose files that request made, under ``results/.runs/``.

A request holds everything a run reads (the simulator and its settings, the parameters, the reduced
record's content, the mesh seed, the run.json entries, the simulator's source) and the simulation is
deterministic, so two runs with one request write the same files. When a batch meets a request that
another experiment's run already made, it copies that run's ``curve.csv``, ``run.json`` and
``manifest.json`` instead of simulating (the manifest vouches for the copy, as for a run of its own).
Where this pays: the folds of a leave-one-record-out series start from the same prior ensemble, so a
record's prior members and their replicates are the same requests in every fold that calibrates on it
(their mesh realizations keyed on the record's position in the series,
:func:`calibration.diagnosis_config.series_position`). No held-out record can enter a shared run: the
request would name its content, and a held-out record is read by no run of its own fold's calibration.

The index holds one small JSON file per request; a missing, stale or altered source (a folder removed,
re-run or edited) is a miss, and the run is simulated. Nothing here imports Snakemake.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from .contracts import atomic_write_json, read_json
from .heal import MANIFEST, check_manifest

__all__ = ["STORE", "remember", "copy_made"]

#: The index's folder, relative to the workflow's working directory (beside the experiments' folders).
STORE = Path("results") / ".runs"
#: What a shared run is: the member contract's files with the manifest that vouches for them.
SHARED_FILES = ("curve.csv", "run.json", MANIFEST)


def _entry(store: Path, key: str) -> Path:
    return Path(store) / key[:2] / f"{key}.json"


def remember(store: str | Path, key: str, folder: str | Path) -> None:
    """Index ``folder`` as the run that ``key`` made (written atomically; the last writer wins, and any
    folder a request made holds the same files)."""
    # relative to the store: a results tree moved or cloned elsewhere keeps its index, and two runs of
    # one config write the same index (tools/compare_runs.py)
    atomic_write_json(_entry(Path(store), key), {"folder": os.path.relpath(folder, store)})


def copy_made(store: str | Path, key: str, folder: str | Path, made_by) -> str | None:
    """Copy into ``folder`` the files of the run indexed under ``key`` when that run's files are intact and
    made by ``key`` (``made_by(folder, key)``); returns the source folder, or None (a miss: simulate).
    The copy is checked against its manifest before it counts; a bad copy is removed."""
    entry = _entry(Path(store), key)
    if not entry.is_file():
        return None
    try:
        source = Path(store) / read_json(entry)["folder"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    folder = Path(folder)
    if source.resolve() == folder.resolve() or not made_by(source, key):
        return None
    folder.mkdir(parents=True, exist_ok=True)
    # the manifest last: a copy killed half-way has no manifest and is made again
    for name in SHARED_FILES:
        tmp = folder / f".{name}.tmp"
        shutil.copyfile(source / name, tmp)
        os.replace(tmp, folder / name)
    if check_manifest(folder / MANIFEST)[1] is not None:
        for name in SHARED_FILES:
            (folder / name).unlink(missing_ok=True)
        return None
    return os.path.normpath(source)
