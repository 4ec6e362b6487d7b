"""Readers for measured SHPB records and their specimen metadata.

Every reader returns a :class:`RawRecord`: the time axis and the untouched gauge channels of the
incident and the transmission bar (volts, or strain when the lab exported strain), together with the
:class:`~shpb.lab.reduction.BarSetup` that converts them (bar E, rho, diameter, gauge distances,
volts-to-strain factors, sign of compression). The reduction itself lives in :mod:`shpb.lab.reduction`.

Formats read here (see the PROVENANCE.md of each folder under ``data/``):

* Freiburg (Rae et al. 2021) DAQ ASCII export, ``;``-delimited, 11 header lines, decimal separator
  ``.`` or ``,``: :func:`read_freiburg_raw`; specimen spreadsheets ``Rae2021/<lith>.xlsx``:
  :func:`read_freiburg_metadata`, :func:`freiburg_specimen`; rock properties
  ``PetrophysicalProperties.xlsx``: :func:`read_petrophysical_properties`, :func:`rock_properties`.
* Other labs (LANL HopPyBar and mini-Kolsky, H. Yao's processor exports): :mod:`shpb.lab.other_labs`.

Units are SI everywhere in what these functions return (s, m, Pa, kg/m^3, strain, V).
Malformed input raises :class:`ValueError` whose message names the file and the field expected.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .bars import FREIBURG_BAR, BarSetup

__all__ = [
    "RawRecord",
    "read_freiburg_raw",
    "read_freiburg_metadata",
    "freiburg_specimen",
    "read_petrophysical_properties",
    "rock_properties",
    "LITHOLOGY_NAMES",
]


# --------------------------------------------------------------------------------------------------
# The common record structure
# --------------------------------------------------------------------------------------------------
@dataclass
class RawRecord:
    """One measured SHPB record as read from the lab's files, before any reduction.

    Attributes
    ----------
    name : str
        Test name (file stem for the Freiburg records; it matches the spreadsheet ``Name``).
    source : str
        Path of the file (or folder) read.
    time : ndarray, shape (n,)
        DAQ time [s], uniform step ``1/sample_rate``; its origin is the lab's (arbitrary, may be < 0).
    incident : ndarray, shape (n_gauges_incident, n)
        Incident-bar gauge channels in ``unit`` (one row per gauge; opposite gauges are averaged
        by the reduction to cancel bending).
    transmitted : ndarray, shape (n_gauges_transmitted, n)
        Transmission-bar gauge channels in ``unit``.
    unit : str
        ``"V"`` (convert with ``bar.strain_per_volt_*``) or ``"strain"`` (already strain, the
        reduction uses a factor of 1).
    sample_rate : float
        Sampling frequency [Hz].
    incident_channels, transmitted_channels : tuple of str
        Channel names, in the row order of ``incident`` / ``transmitted``.
    bar : BarSetup or None
        The bars and measurement chain, when the file (or the lab's documentation) defines them.
    specimen_length, specimen_diameter : float or None
        Specimen dimensions [m] when the file holds them (Freiburg: see :func:`freiburg_specimen`).
    header : dict
        The file's header / metadata fields as read (strings), for traceability.
    notes : list of str
        Anything the reader had to decide (e.g. a rebuilt time axis).
    """

    name: str
    source: str
    time: np.ndarray
    incident: np.ndarray
    transmitted: np.ndarray
    unit: str
    sample_rate: float
    incident_channels: tuple[str, ...]
    transmitted_channels: tuple[str, ...]
    bar: BarSetup | None = None
    specimen_length: float | None = None
    specimen_diameter: float | None = None
    header: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.time = np.asarray(self.time, dtype=float)
        self.incident = np.atleast_2d(np.asarray(self.incident, dtype=float))
        self.transmitted = np.atleast_2d(np.asarray(self.transmitted, dtype=float))
        n = self.time.size
        if self.incident.shape[1] != n or self.transmitted.shape[1] != n:
            raise ValueError(
                f"{self.source}: channel lengths {self.incident.shape}, {self.transmitted.shape} "
                f"do not match the time axis ({n} samples)"
            )
        if self.unit not in ("V", "strain"):
            raise ValueError(f"{self.source}: unit must be 'V' or 'strain', got {self.unit!r}")
        if len(self.incident_channels) != self.incident.shape[0]:
            raise ValueError(f"{self.source}: {len(self.incident_channels)} incident channel names "
                             f"for {self.incident.shape[0]} channels")
        if len(self.transmitted_channels) != self.transmitted.shape[0]:
            raise ValueError(f"{self.source}: {len(self.transmitted_channels)} transmitted channel "
                             f"names for {self.transmitted.shape[0]} channels")

    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
        return 1.0 / self.sample_rate

    @property
    def n_samples(self) -> int:
        return int(self.time.size)


def _check_uniform_time(time: np.ndarray, dt: float, path: Path, what: str) -> None:
    """Raise if the time column departs from ``time[0] + i*dt`` by more than half a step."""
    ideal = time[0] + dt * np.arange(time.size)
    dev = float(np.max(np.abs(time - ideal))) if time.size else 0.0
    if dev > 0.5 * dt:
        raise ValueError(
            f"{path}: time column is not uniform with the {what} step {dt:.6g} s "
            f"(largest deviation {dev:.3g} s)"
        )


# --------------------------------------------------------------------------------------------------
# Freiburg DAQ ASCII export
# --------------------------------------------------------------------------------------------------
_FREIBURG_HEADER_LINES = 11
_FREIBURG_CHANNELS = ("A1", "A2", "A3", "A4")


def _parse_number(text: str, decimal: str) -> float:
    t = text.strip()
    if decimal == ",":
        t = t.replace(",", ".")
    return float(t)


def _check_finite(values: np.ndarray, linenos: list[int], path: Path) -> None:
    """float() reads "nan" and "inf": a gap in the DAQ export must not become a curve."""
    bad_rows, bad_cols = np.nonzero(~np.isfinite(values))
    if bad_rows.size:
        r, c = int(bad_rows[0]), int(bad_cols[0])
        what = "time [s]" if c == 0 else f"channel {_FREIBURG_CHANNELS[c - 1]} " \
            f"({'incident' if c < 3 else 'transmission'} bar gauge {2 - c % 2}) [V]"
        raise ValueError(f"{path}: line {linenos[r]}: {what}: expected a finite number, got "
                         f"{values[r, c]!r} ({bad_rows.size} non-finite value(s) in the data rows)")


def read_freiburg_raw(path: str | Path, bar: BarSetup | None = FREIBURG_BAR) -> RawRecord:
    """Read one Freiburg DAQ record (``Rae2021/SHPBdata/<lith>/<name>.txt``).

    Format: 11 header lines (``Starttime``, ``Triggertime``, ``TriggerSample``,
    ``Samplerate;1250000 Hz``, ``Blocklength``, a blank line, channel names ``A1..A4``, signal kinds,
    units ``s;V;V;V;V``, two blank lines), then one ``;``-delimited row per sample: time [s] and the
    voltages of incident gauges 1, 2 (A1, A2) and transmission gauges 1, 2 (A3, A4). The decimal
    separator is ``,`` (SeeSst files) or ``.`` (the others); it is detected from the data rows.

    The sample rate comes from the header; the time column must agree with it (to half a step) and
    the number of data rows must equal ``Blocklength``.

    Parameters
    ----------
    path : path to the ``.txt`` file.
    bar : the bar set-up attached to the record (default: the Freiburg titanium bars,
        :data:`shpb.lab.reduction.FREIBURG_BAR`).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If a header field is missing or malformed, a data row is not five numbers, the sample rate
        disagrees with the time column, or the row count disagrees with ``Blocklength``. The message
        names the file, the line and the field expected.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Freiburg raw record not found: {path}")
    text = path.read_bytes().decode("latin-1")
    lines = text.splitlines()
    if len(lines) <= _FREIBURG_HEADER_LINES:
        raise ValueError(
            f"{path}: expected {_FREIBURG_HEADER_LINES} header lines followed by data rows, "
            f"found only {len(lines)} lines"
        )

    header: dict[str, str] = {}
    for line in lines[:_FREIBURG_HEADER_LINES]:
        if not line.strip():
            continue
        key, _, value = line.partition(";")
        header[key.strip()] = value.strip()

    if "Samplerate" not in header:
        raise ValueError(
            f"{path}: header field 'Samplerate' (e.g. 'Samplerate;1250000 Hz') not found in the "
            f"first {_FREIBURG_HEADER_LINES} lines"
        )
    m = re.fullmatch(r"\s*([0-9.,eE+-]+)\s*(Hz)?\s*;?\s*", header["Samplerate"])
    try:
        if m is None:
            raise ValueError
        sample_rate = _parse_number(m.group(1), "," if "," in m.group(1) else ".")
    except ValueError:
        raise ValueError(
            f"{path}: header field 'Samplerate' should be '<number> Hz', got {header['Samplerate']!r}"
        ) from None
    if not (sample_rate > 0 and math.isfinite(sample_rate)):
        raise ValueError(f"{path}: header field 'Samplerate' must be positive, got {sample_rate}")

    units = header.get("s")  # the units line reads 's;V;V;V;V;' -> key 's'
    if units is not None and units.rstrip(";").split(";")[:4] != ["V"] * 4:
        raise ValueError(f"{path}: header units line should be 's;V;V;V;V', got 's;{units}'")

    data_lines = [(i, ln) for i, ln in enumerate(lines[_FREIBURG_HEADER_LINES:], start=_FREIBURG_HEADER_LINES + 1)
                  if ln.strip()]
    if not data_lines:
        raise ValueError(f"{path}: no data rows after the {_FREIBURG_HEADER_LINES} header lines")
    decimal = "," if "," in data_lines[0][1] else "."

    values = np.empty((len(data_lines), 5))
    for row, (lineno, ln) in enumerate(data_lines):
        fields = [f for f in ln.strip().split(";") if f.strip() != ""]
        if len(fields) != 5:
            raise ValueError(
                f"{path}: line {lineno}: expected 5 ';'-separated numbers (time [s], A1..A4 [V]), "
                f"got {len(fields)} fields: {ln.strip()!r}"
            )
        try:
            values[row] = [_parse_number(f, decimal) for f in fields]
        except ValueError:
            raise ValueError(
                f"{path}: line {lineno}: expected numbers with decimal separator {decimal!r} "
                f"(time [s], A1..A4 [V]), got {ln.strip()!r}"
            ) from None

    _check_finite(values, [ln for ln, _ in data_lines], path)
    if "Blocklength" in header:
        try:
            block = int(header["Blocklength"].strip().rstrip(";"))
        except ValueError:
            raise ValueError(f"{path}: header field 'Blocklength' should be an integer, "
                             f"got {header['Blocklength']!r}") from None
        if block != values.shape[0]:
            raise ValueError(
                f"{path}: header 'Blocklength' says {block} samples but {values.shape[0]} data rows "
                f"were found (truncated or padded file?)"
            )

    time = values[:, 0]
    dt = 1.0 / sample_rate
    _check_uniform_time(time, dt, path, "header 'Samplerate'")
    record = RawRecord(
        name=path.stem,
        source=str(path),
        time=time,
        incident=values[:, 1:3].T,
        transmitted=values[:, 3:5].T,
        unit="V",
        sample_rate=sample_rate,
        incident_channels=_FREIBURG_CHANNELS[:2],
        transmitted_channels=_FREIBURG_CHANNELS[2:],
        bar=bar,
        header=header,
        notes=[f"decimal separator {decimal!r}"],
    )
    return record


# --------------------------------------------------------------------------------------------------
# Freiburg spreadsheets
# --------------------------------------------------------------------------------------------------
#: Lithology codes -> names used in ``PetrophysicalProperties.xlsx``.
LITHOLOGY_NAMES = {
    "CaMa": "Carrara Marble",
    "SaLi": "Savonnieres Limestone",
    "SeeSst": "Seeberger Sandstone",
    "TaQu": "Taunus Quartzite",
    "MaGr": "Malsburg Granite",
    "MaGn": "Maggia Gneiss",
}

# spreadsheet header -> (output column, scale to SI); the column after a "mu" column holds sigma.
_META_COLUMNS = {
    "Name": ("name", None),
    "Experiment Type": ("experiment_type", None),
    "P (bar)": ("gas_pressure_Pa", 1.0e5),
    "Sample Length (mm)": ("length_m", 1.0e-3),
    "Sample Diameter (mm)": ("diameter_m", 1.0e-3),
    "Failure?": ("failure", None),
    "Strength (MPa)": ("strength_Pa", 1.0e6),
    "Max. Stress (MPa)": ("max_stress_Pa", 1.0e6),
    "Strain Rate (/s)": ("strain_rate_per_s", 1.0),
    "Young's Modulus (GPa)": ("E_Pa", 1.0e9),
    "Failure Strain": ("failure_strain", 1.0),
    "Max Strain": ("max_strain", 1.0),
    "E_abs": ("energy_absorbed_J", 1.0),
    "E_del": ("energy_delivered_J", 1.0),
    "E_trans": ("energy_transmitted_J", 1.0),
    "Poi": ("poisson_ratio", 1.0),
}
_META_WITH_SIGMA = {"strength_Pa", "max_stress_Pa", "strain_rate_per_s", "E_Pa"}


def _sheet_rows(xlsx_path: Path, sheet: str | None = None) -> list[list]:
    """The cell values of one sheet of a spreadsheet (the first when ``sheet`` is None), row by row,
    padded to one width. openpyxl's read-only reader (the engine of pandas' ``read_excel``) is called
    directly: a simulation of a measured record looks up its specimen in a fresh process, and pandas'
    import would cost it 0.2 s."""
    from openpyxl import load_workbook

    wb = load_workbook(xlsx_path, read_only=True, data_only=True)
    try:
        if sheet is not None and sheet not in wb.sheetnames:
            raise ValueError(f"{xlsx_path}: no sheet named {sheet!r} (sheets: {wb.sheetnames})")
        ws = wb.worksheets[0] if sheet is None else wb[sheet]
        rows = [list(r) for r in ws.iter_rows(values_only=True)]
    finally:
        wb.close()
    width = max((len(r) for r in rows), default=0)
    return [r + [None] * (width - len(r)) for r in rows]


def _number(v) -> float:
    """A cell as a float, NaN when it holds no number (``pd.to_numeric(errors="coerce")`` of one cell)."""
    if isinstance(v, bool) or v is None:
        return math.nan
    if isinstance(v, (int, float)):
        return float(v)
    if isinstance(v, str):
        try:
            return float(v.strip())
        except ValueError:
            return math.nan
    return math.nan


def _present(v) -> bool:
    """A cell holds a value (``pd.notna`` of one cell)."""
    return v is not None and not (isinstance(v, float) and math.isnan(v))


def _metadata_columns(xlsx_path: Path) -> dict[str, list]:
    """The columns of :func:`read_freiburg_metadata` as lists (one entry per test)."""
    rows = _sheet_rows(xlsx_path)
    hits = [i for i, r in enumerate(rows) if str(r[0]).strip() == "Name"]
    if not hits:
        raise ValueError(f"{xlsx_path}: no header row with 'Name' in the first column")
    hrow = hits[0]
    headers = [str(h).strip() if isinstance(h, str) else None for h in rows[hrow]]
    body = rows[hrow + 2:]  # skip the mu/sigma sub-header
    out: dict[str, list] = {}
    for col, head in enumerate(headers):
        if head is None or head not in _META_COLUMNS:
            continue
        name, scale = _META_COLUMNS[head]
        cells = [r[col] for r in body]
        if scale is None:
            out[name] = [str(v).strip() if isinstance(v, str) or _present(v) else None for v in cells]
        else:
            out[name] = [_number(v) * scale for v in cells]
        if name in _META_WITH_SIGMA and col + 1 < len(headers):
            out[name.replace("_Pa", "_sd_Pa").replace("_per_s", "_sd_per_s")] = [_number(r[col + 1]) * scale
                                                                                   for r in body]
    missing = [n for n in ("name", "length_m", "diameter_m") if n not in out]
    if missing:
        raise ValueError(f"{xlsx_path}: required columns not found in the header row: {missing}")
    keep = [i for i, n in enumerate(out["name"]) if n is not None and len(n) > 0]
    out = {k: [v[i] for i in keep] for k, v in out.items()}
    first, *rest = list(out)
    out = {first: out[first], "lithology": [xlsx_path.stem] * len(keep), **{k: out[k] for k in rest}}
    strength = out.get("strength_Pa", [math.nan] * len(keep))
    max_stress = out.get("max_stress_Pa", [math.nan] * len(keep))
    out["reference_stress_Pa"] = [a if a == a else b for a, b in zip(strength, max_stress)]
    return out


def read_freiburg_metadata(xlsx_path: str | Path):
    """Read a Freiburg specimen spreadsheet (``Rae2021/{CaMa,SaLi,SeeSst}.xlsx``), SI units, as a DataFrame.

    One row per test (quasi-static ``UCS`` rows included; filter on ``experiment_type``). Columns:

    ``name`` (raw-file stem for SHPB tests), ``lithology`` (the spreadsheet stem), ``experiment_type``
    (``UCS``/``SHPB``), ``gas_pressure_Pa``, ``length_m``, ``diameter_m``, ``failure`` (``Y``, ``Yp``
    partly failed, ``N`` intact), ``strength_Pa`` and ``strength_sd_Pa`` (failed samples),
    ``max_stress_Pa`` and ``max_stress_sd_Pa`` (intact samples), ``strain_rate_per_s`` and
    ``strain_rate_sd_per_s``, ``E_Pa`` and ``E_sd_Pa``, ``failure_strain``, ``max_strain``,
    ``energy_absorbed_J``, ``energy_delivered_J``, ``energy_transmitted_J``, ``poisson_ratio``, and
    ``reference_stress_Pa`` = ``strength_Pa`` where given, else ``max_stress_Pa`` (the value the
    reduction check compares the measured peak stress with).

    The header row is the row whose first cell is ``Name``; the row below it holds the
    mean/standard-deviation sub-header; columns are located by their header text.
    """
    import pandas as pd

    return pd.DataFrame(_metadata_cached(*_xlsx_key(xlsx_path, "Freiburg specimen spreadsheet")))


def _xlsx_key(xlsx_path: str | Path, what: str) -> tuple[str, float]:
    xlsx_path = Path(xlsx_path)
    if not xlsx_path.is_file():
        raise FileNotFoundError(f"{what} not found: {xlsx_path}")
    return str(xlsx_path.resolve()), xlsx_path.stat().st_mtime


@lru_cache(maxsize=16)
def _metadata_cached(path: str, mtime: float) -> dict[str, list]:
    return _metadata_columns(Path(path))


def freiburg_specimen(raw_path: str | Path) -> dict:
    """The spreadsheet row of a Freiburg raw record, as a dict of :func:`read_freiburg_metadata`'s columns.

    ``<root>/Rae2021/SHPBdata/<lith>/<name>.txt`` is looked up as ``Name == <name>`` in
    ``<root>/Rae2021/<lith>.xlsx`` (SI units; a missing number is NaN).

    Raises
    ------
    FileNotFoundError
        If the spreadsheet is missing.
    KeyError
        If the record's name is not in the spreadsheet.
    """
    raw_path = Path(raw_path)
    lith = raw_path.parent.name
    xlsx = raw_path.parent.parent.parent / f"{lith}.xlsx"
    if not xlsx.is_file():
        raise FileNotFoundError(
            f"specimen spreadsheet for {raw_path.name} not found: expected {xlsx} "
            f"(Rae2021/<lithology>.xlsx next to SHPBdata/)"
        )
    meta = _metadata_cached(*_xlsx_key(xlsx, "Freiburg specimen spreadsheet"))
    if raw_path.stem not in meta["name"]:
        raise KeyError(f"{raw_path.stem!r} not found in the 'Name' column of {xlsx}")
    i = meta["name"].index(raw_path.stem)
    return {k: v[i] for k, v in meta.items()}


# --------------------------------------------------------------------------------------------------
# Petrophysical properties
# --------------------------------------------------------------------------------------------------
def _petrophysical_columns(xlsx_path: Path) -> dict[str, list]:
    """The columns of :func:`read_petrophysical_properties` as lists (one entry per rock and variant)."""
    rows = _sheet_rows(xlsx_path, "Summary")
    if not rows:
        raise ValueError(f"{xlsx_path}: sheet 'Summary' is empty")
    head = [str(h).strip() if isinstance(h, str) else "" for h in rows[0]]

    def col(prefix: str) -> int:
        for i, h in enumerate(head):
            if h.startswith(prefix):
                return i
        raise ValueError(f"{xlsx_path}: sheet 'Summary' has no column starting with {prefix!r}")

    spec = [  # (sheet header prefix, output name, scale, has sigma)
        ("E (GPa)", "E_Pa", 1e9, True),
        ("Poi", "nu", 1.0, True),
        ("rho (g/cc)", "rho_kg_m3", 1e3, True),
        ("P-Mod (GPa)", "P_modulus_Pa", 1e9, False),
        ("Vp (km/s)", "Vp_m_s", 1e3, True),
        ("phi", "porosity", 1.0, True),
        ("K_Ic", "K_Ic_Pa_sqrt_m", 1e6, True),
    ]
    body = rows[1:]
    names, current = [], None
    for r in body:  # a rock's name stands on its first row only (its variants follow)
        current = r[0] if isinstance(r[0], str) else current
        names.append(current)
    out: dict[str, list] = {"lithology": names,
                            "variant": [r[1].strip() if isinstance(r[1], str) else "" for r in body]}
    for prefix, name, scale, has_sd in spec:
        c = col(prefix)
        out[name] = [_number(r[c]) * scale for r in body]
        if has_sd:
            sd_name = name.replace("_Pa", "_sd_Pa").replace("_kg_m3", "_sd_kg_m3").replace("_m_s", "_sd_m_s")
            if sd_name == name:
                sd_name = name + "_sd"
            if name == "K_Ic_Pa_sqrt_m":
                sd_name = "K_Ic_sd_Pa_sqrt_m"
            out[sd_name] = [_number(r[c + 1]) * scale for r in body]
    keep = [i for i, (n, e) in enumerate(zip(out["lithology"], out["E_Pa"])) if n is not None and e == e]
    codes = {v.lower(): k for k, v in LITHOLOGY_NAMES.items()}
    lith = [out["lithology"][i] for i in keep]
    return {"lithology": lith, "code": [codes.get(n.strip().lower(), "") for n in lith]} | {
        k: [v[i] for i in keep] for k, v in out.items() if k != "lithology"}


@lru_cache(maxsize=4)
def _petrophysical_cached(path: str, mtime: float) -> dict[str, list]:
    return _petrophysical_columns(Path(path))


def read_petrophysical_properties(xlsx_path: str | Path):
    """Rock properties from ``PetrophysicalProperties.xlsx`` (sheet ``Summary``), SI units, as a DataFrame.

    Columns: ``lithology`` (full name, e.g. ``Carrara Marble``), ``code`` (``CaMa`` ...),
    ``variant`` (``Parallel``/``Perpendicular`` for the gneiss, else empty), ``E_Pa``, ``E_sd_Pa``,
    ``nu``, ``nu_sd``, ``rho_kg_m3``, ``rho_sd_kg_m3``, ``P_modulus_Pa``, ``Vp_m_s``, ``Vp_sd_m_s``,
    ``porosity``, ``porosity_sd``, ``K_Ic_Pa_sqrt_m``, ``K_Ic_sd_Pa_sqrt_m``.
    The sheet's units are GPa, g/cm^3, km/s and MPa m^0.5; each value is followed by its sigma.
    """
    import pandas as pd

    return pd.DataFrame(_petrophysical_cached(*_xlsx_key(xlsx_path, "petrophysical-properties spreadsheet")))


def rock_properties(lithology: str, xlsx_path: str | Path | None = None, variant: str = "") -> dict[str, float]:
    """E [Pa], nu [-], rho [kg/m^3] (and their sigmas) of one lithology.

    ``lithology`` is a code (``CaMa``, ``SaLi``, ``SeeSst``, ...) or a name (``Carrara Marble``),
    case-insensitive. ``xlsx_path`` defaults to ``data/freiburg-rae-rock-shpb/PetrophysicalProperties.xlsx``
    (``shpb.paths``; a missing file raises FileNotFoundError naming it and ``FDEM_DATA_DIR``).
    For the gneiss pass ``variant="Parallel"`` or ``"Perpendicular"``.

    Raises
    ------
    KeyError
        If the lithology (and variant) is not in the sheet.
    """
    if xlsx_path is None:
        from ..paths import data_file, freiburg_data_dir

        xlsx_path = data_file(freiburg_data_dir() / "PetrophysicalProperties.xlsx")
    table = _petrophysical_cached(*_xlsx_key(xlsx_path, "petrophysical-properties spreadsheet"))
    key = lithology.strip().lower()
    sel = [i for i, (code, name) in enumerate(zip(table["code"], table["lithology"]))
           if code.lower() == key or name.strip().lower() == key]
    if variant:
        sel = [i for i in sel if table["variant"][i].lower() == variant.lower()]
    if not sel:
        raise KeyError(f"lithology {lithology!r} (variant {variant!r}) not in {xlsx_path}; "
                       f"known: {sorted(set(table['lithology']))}")
    row = {k: v[sel[0]] for k, v in table.items()}
    return {
        "E": float(row["E_Pa"]), "E_sd": float(row["E_sd_Pa"]),
        "nu": float(row["nu"]), "nu_sd": float(row["nu_sd"]),
        "rho": float(row["rho_kg_m3"]), "rho_sd": float(row["rho_sd_kg_m3"]),
    }
