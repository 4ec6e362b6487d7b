"""The emulator's error as a function of the parameters (issue 30): a heteroscedastic emulated likelihood.

Why: a fracture simulator's own variability is not the same everywhere in the box. Near a brittle corner
(low ``E_t``) the post-peak of runs at one parameter point on different meshes spans from unloading to
re-loading; at a tough one they stay together. The emulated likelihood ``N(d; em(theta), B + C_em)``
(``B = R + D``) carries one ``C_em``, the leave-one-out error at the latest runs, whose members sit
where the posterior is. A data set from a brittle point whose mesh happened to keep its post-peak high is
then better fitted by a tougher point with a narrower scatter, and the truth falls out of the interval
on one side (the development twins' ``E_t`` misses; ``studies/emulator_error_models.py``).

The model here scales ``C_em`` by ``a(theta)``, a local average of the runs' own leave-one-out misfits:

    q_j = r_j^T C_em^-1 r_j / m          (r_j: run j's leave-one-out residual, every run of every iteration)
    a(theta) = sum_j w_j q_j / sum_j w_j,   w_j = exp(-|u - u_j|^2 / 2 h^2)   (u: unit-box coordinates)

with the bandwidth ``h`` chosen among :data:`BANDWIDTHS` by the leave-one-run-out Gaussian log density of
the residuals (``inf``: one constant over the box; the value 1 everywhere, today's model, is a candidate
too, so nothing is assumed). The likelihood of ``d`` is then exact and cheap: with ``B = L L^T`` and
``L^-1 C_em L^-T = V diag(g) V^T`` (once),

    -2 log p(d | theta) = sum_i z_i^2 / (1 + a g_i) + sum_i log(1 + a g_i) + const,   z = V^T L^-1 (em(theta) - d)

The log-determinant matters: without it a wide ``a`` would always win.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg

__all__ = ["BANDWIDTHS", "HeteroscedasticError", "emulated_deviance", "local_scale"]

#: Kernel bandwidths tried, in unit-box coordinates; ``inf`` is one constant scale over the box.
BANDWIDTHS = (0.05, 0.1, 0.2, 0.4, math.inf)


def _weights(U: np.ndarray, Uj: np.ndarray, h: float) -> np.ndarray:
    if math.isinf(h):
        return np.ones((U.shape[0], Uj.shape[0]))
    d2 = np.sum((U[:, None, :] - Uj[None, :, :]) ** 2, axis=2)
    return np.exp(-0.5 * d2 / h ** 2)


def _average(w: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The kernel average of the misfits ``q`` (k,) with weights ``w`` (p, k), one per row: the scale's
    estimator, in one place for the scale and its bandwidth's score."""
    return w @ q / np.maximum(w.sum(axis=1), 1e-300)


def local_scale(U, Uj, q, h: float | None) -> np.ndarray:
    """``a`` at unit-box points ``U`` (p, n) from the runs at ``Uj`` (k, n) with misfits ``q`` (k,);
    ``h`` None: 1 everywhere."""
    U = np.atleast_2d(U)
    if h is None:
        return np.ones(U.shape[0])
    return _average(_weights(U, Uj, h), q)


class HeteroscedasticError:
    """``B + a(theta) C_em`` (module docstring). ``B``, ``C_em`` (m, m) dense; ``U`` (k, n) the runs in
    the unit box and ``residuals`` (k, m) their leave-one-out residuals. ``bandwidth`` None: choose."""

    def __init__(self, B, C_em, U, residuals, *, bandwidth: float | None | str = "choose"):
        B, C_em = np.asarray(B, float), np.asarray(C_em, float)
        self.U = np.atleast_2d(np.asarray(U, float))
        Rr = np.atleast_2d(np.asarray(residuals, float))
        L_em = linalg.cholesky(C_em, lower=True)
        W = linalg.solve_triangular(L_em, Rr.T, lower=True)
        self.q = np.sum(W * W, axis=0) / C_em.shape[0]
        self.scores = {}
        if bandwidth == "choose":
            logdet_em = 2.0 * float(np.sum(np.log(np.diag(L_em))))
            m = C_em.shape[0]
            for h in (None, *BANDWIDTHS):
                self.scores["1" if h is None else f"{h:g}"] = self._loo_score(h, m, logdet_em)
            key = max(self.scores, key=self.scores.get)
            bandwidth = None if key == "1" else float(key)
        self.bandwidth = bandwidth
        L = linalg.cholesky(B, lower=True)
        Li = linalg.solve_triangular(L, np.eye(B.shape[0]), lower=True)
        g, V = linalg.eigh(Li @ C_em @ Li.T)
        self.g = np.maximum(g, 0.0)
        self.T = V.T @ Li  # z = T r

    def _loo_score(self, h, m: int, logdet_em: float) -> float:
        """Sum over runs of the log density of run j's residual under ``N(0, a_-j(u_j) C_em)``."""
        k = self.q.size
        if h is None:
            a = np.ones(k)
        else:
            w = _weights(self.U, self.U, h)
            np.fill_diagonal(w, 0.0)
            a = _average(w, self.q)
        a = np.maximum(a, 1e-3)
        return float(np.sum(-0.5 * (m * self.q / a + m * np.log(a) + logdet_em)))

    def scale(self, U) -> np.ndarray:
        return local_scale(U, self.U, self.q, self.bandwidth)

    def parts(self, resid, U) -> tuple[np.ndarray, np.ndarray]:
        """``(quadratic form, log-determinant)`` of ``-2 log p + const`` for residuals ``resid`` (p, m) =
        em(theta) - d at unit-box points ``U`` (p, n); with the covariance times ``lam`` (the
        self-calibration's factor) the deviance is ``quad / lam + logdet`` (plus a constant)."""
        Z = np.atleast_2d(resid) @ self.T.T
        den = 1.0 + np.outer(self.scale(U), self.g)
        return np.sum(Z * Z / den, axis=1), np.sum(np.log(den), axis=1)

    def describe(self) -> dict:
        return {"bandwidth": None if self.bandwidth is None else float(self.bandwidth),
                "loo_log_density": self.scores,
                "misfit_q": {"min": float(self.q.min()), "median": float(np.median(self.q)),
                             "max": float(self.q.max())}}


def emulated_deviance(em, B, C_em, X, lower, upper):
    """``(deviance, het)``: ``deviance(P, y)`` (p,) is ``-2 log p(y | theta) + const`` at parameters ``P``
    (p, n) for the emulator ``em`` (callable on ``P``, with ``loo_residuals()`` at its runs ``X``) under
    ``B + a(theta) C_em``; ``het`` the :class:`HeteroscedasticError` (its ``describe()`` for the record)."""
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    het = HeteroscedasticError(B, C_em, (np.asarray(X, float) - lo) / (hi - lo), em.loo_residuals())

    def deviance(P, y):
        P = np.atleast_2d(P)
        quad, logdet = het.parts(em(P) - y, (P - lo) / (hi - lo))
        return quad + logdet
    return deviance, het
