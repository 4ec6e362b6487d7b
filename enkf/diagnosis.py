"""Diagnosis of a calibrated model's residual and the choice of model extensions ("effects").

Generic: it sees residual vectors, sensitivities (Jacobian columns, finite-difference or ensemble
estimates), candidate names and null values; it knows nothing about FDEM or SHPB. Conventions:

* residual ``r = obs - sim`` (data minus model), whitened ``w = L^{-1} r`` with the observation error
  model ``R = L L^T`` (:mod:`enkf.covariance`); under a correct model and correct ``R``, ``w`` is
  standard white noise.
* sensitivities ``S = d sim / d theta`` (``m x n``, one column per parameter, the caller's parameter
  units or the unbounded ones; only spans and ratios matter), whitened ``L^{-1} S``.

Steps (issue 8, "Diagnosis"):

1. :func:`whitened_residual`.
2. :func:`structure_tests`: chi-square (``|w|^2`` against ``chi2(m - n_params)``, upper tail), the
   Wald-Wolfowitz runs test on the signs of ``w`` (normal approximation, two-sided), the Ljung-Box
   portmanteau ``Q = m (m + 2) sum_{k=1}^{h} rho_k^2 / (m - k)`` against ``chi2(h)`` with the lag
   ``h = min(10, m // 5)`` by default (Hyndman & Athanasopoulos' rule for non-seasonal series), the
   Durbin-Watson statistic ``DW = sum (w_i - w_{i-1})^2 / sum w_i^2 ~ 2 (1 - rho_1)`` (reported, no
   p-value), and the RMS of ``w`` per named time window (:func:`default_windows`: before arrival,
   rise, peak, post-peak). The residual "passes" when the three p-values all exceed ``alpha / 3``
   (Bonferroni: ``alpha``, default 0.01, is the family-wise false-alarm rate; three separate 1% tests
   would flag about 3.4% of white-noise records, measured over 5,000 seeds of length 300).
   :func:`covariate_trends`: across records, a statistic (mean residual, a fitted parameter) against
   a covariate such as the strain rate (least-squares slope, Pearson and Spearman tests).
3. :func:`score_test` / :func:`rank_candidates`: with ``P`` the projector onto the orthogonal complement
   of the whitened base sensitivities' span, the score (Lagrange-multiplier) statistic of a candidate
   with whitened sensitivity columns ``C`` (``k`` parameters) at its null is::

       T = (C^T P w)^T (C^T P C)^{-1} (C^T P w)   ~ chi2(k) under the null           (k = 1: (w^T P c)^2 / c^T P c)

   the squared length of the residual's projection on the candidate's new directions. It is the
   drop in chi-square a linearised re-fit with the candidate would give; the Gauss-Newton step from
   the null is ``(C^T P C)^{-1} C^T P w``. Collinearity with the base: ``1 - lambda_min`` where
   ``lambda_min`` is the smallest eigenvalue of ``Q_c^T P Q_c`` (``Q_c`` an orthonormal basis of ``C``),
   i.e. ``cos^2`` of the smallest principal angle between the candidate's and the base's spans; for
   one column ``1 - |P c|^2 / |c|^2``. "Explained excess" = ``(T - k) / (|P w|^2 - (m - rank))``, the
   fraction of the residual energy above its noise expectation the candidate accounts for.
4. :func:`bic` with :func:`effective_sample_size`, :func:`accept_effect`, and the driver
   :func:`diagnose_loop` (score-rank, re-calibrate, accept or stop). The score test is local: where
   the curve responds sharply and nonlinearly (a failure peak whose time moves with the strength),
   the linearised share of the residual a candidate explains can be a few percent although the
   re-calibrated model explains nearly all of it. The loop therefore screens by significance only and
   judges "how much it explains" after re-calibration: the drop in chi-square as a fraction of the
   residual's excess over its noise expectation (the criterion that keeps a candidate which merely
   projects a sliver of an out-of-catalogue structure from being claimed).
5. :func:`report_to_json` and :func:`write_report` (tables, JSON and plots for
   ``results/<experiment>/diagnosis/``).

BIC: ``BIC = chi2_min + k ln(n_eff)`` where ``chi2_min = |L^{-1}(obs - sim)|^2`` is ``-2 ln L`` up to a
constant for Gaussian errors with covariance ``R``, ``k`` the number of calibrated parameters, and
``n_eff`` the effective number of independent observations, so that the penalty (``ln det`` of the
Fisher information, Schwarz's derivation) is not overstated for a correlated dense curve. For an error
model ``R`` the exact value for a common level is ``n_eff = 1^T C^{-1} 1`` with ``C`` the correlation
matrix, computed as ``|L^{-1} sigma|^2``; for AR(1) with lag-one correlation ``rho_1`` it is
``(m - (m - 2) rho_1) / (1 + rho_1) ~ m (1 - rho_1) / (1 + rho_1)``. From a residual, the AR(1)
formula with its sample ``rho_1`` (clipped at 0).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import linalg, stats

from .covariance import ObservationError
from .diagnostics import jsonable, posterior_dict, rmse

VERDICTS = ("explained", "unexplained", "no structure")


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


# ----------------------------------------------------------------------------------------------
# Sensitivities
# ----------------------------------------------------------------------------------------------

def ensemble_sensitivity(params, responses, *, alive=None, rcond: float | None = None) -> np.ndarray:
    """Ensemble estimate of the Jacobian ``d y / d theta`` by least-squares regression of the response
    anomalies on the parameter anomalies across members: ``dY ~ dTheta B``, returned as ``B^T`` (``m x n``).

    Pass the parameters in the space the sensitivities should refer to (e.g. the unbounded
    ``params_unbounded``); spans, and therefore score tests, are the same in any smooth
    reparametrisation near the ensemble. Needs ``N > n`` members with a non-degenerate spread;
    rows that are dead (``alive`` False) or non-finite are ignored.
    """
    P = np.array(params, dtype=float, ndmin=2)
    Y = np.array(responses, dtype=float, ndmin=2)
    if P.shape[0] != Y.shape[0]:
        raise ValueError("params and responses need the same number of rows (members)")
    ok = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(Y), axis=1)
    if alive is not None:
        ok &= np.asarray(alive, dtype=bool)
    P, Y = P[ok], Y[ok]
    if P.shape[0] <= P.shape[1]:
        raise ValueError(f"need more members ({P.shape[0]}) than parameters ({P.shape[1]}) for a regression")
    dP = P - P.mean(axis=0)
    dY = Y - Y.mean(axis=0)
    B, *_ = linalg.lstsq(dP, dY, cond=rcond)
    return B.T


def finite_difference_sensitivity(forward: Callable[[np.ndarray], np.ndarray], x0, steps, *,
                                  lower=None, upper=None, scheme: str = "central") -> np.ndarray:
    """Finite-difference Jacobian ``d y / d x`` at ``x0`` (``m x n``).

    ``forward`` maps a ``(k, n)`` array of parameter rows to ``(k, m)`` responses (as in
    :func:`enkf.assimilate`); all perturbed points go in one call. ``scheme`` = ``"central"`` or
    ``"forward"``; with a box (``lower``, ``upper``) a central difference that would leave the box falls
    back to the one-sided difference that stays inside (e.g. a null at a bound).
    """
    x0 = np.asarray(x0, dtype=float)
    h = np.broadcast_to(np.asarray(steps, dtype=float), x0.shape).copy()
    if np.any(h <= 0):
        raise ValueError("finite-difference steps must be positive")
    if scheme not in ("central", "forward"):
        raise ValueError("scheme must be 'central' or 'forward'")
    n = x0.size
    lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
    plus, minus = x0 + h, x0 - h
    rows, plan = [x0], []
    for j in range(n):
        up = plus[j] <= hi[j]
        down = minus[j] >= lo[j]
        if scheme == "central" and up and down:
            plan.append(("c", len(rows), len(rows) + 1))
            rows += [_with(x0, j, plus[j]), _with(x0, j, minus[j])]
        elif up:
            plan.append(("f", len(rows), None))
            rows.append(_with(x0, j, plus[j]))
        elif down:
            plan.append(("b", len(rows), None))
            rows.append(_with(x0, j, minus[j]))
        else:
            raise ValueError(f"step {h[j]} of parameter {j} leaves the box on both sides")
    Y = np.array(forward(np.vstack(rows)), dtype=float, ndmin=2)
    J = np.empty((Y.shape[1], n))
    for j, (kind, a, b) in enumerate(plan):
        if kind == "c":
            J[:, j] = (Y[a] - Y[b]) / (2.0 * h[j])
        elif kind == "f":
            J[:, j] = (Y[a] - Y[0]) / h[j]
        else:
            J[:, j] = (Y[0] - Y[a]) / h[j]
    return J


def _with(x, j, v):
    y = x.copy()
    y[j] = v
    return y


# ----------------------------------------------------------------------------------------------
# 3. Score test and ranking
# ----------------------------------------------------------------------------------------------

def _orth(A: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Orthonormal basis of the column span of ``A`` (thin SVD, singular values above ``rtol * s_max``)."""
    if A.size == 0 or A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    U, s, _ = linalg.svd(A, full_matrices=False, check_finite=False)
    if s.size == 0 or s[0] == 0:
        return np.zeros((A.shape[0], 0))
    return U[:, s > rtol * s[0]]


