"""One reader per test-sheet format (:mod:`shpb.lab.sheet`), each giving the existing
:class:`~shpb.lab.records.RawRecord` with the sheet's bars and specimen attached.

* ``freiburg``: the Freiburg DAQ export (:func:`shpb.lab.records.read_freiburg_raw`);
* ``lanl_raw``, ``lanl_minikolsky``: LANL HopPyBar files (:mod:`shpb.lab.other_labs`); their own bridge
  factors are used where the sheet gives none;
* ``yao``: H. Yao's processor exports (``.csv``/``.xls``/``.xlsx``; a time column rounded to a few
  digits is rebuilt uniform there, the record's notes say so);
* ``csv``: any CSV with a header row, the columns and units named in the sheet. Its time axis must
  be uniform (within 1 % of a step) and no value may be missing: the reduction interpolates on the
  sampling step, so a gap or a NaN would silently become a wrong stress.

Every problem raises :class:`~shpb.lab.sheet.SheetError` naming the sheet, the field and what was
expected; a reader's own message (with the signals file's name and line) is kept in it.
"""
from __future__ import annotations

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


def _csv_record(sheet: Sheet) -> RawRecord:
    import pandas as pd

    where, path, sig = str(sheet.path), sheet.signals_file, sheet.signals
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise SheetError([f"{where}: signals.file: expected a CSV file with a header row, {path} "
                          f"cannot be read ({exc})"]) from None
    have = [str(c) for c in df.columns]
    wanted = [("signals.time.column", sig["time"]["column"])]
    wanted += [(f"signals.{bar}.columns", c) for bar in ("incident", "transmitted") for c in sig[bar]["columns"]]
    problems = [f"{where}: {key}: expected a column of {path.name} ({have}), {c!r} not found"
                for key, c in wanted if c not in have]
    if problems:
        raise SheetError(problems)
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
