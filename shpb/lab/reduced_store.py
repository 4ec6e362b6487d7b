"""A measured record reduced once and stored for the jobs that read it.

The workflow's observations stage reduces each record of an experiment once and writes
``results/<experiment>/observations/<record>/`` (docs/workflow.md); every simulation of that record then
reads its incident wave and its bars, specimen and rock from there instead of reducing the raw file
again. Three files, SI units:

``incident.csv``
    ``time_s, strain``: the incident wave at the incident gauge (time 0 = its arrival there,
    :meth:`shpb.lab.reduction.ReducedRecord.incident_wave_at_gauge`), the wave a simulation injects.
``curves.csv``
    the reduced record on the specimen-face time axis: ``time_s, stress_Pa`` (back face, the specimen
    stress), ``stress_front_Pa``, ``strain_rate_per_s``, ``strain``, ``force_balance`` (empty where
    undefined).
``record.json``
    ``source`` (the raw file or sheet), ``simulation`` (what a simulation needs besides the wave:
    ``geometry``, specimen ``length``/``diameter`` [m] (a disc's length: None), ``rock`` {E, nu, rho}, ``bars`` (None: the
    Freiburg bars; else ``material`` {E, nu, rho}, ``diameter_m``, ``gauge_distance_m``, ``label``),
    ``specimen``) and ``observation`` (the record's noise, checks and scalars; written by
    :mod:`calibration.observations`). Written last: its presence means the folder is complete.

Numbers are written with 17 significant digits, which read back to the same float64, so a simulation
of the stored wave is the simulation of the raw record's wave, bit for bit.

The noise arithmetic of a record (:func:`pretrigger_stress`) lives here too: the stress samples before
the incident wave reaches the gauge, whose scatter is the record's observation noise.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_text

__all__ = ["INCIDENT_FILE", "CURVES_FILE", "RECORD_FILE", "CURVE_FIELDS", "pretrigger_stress",
           "simulation_inputs", "write_reduced", "read_reduced", "read_curves", "StoredIncident", "is_reduced"]

INCIDENT_FILE = "incident.csv"
CURVES_FILE = "curves.csv"
RECORD_FILE = "record.json"
#: curves.csv column -> ReducedRecord attribute
CURVE_FIELDS = {"time_s": "time", "stress_Pa": "stress", "stress_front_Pa": "stress_front",
                "strain_rate_per_s": "strain_rate", "strain": "strain", "force_balance": "force_balance"}
#: The pre-trigger window ends this long before the incident wave's foot at the gauge [s]: the foot's
#: detection marks where the wave is already above the noise, and its rise starts a few us earlier.
PRETRIGGER_GUARD_S = 10.0e-6


def pretrigger_stress(raw, red, disc_thickness_m: float | None = None) -> np.ndarray:
    """The specimen stress [Pa] the transmitted bar's signal would give before the incident wave arrives:
    the averaged transmitted channels the reduction used, times the reduction's strain-to-stress factor,
    up to :data:`PRETRIGGER_GUARD_S` before the incident foot at the gauge. Its scatter is the record's
    observation noise (its standard deviation and AR(1) correlation time, :func:`enkf.estimate_noise`).

    The factor is ``E_b A_b / (pi D^2 / 4)`` for a cylinder; for a Brazilian disc (``disc_thickness_m``
    given) the stress is ``2 F / (pi D t)``, the cylinder's factor times ``D / (2 t)``."""
    bar = red.bar
    k_pa = bar.E * bar.area / (math.pi * red.specimen_diameter ** 2 / 4.0)
    if disc_thickness_m is not None:
        k_pa *= red.specimen_diameter / (2.0 * float(disc_thickness_m))
    used = [raw.transmitted_channels.index(c) for c in red.channels_used["transmitted"]]
    spv = 1.0 if raw.unit == "strain" else bar.strain_per_volt_transmitted
    tra = bar.compression_sign * spv * raw.transmitted[used].mean(axis=0)
    i_a = int(np.searchsorted(raw.time, red.arrival_time_gauge))
    i_pre = i_a - max(1, int(round(PRETRIGGER_GUARD_S / raw.dt)))
    return k_pa * tra[:i_pre]


