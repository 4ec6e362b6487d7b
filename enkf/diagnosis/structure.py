"""Residual structure: the whitened residual, its tests (chi-square, runs, Ljung-Box, Durbin-Watson,
per-window RMS) and trends across records (:mod:`enkf.diagnosis`, part 1)."""
from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from ..covariance import ObservationError


# ----------------------------------------------------------------------------------------------
# 1. Residual
# ----------------------------------------------------------------------------------------------

def whitened_residual(sim, obs, obs_error: ObservationError) -> np.ndarray:
    """``L^{-1} (obs - sim)``, shape ``(m,)`` (or ``(m, k)`` for ``k`` columns of ``sim``)."""
    return obs_error.whiten(np.asarray(obs, dtype=float) - np.asarray(sim, dtype=float))


# ----------------------------------------------------------------------------------------------
# 2. Structure tests
# ----------------------------------------------------------------------------------------------

def default_windows(times, curve, *, arrival_fraction: float = 0.05,
                    rise_fraction: float = 0.9) -> dict[str, tuple[float, float]]:
    """Windows of a pulse-shaped curve (positive peak): ``before_arrival``, ``rise``, ``peak``, ``post_peak``.

    Arrival: the first time the curve reaches ``arrival_fraction`` of its maximum; the rise ends when it
    first reaches ``rise_fraction`` of it; the peak window runs until it falls below that level again.
    Each window is ``[start, end)`` in the units of ``times``; the last one ends at ``+inf``.
    """
    t = np.asarray(times, dtype=float)
    y = np.asarray(curve, dtype=float)
    if t.shape != y.shape or t.ndim != 1 or t.size < 2:
        raise ValueError("times and curve must be 1-D arrays of equal length >= 2")
    k_peak = int(np.argmax(y))
    peak = y[k_peak]
    if not peak > 0:
        raise ValueError("default_windows needs a curve with a positive maximum")
    pre = y[: k_peak + 1]
    k_arr = int(np.argmax(pre >= arrival_fraction * peak))
    k_rise = int(np.argmax(pre >= rise_fraction * peak))
    below = np.flatnonzero(y[k_peak:] < rise_fraction * peak)
    k_end = k_peak + int(below[0]) if below.size else t.size - 1
    edges = [t[0], t[k_arr], t[k_rise], t[k_end]]
    return {"before_arrival": (-math.inf, edges[1]), "rise": (edges[1], edges[2]),
            "peak": (edges[2], edges[3]), "post_peak": (edges[3], math.inf)}


def autocorrelation(x, max_lag: int) -> np.ndarray:
    """Sample autocorrelation ``rho_k = sum_i x_i x_{i+k} / sum_i x_i^2`` of the mean-removed series,
    ``k = 0..max_lag`` (the biased estimator used by Ljung-Box)."""
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    denom = float(np.dot(x, x))
    if denom == 0.0:
        return np.concatenate([[1.0], np.zeros(max_lag)])
    return np.array([np.dot(x[: x.size - k], x[k:]) / denom for k in range(max_lag + 1)])


def runs_test(x) -> dict:
    """Wald-Wolfowitz runs test on the signs of ``x`` (zeros dropped), normal approximation.

    ``R`` runs of ``n1`` positive and ``n2`` negative values; ``E[R] = 2 n1 n2 / n + 1``,
    ``Var[R] = 2 n1 n2 (2 n1 n2 - n) / (n^2 (n - 1))``, ``z = (R - E[R]) / sd``; two-sided p-value.
    Too few runs (``z < 0``) means positively correlated residuals (slow structure); too many,
    alternation. A series of one sign gets ``z = -inf``, ``p = 0``.
    """
    x = np.asarray(x, dtype=float)
    s = np.sign(x[x != 0])
    n = s.size
    n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
    runs = int(1 + np.count_nonzero(s[1:] != s[:-1])) if n else 0
    if n1 == 0 or n2 == 0:
        return {"runs": runs, "n_pos": n1, "n_neg": n2, "expected": float(runs), "z": -math.inf, "p": 0.0}
    mu = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
    z = (runs - mu) / math.sqrt(var) if var > 0 else 0.0
    return {"runs": runs, "n_pos": n1, "n_neg": n2, "expected": mu, "z": z, "p": float(2.0 * stats.norm.sf(abs(z)))}


