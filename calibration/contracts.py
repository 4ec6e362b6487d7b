"""The workflow's base contracts, below everything else in the package: the simulator's parameter
names, the config error, atomic JSON/CSV writes, and the records of an experiment. Imports nothing
of the package (so that the config validation, the sensitivity stage and the observations can all
use it without import circles)."""
from __future__ import annotations

import json
import re
from collections.abc import Mapping
from pathlib import Path

from shpb.atomic import atomic_write_bytes, atomic_write_text  # noqa: F401 (atomic_write_bytes: re-exported)

__all__ = ["PARAM_NAMES", "ConfigError", "atomic_write_text", "atomic_write_json", "atomic_write_csv", "read_json",
           "record_name", "experiment_records", "known_parameters"]

#: Parameter names the simulator accepts (``--param NAME=VALUE``), SI units (docs/workflow.md, "What goes where").
PARAM_NAMES = ("sigma_n", "sigma_t", "E_n", "E_t", "a", "b", "c", "E", "nu", "rho")


class ConfigError(ValueError):
    """The workflow config is invalid; the message lists every problem with the key that causes it."""


def atomic_write_json(path: str | Path, obj) -> Path:
    """Strict JSON (NaN/inf must already be ``None``), indented, keys in insertion order."""
    return atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def atomic_write_csv(df, path: str | Path) -> Path:
    """``df.to_csv`` without index, floats written with full precision (round-trip exact)."""
    return atomic_write_text(path, df.to_csv(index=False, lineterminator="\n"))


def read_json(path: str | Path) -> dict:
    with open(path) as fh:
        return json.load(fh)


def record_name(path: str | Path) -> str:
    """Short name of a measured record: ``CaMa_SHPB_005`` for ``CaMa_SHPB_005_Ti25_60b_Al12b_0_001.txt``
    (the Freiburg test name), else the file stem."""
    stem = Path(path).stem
    m = re.match(r"^([A-Za-z]+_SHPB_\d+)(_|$)", stem)
    return m.group(1) if m else stem


def experiment_records(exp: Mapping) -> dict[str, str]:
    """``{record name: raw file}``: the measured records of a measured experiment; for a twin
    ``{"synthetic": incident record or ""}`` (the record only supplies a cylinder's incident wave)."""
    if exp["kind"] == "twin":
        return {"synthetic": exp["observations"].get("incident_record") or ""}
    return {record_name(p): str(p) for p in exp["observations"]["records"]}


def known_parameters(geometry: str) -> tuple[str, ...]:
    """Parameter names the simulator accepts for ``geometry``: the contract's :data:`PARAM_NAMES` plus
    the model settings of :mod:`shpb.parameters` (``phi_deg``, ``damping.beta`` ...) when present."""
    try:
        from shpb.parameters import defaults
    except ImportError:  # pragma: no cover - the simulator's parameter table is optional here
        return PARAM_NAMES
    try:
        return tuple(dict.fromkeys([*PARAM_NAMES, *defaults(geometry)]))
    except ValueError:
        return PARAM_NAMES