def _project_out(Q: np.ndarray, X: np.ndarray) -> np.ndarray:
    return X - Q @ (Q.T @ X) if Q.shape[1] else X.copy()


def _as_columns(A, m: int, what: str) -> np.ndarray:
    A = np.asarray(A, dtype=float)
    if A.ndim == 1:
        A = A[:, None]
    if A.ndim != 2 or A.shape[0] != m:
        raise ValueError(f"{what} must have shape ({m}, k), got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"{what} contains non-finite values")
    return A


def chi2_log10_sf(x: float, dof: int) -> float:
    """``log10 P(chi2(dof) > x)``, finite far in the tail where the p-value underflows: there it uses
    ``Gamma(s, y) ~ y^(s-1) e^(-y) (1 + (s-1)/y + (s-1)(s-2)/y^2)``, ``s = dof/2``, ``y = x/2``."""
    v = float(stats.chi2.logsf(x, dof))
    if not math.isfinite(v):
        s, y = 0.5 * dof, 0.5 * float(x)
        v = (s - 1.0) * math.log(y) - y - math.lgamma(s) + math.log1p((s - 1.0) / y + (s - 1.0) * (s - 2.0) / (y * y))
    return v / math.log(10.0)


def score_test(white_resid, S_base_white, S_cand_white, *, rtol: float = 1e-10) -> dict:
    """Score test of one candidate effect at its null, the base parameters free (module docstring).

    Parameters
    ----------
    white_resid : (m,) whitened residual ``L^{-1}(obs - sim)`` of the calibrated base model.
    S_base_white : (m, p) whitened sensitivities of the base parameters (``p`` may be 0).
    S_cand_white : (m,) or (m, k) whitened sensitivities of the candidate's parameters at their null.

    Returns
    -------
    dict: ``score`` (T), ``dof`` (rank of the candidate's new directions), ``p_value``, ``log10_p``,
    ``collinearity`` (``cos^2`` of the smallest principal angle to the base span; 1 = inside it),
    ``principal_angle_deg``, ``explained_fraction`` (``T / |P w|^2``), ``explained_excess``
    (``(T - dof) / (|P w|^2 - (m - rank_base))``, NaN if the residual has no excess energy),
    ``step`` (Gauss-Newton step of the candidate's parameters from the null, in the units of the
    sensitivities' parameters), ``residual_energy`` (``|w|^2``), ``projected_energy`` (``|P w|^2``),
    ``rank_base``.
    """
    w = np.asarray(white_resid, dtype=float)
    if w.ndim != 1:
        raise ValueError("white_resid must be 1-D")
    m = w.size
    B = _as_columns(S_base_white, m, "S_base_white") if np.size(S_base_white) else np.zeros((m, 0))
    C = _as_columns(S_cand_white, m, "S_cand_white")
    k = C.shape[1]
    Qb = _orth(B, rtol)
    Pw = _project_out(Qb, w)
    PC = _project_out(Qb, C)
    e_res, e_proj = float(w @ w), float(Pw @ Pw)
    excess = e_proj - (m - Qb.shape[1])

    Qc = _orth(C, rtol)
    if Qc.shape[1] == 0:
        lam = np.zeros(1)
    else:
        PQc = _project_out(Qb, Qc)
        lam = np.clip(linalg.eigvalsh(PQc.T @ PQc), 0.0, 1.0)
    collinearity = float(1.0 - lam.min())
    angle = float(np.degrees(np.arcsin(math.sqrt(lam.min()))))

    G = PC.T @ PC
    U = PC.T @ Pw
    ev, V = linalg.eigh(G)
    keep = ev > rtol * max(float(ev.max()), 0.0)
    # a candidate inside the base span (to round-off) has no new direction: score 0, dof 0
    if lam.max() < rtol or not np.any(keep):
        score, dof, step = 0.0, 0, np.full(k, math.nan)
    else:
        Vk, ek = V[:, keep], ev[keep]
        coef = (Vk.T @ U) / ek
        score = float(np.sum((Vk.T @ U) * coef))
        step = Vk @ coef
        dof = int(keep.sum())
    if dof:
        p = float(stats.chi2.sf(score, dof))
        log10_p = chi2_log10_sf(score, dof)
    else:
        p, log10_p = 1.0, 0.0
    return {
        "score": score, "dof": dof, "p_value": p, "log10_p": log10_p,
        "collinearity": collinearity, "principal_angle_deg": angle,
        "explained_fraction": score / e_proj if e_proj > 0 else math.nan,
        "explained_excess": (score - dof) / excess if excess > 0 else math.nan,
        "step": step, "residual_energy": e_res, "projected_energy": e_proj, "rank_base": int(Qb.shape[1]),
    }


def rank_candidates(white_resid, S_base_white, candidates: Mapping[str, np.ndarray], *,
                    param_names: Mapping[str, Sequence[str]] | None = None, alpha: float = 1e-3,
                    min_explained: float = 0.0, max_collinearity: float = 0.999,
                    rtol: float = 1e-10) -> pd.DataFrame:
    """Score-test every candidate and rank them, most significant first.

    ``candidates`` maps an effect name to its whitened sensitivity column(s) ``(m,)`` or ``(m, k)``.
    A candidate ``passes`` when its score test rejects the null at level ``alpha`` (default 1e-3, per
    candidate: the 99.9% quantile of ``chi2(k)``), its collinearity with the base span is at most
    ``max_collinearity`` (otherwise the base already absorbs it and its parameter is not identifiable),
    and its linearised share of the residual's excess energy is at least ``min_explained`` (off by
    default: that share is only reliable for responses close to linear, see the module docstring).

    Columns: ``rank, effect, n_params, score, dof, p_value, log10_p, significant, explained_fraction,
    explained_excess, collinearity, principal_angle_deg, nearest_candidate, candidate_collinearity,
    step, passes`` (``step`` a JSON string ``{param: Gauss-Newton step from the null}``;
    ``candidate_collinearity`` the collinearity, after removing the base span, with the most similar
    other candidate: near 1 means the two are indistinguishable to first order).
    """
    w = np.asarray(white_resid, dtype=float)
    m = w.size
    B = _as_columns(S_base_white, m, "S_base_white") if np.size(S_base_white) else np.zeros((m, 0))
    Qb = _orth(B, rtol)
    names = list(candidates)
    proj_bases = {}
    rows = []
    for name in names:
        C = _as_columns(candidates[name], m, f"sensitivity of {name!r}")
        res = score_test(w, B, C, rtol=rtol)
        pnames = list(param_names[name]) if param_names and name in param_names else \
            [f"{name}[{j}]" for j in range(C.shape[1])]
        proj_bases[name] = _orth(_project_out(Qb, C), 1e-8)
        rows.append({
            "effect": name, "n_params": C.shape[1], "score": res["score"], "dof": res["dof"],
            "p_value": res["p_value"], "log10_p": res["log10_p"],
            "significant": bool(res["dof"] > 0 and res["p_value"] < alpha),
            "explained_fraction": res["explained_fraction"], "explained_excess": res["explained_excess"],
            "collinearity": res["collinearity"], "principal_angle_deg": res["principal_angle_deg"],
            "step": json.dumps(jsonable(dict(zip(pnames, res["step"])))),
        })
    for row in rows:
        best, best_c = None, math.nan
        Qi = proj_bases[row["effect"]]
        for other in names:
            Qj = proj_bases[other]
            if other == row["effect"] or Qi.shape[1] == 0 or Qj.shape[1] == 0:
                continue
            c = float(linalg.svdvals(Qi.T @ Qj).max() ** 2)
            if best is None or c > best_c:
                best, best_c = other, c
        row["nearest_candidate"] = best
        row["candidate_collinearity"] = best_c
        row["passes"] = bool(row["significant"] and np.isfinite(row["explained_excess"])
                             and row["explained_excess"] >= min_explained
                             and row["collinearity"] <= max_collinearity)
    cols = ["effect", "n_params", "score", "dof", "p_value", "log10_p", "significant", "explained_fraction",
            "explained_excess", "collinearity", "principal_angle_deg", "nearest_candidate",
            "candidate_collinearity", "step", "passes"]
    table = pd.DataFrame(rows, columns=cols)
    if len(table):
        table = table.sort_values(["log10_p", "score"], ascending=[True, False], kind="stable").reset_index(drop=True)
    table.insert(0, "rank", np.arange(1, len(table) + 1))
    return table


# ----------------------------------------------------------------------------------------------
# 4. Model choice
# ----------------------------------------------------------------------------------------------

def bic(chi2: float, n_params: int, n_eff: float) -> float:
    """``BIC = chi2 + n_params ln(n_eff)`` (``chi2`` = ``-2 ln L`` up to a constant; module docstring)."""
    if not n_eff >= 1:
        raise ValueError(f"n_eff must be >= 1, got {n_eff}")
    return float(chi2) + int(n_params) * math.log(float(n_eff))


def effective_sample_size(source, n: int | None = None) -> float:
    """Effective number of independent observations.

    ``source``:

    * an :class:`~enkf.covariance.ObservationError`: ``1^T C^{-1} 1 = |L^{-1} sigma|^2`` with ``C`` its
      correlation matrix (``m`` for independent errors; for AR(1) ``(m - (m-2) rho_1)/(1 + rho_1)``);
    * a residual vector (e.g. whitened): ``m (1 - rho_1) / (1 + rho_1)`` with its sample lag-one
      autocorrelation ``rho_1`` clipped to ``[0, 0.999]``;
    * a number: ``rho_1`` itself, with ``n`` given.
    """
    if isinstance(source, ObservationError):
        return float(source.chi2(source.std))
    if np.ndim(source) == 0:
        if n is None:
            raise ValueError("give n with a scalar rho1")
        rho, m = float(source), int(n)
    else:
        x = np.asarray(source, dtype=float)
        m = x.size if n is None else int(n)
        rho = float(autocorrelation(x, 1)[1])
    rho = min(max(rho, 0.0), 0.999)
    return max(1.0, m * (1.0 - rho) / (1.0 + rho))


def pinned_at_bounds(samples, lower, upper, names: Sequence[str], *, nulls: Mapping[str, float] | None = None,
                     fraction: float = 0.02) -> list[dict]:
    """Parameters whose posterior median lies within ``fraction`` of the box width of a bound of the box
    the calibration was confined to: there the box, not the data, decided the estimate (a bounded
    transform piles the ensemble up against a bound the data push it through). A bound equal to the
    parameter's null value (``nulls``) is exempt: an estimate at the null is the null criterion's
    business, not a box limit. Returns one dict per pinned parameter: ``name``, ``median``, ``side``
    (``"lower"``/``"upper"``), ``bound``, ``text``."""
    X = np.array(samples, dtype=float, ndmin=2)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if X.shape[1] != len(names) or lo.shape != (len(names),) or hi.shape != (len(names),):
        raise ValueError("samples, lower, upper and names must describe the same parameters")
    nulls = nulls or {}
    out = []
    for j, n in enumerate(names):
        med, width = float(np.median(X[:, j])), float(hi[j] - lo[j])
        for side, b in (("lower", lo[j]), ("upper", hi[j])):
            if n in nulls and math.isclose(float(nulls[n]), float(b), rel_tol=0.0, abs_tol=1e-12 * width):
                continue
            if abs(med - b) <= fraction * width:
                out.append({"name": n, "median": med, "side": side, "bound": float(b),
                            "text": f"{n} median {med:.4g} at its {side} bound {b:.4g}"})
    return out


def accept_effect(bic_base: float, bic_aug: float, posterior_samples_of_effect_param, null_value,
                  heldout_err_base: float | None, heldout_err_aug: float | None, *, margin: float = 10.0,
                  interval: float = 0.90, null_tolerance=0.0, explained: float | None = None,
                  min_explained: float = 0.25, pinned: Sequence[dict] | None = None) -> tuple[bool, list[str]]:
    """Keep an added effect only if all hold:

    1. the BIC improves by at least ``margin`` (default 10, "very strong" on Kass & Raftery's scale);
    2. the central ``interval`` (default 90%) of its parameter's posterior excludes the null value by
       more than ``null_tolerance`` (for an effect with several parameters: at least one of them does;
       the tolerance matters for a null at a bound, e.g. a low-pass ``tau = 0``, which every member
       trivially exceeds);
    3. the error on held-out data falls (skipped, and said so, when no held-out data are given);
    4. if ``explained`` is given (the re-calibrated model's drop in chi-square as a fraction of the
       base residual's excess over its noise expectation), it is at least ``min_explained``;
    5. if ``pinned`` is given (:func:`pinned_at_bounds` of the augmented calibration), it is empty: an
       estimate the box decided says only that the answer lies outside the box.

    Returns ``(accepted, reasons)``, one human-readable line per criterion starting with ``pass`` or ``fail``.
    """
    reasons: list[str] = []
    gain = float(bic_base) - float(bic_aug)
    ok_bic = gain >= margin
    reasons.append(f"{'pass' if ok_bic else 'fail'}: BIC {bic_base:.6g} -> {bic_aug:.6g} "
                   f"(improves by {gain:.4g}, margin {margin:g})")

    X = np.asarray(posterior_samples_of_effect_param, dtype=float)
    X = X[:, None] if X.ndim == 1 else X
    nulls = np.broadcast_to(np.asarray(null_value, dtype=float), (X.shape[1],))
    tols = np.broadcast_to(np.asarray(null_tolerance, dtype=float), (X.shape[1],))
    lo_q, hi_q = 0.5 - interval / 2.0, 0.5 + interval / 2.0
    q_lo, q_hi = np.quantile(X, lo_q, axis=0), np.quantile(X, hi_q, axis=0)
    excl = (q_lo - nulls > tols) | (nulls - q_hi > tols)
    ok_null = bool(np.any(excl))
    parts = [f"[{a:.4g}, {b:.4g}] {'excludes' if e else 'contains'} null {z:.4g}"
             for a, b, z, e in zip(q_lo, q_hi, nulls, excl)]
    reasons.append(f"{'pass' if ok_null else 'fail'}: {100 * interval:.0f}% interval " + "; ".join(parts)
                   + (f" (tolerance {', '.join(f'{t:.3g}' for t in tols)})" if np.any(tols > 0) else ""))

    if heldout_err_base is None or heldout_err_aug is None:
        ok_ho = True
        reasons.append("pass: no held-out data, held-out criterion skipped")
    else:
        ok_ho = float(heldout_err_aug) < float(heldout_err_base)
        reasons.append(f"{'pass' if ok_ho else 'fail'}: held-out error {heldout_err_base:.4g} -> "
                       f"{heldout_err_aug:.4g}")
    ok_ex = True
    if explained is not None:
        ok_ex = bool(np.isfinite(explained) and explained >= min_explained)
        reasons.append(f"{'pass' if ok_ex else 'fail'}: explains {explained:.1%} of the excess residual "
                       f"(minimum {min_explained:.0%})")
    ok_box = True
    if pinned is not None:
        ok_box = not pinned
        reasons.append("pass: no estimate at a bound of its box" if ok_box else
                       "fail: set by the box, not the data: " + "; ".join(p["text"] for p in pinned))
    return bool(ok_bic and ok_null and ok_ho and ok_ex and ok_box), reasons


def curve_errors(times, sim, obs) -> dict:
    """``rmse``, ``nrmse`` (by the observed range), ``peak_error`` (``max sim - max obs``), ``peak_rel_error``
    (by ``max obs``) and ``time_to_peak_error`` (``t[argmax sim] - t[argmax obs]``), in the caller's units."""
    t = np.asarray(times, dtype=float)
    y = np.asarray(sim, dtype=float)
    d = np.asarray(obs, dtype=float)
    span = float(d.max() - d.min())
    e = float(rmse(y, d))
    peak_d = float(d.max())
    return {"rmse": e, "nrmse": e / span if span > 0 else math.nan,
            "peak_error": float(y.max()) - peak_d,
            "peak_rel_error": (float(y.max()) - peak_d) / abs(peak_d) if peak_d != 0 else math.nan,
            "time_to_peak_error": float(t[int(np.argmax(y))] - t[int(np.argmax(d))])}


@dataclass
class Candidate:
    """A generic candidate effect for :func:`diagnose_loop`: a name, its parameters' names and null values,
    optionally their prior box (used for the null tolerance). ``shpb.effects.Effect`` has the same
    attributes and can be passed directly."""

    name: str
    param_names: tuple[str, ...]
    nulls: tuple[float, ...]
    lower: tuple[float, ...] | None = None
    upper: tuple[float, ...] | None = None


@dataclass
class CalibrationResult:
    """What ``calibrate(param_names)`` returns to :func:`diagnose_loop`.

    names : the calibrated parameters, in order (the columns of ``params``).
    params : (N, n) posterior ensemble (bounded, the caller's units).
    fitted : (m,) the calibrated model's curve on the calibration observations (e.g. the response at
        the posterior mean).
    heldout : (m_h,) its prediction of the held-out observations, or None.
    responses : (N, m) the posterior ensemble's responses, if the caller wants ensemble sensitivities.
    info : anything else (JSON-ready), copied into the report.
    lower, upper : (n,) the box the calibration was confined to (prior box, or an emulator's design box),
        if it had one; the loop then refuses estimates the box, not the data, decided
        (:func:`pinned_at_bounds`).
    """

    names: list[str]
    params: np.ndarray
    fitted: np.ndarray
    heldout: np.ndarray | None = None
    responses: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def __post_init__(self):
        self.names = list(self.names)
        self.params = np.array(self.params, dtype=float, ndmin=2)
        self.fitted = np.asarray(self.fitted, dtype=float)
        if self.params.shape[1] != len(self.names):
            raise ValueError(f"params has {self.params.shape[1]} columns for {len(self.names)} names")
        if (self.lower is None) != (self.upper is None):
            raise ValueError("give both lower and upper, or neither")
        if self.lower is not None:
            self.lower, self.upper = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
            if self.lower.shape != (len(self.names),) or self.upper.shape != (len(self.names),):
                raise ValueError(f"lower/upper need {len(self.names)} entries, one per name")

    def mean(self) -> dict[str, float]:
        return dict(zip(self.names, self.params.mean(axis=0).tolist()))

    def samples(self, names: Sequence[str]) -> np.ndarray:
        idx = [self.names.index(n) for n in names]
        return self.params[:, idx]


def _candidate_tolerances(cand, fraction: float) -> np.ndarray:
    k = len(cand.param_names)
    lower, upper = getattr(cand, "lower", None), getattr(cand, "upper", None)
    if lower is None or upper is None:
        return np.zeros(k)
    return fraction * (np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float))


