"""Random-number plumbing: every drawing function takes a Generator or an integer seed.

Nothing in :mod:`enkf` touches NumPy's global random state. ``None`` is refused on purpose: an
unseeded run cannot be reproduced, and reproducibility is part of the contract (same seed, bit-identical
outputs).
"""

from __future__ import annotations

import numbers

import numpy as np

RngLike = np.random.Generator | int


def as_generator(rng: RngLike) -> np.random.Generator:
    """Return ``rng`` if it is a :class:`numpy.random.Generator`, else ``default_rng(rng)`` for an int seed."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, numbers.Integral) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise TypeError(
        f"rng must be a numpy.random.Generator or an integer seed, got {type(rng).__name__}; "
        "pass an explicit seed so the run can be reproduced"
    )
