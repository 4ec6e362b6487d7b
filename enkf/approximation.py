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
correlation time. What it must hold follows from where the rest of the error model already counts the
mesh. The workflow gives the data the coarse model's own variability ``S`` (the likelihood of the mean
over realizations is ``R + S + D``, a member against the data ``R + 2 S + D``, the emulator's error
stands for the data's ``S``), while data from the fine model scatter about the coarse mean by

    Var[f_fine(theta) - mu_coarse(theta)] = S_fine + Var_theta[bias]

and a pair's difference, against the mean of ``k`` coarse runs, by that plus ``S_coarse / k``. So
``coarse_variability="subtracted"`` (the workflow's default) takes ``(1 + 1/k) S_coarse`` off the pairs'
variance, ``S_coarse`` measured by the coarse runs' own scatter at each design point (``k - 1`` degrees
of freedom per point, hence ``k >= 2``); the term left is what the data need beyond the ``S`` they are
given, floored at zero where the fine mesh scatters less than the coarse one. ``"counted"`` keeps the
pairs' raw scatter: the coarse model's variability then enters ``1 + 1/k`` times more than it should
(wider intervals: on the disc at ``fast`` against ``standard`` its 50 % intervals of ``sigma_t``
over-cover, ``studies/results/coverage_misspecified_counted_pooled.json``).
"""

from __future__ import annotations

import numpy as np

from .covariance import AR1Error
from .variability import SMOOTH_WINDOW, simulator_variability, smoothed_variance

__all__ = ["COARSE_VARIABILITY", "approximation_error"]

#: What ``M`` does with the coarse model's own mesh variability (module docstring).
COARSE_VARIABILITY = ("subtracted", "counted")


def approximation_error(fine, coarse, times, groups=None, *, window: int = SMOOTH_WINDOW,
                        coarse_variability: str = "subtracted") -> tuple[np.ndarray, AR1Error | None, dict]:
    """``(offset, M, info)`` from paired curves on one grid: ``fine`` ``(n, m)`` (one run per design
    point) and ``coarse`` ``(n, k, m)`` (``k`` realizations per point, averaged; ``(n, m)`` is ``k = 1``).

    A pair with a non-finite value (a failed run) is left out; fewer than three usable pairs is an
    error (a mean and a scatter need more than one draw each, and two make a covariance of rank one).
    ``offset`` is the pairs' mean difference ``fine - coarse``; ``M`` the AR(1) covariance of the
    differences about it, less ``(1 + 1/k)`` times the coarse runs' own variance with
    ``coarse_variability="subtracted"`` (module docstring; needs ``k >= 2``); None where nothing is left.
    """
    if coarse_variability not in COARSE_VARIABILITY:
        raise ValueError(f"coarse_variability must be one of {COARSE_VARIABILITY}, got {coarse_variability!r}")
    F = np.array(fine, dtype=float, ndmin=2)
    C3 = np.array(coarse, dtype=float)
    if C3.ndim < 3:
        C3 = np.array(C3, ndmin=2)[:, None, :]
    k = C3.shape[1]
    C = C3.mean(axis=1)
    t = np.asarray(times, dtype=float)
    if F.shape != C.shape or F.shape[1] != t.size:
        raise ValueError(f"fine {F.shape} and coarse {C.shape} curves must match each other and the grid ({t.size} times)")
    if coarse_variability == "subtracted" and k < 2:
        raise ValueError("coarse_variability='subtracted' needs at least 2 coarse realizations per design point "
                         f"(their scatter measures the coarse model's own variability), got {k}")
    E = F - C
    ok = np.all(np.isfinite(E), axis=1) & np.all(np.isfinite(C3), axis=(1, 2))
    n = int(ok.sum())
    if n < 3:
        raise ValueError(f"approximation error needs at least 3 usable pairs of runs, got {n} of {F.shape[0]}")
    E = E[ok]
    offset = E.mean(axis=0)
    extra = {}
    subtract = None
    if coarse_variability == "subtracted":
        g = np.zeros(t.size, int) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
        dev = (C3[ok] - C[ok][:, None, :]).reshape(-1, t.size)
        var_c = smoothed_variance(dev, n * (k - 1), g, window)
        subtract = (1.0 + 1.0 / k) * var_c
        raw = smoothed_variance(E - offset, n - 1, g, window)
        extra = {"scatter_rms_Pa": float(np.sqrt(np.mean(raw))),
                 "coarse_variability_rms_Pa": float(np.sqrt(np.mean(var_c)))}
    M, info = simulator_variability(E, t, groups, window=window, subtract_variance=subtract)
    info = {key: v for key, v in info.items() if key != "n_replicates"}
    info.update({"n_pairs": int(F.shape[0]), "n_pairs_used": n, "coarse_variability": coarse_variability, **extra,
                 "offset_rms_Pa": float(np.sqrt(np.mean(offset ** 2))),
                 "offset_max_abs_Pa": float(np.max(np.abs(offset)))})
    return offset, M, info