def ljung_box(x, lag: int | None = None) -> dict:
    """Ljung-Box ``Q = m (m + 2) sum_{k=1}^{h} rho_k^2 / (m - k)`` against ``chi2(h)``; default
    ``h = min(10, m // 5)``."""
    x = np.asarray(x, dtype=float)
    m = x.size
    h = min(10, m // 5) if lag is None else int(lag)
    if not 1 <= h < m:
        raise ValueError(f"Ljung-Box lag must lie in [1, {m - 1}], got {h}")
    rho = autocorrelation(x, h)[1:]
    q = float(m * (m + 2.0) * np.sum(rho * rho / (m - np.arange(1, h + 1))))
    return {"Q": q, "lag": h, "p": float(stats.chi2.sf(q, h))}


def durbin_watson(x) -> float:
    """``sum (x_i - x_{i-1})^2 / sum x_i^2``: 2 for white noise, near 0 for slow structure."""
    x = np.asarray(x, dtype=float)
    denom = float(np.dot(x, x))
    return float(np.sum(np.diff(x) ** 2) / denom) if denom > 0 else math.nan


def structure_tests(white_resid, times=None, windows: Mapping[str, tuple[float, float]] | None = None, *,
                    n_params: int = 0, lag: int | None = None, alpha: float = 0.01) -> dict:
    """Tests of a whitened residual ``w`` for structure (see the module docstring).

    Parameters
    ----------
    white_resid : (m,) whitened residual ``L^{-1}(obs - sim)``.
    times : (m,) observation times, needed for ``windows``.
    windows : ``{name: (start, end)}``, half-open ``[start, end)`` in the units of ``times``; the RMS,
        mean and chi-square p-value of ``w`` are reported per window (not part of the pass decision).
    n_params : calibrated parameters; the chi-square has ``m - n_params`` degrees of freedom.
    lag : Ljung-Box lag (default ``min(10, m // 5)``).
    alpha : family-wise level; each of the three tests is taken at ``alpha / 3`` (Bonferroni).

    Returns
    -------
    dict with ``n``, ``chi2`` (value, dof, per_obs, p), ``runs`` (runs, expected, z, p), ``ljung_box``
    (Q, lag, p), ``durbin_watson``, ``rho1``, ``windows`` (per name: n, rms, mean, chi2_p), ``alpha``,
    ``alpha_per_test`` (``alpha / 3``), ``passed`` (bool) and ``failed`` (names of the tests with
    ``p <= alpha / 3``).
    """
    w = np.asarray(white_resid, dtype=float)
    if w.ndim != 1 or w.size < 10:
        raise ValueError("structure tests need a 1-D whitened residual with at least 10 values")
    if not np.all(np.isfinite(w)):
        raise ValueError("whitened residual contains non-finite values")
    m = w.size
    c2 = float(np.dot(w, w))
    dof = max(m - int(n_params), 1)
    out = {
        "n": m,
        "chi2": {"value": c2, "dof": dof, "per_obs": c2 / m, "p": float(stats.chi2.sf(c2, dof))},
        "runs": runs_test(w),
        "ljung_box": ljung_box(w, lag),
        "durbin_watson": durbin_watson(w),
        "rho1": float(autocorrelation(w, 1)[1]),
        "windows": {},
        "alpha": alpha,
        "alpha_per_test": alpha / 3.0,
    }
    if windows:
        if times is None:
            raise ValueError("windows need the observation times")
        t = np.asarray(times, dtype=float)
        if t.shape != w.shape:
            raise ValueError("times must have the residual's shape")
        for name, (start, end) in windows.items():
            sel = (t >= start) & (t < end)
            k = int(sel.sum())
            ww = w[sel]
            out["windows"][name] = {
                "start": start, "end": end, "n": k,
                "rms": float(np.sqrt(np.mean(ww * ww))) if k else math.nan,
                "mean": float(ww.mean()) if k else math.nan,
                "chi2_p": float(stats.chi2.sf(np.dot(ww, ww), k)) if k else math.nan,
            }
    failed = [name for name, p in (("chi2", out["chi2"]["p"]), ("runs", out["runs"]["p"]),
                                   ("ljung_box", out["ljung_box"]["p"])) if not p > alpha / 3.0]
    out["failed"] = failed
    out["passed"] = not failed
    return out


def spearman_exact(x, y) -> tuple[float, float]:
    """Spearman's rho and its exact two-sided p-value: the share of all orderings of ``y`` whose |rho|
    is at least the observed one (ties ranked by their mean rank). For small n only (n! orderings)."""
    rx, ry = stats.rankdata(x), stats.rankdata(y)

    def rho_of(r):
        return float(np.corrcoef(rx, r)[0, 1])

    rho = rho_of(ry)
    perms = [rho_of(np.asarray(p)) for p in itertools.permutations(ry)]
    p = sum(abs(r) >= abs(rho) - 1e-12 for r in perms) / len(perms)
    return rho, float(p)


def covariate_trends(table: pd.DataFrame, covariate: str, columns: Sequence[str] | None = None) -> pd.DataFrame:
    """Across records: each column (a residual statistic or fitted parameter, one row per record)
    against a covariate (e.g. the strain rate). Least-squares ``slope`` and ``intercept``, Pearson ``r``
    and its two-sided ``p_pearson``, Spearman ``rho`` and ``p_spearman``, ``n`` (rows with finite values).
    A trend (small p) means the calibrated model misses a dependence on the covariate. With a handful of
    records (n <= 8) the Spearman p-value is exact (all n! orderings; scipy's t approximation says p = 0
    for a perfect rank correlation of 3 points, whose exact two-sided p is 1/3)."""
    if covariate not in table:
        raise KeyError(f"covariate {covariate!r} not in the table")
    cols = [c for c in table.columns if c != covariate] if columns is None else list(columns)
    rows = []
    for col in cols:
        x = table[covariate].to_numpy(dtype=float)
        y = table[col].to_numpy(dtype=float)
        ok = np.isfinite(x) & np.isfinite(y)
        x, y = x[ok], y[ok]
        row = {"column": col, "n": int(ok.sum())}
        if x.size >= 3 and np.ptp(x) > 0 and np.ptp(y) > 0:
            lr = stats.linregress(x, y)
            if x.size <= 8:
                rho, p_rho = spearman_exact(x, y)
            else:
                sp = stats.spearmanr(x, y)
                rho, p_rho = float(sp.statistic), float(sp.pvalue)
            row.update(slope=lr.slope, intercept=lr.intercept, r=lr.rvalue, p_pearson=lr.pvalue,
                       rho=rho, p_spearman=p_rho)
        else:
            row.update(slope=math.nan, intercept=math.nan, r=math.nan, p_pearson=math.nan, rho=math.nan,
                       p_spearman=math.nan)
        rows.append(row)
    return pd.DataFrame(rows).set_index("column")
