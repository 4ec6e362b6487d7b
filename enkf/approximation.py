"""The approximation error of a coarse model against a finer one (Kaipio & Somersalo's Bayesian
approximation error).

Data that come from a finer discretisation than the model's (a lab's specimen has no mesh; a twin made
on the ``standard`` mesh and calibrated at ``fast``) carry a resolution error the coarse model cannot
fit: ``d = f_fine(theta) + e = f_coarse(theta) + eps(theta) + e``. Paired runs of both models at design
points drawn from the prior give draws of ``eps``; its mean ``offset`` is a bias the coarse model makes
everywhere in the box (subtracted from the data) and its scatter about that mean, over the prior and
over both models' mesh realizations, an error covariance ``M`` added to the instrument noise. This is
the approximation-error model's Gaussian step: it removes the bias a coarse model puts into the
parameters and widens the likelihood by what the bias does not explain, so the posterior is not made
sure by a model error it cannot see.

``M`` has the structure of the simulator's own variability (:mod:`enkf.variability`): a per-time
standard deviation (the pairs' unbiased variance, smoothed over neighbouring times) and one AR(1)
correlation time. It holds the scatter of a single fine run and of the coarse runs' mean, so with the
ensemble's own ``S`` beside it the likelihood counts the coarse model's mesh variability more than once
(conservative: wider, never narrower, intervals).
"""

from __future__ import annotations

import numpy as np

from .covariance import AR1Error
from .variability import SMOOTH_WINDOW, simulator_variability

__all__ = ["approximation_error"]


def approximation_error(fine, coarse, times, groups=None, *,
                        window: int = SMOOTH_WINDOW) -> tuple[np.ndarray, AR1Error | None, dict]:
    """``(offset, M, info)`` from paired curves on one grid: ``fine`` ``(n, m)`` (one run per design
    point) and ``coarse`` ``(n, m)`` or ``(n, k, m)`` (``k`` realizations per point, averaged).

    A pair with a non-finite value (a failed run) is left out; fewer than three usable pairs is an
    error (a mean and a scatter need more than one draw each, and two make a covariance of rank one).
    ``offset`` is the pairs' mean difference ``fine - coarse``; ``M`` the AR(1) covariance of the
    differences about it (None where they agree to round-off).
    """
    F = np.array(fine, dtype=float, ndmin=2)
    C = np.array(coarse, dtype=float)
    if C.ndim == 3:
        C = C.mean(axis=1)
    C = np.array(C, ndmin=2)
    t = np.asarray(times, dtype=float)
    if F.shape != C.shape or F.shape[1] != t.size:
        raise ValueError(f"fine {F.shape} and coarse {C.shape} curves must match each other and the grid ({t.size} times)")
    E = F - C
    ok = np.all(np.isfinite(E), axis=1)
    n = int(ok.sum())
    if n < 3:
        raise ValueError(f"approximation error needs at least 3 usable pairs of runs, got {n} of {F.shape[0]}")
    E = E[ok]
    offset = E.mean(axis=0)
    M, info = simulator_variability(E, t, groups, window=window)
    info = {k: v for k, v in info.items() if k != "n_replicates"}
    info.update({"n_pairs": int(F.shape[0]), "n_pairs_used": n,
                 "offset_rms_Pa": float(np.sqrt(np.mean(offset ** 2))),
                 "offset_max_abs_Pa": float(np.max(np.abs(offset)))})
    return offset, M, info
