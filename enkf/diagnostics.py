"""Misfit and spread diagnostics, as plain numbers, JSON-ready dicts and pandas DataFrames.

Definitions (units are whatever the caller passes; for stress curves in Pa, ``rmse`` is in Pa):

* ``rmse(sim, obs)   = sqrt(mean_k (sim_k - obs_k)^2)``
* ``nrmse(sim, obs)  = rmse / (max(obs) - min(obs))``   (normalised by the observed range, so a
  stress-time curve's nrmse reads as a fraction of its peak-to-trough span)
* ``chi2_per_obs(sim, obs, R) = |L^{-1} (sim - obs)|^2 / m``   with ``R = L L^T``
  (about 1 when the residual is pure observation noise: the discrepancy principle)
* ``standardized_chi2_per_obs(sim, obs, C) = mean_k (sim_k - obs_k)^2 / C_kk``: the same against the
  error model's variances only (the stop test's statistic, :func:`member_standardized_misfit`)

The misfit "of the mean" is that of the ensemble-mean response ``y_bar = mean_i y_i`` over the members
alive, the quantity the paper's stopping rule ``|x_bar - y_o| < tol`` uses. Member rows of failed
members are NaN in arrays and ``None`` in JSON dicts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from .covariance import DiagonalError, ObservationError
from .scores import expected_score_over_prior


def _rows(sim) -> np.ndarray:
    return np.atleast_2d(np.asarray(sim, dtype=float))


def _squeeze(values: np.ndarray, sim) -> np.ndarray | float:
    return float(values[0]) if np.ndim(sim) == 1 else values


def rmse(sim, obs):
    """Root-mean-square error of ``sim`` (shape ``(m,)`` or ``(N, m)``, rows = members) against ``obs``."""
    r = _rows(sim) - np.asarray(obs, dtype=float)
    return _squeeze(np.sqrt(np.mean(r * r, axis=1)), sim)


def nrmse(sim, obs):
    """``rmse / (max(obs) - min(obs))``; NaN if the observations have zero range."""
    obs = np.asarray(obs, dtype=float)
    span = float(obs.max() - obs.min())
    value = rmse(sim, obs)
    return value / span if span > 0 else value * np.nan


def chi2_per_obs(sim, obs, obs_error: ObservationError):
    """``|L^{-1}(sim - obs)|^2 / m``, the whitened misfit per observation (rows = members)."""
    r = _rows(sim) - np.asarray(obs, dtype=float)
    out = np.full(r.shape[0], np.nan)
    ok = np.all(np.isfinite(r), axis=1)
    if np.any(ok):
        out[ok] = obs_error.chi2(r[ok].T) / r.shape[1]
    return _squeeze(out, sim)


def default_names(n_params: int, names: Sequence[str] | None = None) -> list[str]:
    if names is None:
        return [f"p{j}" for j in range(n_params)]
    names = [str(n) for n in names]
    if len(names) != n_params:
        raise ValueError(f"{len(names)} names for {n_params} parameters")
    return names


def jsonable(obj):
    """Recursively convert NumPy scalars/arrays to Python types and non-finite floats to ``None``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def misfit_table(responses, obs, obs_error: ObservationError, alive=None) -> pd.DataFrame:
    """One row per member: ``member, alive, rmse, nrmse, chi2_per_obs`` (NaN for failed members)."""
    y = _rows(responses)
    alive = _alive_mask(y, alive)
    out = pd.DataFrame({"member": np.arange(y.shape[0]), "alive": alive})
    for name, fn in (("rmse", rmse), ("nrmse", nrmse)):
        v = np.full(y.shape[0], np.nan)
        if np.any(alive):
            v[alive] = fn(y[alive], obs)
        out[name] = v
    c = np.full(y.shape[0], np.nan)
    if np.any(alive):
        c[alive] = chi2_per_obs(y[alive], obs, obs_error)
    out["chi2_per_obs"] = c
    return out


def mean_misfit(responses, obs, obs_error: ObservationError, alive=None) -> dict:
    """Misfit of the ensemble-mean response over the alive members: ``{rmse, nrmse, chi2_per_obs}``."""
    y = _rows(responses)
    alive = _alive_mask(y, alive)
    if not np.any(alive):
        return {"rmse": math.nan, "nrmse": math.nan, "chi2_per_obs": math.nan}
    y_bar = y[alive].mean(axis=0)
    return {"rmse": float(rmse(y_bar, obs)), "nrmse": float(nrmse(y_bar, obs)),
            "chi2_per_obs": float(chi2_per_obs(y_bar, obs, obs_error))}


