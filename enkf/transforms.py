"""Maps between the bounded parameter box and an unbounded space where the analysis is done.

The Kalman update is linear and Gaussian-minded; applied to bounded parameters directly it can push
members out of their physical range (negative energies, strengths above the prior's upper limit).
Every analysis in :mod:`enkf` therefore works on

    u = (p - lower) / (upper - lower)            in (0, 1)
    z = logit(u) = log(u / (1 - u))               (default), or
    z = probit(u) = Phi^{-1}(u)                   (standard-normal quantile),

and maps the result back with ``u = expit(z)`` or ``u = Phi(z)``, so no member can leave its box.
Inflation (paper eq. 5) is applied to ``z`` as well, for the same reason.

Exact bounds are clipped to ``u in [eps, 1 - eps]`` (``eps = 1e-12``) before the forward map, so a
member that saturated at a bound stays finite (``|logit| <= 27.6``, ``|probit| <= 7.03``).

A uniform prior on the box maps to a logistic distribution (std ``pi / sqrt(3)``) under logit and to a
standard normal (std 1) under probit; :meth:`BoxTransform.prior_std` returns that value, the reference
spread used by the paper-style inflation floor when no prior ensemble is given.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .sampling import _check_box

EPS_U = 1e-12
_KINDS = ("logit", "probit")


@dataclass(frozen=True)
class BoxTransform:
    """Bounded box ``[lower, upper]`` <-> unbounded space, ``kind`` = ``"logit"`` (default) or ``"probit"``."""

    lower: np.ndarray
    upper: np.ndarray
    kind: str = "logit"
    width: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        lower, upper = _check_box(self.lower, self.upper)
        if self.kind not in _KINDS:
            raise ValueError(f"kind must be one of {_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)
        object.__setattr__(self, "width", upper - lower)

    @property
    def n_params(self) -> int:
        return self.lower.size

    def to_unit(self, params) -> np.ndarray:
        """``u = (p - lower) / (upper - lower)``, clipped to ``[eps, 1 - eps]``."""
        p = np.asarray(params, dtype=float)
        if p.shape[-1] != self.n_params:
            raise ValueError(f"params last axis has {p.shape[-1]} entries, box has {self.n_params}")
        return np.clip((p - self.lower) / self.width, EPS_U, 1.0 - EPS_U)

    def to_unbounded(self, params) -> np.ndarray:
        """Bounded parameters ``p`` (rows = members) -> unbounded ``z`` (logit or probit of ``u``)."""
        u = self.to_unit(params)
        return special.logit(u) if self.kind == "logit" else special.ndtri(u)

    def to_bounded(self, z) -> np.ndarray:
        """Unbounded ``z`` -> bounded ``p = lower + u (upper - lower)``, always inside ``[lower, upper]``."""
        z = np.asarray(z, dtype=float)
        if np.any(np.isnan(z)):
            raise ValueError("unbounded parameters contain NaN")
        u = special.expit(z) if self.kind == "logit" else special.ndtr(z)
        return np.clip(self.lower + u * self.width, self.lower, self.upper)

    def prior_std(self) -> np.ndarray:
        """Std in the unbounded space of a uniform prior on the box: ``pi/sqrt(3)`` (logit) or 1 (probit)."""
        value = np.pi / np.sqrt(3.0) if self.kind == "logit" else 1.0
        return np.full(self.n_params, value)


@dataclass(frozen=True)
class IdentityTransform:
    """No transform: the parameters are already unbounded (used for Gauss-linear checks)."""

    def to_unbounded(self, params) -> np.ndarray:
        return np.array(params, dtype=float, copy=True)

    def to_bounded(self, z) -> np.ndarray:
        return np.array(z, dtype=float, copy=True)

    def prior_std(self):
        return None
