"""Initial ensemble by Latin hypercube sampling inside the prior box (paper, section 5.1).

The paper draws its initial ensemble of ``(sigma_t, E_t)`` with Latin hypercube sampling from uniform
priors on the intervals of its Table 2. Here the unit-cube design comes from
:class:`scipy.stats.qmc.LatinHypercube` (seeded) and is mapped affinely into the box
``lower <= p <= upper``: ``p = lower + u * (upper - lower)``.

Each of the ``n`` equal-width strata ``[lower + k w, lower + (k+1) w)``, ``w = (upper - lower) / n``,
of each parameter holds exactly one sample.
"""

from __future__ import annotations

import numpy as np

from ._rng import RngLike, as_generator


def _check_box(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    lower = np.atleast_1d(np.asarray(lower, dtype=float))
    upper = np.atleast_1d(np.asarray(upper, dtype=float))
    if lower.shape != upper.shape or lower.ndim != 1:
        raise ValueError(f"lower and upper must be 1-D of equal length, got {lower.shape} and {upper.shape}")
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise ValueError("prior box bounds must be finite")
    if np.any(upper <= lower):
        bad = np.flatnonzero(upper <= lower).tolist()
        raise ValueError(f"upper must exceed lower for every parameter; violated at indices {bad}")
    return lower, upper


def latin_hypercube_unit(n_members: int, n_params: int, rng: RngLike, *, centered: bool = False) -> np.ndarray:
    """Latin hypercube design in the unit cube, shape ``(n_members, n_params)``.

    ``centered=True`` puts each point at the centre of its stratum (scipy's ``scramble=False``);
    the default places it uniformly at random inside the stratum.
    """
    if n_members < 1 or n_params < 1:
        raise ValueError("n_members and n_params must be positive")
    from scipy.stats import qmc  # here: 1.2 s of import every transform's user would pay otherwise

    sampler = qmc.LatinHypercube(d=n_params, scramble=not centered, rng=as_generator(rng))
    return sampler.random(n_members)


def latin_hypercube(lower, upper, n_members: int, rng: RngLike, *, centered: bool = False) -> np.ndarray:
    """Initial ensemble: Latin hypercube sample mapped into the prior box.

    Parameters
    ----------
    lower, upper : array_like, shape (n_params,)
        Prior box, in the caller's units.
    n_members : int
        Ensemble size ``N``.
    rng : numpy.random.Generator or int
        Source of randomness (no global state is used).
    centered : bool
        Place samples at stratum centres instead of at random inside the strata.

    Returns
    -------
    ndarray, shape (n_members, n_params)
        One row per member, ``p = lower + u (upper - lower)``.
    """
    lower, upper = _check_box(lower, upper)
    u = latin_hypercube_unit(n_members, lower.size, rng, centered=centered)
    return lower + u * (upper - lower)


def stratum_index(params, lower, upper, n_members: int) -> np.ndarray:
    """Index ``floor(n (p - lower) / (upper - lower))`` of the stratum holding each sample (clipped to n-1)."""
    lower, upper = _check_box(lower, upper)
    u = (np.asarray(params, dtype=float) - lower) / (upper - lower)
    return np.clip(np.floor(u * n_members).astype(int), 0, n_members - 1)
