"""The approximation error of an experiment's preset against a finer one
(``observations.model_error.approximation_error``; :mod:`enkf.approximation`).

A calibration at the ``fast`` preset of data from a finer mesh (a twin made at ``standard``, or a lab's
records, which have no mesh at all) carries the coarse mesh's resolution error into its parameters:
the ``fast`` disc fails differently from the ``standard`` one at the same parameters
(``studies/results/approximation_pairs.png``). With
``pairs: n`` the workflow runs, before any analysis, ``n`` design points of a Latin hypercube of the
prior box at the finer ``preset`` (one run each) and at the experiment's own preset
(``coarse_realizations`` runs each), every run on its own mesh realization, record by record with the
experiment's own records; the observations are then the data less the pairs' mean difference, with the
pairs' scatter beyond the coarse model's own variability (``coarse_variability``) added to their error model (:func:`calibration.observations.with_approximation_error`).
Every later step (ES-MDA, the discrepancy over it, the emulator and its MCMC, the stop test, the
predictive coverage) sees the corrected observations and the wider error model.

Run folders: ``results/<exp>/approximation/<run>/<record>/`` with ``<run>`` ``fine_<i>`` or
``coarse_<i>_<r>``, for the calibration and the held-out records (a leave-one-record-out series runs
them once under its own folder, and its folds read them there).
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np
import pandas as pd

# enkf and calibration.experiment (SciPy under both) are imported by the functions that compute: the
# workflow's parse reads the run names and settings from here and must not pay for SciPy (issue 54)
from .model_error import mesh_seed
from .observations import Observations, response_matrix, with_approximation_error

__all__ = ["approximation_settings", "approximation_design", "approximation_run_ids", "approximation_run",
           "approximation_mesh_seed", "apply_approximation_error", "apply_stored_approximation_error",
           "approximation_from_runs"]

_RUN_RE = re.compile(r"^(fine)_(\d+)$|^(coarse)_(\d+)_(\d+)$")


def approximation_settings(exp: Mapping) -> dict | None:
    """The validated ``observations.model_error.approximation_error`` block, None when it is off."""
    block = ((exp.get("observations") or {}).get("model_error") or {}).get("approximation_error") or {}
    return dict(block) if block.get("pairs") else None


def approximation_design(name: str, exp: Mapping) -> np.ndarray:
    """``(pairs, n_params)``: the design points, a Latin hypercube of the prior box from the
    experiment's seed (its own stream, so the members' prior is not moved by it)."""
    from enkf import latin_hypercube

    from .experiment import ExperimentSpec, rng_for

    spec = ExperimentSpec.from_config(name, exp)
    n = int(approximation_settings(exp)["pairs"])
    return latin_hypercube(spec.lower, spec.upper, n, rng_for(spec.seed, "approximation"))


def approximation_run_ids(exp: Mapping) -> list[str]:
    """The run folders, fine run first at each design point: ``fine_<i>``, ``coarse_<i>_<r>``."""
    s = approximation_settings(exp)
    if s is None:
        return []
    out = []
    for i in range(int(s["pairs"])):
        out.append(f"fine_{i:03d}")
        out += [f"coarse_{i:03d}_{r}" for r in range(int(s["coarse_realizations"]))]
    return out


def approximation_run(run_id: str) -> tuple[str, int, int]:
    """``(level, design index, realization)`` of a run folder name (``fine`` runs are realization 0)."""
    m = _RUN_RE.match(run_id)
    if m is None:
        raise ValueError(f"approximation run {run_id!r} is not fine_<i> or coarse_<i>_<r>")
    if m.group(1):
        return "fine", int(m.group(2)), 0
    return "coarse", int(m.group(4)), int(m.group(5))


def approximation_mesh_seed(exp: Mapping, run_id: str, record: int = 0) -> int:
    """Every approximation run on its own mesh realization (the fine run at ``k = 0``, the coarse
    realization ``r`` at ``k = 1 + r``): the pairs' scatter must hold what the mesh changes."""
    level, i, r = approximation_run(run_id)
    return mesh_seed(int(exp["seed"]), "approximation", 0 if level == "fine" else 1 + r, i, record)


def apply_approximation_error(obs: Observations, exp: Mapping,
                              curves: Mapping[str, Mapping[str, pd.DataFrame]]) -> Observations:
    """``obs`` corrected by the approximation error of the runs ``curves[run_id][record]`` (a failed
    run's empty curve leaves its pair out)."""
    Y = response_matrix([curves[r] for r in approximation_run_ids(exp)], obs)
    return with_approximation_error(obs, *approximation_from_runs(exp, Y, obs.time, obs.groups))


def apply_stored_approximation_error(obs: Observations, exp: Mapping, folder) -> Observations:
    """``obs`` corrected by its records' runs stored under ``folder`` (``results/<exp>/approximation``; a
    leave-one-record-out fold's: its series'): the calibration records' observations and the held-out
    records' alike; ``obs`` as it is when the experiment has no approximation error."""
    from pathlib import Path

    from .observations import read_curve

    runs = approximation_run_ids(exp)
    if not runs:
        return obs
    curves = {r: {rec: read_curve(Path(folder) / r / rec / "curve.csv") for rec in obs.records} for r in runs}
    return apply_approximation_error(obs, exp, curves)


def approximation_from_runs(exp: Mapping, Y: np.ndarray, times, groups=None) -> tuple:
    """``(offset, M, info)`` of the runs' curves ``Y`` on the observation grid, one row per run in the
    order of :func:`approximation_run_ids` (NaN rows: failed runs)."""
    from enkf.approximation import approximation_error

    s = approximation_settings(exp)
    n, k = int(s["pairs"]), int(s["coarse_realizations"])
    Y = np.asarray(Y, float).reshape(n, 1 + k, -1)
    offset, M, info = approximation_error(Y[:, 0], Y[:, 1:], times, groups, coarse_variability=s["coarse_variability"])
    return offset, M, {**info, "fine_preset": s["preset"], "coarse_preset": exp["preset"], "coarse_realizations": k}