def member_misfit(responses, obs, obs_error: ObservationError, alive=None) -> dict:
    """Misfit of the members themselves, not of their mean: the chi^2 per observation of the median
    member (the stop test's statistic), the best member, the quartiles, and the mean curve's for
    comparison.

    Why the median member: with step-like responses (a member that unloads, one that re-loads) the
    mean of the members is a blurred curve that can fit where no member does; the median member's
    chi^2 falls to the noise level only when at least half the members fit.
    """
    y = _rows(responses)
    alive = _alive_mask(y, alive)
    nan = {"median_chi2_per_obs": math.nan, "best_chi2_per_obs": math.nan, "q25_chi2_per_obs": math.nan,
           "q75_chi2_per_obs": math.nan, "mean_curve_chi2_per_obs": math.nan, "median_rmse": math.nan,
           "median_nrmse": math.nan}
    if not np.any(alive):
        return nan
    c = np.atleast_1d(chi2_per_obs(y[alive], obs, obs_error))
    r = np.atleast_1d(rmse(y[alive], obs))
    span = float(np.max(obs) - np.min(obs))
    med_rmse = float(np.median(r))
    return {"median_chi2_per_obs": float(np.median(c)), "best_chi2_per_obs": float(np.min(c)),
            "q25_chi2_per_obs": float(np.quantile(c, 0.25)), "q75_chi2_per_obs": float(np.quantile(c, 0.75)),
            "mean_curve_chi2_per_obs": float(chi2_per_obs(y[alive].mean(axis=0), obs, obs_error)),
            "median_rmse": med_rmse, "median_nrmse": med_rmse / span if span > 0 else math.nan}


def standardized_chi2_per_obs(sim, obs, obs_error: ObservationError):
    """``mean_k (sim_k - obs_k)^2 / C_kk``, the misfit standardised by the error model's variances alone
    (rows = members). Its mean is 1 for residuals drawn from ``C`` whatever ``C``'s correlations, so a
    correlation structure the model gets wrong cannot inflate it (:func:`standardized_target`)."""
    return chi2_per_obs(sim, obs, DiagonalError(obs_error.std))


def standardized_target(obs_error: ObservationError, n_sd: float = 2.0) -> float:
    """``1 + n_sd sqrt(2 tr(P^2)) / m``, ``P`` the error model's correlation matrix: the mean plus ``n_sd``
    standard deviations of :func:`standardized_chi2_per_obs` for residuals drawn from the model (the
    quadratic form's variance ``2 tr(P^2) / m^2``). White errors give ``1 + 2 sqrt(2/m)``, the chi-square
    target; correlated ones fewer independent observations and a wider margin."""
    C = obs_error.dense()
    sd = np.sqrt(np.diag(C))
    P = C / np.outer(sd, sd)
    return 1.0 + float(n_sd) * math.sqrt(2.0 * float(np.sum(P * P))) / sd.size


def member_standardized_misfit(responses, obs, obs_error: ObservationError, alive=None) -> dict:
    """``{median, best, target}``: :func:`standardized_chi2_per_obs` of the median and the best alive
    member and :func:`standardized_target` of ``obs_error``: the stop test (:mod:`enkf.stopping`).

    Why standardised and not whitened: re-runs of a twin's truth on mesh realizations of their own,
    scored against ``R + 2 S``, are this test's null; whitened by the AR(1) model of ``S`` they fail
    ``1 + 2 sqrt(2/m)`` more often than not, standardised by its variances they score about 1: the
    variances are right, the AR(1) correlation of the departures after the peak is not (numbers in
    docs/inference.md, Stopping; ``studies/stop_rule_dev.py``)."""
    y = _rows(responses)
    alive = _alive_mask(y, alive)
    target = standardized_target(obs_error)
    if not np.any(alive):
        return {"median": math.nan, "best": math.nan, "target": target}
    c = np.atleast_1d(standardized_chi2_per_obs(y[alive], obs, obs_error))
    return {"median": float(np.median(c)), "best": float(np.min(c)), "target": target}


def parameter_summary(params, names: Sequence[str] | None = None, alive=None) -> pd.DataFrame:
    """Per parameter over the alive members: ``mean, std, q05, q50, q95, min, max`` (index = names)."""
    p = _rows(params)
    names = default_names(p.shape[1], names)
    alive = np.ones(p.shape[0], bool) if alive is None else np.asarray(alive, bool)
    q = p[alive]
    return pd.DataFrame(
        {"mean": q.mean(axis=0), "std": q.std(axis=0, ddof=1) if q.shape[0] > 1 else np.zeros(q.shape[1]),
         "q05": np.quantile(q, 0.05, axis=0), "q50": np.quantile(q, 0.50, axis=0),
         "q95": np.quantile(q, 0.95, axis=0), "min": q.min(axis=0), "max": q.max(axis=0)},
        index=pd.Index(names, name="param"),
    )


