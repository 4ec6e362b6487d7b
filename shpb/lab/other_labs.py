"""Readers for other labs' SHPB records, into the same :class:`~shpb.lab.records.RawRecord` (format
checks of the reduction; metals and polymer):

* LANL HopPyBar ``.raw`` (tab-delimited, metadata table + two waveform columns): :func:`read_lanl_raw`.
* LANL mini-Kolsky Tektronix CSVs (one file per channel) + ``*_Input.dat`` test sheet:
  :func:`read_lanl_minikolsky`.
* H. Yao SHPB processor exports (``.csv``/``.xls``/``.xlsx``, columns ``Time/s``,
  ``incident_bar_signal/<unit>``, ``transmission_bar_signal/<unit>``): :func:`read_yao_record`.

Units SI in what these return; malformed input raises :class:`ValueError` naming the file and field.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from .bars import BarSetup, bridge_strain_per_volt
from .records import RawRecord, _check_uniform_time

__all__ = ["read_lanl_raw", "read_lanl_minikolsky", "read_yao_record"]


# --------------------------------------------------------------------------------------------------
# LANL HopPyBar formats
# --------------------------------------------------------------------------------------------------
def _norm_key(key: str) -> str:
    """Metadata key without units/odd characters: 'Incident Bar Diameter(mm)' -> 'incidentbardiameter'."""
    key = re.sub(r"\(.*?\)", "", key)
    return re.sub(r"[^a-z0-9]", "", key.lower())


def _meta_float(meta: dict[str, str], key: str, path: Path) -> float:
    nk = _norm_key(key)
    for k, v in meta.items():
        if _norm_key(k) == nk:
            try:
                return float(str(v).strip())
            except ValueError:
                raise ValueError(f"{path}: metadata field {key!r} should be a number, got {v!r}") from None
    raise ValueError(f"{path}: metadata field {key!r} not found")


def _lanl_bar_setup(meta: dict[str, str], path: Path, compression_sign: int, name: str) -> BarSetup:
    """Bar set-up from a HopPyBar metadata table (incident and transmitted bar must be alike).

    Volts to strain (two active arms, HopPyBar's formula): eps = 2 U / (GF * gain * U_exc), with the
    test-level gains ``Incident/Reflected Bar Gain`` and ``Transmitted Bar Gain``.
    The density is written in g/cm^3 even where the label says kg/m^3; a value below 100 is read as
    g/cm^3.
    """
    def bar(prefix: str) -> dict[str, float]:
        rho = _meta_float(meta, f"{prefix} Bar Density", path)
        return {
            "E": _meta_float(meta, f"{prefix} Bar Young's Modulus", path) * 1e9,
            "rho": rho * 1e3 if rho < 100.0 else rho,
            "D": _meta_float(meta, f"{prefix} Bar Diameter", path) * 1e-3,
            "x": _meta_float(meta, f"{prefix} Bar Strain Gage Location", path) * 1e-3,
            "GF": _meta_float(meta, f"{prefix} Bar Calibrated Gage Factor", path),
            "Uexc": _meta_float(meta, f"{prefix} Bar Excitation Voltage", path),
        }

    bi, bt = bar("Incident"), bar("Transmitted")
    for q in ("E", "rho", "D"):
        if not math.isclose(bi[q], bt[q], rel_tol=1e-3):
            raise ValueError(f"{path}: incident and transmitted bars differ in {q} "
                             f"({bi[q]} vs {bt[q]}); BarSetup assumes identical bars")
    gain_i = _meta_float(meta, "Incident/Reflected Bar Gain", path)
    gain_t = _meta_float(meta, "Transmitted Bar Gain", path)
    return BarSetup(
        E=bi["E"], rho=bi["rho"], diameter=bi["D"],
        gauge_distance_incident=bi["x"], gauge_distance_transmitted=bt["x"],
        strain_per_volt_incident=bridge_strain_per_volt(bi["Uexc"], gain_i, bi["GF"], active_arms=2),
        strain_per_volt_transmitted=bridge_strain_per_volt(bt["Uexc"], gain_t, bt["GF"], active_arms=2),
        compression_sign=compression_sign,
        name=name,
    )


def read_lanl_raw(path: str | Path) -> RawRecord:
    """Read a LANL HopPyBar ``.raw`` record (e.g. ``LANLstandard/Cu/20061201_1148HE_CuOFE_273K.raw``).

    Tab-delimited, cp1252. Columns 1-2: the metadata table (label, value). Columns 3-4: the
    ``Incident/Reflected Waveform`` and ``Transmitted Waveform`` [V]; in each, the first numeric row
    is t0 [s], the second dt [s], then the voltages. One gauge signal per bar (the bridge already
    sums the opposite gauges). Positive voltage is compression (``compression_sign=+1``).
    Specimen diameter/length and the bar set-up are taken from the metadata.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"LANL .raw record not found: {path}")
    lines = path.read_bytes().decode("cp1252").splitlines()
    if not lines:
        raise ValueError(f"{path}: empty file")
    meta: dict[str, str] = {}
    wave: list[tuple[float, float]] = []
    first = lines[0].split("\t")
    if len(first) < 4 or "incident" not in first[2].lower() or "transmitted" not in first[3].lower():
        raise ValueError(f"{path}: expected columns 3-4 of line 1 to be 'Incident/Reflected Waveform' "
                         f"and 'Transmitted Waveform', got {first[2:4]!r}")
    meta[first[0].strip()] = first[1].strip()
    for lineno, line in enumerate(lines[1:], start=2):
        parts = line.split("\t")
        if len(parts) < 4:
            raise ValueError(f"{path}: line {lineno}: expected 4 tab-separated columns "
                             f"(label, value, incident V, transmitted V), got {len(parts)}")
        if parts[0].strip():
            meta[parts[0].strip()] = parts[1].strip()
        try:
            wave.append((float(parts[2]), float(parts[3])))
        except ValueError:
            raise ValueError(f"{path}: line {lineno}: waveform columns 3-4 should be numbers, "
                             f"got {parts[2:4]!r}") from None
    arr = np.asarray(wave)
    if arr.shape[0] < 3:
        raise ValueError(f"{path}: waveform columns need t0, dt and samples; got {arr.shape[0]} rows")
    t0, dt = float(arr[0, 0]), float(arr[1, 0])
    if not (dt > 0) or not math.isclose(arr[1, 0], arr[1, 1]) or not math.isclose(arr[0, 0], arr[0, 1]):
        raise ValueError(f"{path}: waveform t0/dt rows should be equal in both columns with dt > 0, "
                         f"got t0={arr[0].tolist()}, dt={arr[1].tolist()}")
    volts = arr[2:]
    n = volts.shape[0]
    bar = _lanl_bar_setup(meta, path, compression_sign=+1, name=f"LANL {meta.get('System ID', '')} bars")
    return RawRecord(
        name=path.stem,
        source=str(path),
        time=t0 + dt * np.arange(n),
        incident=volts[:, 0][None, :],
        transmitted=volts[:, 1][None, :],
        unit="V",
        sample_rate=1.0 / dt,
        incident_channels=("incident",),
        transmitted_channels=("transmitted",),
        bar=bar,
        specimen_length=_meta_float(meta, "Initial Sample Length", path) * 1e-3,
        specimen_diameter=_meta_float(meta, "Initial Sample Diameter", path) * 1e-3,
        header=meta,
    )


