"""Test sheets generated from the Freiburg spreadsheets: the Freiburg layout (raw DAQ file, the
specimen's row in ``Rae2021/<lith>.xlsx``, the rock in ``PetrophysicalProperties.xlsx``, the bars of
:data:`shpb.lab.bars.FREIBURG_BAR`) written out as a sheet, so that Freiburg records take the same
route as anybody's (``python -m shpb sheet-from-freiburg RAW --out SHEET``).

The sheet carries exactly what today's Freiburg path uses: the bars and bridge constants of
``FREIBURG_BAR``, the specimen's length and diameter from its spreadsheet row, and E, nu, rho of the lithology
(``PetrophysicalProperties.xlsx``). The row's own E, the slope of that test's stress-strain curve, is
kept in ``metadata.test_modulus_Pa`` for the reader: a response of the record, never a model input. Floats are written with
``repr`` digits, so the sheet reproduces those numbers bit for bit.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_text
from .records import freiburg_specimen, rock_properties

__all__ = ["freiburg_sheet", "write_sheet", "FREIBURG_BRIDGE"]

#: The Freiburg bridge (quarter bridge per gauge, U0 = 5 V, gain 400, k = 1.99: shpb.lab.bars).
FREIBURG_BRIDGE = {"excitation_V": 5.0, "gain": 400.0, "gauge_factor": 1.99, "active_arms": 1}


def freiburg_sheet(raw_path: str | Path, sheet_dir: str | Path) -> dict:
    """The sheet of a Freiburg raw record, its ``signals.file`` relative to ``sheet_dir``."""
    raw_path = Path(raw_path)
    spec = freiburg_specimen(raw_path)
    lith = str(spec.get("lithology", raw_path.parent.name))
    rock = rock_properties(lith)
    ref = spec.get("reference_stress_Pa")
    meta = {"notes": f"generated from the Freiburg spreadsheets ({lith}.xlsx, PetrophysicalProperties.xlsx) "
                     f"by shpb.lab.sheet_freiburg"}
    if ref is not None and np.isfinite(ref):
        meta["reference_stress_Pa"] = float(ref)
    if np.isfinite(spec.get("strain_rate_per_s", np.nan)):
        meta["strain_rate_per_s"] = float(spec["strain_rate_per_s"])
    if np.isfinite(spec.get("E_Pa", np.nan)):
        # kept for the reader only: the lab's slope of this test's own stress-strain curve (25-75 % of its
        # peak), a response of the record; the model takes the rock's E (rock.E below)
        meta["test_modulus_Pa"] = float(spec["E_Pa"])
    return {
        "name": m.group(1) if (m := re.match(r"^([A-Za-z]+_SHPB_\d+)(_|$)", raw_path.stem)) else raw_path.stem,
        "signals": {"file": os.path.relpath(raw_path.resolve(), Path(sheet_dir).resolve()),
                    "format": "freiburg", "bridge": dict(FREIBURG_BRIDGE)},
        "bars": {"material": "titanium (Freiburg)", "E": 110.0e9, "rho": 4430.0, "nu": 0.32, "diameter": 0.050,
                 "gauge_distance_incident": 1.25, "gauge_distance_transmitted": 1.00},
        "specimen": {"geometry": "cylinder", "length": float(spec["length_m"]), "diameter": float(spec["diameter_m"])},
        "rock": {"lithology": lith, "E": rock["E"], "nu": rock["nu"], "rho": rock["rho"]},
        "metadata": meta,
    }


def write_sheet(doc: dict, path: str | Path, header: str = "") -> Path:
    """Write a sheet as YAML, atomically (``header``: comment lines put first)."""
    import yaml

    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(doc, sort_keys=False)
    return atomic_write_text(path, text)