def diagnose_loop(calibrate: Callable[[list[str]], CalibrationResult],
                  sensitivities: Callable[[CalibrationResult, list[str]], np.ndarray], *,
                  base_names: Sequence[str], candidates: Sequence, obs, obs_error: ObservationError, times,
                  heldout_obs=None, heldout_times=None, max_additions: int = 2, alpha_structure: float = 0.01,
                  alpha_score: float = 1e-3, min_explained: float = 0.25, max_collinearity: float = 0.999,
                  screen_min_explained: float = 0.0,
                  bic_margin: float = 10.0, interval: float = 0.90, null_tolerance_fraction: float = 0.01,
                  n_eff: str | float = "model", max_trials: int = 3, tie_fraction: float = 0.25,
                  windows: Mapping[str, tuple[float, float]] | None = None, lag: int | None = None,
                  base_result: CalibrationResult | None = None, bound_fraction: float | None = 0.02) -> dict:
    """The discrepancy loop: calibrate the base model, test its residual, rank the candidate effects by
    score test, add the best one if re-calibration justifies it, repeat.

    Parameters
    ----------
    calibrate : ``calibrate(param_names) -> CalibrationResult``; ``param_names`` are the base names
        followed by the effect parameters added so far (effects not named are at their null).
    sensitivities : ``sensitivities(result, names) -> (m, len(names))``: ``d fitted / d theta`` at the
        calibrated estimate of ``result``, candidate parameters at their null. The loop asks for the
        current calibrated parameters followed by every remaining candidate's parameters. Unwhitened
        (the loop whitens with ``obs_error``); finite differences or :func:`ensemble_sensitivity`.
    base_names : the base model's calibrated parameters.
    candidates : effects offered, each with ``name``, ``param_names``, ``nulls`` and optionally ``lower``,
        ``upper`` (:class:`Candidate`, ``shpb.effects.Effect``).
    obs, obs_error, times : calibration observations, their error model and times.
    heldout_obs, heldout_times : observations not used to calibrate (another record, or the post-peak
        part), predicted by ``CalibrationResult.heldout``; None to skip the held-out criterion.
    max_additions : at most this many effects are added.
    alpha_structure : family-wise level of the structure tests; the loop stops as soon as the residual
        passes them.
    alpha_score, max_collinearity, screen_min_explained : candidate screening (:func:`rank_candidates`;
        its linearised explained share is off by default).
    bic_margin, interval, null_tolerance_fraction, min_explained : :func:`accept_effect` (the tolerance
        is this fraction of each effect parameter's box width when the candidate has one;
        ``min_explained`` is the share of the current residual's excess chi-square over its noise
        expectation ``m - n_params`` that the re-calibrated augmented model must remove).
    n_eff : ``"model"`` (from ``obs_error``), ``"residual"`` (from the base model's whitened residual) or a
        number; fixed for the whole loop so the BIC values are comparable.
    max_trials, tie_fraction : the screened candidates whose score is at least ``tie_fraction`` of the
        best one are each re-calibrated (at most ``max_trials``, best scores first) and the accepted one
        with the lowest BIC is kept. ``max_trials = 1`` is the plain "add the best candidate" rule. Near
        ties arise because effects can share their first-order signature (a one-pole low-pass of time
        constant tau is a delay by tau to first order; a gain steepens the rise as an earlier trigger
        would), which a score test at the null cannot separate.
    windows : structure-test windows (default :func:`default_windows` of the base model's curve).
    lag : Ljung-Box lag.
    base_result : an already calibrated base model (skips the first ``calibrate`` call).
    bound_fraction : for calibrations that report their box (``CalibrationResult.lower``/``upper``): an
        augmented calibration with any parameter's median within this fraction of the box width of a
        bound is refused (:func:`pinned_at_bounds`, :func:`accept_effect` criterion 5), and a base
        calibration at a bound is reported (``box_limited``) and said in ``why``. None disables it.

    After an addition, every effect added earlier whose interval now contains its null is re-tested:
    the model is re-calibrated without it and it is dropped unless it is worth the BIC margin (an early
    addition that only stood in for the later one, e.g. a trigger shift mimicking a gain's steeper rise).

    Returns
    -------
    dict (make it JSON-ready with :func:`report_to_json`):
    ``verdict`` ("explained" | "unexplained" | "no structure"), ``why``, ``added`` (effects kept),
    ``chosen`` (first effect kept or None), ``candidate_table`` (DataFrame of the first ranking),
    ``iterations`` (per round: names, structure, candidates, trials, chosen, dropped, why),
    ``structure_before``,
    ``structure_after``, ``params_before`` / ``params_after`` (posterior mean, std, q05, q95),
    ``base_shift`` (how far each base parameter's mean moved, in before-posterior std and relative),
    ``bic`` (before, after, n_eff), ``errors`` (``calibration`` and ``heldout``, each ``before``/``after``
    from :func:`curve_errors`), ``box_limited`` (``base`` and ``final``: :func:`pinned_at_bounds` of the
    base and of the final calibration, None when the calibrations report no box) and ``curves`` (arrays
    for plotting).
    """
    obs = np.asarray(obs, dtype=float)
    times = np.asarray(times, dtype=float)
    m = obs.size
    if obs_error.m != m or times.shape != obs.shape:
        raise ValueError("obs, times and obs_error must describe the same m observations")
    has_ho = heldout_obs is not None
    ho_obs = np.asarray(heldout_obs, dtype=float) if has_ho else None
    ho_t = np.asarray(heldout_times, dtype=float) if has_ho else None
    if has_ho and (ho_t is None or ho_t.shape != ho_obs.shape):
        raise ValueError("heldout_times must match heldout_obs")
    cand_by_name = {c.name: c for c in candidates}
    if len(cand_by_name) != len(candidates):
        raise ValueError("candidate names must be unique")

    base_names = list(base_names)
    base = base_result if base_result is not None else calibrate(list(base_names))
    if list(base.names) != base_names:
        raise ValueError(f"calibrate returned names {base.names}, expected {base_names}")
    effect_nulls = {p: z for c in candidates for p, z in zip(c.param_names, c.nulls)}

    def pinned(res: CalibrationResult) -> list[dict] | None:
        if bound_fraction is None or res.lower is None:
            return None
        return pinned_at_bounds(res.params, res.lower, res.upper, res.names, nulls=effect_nulls,
                                fraction=bound_fraction)

    base_pinned = pinned(base)
    if windows is None:
        try:
            windows = default_windows(times, base.fitted)
        except ValueError:
            windows = None

    w0 = whitened_residual(base.fitted, obs, obs_error)
    if n_eff == "model":
        neff = effective_sample_size(obs_error)
    elif n_eff == "residual":
        neff = effective_sample_size(w0)
    else:
        neff = float(n_eff)

    def evaluate(res: CalibrationResult) -> dict:
        w = whitened_residual(res.fitted, obs, obs_error)
        c2 = float(w @ w)
        ho_rmse = None
        if has_ho:
            if res.heldout is None:
                raise ValueError("held-out observations given but calibrate returned no heldout prediction")
            ho_rmse = float(rmse(res.heldout, ho_obs))
        return {"w": w, "chi2": c2, "bic": bic(c2, len(res.names), neff), "heldout_rmse": ho_rmse}

    current, cur_eval = base, evaluate(base)
    base_eval = cur_eval
    added: list[str] = []
    remaining = [c.name for c in candidates]
    iterations: list[dict] = []
    first_table = None
    verdict, why = "unexplained", ""

    for round_ in range(max_additions + 1):
        st = structure_tests(cur_eval["w"], times, windows, n_params=len(current.names), lag=lag,
                             alpha=alpha_structure)
        step = {"round": round_, "names": list(current.names), "bic": cur_eval["bic"], "structure": st,
                "candidates": None, "trials": [], "chosen": None, "dropped": [], "why": ""}
        iterations.append(step)
        if st["passed"]:
            verdict = "explained" if added else "no structure"
            why = ("the residual passes the structure tests" +
                   (f" after adding {', '.join(added)}" if added else " of the base model; nothing to add"))
            break
        if round_ == max_additions:
            why = (f"the residual still fails {', '.join(st['failed'])} after {len(added)} addition(s) "
                   f"(maximum {max_additions})")
            break
        if not remaining:
            why = f"the residual fails {', '.join(st['failed'])} and no candidate is left"
            break

        cand_params = [p for name in remaining for p in cand_by_name[name].param_names]
        S = np.asarray(sensitivities(current, list(current.names) + cand_params), dtype=float)
        n_cur = len(current.names)
        if S.shape != (m, n_cur + len(cand_params)):
            raise ValueError(f"sensitivities returned shape {S.shape}, expected {(m, n_cur + len(cand_params))}")
        Sw = obs_error.whiten(S)
        cols, j = {}, n_cur
        for name in remaining:
            k = len(cand_by_name[name].param_names)
            cols[name] = Sw[:, j:j + k]
            j += k
        table = rank_candidates(cur_eval["w"], Sw[:, :n_cur], cols,
                                param_names={n: cand_by_name[n].param_names for n in remaining},
                                alpha=alpha_score, min_explained=screen_min_explained,
                                max_collinearity=max_collinearity)
        step["candidates"] = table
        if first_table is None:
            first_table = table
        passing = table[table["passes"]]
        if passing.empty:
            why = (f"the residual fails {', '.join(st['failed'])} but no candidate passes the score screening "
                   f"(p < {alpha_score:g}, collinearity <= {max_collinearity:g}"
                   + (f", linearised share >= {screen_min_explained:.0%}" if screen_min_explained > 0 else "")
                   + ")")
            step["why"] = why
            break
        best_score = float(passing["score"].iloc[0])
        trial_names = [r.effect for r in passing.itertuples() if r.score >= tie_fraction * best_score][:max_trials]

        accepted = []
        for name in trial_names:
            cand = cand_by_name[name]
            res = calibrate(list(current.names) + list(cand.param_names))
            ev = evaluate(res)
            excess = cur_eval["chi2"] - (m - len(current.names))
            explained = (cur_eval["chi2"] - ev["chi2"]) / excess if excess > 0 else math.nan
            ok, reasons = accept_effect(cur_eval["bic"], ev["bic"], res.samples(cand.param_names), cand.nulls,
                                        cur_eval["heldout_rmse"], ev["heldout_rmse"], margin=bic_margin,
                                        interval=interval,
                                        null_tolerance=_candidate_tolerances(cand, null_tolerance_fraction),
                                        explained=explained, min_explained=min_explained, pinned=pinned(res))
            step["trials"].append({"effect": name, "accepted": ok, "reasons": reasons, "bic": ev["bic"],
                                   "explained": explained,
                                   "chi2": ev["chi2"], "heldout_rmse": ev["heldout_rmse"],
                                   "posterior": posterior_dict(res.params, res.names), "info": res.info})
            if ok:
                accepted.append((ev["bic"], name, res, ev, reasons))
        if not accepted:
            why = ("the best candidate(s) " + ", ".join(trial_names) + " did not earn their place: "
                   + " | ".join(f"{t['effect']}: " + "; ".join(r for r in t["reasons"] if r.startswith("fail"))
                                for t in step["trials"]))
            step["why"] = why
            break
        accepted.sort(key=lambda a: a[0])
        _, name, res, ev, reasons = accepted[0]
        row = table[table["effect"] == name].iloc[0]
        step["chosen"] = name
        step["why"] = (f"{name}: score {row['score']:.4g} (p = {row['p_value']:.3g}, rank {int(row['rank'])}), "
                       f"collinearity with the base {row['collinearity']:.3f}; " + "; ".join(reasons)
                       + (f"; lowest BIC of the {len(trial_names)} re-calibrated near-tied candidates "
                          f"({', '.join(trial_names)})" if len(trial_names) > 1 else ""))
        added.append(name)
        remaining.remove(name)
        current, cur_eval = res, ev

        # backward check: an earlier effect whose interval now contains its null, and whose removal costs
        # less than the BIC margin, was standing in for the new one; drop it (it may come back later)
        for old in [e for e in added if e != name]:
            cand = cand_by_name[old]
            X = current.samples(cand.param_names)
            q_lo, q_hi = np.quantile(X, 0.5 - interval / 2, axis=0), np.quantile(X, 0.5 + interval / 2, axis=0)
            tol = _candidate_tolerances(cand, null_tolerance_fraction)
            nulls = np.asarray(cand.nulls, dtype=float)
            if np.any((q_lo - nulls > tol) | (nulls - q_hi > tol)):
                continue
            res_wo = calibrate([n for n in current.names if n not in cand.param_names])
            ev_wo = evaluate(res_wo)
            drop = ev_wo["bic"] < cur_eval["bic"] + bic_margin
            step["dropped"].append({"effect": old, "dropped": bool(drop), "bic_with": cur_eval["bic"],
                                    "bic_without": ev_wo["bic"],
                                    "reason": f"its {100 * interval:.0f}% interval contains the null after adding "
                                              f"{name}; BIC without it {ev_wo['bic']:.6g} vs {cur_eval['bic']:.6g} "
                                              f"with it (margin {bic_margin:g})"})
            if drop:
                added.remove(old)
                remaining.append(old)
                current, cur_eval = res_wo, ev_wo
                step["why"] += f"; dropped {old} (" + step["dropped"][-1]["reason"] + ")"

    if base_pinned:
        why = ("the base calibration is box-limited (" + "; ".join(p["text"] for p in base_pinned)
               + "): its residual, and what the candidates are measured against, is that of a base model "
               "held at the edge of its box. " + why)
    final_struct = iterations[-1]["structure"]
    before_post = posterior_dict(base.params, base.names)
    after_post = posterior_dict(current.params, current.names)
    shift = {}
    for p in base_names:
        b, a = before_post[p], after_post[p]
        shift[p] = {"mean_before": b["mean"], "mean_after": a["mean"],
                    "shift_in_sd": (a["mean"] - b["mean"]) / b["std"] if b["std"] > 0 else math.nan,
                    "relative": (a["mean"] - b["mean"]) / abs(b["mean"]) if b["mean"] != 0 else math.nan}
    errors = {"calibration": {"before": curve_errors(times, base.fitted, obs),
                              "after": curve_errors(times, current.fitted, obs)}}
    if has_ho:
        errors["heldout"] = {"before": curve_errors(ho_t, base.heldout, ho_obs),
                             "after": curve_errors(ho_t, current.heldout, ho_obs)}
    return {
        "verdict": verdict, "why": why, "added": added, "chosen": added[0] if added else None,
        "candidate_table": first_table, "iterations": iterations,
        "structure_before": iterations[0]["structure"], "structure_after": final_struct,
        "params_before": before_post, "params_after": after_post, "base_shift": shift,
        "bic": {"before": base_eval["bic"], "after": cur_eval["bic"], "n_eff": neff},
        "errors": errors,
        "box_limited": {"base": base_pinned, "final": pinned(current)},
        "settings": {"max_additions": max_additions, "alpha_structure": alpha_structure, "alpha_score": alpha_score,
                     "min_explained": min_explained, "screen_min_explained": screen_min_explained,
                     "max_collinearity": max_collinearity, "bic_margin": bic_margin,
                     "interval": interval, "null_tolerance_fraction": null_tolerance_fraction, "n_eff": n_eff,
                     "max_trials": max_trials, "tie_fraction": tie_fraction, "windows": windows,
                     "bound_fraction": bound_fraction},
        "curves": {"times": times, "obs": obs, "fitted_before": base.fitted, "fitted_after": current.fitted,
                   "white_before": base_eval["w"], "white_after": cur_eval["w"],
                   "heldout_times": ho_t, "heldout_obs": ho_obs,
                   "heldout_before": base.heldout if has_ho else None,
                   "heldout_after": current.heldout if has_ho else None},
    }


