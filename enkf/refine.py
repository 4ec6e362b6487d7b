"""A refinement batch of simulator runs for the emulator posterior (issue 30).

Why: the loop's ES-MDA puts its last ensemble where the (tempered-down) posterior is, densely. The
emulator posterior (:mod:`enkf.ces`) measures the emulator's error at those runs, where it is smallest,
and its tails lie where runs are few: a truth in a tail (the disc's brittle end, low ``E_t``) is
penalised by a local error scale set by sparse, distant runs (:mod:`enkf.hetero`) and falls outside the
interval. A batch of runs spread over a *tempered* emulator posterior (the log-likelihood divided by
``temper``: about ``sqrt(temper)`` times wider) puts runs in those tails; the reported posterior then
measures the emulator's error, and self-calibrates, at that batch: over the whole region its interval
may reach, not only at its core (the benchmark's development data, ``docs/inference.md``).

The batch is the ``n`` k-means centroids of the tempered sample in unit-box coordinates (SciPy's
``kmeans2``, k-means++ seeding): spread over the sample's support with a density about the sample's
to the power ``d / (d + 2)`` (Gersho 1979; 1/2 in 2D), so the tails get more runs than their mass
share, where ``n`` random draws would crowd the mode.
"""

from __future__ import annotations

import numpy as np
from scipy.cluster.vq import kmeans2

from ._rng import RngLike, as_generator

__all__ = ["refinement_design"]

#: At most this many sample points are clustered (k-means cost grows with them; the centroids do not move).
MAX_POINTS = 4000


def refinement_design(samples, lower, upper, n: int, rng: RngLike) -> np.ndarray:
    """``(n, d)`` parameters: k-means centroids of ``samples`` ``(S, d)`` in the unit box of
    ``[lower, upper]``, mapped back (module docstring)."""
    X = np.asarray(samples, float)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    if X.ndim != 2 or X.shape[1] != lo.size:
        raise ValueError(f"samples must be (S, {lo.size}), got {X.shape}")
    if not 1 <= n <= X.shape[0]:
        raise ValueError(f"cannot place {n} refinement runs on {X.shape[0]} samples")
    rng = as_generator(rng)
    U = (X - lo) / (hi - lo)
    if U.shape[0] > MAX_POINTS:
        U = U[rng.choice(U.shape[0], MAX_POINTS, replace=False)]
    centroids, _ = kmeans2(U, n, minit="++", seed=rng)
    return lo + np.clip(centroids, 0.0, 1.0) * (hi - lo)