def _read_tektronix_csv(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """Time [s], voltage [V] and sample interval [s] of one Tektronix CSV channel file."""
    interval = None
    with path.open("r", encoding="latin-1") as fh:
        for _, line in zip(range(10), fh):
            parts = [p.strip().strip('"') for p in line.split(",")]
            if parts and parts[0] == "Sample Interval":
                interval = float(parts[1])
    if interval is None:
        raise ValueError(f"{path}: Tektronix header field 'Sample Interval' not found in the first rows")
    try:
        data = np.loadtxt(path, delimiter=",", usecols=(3, 4), encoding="latin-1")
    except ValueError as exc:
        raise ValueError(f"{path}: columns 4-5 should hold time [s] and voltage [V] on every row ({exc})") from None
    return data[:, 0], data[:, 1], interval


def read_lanl_minikolsky(input_dat: str | Path) -> RawRecord:
    """Read a LANL mini-Kolsky test: ``<test>_Input.dat`` plus ``*_Ch1..Ch4.csv`` in the same folder.

    Ch1/Ch2 are the incident-bar gauges and Ch3/Ch4 the transmitted-bar gauges (Tektronix CSV,
    columns 4-5 = time [s], voltage [V]). On this set-up the first (compressive) incident pulse is
    negative, so ``compression_sign=-1``. Bars and specimen come from the test sheet (square bars
    and specimen enter through their equivalent diameters).
    """
    input_dat = Path(input_dat)
    if not input_dat.is_file():
        raise FileNotFoundError(f"mini-Kolsky test sheet not found: {input_dat}")
    meta: dict[str, str] = {}
    for line in input_dat.read_bytes().decode("cp1252").splitlines():
        parts = line.split("\t")
        if len(parts) >= 2 and parts[0].strip():
            meta[parts[0].strip()] = parts[1].strip().strip('"')
    chans = sorted(input_dat.parent.glob("*_Ch[1-4].csv"))
    if len(chans) != 4:
        raise ValueError(f"{input_dat.parent}: expected four channel files *_Ch1..Ch4.csv, found {len(chans)}")
    reads = [_read_tektronix_csv(p) for p in chans]
    t, _, dt = reads[0]
    for p, (ti, _, dti) in zip(chans, reads):
        if ti.size != t.size or not math.isclose(dti, dt) or not np.allclose(ti, t, atol=0.5 * dt, rtol=0):
            raise ValueError(f"{p}: time axis differs from {chans[0].name}")
    _check_uniform_time(t, dt, chans[0], "'Sample Interval'")
    bar = _lanl_bar_setup(meta, input_dat, compression_sign=-1, name="LANL mini-Kolsky Al 7075-T6 bars")
    return RawRecord(
        name=input_dat.stem.replace("_Input", ""),
        source=str(input_dat.parent),
        time=t,
        incident=np.vstack([reads[0][1], reads[1][1]]),
        transmitted=np.vstack([reads[2][1], reads[3][1]]),
        unit="V",
        sample_rate=1.0 / dt,
        incident_channels=("Ch1", "Ch2"),
        transmitted_channels=("Ch3", "Ch4"),
        bar=bar,
        specimen_length=_meta_float(meta, "Initial Sample Length", input_dat) * 1e-3,
        specimen_diameter=_meta_float(meta, "Initial Sample Diameter", input_dat) * 1e-3,
        header=meta,
    )


# --------------------------------------------------------------------------------------------------
# H. Yao SHPB/SHTB data-processor exports
# --------------------------------------------------------------------------------------------------
_YAO_UNIT_SCALE = {"voltage": ("V", 1.0), "v": ("V", 1.0), "strain": ("strain", 1.0), "ε": ("strain", 1.0),
                   "με": ("strain", 1e-6), "µε": ("strain", 1e-6), "microstrain": ("strain", 1e-6)}


def _yao_details(folder: Path) -> dict[str, float]:
    """Bar and specimen numbers [SI] from ``experiment_details_en-US.txt`` in a material folder."""
    path = folder / "experiment_details_en-US.txt"
    if not path.is_file():
        raise FileNotFoundError(f"Yao experiment details not found: {path}")
    text = path.read_text(encoding="utf-8")
    want = {
        "Bar diameter": ("D", 1e-3), "Specimen length": ("L", 1e-3), "Specimen diameter": ("Ds", 1e-3),
        "Bar elastic modulus": ("E", 1e9), "Bar density": ("rho", 1.0),
        "Incident-bar strain gauge distance to specimen end face": ("xi", 1e-3),
        "Transmitted-bar strain gauge distance to specimen end face": ("xt", 1e-3),
    }
    out: dict[str, float] = {}
    for label, (key, scale) in want.items():
        m = re.search(r"^- " + re.escape(label) + r":\s*`([0-9.eE+-]+)", text, flags=re.M)
        if m is None:
            raise ValueError(f"{path}: field {label!r} (e.g. '- {label}: `20 mm`') not found")
        out[key] = float(m.group(1)) * scale
    return out


def read_yao_record(path: str | Path, strain_per_volt: float | None = None) -> RawRecord:
    """Read one H. Yao SHPB export (``raw_voltage``/``raw_strain``/``raw_microstrain`` .csv/.xls/.xlsx,
    or a steel batch input), with bars and specimen from the material folder's
    ``experiment_details_en-US.txt`` (the first folder above the file that has one).

    Columns: ``Time/s``, ``incident_bar_signal/<unit>``, ``transmission_bar_signal/<unit>`` with unit
    ``voltage``, ``ε`` or ``με``. Microstrain is converted to strain. Voltage files need
    ``strain_per_volt`` (PROVENANCE: 5.01e-4 for epoxy and AZ42M, 4.96e-4 for 945 steel).
    Compression is negative in these files (``compression_sign=-1``). If the time column is not
    uniform (rounded to 3 significant digits in the epoxy sample_01 CSVs), the time axis is rebuilt
    as ``t0 + i*dt`` with ``dt = (t_end - t0)/(n - 1)``; the record's ``notes`` say so.
    Caveat (PROVENANCE): ``epoxy_resin/sample_01/raw_strain.csv`` has the factor applied twice; use
    its ``raw_voltage.csv``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Yao record not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        raw = path.read_bytes()
        for enc in ("utf-8", "gbk", "latin-1"):
            try:
                text = raw.decode(enc)
                break
            except UnicodeDecodeError:
                continue
        header = text.splitlines()[0].split(",")
        body = np.loadtxt(text.splitlines()[1:], delimiter=",")
    elif suffix == ".xls":  # old BIFF format: xlrd directly (pandas' xlrd engine is deprecated)
        import xlrd

        sheet = xlrd.open_workbook(str(path)).sheet_by_index(0)
        header = [str(v) for v in sheet.row_values(0)]
        body = pd.DataFrame([sheet.row_values(r) for r in range(1, sheet.nrows)]).apply(
            pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    elif suffix == ".xlsx":
        df = pd.read_excel(path, header=None, engine="openpyxl")
        header = [str(h) for h in df.iloc[0]]
        body = df.iloc[1:].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    else:
        raise ValueError(f"{path}: expected a .csv, .xls or .xlsx file")
    if len(header) < 3 or not header[0].strip().lower().startswith("time"):
        raise ValueError(f"{path}: expected header 'Time/s, incident_bar_signal/<unit>, "
                         f"transmission_bar_signal/<unit>', got {header!r}")
    if body.ndim != 2 or body.shape[1] < 3 or np.isnan(body[:, :3]).any():
        raise ValueError(f"{path}: expected three numeric columns (time, incident, transmitted) on every row")
    unit_text = header[1].split("/")[-1].strip().lower()
    if unit_text in _YAO_UNIT_SCALE:
        unit, scale = _YAO_UNIT_SCALE[unit_text]
    elif "micro" in path.stem.lower():  # garbled 'με' in a non-UTF-8 header
        unit, scale = "strain", 1e-6
    elif "strain" in path.stem.lower():
        unit, scale = "strain", 1.0
    else:
        raise ValueError(f"{path}: unknown signal unit {unit_text!r} (expected voltage, ε or με)")
    if unit == "V" and strain_per_volt is None:
        raise ValueError(f"{path}: voltage record needs strain_per_volt (see the folder's PROVENANCE.md)")

    time = body[:, 0]
    n = time.size
    notes = []
    dt = (time[-1] - time[0]) / (n - 1)
    if np.max(np.abs(np.diff(time) - dt)) > 0.01 * dt:
        notes.append(f"time column not uniform (rounded); rebuilt as t0 + i*{dt:.6g} s")
    time = time[0] + dt * np.arange(n)

    folder = next((p for p in path.parents if (p / "experiment_details_en-US.txt").is_file()), None)
    if folder is None:
        raise FileNotFoundError(f"{path}: no experiment_details_en-US.txt in any parent folder")
    d = _yao_details(folder)
    spv = 1.0 if unit == "strain" else float(strain_per_volt)
    bar = BarSetup(E=d["E"], rho=d["rho"], diameter=d["D"], gauge_distance_incident=d["xi"],
                   gauge_distance_transmitted=d["xt"], strain_per_volt_incident=spv,
                   strain_per_volt_transmitted=spv, compression_sign=-1, name="Yao steel bars")
    return RawRecord(
        name=f"{folder.name}/{path.relative_to(folder).with_suffix('')}",
        source=str(path),
        time=time,
        incident=body[:, 1][None, :] * scale,
        transmitted=body[:, 2][None, :] * scale,
        unit=unit,
        sample_rate=1.0 / dt,
        incident_channels=("incident",),
        transmitted_channels=("transmitted",),
        bar=bar,
        specimen_length=d["L"],
        specimen_diameter=d["Ds"],
        header={"columns": ",".join(header)},
        notes=notes,
    )
