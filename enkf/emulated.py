"""Emulator-assisted ES-MDA: each analysis is an ES-MDA on an emulator of every run simulated so far.

Why: the disc's stress curve moves with the time of splitting, so the response is close to a shifted
step in the parameters, and on top of that the discrete joints make it rugged at the 1 % scale (one
more or fewer broken joint changes the post-peak curve). An ensemble smoother that linearises the
response over its own members (the paper's EnKF, ES-MDA) needs many small steps to get through
that; with the three analyses the twin experiments allow it stops 4-16 % off the truth. Here the
simulator runs of all iterations are kept, and every analysis is:

1. an interpolating emulator of the curves over the prior box, built on all runs so far
   (:class:`enkf.emulator.CurveEmulator`, thin-plate RBF in the unit box);
2. its error where the posterior is: the leave-one-out residuals of the members of the iteration
   being analysed (the previous analysis put them where it believed the posterior to be), as a
   per-time variance with an AR(1) correlation fitted to the residuals' lag-1 autocorrelation (the
   residuals are time-correlated, so a diagonal term would count every time as independent and give
   over-confident intervals). This term also carries the simulator's own ruggedness (the scatter of
   neighbouring runs), which no smooth model can fit and which the posterior must therefore admit;
3. ES-MDA from a fresh Latin hypercube of ``inner_members`` points of the prior box, with
   ``inner_steps`` analyses on the emulator against ``temper * (R + C_emulator)`` (a prior draw each
   time, so the data are used once per analysis, never twice). ``temper >= 1`` widens the posterior of
   the early analyses, whose emulator rests on few runs (the caller uses ``base^(K-1-k)`` for analysis
   ``k`` of ``K``, so the last one is untempered): a confident but wrong first emulator would otherwise
   put every later run in the wrong basin, and nothing there would show it (annealing, as ES-MDA's
   inflated ``alpha``);
4. the next ensemble: the first ``n_members`` members of that ES-MDA ensemble (rows of a Latin
   hypercube are exchangeable, so this is a random subsample of the emulated posterior).

Each iteration's new runs sit where the posterior is, so the emulator sharpens there: a sequential
design (as in Bayesian calibration of computer models). The outer loop is still "simulate the
ensemble, analyse, repeat", one Snakemake job per member; only the analysis changed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ._rng import RngLike, as_generator
from .analysis import esmda_alphas
from .covariance import AR1Error, DenseError, ObservationError
from .diagnostics import default_names, jsonable, posterior_dict
from .emulator import design_arrays, smoothed_emulator
from .variability import lag1_correlation
from .loop import assimilate
from .sampling import latin_hypercube
from .transforms import BoxTransform

__all__ = ["EmulatedAnalysis", "emulated_esmda_update", "emulator_error_model"]


class EmulatedAnalysis:
    """Next ensemble ``params`` (N, n), JSON-ready ``diagnostics`` and the measured emulator ``error``
    (the AR(1) model of the leave-one-out residuals at the latest runs, :func:`emulator_error_model`)."""

    def __init__(self, params: np.ndarray, diagnostics: dict, error: AR1Error | None = None):
        self.params = params
        self.diagnostics = diagnostics
        self.error = error

    def to_dict(self) -> dict:
        return jsonable(self.diagnostics)


def emulator_error_model(residuals: np.ndarray, times, groups=None) -> tuple[AR1Error | None, dict]:
    """The emulator's error from residual curves ``(k, m)``: per-time rms with AR(1) correlation.

    The correlation time is ``-dt / ln(rho)`` with ``rho`` the residuals' lag-1 correlation per pair of
    neighbouring times, averaged (:func:`enkf.variability.lag1_correlation`), ``dt`` the median grid step.
    Returns ``(None, info)`` when there are no residuals.
    """
    R = np.array(residuals, dtype=float, ndmin=2)
    t = np.asarray(times, dtype=float)
    g = np.zeros(t.size, int) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
    if R.shape[0] == 0:
        return None, {"n_residuals": 0}
    if R.shape[1] != t.size:
        raise ValueError(f"residuals have {R.shape[1]} columns, the grid {t.size} times")
    sd = np.sqrt(np.mean(R ** 2, axis=0))
    floor = 1e-9 * max(float(sd.max()), 1e-300)
    sd = np.maximum(sd, floor)
    rho, corr_time = lag1_correlation(R, t, g)
    err = AR1Error(sd, t, corr_time, groups=g)
    return err, {"n_residuals": int(R.shape[0]), "rms": float(np.sqrt(np.mean(sd ** 2))),
                 "max": float(sd.max()), "lag1_correlation": rho, "corr_time": corr_time}


def emulated_esmda_update(design_params, design_responses, latest, obs, obs_error: ObservationError, *,
                          lower, upper, n_members: int, rng: RngLike, times, groups=None,
                          inner_members: int = 400, inner_steps: int = 8, transform_kind: str = "logit",
                          temper: float = 1.0, smoothing="loo", loo_scale=None,
                          names: Sequence[str] | None = None) -> EmulatedAnalysis:
    """One analysis of the emulator-assisted ES-MDA (module docstring).

    Parameters
    ----------
    design_params : (k, n) parameters of every successful run so far (all iterations).
    design_responses : (k, m) their curves on the observation grid (finite).
    latest : (k,) bool, the runs of the iteration being analysed (where the emulator error is measured).
    obs, obs_error : the observations and their error ``R``.
    lower, upper : the prior box (the emulator's domain).
    n_members : size of the next ensemble (at most ``inner_members``).
    rng : the analysis' random stream (inner Latin hypercube and ES-MDA perturbations).
    times, groups : observation times and record labels, for the AR(1) emulator error.
    smoothing : the emulator's nugget (RBF smoothing) or ``"loo"`` (default: the value with the least
        leave-one-out error at the latest runs, :func:`enkf.emulator.smoothed_emulator`), each time's
        residual divided by ``loo_scale`` (m,) where given.
    """
    X, Y, latest, d = design_arrays(design_params, design_responses, latest, obs)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    n = lo.size
    names = default_names(n, names)
    if not 2 <= n_members <= inner_members:
        raise ValueError(f"n_members must lie in [2, inner_members = {inner_members}], got {n_members}")
    if not (math.isfinite(temper) and temper >= 1.0):
        raise ValueError(f"temper must be a finite number >= 1, got {temper}")
    if X.shape[0] < n + 2 or latest.sum() < 2:
        raise ValueError(f"the emulator needs at least {n + 2} runs and 2 of the latest iteration; "
                         f"got {X.shape[0]} and {int(latest.sum())}")
    rng = as_generator(rng)

    em, smoothing_info = smoothed_emulator(X, Y, lo, hi, names, latest, smoothing, loo_scale)
    emu_err, emu_info = emulator_error_model(em.loo_residuals()[latest], times, groups)
    emu_info.update(smoothing_info)

    C = DenseError(temper * (obs_error.dense() + emu_err.dense()), _symmetric=True)
    P0 = latin_hypercube(lo, hi, inner_members, rng)
    res = assimilate(em, P0, d, C, rng=rng, method="esmda", alphas=esmda_alphas(inner_steps),
                     transform=BoxTransform(lo, hi, kind=transform_kind), names=names)
    P_inner = res.params[res.alive]
    if P_inner.shape[0] < n_members:
        raise RuntimeError(f"the emulated ES-MDA kept {P_inner.shape[0]} members, fewer than {n_members}")
    P_next = P_inner[:n_members]

    w = obs_error.whiten(em(P_inner.mean(axis=0))[0] - d)
    diagnostics = {
        "method": "emulated_esmda",
        "design_points": int(X.shape[0]),
        "latest_points": int(latest.sum()),
        "emulator_error": emu_info,
        "obs_sigma_rms": float(np.sqrt(np.mean(obs_error.std ** 2))),
        "inner": {"members": inner_members, "steps": inner_steps,
                  "alphas": esmda_alphas(inner_steps).tolist(),
                  "posterior": posterior_dict(P_inner, names)},
        "emulated_mean_chi2_per_obs": float(np.dot(w, w) / d.size),
        "temper": temper,
        "params": {name: {"mean_after": float(P_next[:, j].mean()), "std_after": float(P_next[:, j].std(ddof=1))}
                   for j, name in enumerate(names)},
    }
    return EmulatedAnalysis(P_next, jsonable(diagnostics), emu_err)