def _plain(v):
    """A JSON-ready copy (floats, strings, lists, dicts; a non-finite float kept, as Python's json writes
    and reads it, so that what is read back is what was reduced)."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if v is None or isinstance(v, str):
        return v
    return str(v)


def simulation_inputs(path, *, sheet=None, spec=None) -> dict:
    """What a simulation of a measured record needs besides its incident wave (JSON-ready): a test
    sheet's bars, specimen and rock (``sheet``: its :class:`shpb.lab.sheet.Sheet`), or a Freiburg
    record's specimen from its spreadsheet row (``spec``) with the lithology's mean elastic constants.

    The Freiburg specimen's constants are the rock's, never the test row's E: the source lab took that E
    from the slope of this test's own stress-strain curve, so it is the record's response, and a held-out
    record's prediction may not use it (docs/closing-the-loop.md)."""
    if sheet is not None:
        b = sheet.bar
        bars = {"material": {"E": float(b.E), "nu": float(sheet.bar_nu), "rho": float(b.rho)},
                "diameter_m": float(b.diameter),
                "gauge_distance_m": [float(b.gauge_distance_incident), float(b.gauge_distance_transmitted)],
                "label": sheet.bar_material}
        return _plain({"geometry": sheet.geometry, "length": sheet.specimen_length,
                       "diameter": sheet.specimen_diameter, "rock": dict(sheet.rock), "bars": bars,
                       "specimen": dict(sheet.specimen)})
    from .records import rock_properties

    L, D = float(spec["length_m"]), float(spec["diameter_m"])
    rock = rock_properties(str(spec.get("lithology", Path(path).parent.name)))
    return _plain({"geometry": "cylinder", "length": L, "diameter": D, "rock": dict(rock), "bars": None,
                   "specimen": {"geometry": "cylinder", "length": L, "diameter": D}})


def _csv_text(columns: dict) -> str:
    data = np.column_stack([np.asarray(v, dtype=float) for v in columns.values()])
    rows = (",".join("" if v != v else "%.17g" % v for v in row) for row in data.tolist())
    return "\n".join([",".join(columns), *rows]) + "\n"


def write_reduced(folder, red, *, source, simulation: dict, observation: dict) -> Path:
    """Write a reduced record's folder (module docstring), each file atomically, ``record.json`` last."""
    folder = Path(folder)
    t_g, eps_g = red.incident_wave_at_gauge()
    atomic_write_text(folder / INCIDENT_FILE, _csv_text({"time_s": t_g, "strain": eps_g}))
    atomic_write_text(folder / CURVES_FILE,
                      _csv_text({c: getattr(red, a) for c, a in CURVE_FIELDS.items()}))
    doc = {"source": str(source), "simulation": _plain(simulation), "observation": _plain(observation)}
    return atomic_write_text(folder / RECORD_FILE, json.dumps(doc, indent=1))


def is_reduced(path) -> bool:
    """A record path names a stored reduced record when it is a folder or its ``record.json``."""
    p = Path(path)
    return p.is_dir() or p.name == RECORD_FILE


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    """The columns of one of this module's CSV files (an empty cell is NaN)."""
    with open(path) as fh:
        header = fh.readline().strip().split(",")
        rows = [[float(x) if x else math.nan for x in line.rstrip("\n").split(",")] for line in fh if line.strip()]
    if not rows or any(len(r) != len(header) for r in rows):
        raise ValueError(f"{path}: expected {len(header)} values in every row of {header}")
    data = np.array(rows, dtype=float)
    return {h: data[:, i].copy() for i, h in enumerate(header)}


class StoredIncident:
    """The stored incident wave, in the place of a :class:`~shpb.lab.reduction.ReducedRecord` where a
    simulation asks for it."""

    def __init__(self, time: np.ndarray, strain: np.ndarray, source: str):
        self.incident_gauge_time, self.incident_gauge_strain, self.name = time, strain, source

    def incident_wave_at_gauge(self) -> tuple[np.ndarray, np.ndarray]:
        return self.incident_gauge_time, self.incident_gauge_strain


def read_reduced(path) -> dict:
    """A stored reduced record (its folder or ``record.json``): the ``record.json`` document plus
    ``incident`` (a :class:`StoredIncident`). ValueError names the file when it is malformed."""
    p = Path(path)
    folder = p if p.is_dir() else p.parent
    try:
        doc = json.loads((folder / RECORD_FILE).read_text())
        sim = doc["simulation"]
        for key in ("geometry", "length", "diameter", "rock", "specimen"):
            sim[key]  # noqa: B018 - a missing key is the file's fault, reported below
        wave = _read_csv(folder / INCIDENT_FILE)
        incident = StoredIncident(wave["time_s"], wave["strain"], str(doc["source"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"reduced record {folder}: cannot be read ({type(exc).__name__}: {exc}); "
                         f"expected {RECORD_FILE} and {INCIDENT_FILE} written by the observations stage") from None
    return {**doc, "incident": incident}


def read_curves(path) -> dict[str, np.ndarray]:
    """The stored reduced curves (``curves.csv`` of a reduced record's folder or of its ``record.json``)."""
    p = Path(path)
    return _read_csv((p if p.is_dir() else p.parent) / CURVES_FILE)
