"""fdem: a 2D combined finite-discrete element engine (Munjiza's model) compiled with Numba.

Public API: Material, Body (inputs); JointParams, ContactParams, build_model, stable_time_step
(assembly); VelocityBC, TractionBC, run, Result (simulation); softening.A0 / z / delta_max.
"""
from pathlib import Path as _Path

from .cache_guard import clear_if_stale as _clear_if_stale

_clear_if_stale(_Path(__file__).parent)  # before any compiled module is loaded

from .body import Body, Material
from .model import ContactParams, JointParams, Model, build_model, stable_time_step
from .solver import Result, Snapshot, TractionBC, VelocityBC, run

__all__ = ["Body", "Material", "ContactParams", "JointParams", "Model", "build_model",
           "stable_time_step", "Result", "Snapshot", "TractionBC", "VelocityBC", "run"]