#: Draws of an ensemble's predictive distribution on which its expected score is read (quantiles at equal
#: steps: deterministic).
PREDICTIVE_DRAWS = 999
#: Central levels of the reported intervals and the summary keys of their bounds.
INTERVAL_LEVELS = {"90": ("q05", "q95", 0.90), "50": ("q25", "q75", 0.50)}


def prediction_interval_dict(params, names: Sequence[str] | None = None, alive=None, transform=None) -> dict:
    """``{param: {mean, std, q05, q25, q75, q95, n, interval}}`` of an ensemble of ``N`` members read as
    ``N`` draws from the posterior: the bounds are the normal-theory *prediction* intervals of one more
    draw, ``zbar +- t_{N-1} s sqrt(1 + 1/N)`` in the unbounded space of ``transform`` (a
    :class:`enkf.transforms.BoxTransform`; None: the parameters as they are), mapped back.

    Why not the members' 5-95 % sample quantiles: the truth of a calibrated posterior is one more draw
    from the same distribution, and the interval between sample quantiles of ``N`` draws holds it with
    probability ``0.9 (N - 1) / (N + 1)`` only (83 % at N = 25, 70 % at N = 8). The prediction interval
    holds it with the stated probability for any ``N`` when the unbounded members are Gaussian, which
    the ensemble smoother's linear update makes them close to. ``mean``/``std`` are the members' own.
    """
    from scipy import stats

    p = _rows(params)
    names = default_names(p.shape[1], names)
    a = np.ones(p.shape[0], bool) if alive is None else np.asarray(alive, bool)
    q = p[a]
    n = q.shape[0]
    z = q if transform is None else transform.to_unbounded(q)
    zbar, sz = z.mean(axis=0), (z.std(axis=0, ddof=1) if n > 1 else np.zeros(z.shape[1]))
    out = {name: {"mean": float(q[:, j].mean()), "std": float(q[:, j].std(ddof=1)) if n > 1 else 0.0, "n": int(n),
                  "interval": "t prediction interval of one more draw, unbounded space"}
           for j, name in enumerate(names)}
    for lo_key, hi_key, level in INTERVAL_LEVELS.values():
        half = (stats.t.ppf(0.5 + 0.5 * level, n - 1) if n > 1 else 0.0) * sz * math.sqrt(1.0 + 1.0 / max(n, 1))
        bounds = [zbar - half, zbar + half]
        if transform is not None:
            bounds = [transform.to_bounded(b[None, :])[0] for b in bounds]
        for j, name in enumerate(names):
            out[name][lo_key], out[name][hi_key] = float(bounds[0][j]), float(bounds[1][j])
    if transform is not None and n > 1:
        # the score the predictive distribution expects, on its quantiles at PREDICTIVE_DRAWS equal steps
        u = (np.arange(PREDICTIVE_DRAWS) + 0.5) / PREDICTIVE_DRAWS
        draws = transform.to_bounded(zbar + np.outer(stats.t.ppf(u, n - 1), sz) * math.sqrt(1.0 + 1.0 / n))
        for j, name in enumerate(names):
            out[name]["score_over_prior"] = expected_score_over_prior(draws[:, j], transform.lower[j],
                                                                      transform.upper[j])
    return out


def posterior_dict(params, names: Sequence[str] | None = None, alive=None) -> dict:
    """``{param: {mean, std, q05, q95}}``, the ``posterior`` block of ``summary.json``."""
    s = parameter_summary(params, names, alive)
    return {name: {k: float(s.loc[name, k]) for k in ("mean", "std", "q05", "q95")} for name in s.index}


def member_table(params, names: Sequence[str] | None = None, responses=None, obs=None,
                 obs_error: ObservationError | None = None, alive=None) -> pd.DataFrame:
    """One row per member: the parameters (named columns) and, if responses are given, the misfits.

    Ready to write as ``iter_<k>/params.csv``.
    """
    p = _rows(params)
    names = default_names(p.shape[1], names)
    table = pd.DataFrame(p, columns=names)
    table.insert(0, "member", np.arange(p.shape[0]))
    if responses is not None:
        if obs is None or obs_error is None:
            raise ValueError("misfits need obs and obs_error")
        mis = misfit_table(responses, obs, obs_error, alive)
        table = pd.concat([table, mis.drop(columns="member")], axis=1)
    elif alive is not None:
        table["alive"] = np.asarray(alive, bool)
    return table


def alive_mask(y: np.ndarray, alive=None) -> np.ndarray:
    """Rows of ``y`` that are finite and (if ``alive`` is given) flagged alive."""
    finite = np.all(np.isfinite(y), axis=1)
    return finite if alive is None else finite & np.asarray(alive, bool)


_alive_mask = alive_mask
