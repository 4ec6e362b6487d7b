"""How strongly, and how separably, an ensemble's curves constrain each parameter (linearised Fisher
information and Cramer-Rao bounds; the ``sensitivity`` block of ``summary.json``)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from enkf import jsonable

from .observations import Observations

__all__ = ["linear_sensitivity"]


def linear_sensitivity(params: pd.DataFrame, names: Sequence[str], lower, upper, responses: np.ndarray,
                       obs: Observations, alive=None) -> dict:
    """How strongly, and how separably, the curve constrains each parameter, from an ensemble.

    Least-squares fit of the whitened responses on the parameters scaled to the box,
    ``L^{-1} y_i ~ a + G u_i`` with ``u = (p - lower)/(upper - lower)``. Column ``j`` of ``G`` is the
    change of the curve, in noise standard deviations, when parameter ``j`` crosses its whole box.
    The linearised Fisher information is ``F = G^T G`` (white whitened noise), so
    ``sqrt((F^-1)_jj) * (upper - lower)`` is the Cramer-Rao bound of the parameter's std [its units]
    from this observation vector, *with the other parameters unknown*; ``1/sqrt(F_jj)`` is the bound
    if they were known. A ratio ``crlb_joint / crlb_alone`` much larger than 1 means the parameters
    trade off (identifiability, not sensitivity, is the problem). Valid where the response is close to
    linear over the ensemble: use a narrow (late-iteration) ensemble for local numbers.
    """
    names = list(names)
    P = params[names].to_numpy(float)
    Y = np.asarray(responses, float)
    alive = np.all(np.isfinite(Y), axis=1) if alive is None else np.asarray(alive, bool) & np.all(np.isfinite(Y), axis=1)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    U = (P[alive] - lo) / (hi - lo)
    W = obs.error_model().whiten((Y[alive] - obs.values).T).T  # (Na, m)
    n = len(names)
    if U.shape[0] < n + 2:
        return {"n_members": int(U.shape[0]), "note": "too few members for a regression"}
    X = np.hstack([np.ones((U.shape[0], 1)), U - U.mean(axis=0)])
    coef, *_ = np.linalg.lstsq(X, W, rcond=None)
    G = coef[1:].T  # (m, n)
    resid = W - X @ coef
    F = G.T @ G
    out = {"n_members": int(U.shape[0]), "fit_r2": float(1.0 - np.sum(resid ** 2) / max(np.sum((W - W.mean(0)) ** 2), 1e-300)),
           "params": {}}
    try:
        Finv = np.linalg.inv(F)
    except np.linalg.LinAlgError:
        Finv = np.full_like(F, np.inf)
    for j, p in enumerate(names):
        width = hi[j] - lo[j]
        joint = math.sqrt(max(Finv[j, j], 0.0)) * width if np.isfinite(Finv[j, j]) else math.inf
        alone = width / math.sqrt(F[j, j]) if F[j, j] > 0 else math.inf
        out["params"][p] = {"curve_change_over_box_noise_std": float(math.sqrt(F[j, j])),
                            "crlb_std_joint": joint, "crlb_std_alone": alone,
                            "tradeoff_ratio": joint / alone if alone > 0 and math.isfinite(alone) else None,
                            "box_mean": float(P[alive, j].mean())}
    if n >= 2:
        d = np.sqrt(np.diag(F))
        corr = F / np.outer(d, d) if np.all(d > 0) else np.full_like(F, np.nan)
        out["information_correlation"] = corr.tolist()
    return jsonable(out)
