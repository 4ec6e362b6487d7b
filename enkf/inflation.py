"""Parameter inflation, paper eq. (5): ``p_hat_i = p_bar + lambda (p_i - p_bar)``.

Applied to the parameters in the *unbounded* space (``z``, see :mod:`enkf.transforms`), per parameter
``j`` with its own ``lambda_j``, so inflated members still map back inside their box. The ensemble mean
is unchanged; the spread of parameter ``j`` is multiplied by ``lambda_j``.

Two ways to choose ``lambda``:

* :class:`Multiplicative` - a plain constant factor ``lambda`` (e.g. 1.05), the textbook form.
* :class:`SpreadFloor` - our documented reading of the paper's "lambda is set to approximately 45% of
  the standard deviation for the initial parameter spread". Taken literally the sentence mixes a
  dimensionless factor with a standard deviation; we read it as a *floor on the spread*: after the
  analysis, parameter ``j`` is inflated just enough that its ensemble std is at least ``fraction``
  (default 0.45) times its initial (prior-ensemble) std,

      lambda_j = max(1, fraction * sd_prior_j / sd_current_j),

  all stds taken in the unbounded space. It prevents the collapse the paper inflates against, leaves
  a healthy ensemble untouched, and never deflates. ``sd_prior`` is the std of the initial ensemble
  (pass it) or, by default, the analytic std of a uniform prior on the box in the unbounded space
  (``pi/sqrt(3)`` under logit, 1 under probit). A parameter whose spread is exactly zero cannot be
  inflated multiplicatively and keeps ``lambda = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def inflate(z, lam) -> np.ndarray:
    """Paper eq. (5) per column: ``z_bar + lam_j (z_ij - z_bar_j)`` for rows ``i`` (members)."""
    z = np.asarray(z, dtype=float)
    z_bar = z.mean(axis=0)
    return z_bar + np.asarray(lam, dtype=float) * (z - z_bar)


@dataclass(frozen=True)
class Multiplicative:
    """Constant inflation factor ``lambda`` for every parameter (eq. 5)."""

    lam: float

    def __post_init__(self):
        if not (np.isfinite(self.lam) and self.lam > 0):
            raise ValueError("inflation factor lambda must be finite and positive")

    def factors(self, z, prior_std=None) -> np.ndarray:
        return np.full(np.shape(z)[1], float(self.lam))

    def describe(self) -> dict:
        return {"kind": "multiplicative", "lambda": float(self.lam)}


@dataclass(frozen=True)
class SpreadFloor:
    """Paper reading: ``lambda_j = max(1, fraction * sd_prior_j / sd_j)`` (spread floor, default 45%)."""

    fraction: float = 0.45

    def __post_init__(self):
        if not (np.isfinite(self.fraction) and self.fraction >= 0):
            raise ValueError("spread-floor fraction must be finite and >= 0")

    def factors(self, z, prior_std=None) -> np.ndarray:
        if prior_std is None:
            raise ValueError("SpreadFloor inflation needs the prior spread (prior_std) in the unbounded space")
        z = np.asarray(z, dtype=float)
        sd = z.std(axis=0, ddof=1)
        target = self.fraction * np.broadcast_to(np.asarray(prior_std, dtype=float), sd.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(sd > 0, np.maximum(1.0, target / sd), 1.0)
        return lam

    def describe(self) -> dict:
        return {"kind": "spread_floor", "fraction": float(self.fraction)}


Inflation = Multiplicative | SpreadFloor


def as_inflation(spec) -> Inflation | None:
    """Normalise an inflation spec: ``None`` (off), a number (multiplicative lambda), ``"paper"``
    (``SpreadFloor(0.45)``), or a :class:`Multiplicative` / :class:`SpreadFloor` instance."""
    if spec is None:
        return None
    if isinstance(spec, (Multiplicative, SpreadFloor)):
        return spec
    if isinstance(spec, str):
        if spec == "paper":
            return SpreadFloor(0.45)
        raise ValueError(f"unknown inflation {spec!r}; use 'paper', a number, or None")
    if isinstance(spec, (int, float, np.floating, np.integer)) and not isinstance(spec, bool):
        return Multiplicative(float(spec))
    raise TypeError(f"cannot interpret inflation spec {spec!r}")
