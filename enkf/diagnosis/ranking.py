"""Sensitivities (ensemble, finite-difference) and the score test that ranks candidate effects by the
residual structure they explain beyond the base parameters (:mod:`enkf.diagnosis`, part 2; the protocol
uses the ranking only to order the candidates it tries)."""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd
from scipy import linalg, stats

from ..diagnostics import jsonable


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

    ``candidates`` maps an effect name to its whitened sensitivity column(s) ``(m,)`` or ``(m, k)``; an
    effect with one parameter per record has one column per record (zero outside its record's block), so
    ``k`` and the chi-square degrees of freedom count the records.
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