# ----------------------------------------------------------------------------------------------
# 5. Report
# ----------------------------------------------------------------------------------------------

def report_to_json(report: dict, *, curves: bool = False) -> dict:
    """Strict-JSON version of a :func:`diagnose_loop` report (DataFrames as lists of records; the
    ``curves`` arrays only if asked)."""
    def conv(obj):
        if isinstance(obj, pd.DataFrame):
            return obj.to_dict(orient="records")
        if isinstance(obj, dict):
            return {k: conv(v) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [conv(v) for v in obj]
        return obj
    out = {k: v for k, v in report.items() if curves or k != "curves"}
    return jsonable(conv(out))


def _split_records(t, y):
    """``(t, y)`` with a NaN gap wherever the time runs backwards (the next record of a concatenated
    vector starts), so a plotted line does not join the end of one record to the start of the next."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    cut = np.nonzero(np.diff(t) < 0)[0] + 1
    return np.insert(t, cut, np.nan), np.insert(y, cut, np.nan)


def write_report(report: dict, directory, *, time_scale: float = 1e6, value_scale: float = 1e-6,
                 time_label: str = "time [us]", value_label: str = "stress [MPa]") -> list[Path]:
    """Write a :func:`diagnose_loop` report to ``directory`` (e.g. ``results/<experiment>/diagnosis/``):

    ``report.json`` (everything but the curves), ``candidates.csv`` (every round's ranking with a
    ``round`` column), ``params.csv`` (posterior before/after), ``errors.csv`` (RMSE, peak and
    time-to-peak errors before/after on calibration and held-out data), and the plots ``fit.png``
    (data and fits before/after, whitened residuals) and ``candidates.png`` (score-test significance and
    collinearity per candidate). Returns the paths written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = []

    p = out / "report.json"
    p.write_text(json.dumps(report_to_json(report), indent=2, allow_nan=False))
    paths.append(p)

    tables = [it["candidates"].assign(round=it["round"]) for it in report["iterations"]
              if it["candidates"] is not None]
    p = out / "candidates.csv"
    (pd.concat(tables, ignore_index=True) if tables else pd.DataFrame(columns=["round", "effect"])).to_csv(p, index=False)
    paths.append(p)

    rows = []
    for when, post in (("before", report["params_before"]), ("after", report["params_after"])):
        for name, s in post.items():
            rows.append({"when": when, "param": name, **s})
    p = out / "params.csv"
    pd.DataFrame(rows).to_csv(p, index=False)
    paths.append(p)

    rows = [{"data": data, "when": when, **vals} for data, d in report["errors"].items() for when, vals in d.items()]
    p = out / "errors.csv"
    pd.DataFrame(rows).to_csv(p, index=False)
    paths.append(p)

    c = report["curves"]
    ho = c.get("heldout_obs") is not None
    fig, axes = plt.subplots(2, 2 if ho else 1, figsize=(11 if ho else 6.5, 6.5), squeeze=False,
                             sharex="col", gridspec_kw={"height_ratios": [2, 1]})
    t = np.asarray(c["times"]) * time_scale
    ax = axes[0, 0]
    ax.plot(*_split_records(t, np.asarray(c["obs"]) * value_scale), ".", ms=2, color="0.5", label="data")
    ax.plot(*_split_records(t, np.asarray(c["fitted_before"]) * value_scale), label="base model")
    ax.plot(*_split_records(t, np.asarray(c["fitted_after"]) * value_scale),
            label="with " + (", ".join(report["added"]) if report["added"] else "nothing added"))
    ax.set_ylabel(value_label)
    ax.set_title(f"calibration data; verdict: {report['verdict']}")
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(*_split_records(t, c["white_before"]), lw=0.8, label="base")
    ax.plot(*_split_records(t, c["white_after"]), lw=0.8, label="after")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylabel("whitened residual")
    ax.set_xlabel(time_label)
    ax.legend(fontsize=8)
    if ho:
        th = np.asarray(c["heldout_times"]) * time_scale
        ax = axes[0, 1]
        ax.plot(*_split_records(th, np.asarray(c["heldout_obs"]) * value_scale), ".", ms=2, color="0.5", label="held-out data")
        ax.plot(*_split_records(th, np.asarray(c["heldout_before"]) * value_scale), label="base model")
        ax.plot(*_split_records(th, np.asarray(c["heldout_after"]) * value_scale), label="after")
        ax.set_title("held-out data")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        ax.plot(*_split_records(th, (np.asarray(c["heldout_obs"]) - np.asarray(c["heldout_before"])) * value_scale), lw=0.8,
                label="base")
        ax.plot(*_split_records(th, (np.asarray(c["heldout_obs"]) - np.asarray(c["heldout_after"])) * value_scale), lw=0.8,
                label="after")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"residual [{value_label.split('[')[-1]}" if "[" in value_label else "residual")
        ax.set_xlabel(time_label)
    fig.tight_layout()
    p = out / "fit.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    if tables:
        tab = tables[0]
        y = np.arange(len(tab))
        axes[0].barh(y, -tab["log10_p"], color=["C2" if ok else "C7" for ok in tab["passes"]])
        axes[0].set_yticks(y, tab["effect"])
        axes[0].invert_yaxis()
        alpha = report["settings"]["alpha_score"]
        axes[0].axvline(-math.log10(alpha), color="k", ls="--", lw=0.8, label=f"p = {alpha:g}")
        axes[0].set_xlabel("-log10 p (score test)")
        axes[0].set_title(f"first ranking; kept: {', '.join(report['added']) or 'none'}", fontsize=9)
        axes[0].set_xscale("symlog", linthresh=1.0)
        axes[0].legend(fontsize=8)
        axes[1].barh(y, tab["collinearity"], color="C1")
        axes[1].set_yticks(y, tab["effect"])
        axes[1].invert_yaxis()
        axes[1].set_xlim(0, 1)
        axes[1].set_xlabel("collinearity with the base parameters")
    else:
        for ax in axes:
            ax.text(0.5, 0.5, "no candidates ranked\n(" + report["verdict"] + ")", ha="center", va="center")
            ax.set_axis_off()
    fig.tight_layout()
    p = out / "candidates.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    return paths
