"""When to stop iterating, with a reason.

Checked after each ensemble of simulations (``iteration`` = number of analyses done so far, 0 for the
prior ensemble), in this order:

1. ``"discrepancy"`` (converged): the members fit the data to the level of the error model,
   ``chi2_per_obs <= chi2_target``, where the callers pass the median member's misfit per observation
   against the full error model (noise plus any model error): a blurred mean of step-like members can
   fit where no member does. The discrepancy principle: iterating further fits the noise and
   collapses the ensemble. Default target ``1 + 2 sqrt(2/m)``: the chi-square of pure noise has mean
   ``m`` and std ``sqrt(2m)``, so at the truth ``chi2/m`` exceeds this only ~2% of the time. Callers
   whose statistic is standardised by a correlated model's variances
   (:func:`enkf.diagnostics.member_standardized_misfit`) pass its own mean-plus-two-sd as
   ``model_target``, used where the criteria set none.
2. ``"tolerance"`` (converged): the user's tolerance on the normalised RMSE of the ensemble-mean
   response the caller passes (the median member's), ``nrmse <= nrmse_tol`` (the paper's
   ``|x_bar - y_o| < tol``); off by default.
3. ``"collapse"`` (not converged): the spread of some parameter, in the unbounded space, fell below
   ``collapse_fraction`` times its prior spread (default 1e-3); the ensemble can no longer move it.
   (A sharp but legitimate posterior from a dense record can be ~0.5% of a wide prior box in the
   logit space, so the default is well below that.)
4. ``"max_iterations"`` (not converged): ``iteration >= max_iterations``.

Otherwise ``"continue"``. ``allow_convergence=False`` suspends 1-2 (used for ES-MDA before its
schedule of ``alpha`` is complete: its posterior is only defined at the end).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .diagnostics import jsonable


@dataclass(frozen=True)
class StopCriteria:
    """Stopping thresholds (see module docstring). ``chi2_target=None`` means the caller's
    ``model_target`` where it passes one, else ``1 + 2 sqrt(2/m)``."""

    chi2_target: float | None = None
    nrmse_tol: float | None = None
    collapse_fraction: float = 1e-3
    max_iterations: int = 5

    def __post_init__(self):
        if self.max_iterations < 0:
            raise ValueError("max_iterations must be >= 0")
        if not 0.0 <= self.collapse_fraction < 1.0:
            raise ValueError("collapse_fraction must lie in [0, 1)")

    def target(self, n_obs: int, model_target: float | None = None) -> float:
        if self.chi2_target is not None:
            return self.chi2_target
        return float(model_target) if model_target is not None else 1.0 + 2.0 * math.sqrt(2.0 / n_obs)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class StopDecision:
    """The outcome of :func:`check_stop`: ``stop``, ``converged``, ``reason``, a message and the numbers."""

    stop: bool
    converged: bool
    reason: str
    message: str
    iteration: int
    values: dict

    def to_dict(self) -> dict:
        return jsonable(asdict(self))


def check_stop(iteration: int, *, chi2_per_obs: float, nrmse: float, n_obs: int, spread=None,
               prior_spread=None, criteria: StopCriteria | None = None,
               allow_convergence: bool = True, model_target: float | None = None) -> StopDecision:
    """Decide whether to stop after ``iteration`` analyses.

    Parameters
    ----------
    chi2_per_obs, nrmse : misfit of the median member (:func:`enkf.diagnostics.member_misfit`, or
        :func:`enkf.diagnostics.member_standardized_misfit` with its ``model_target``).
    n_obs : number of observations (for the default chi-square target).
    model_target : the statistic's own target where the criteria set no ``chi2_target`` (module docstring).
    spread, prior_spread : (n,) per-parameter std now and of the initial ensemble, unbounded space.
        The collapse guard is skipped if either is ``None``.
    """
    c = criteria or StopCriteria()
    target = c.target(n_obs, model_target)
    ratio = None
    if spread is not None and prior_spread is not None:
        ratio = np.asarray(spread, float) / np.asarray(prior_spread, float)
    values = {"chi2_per_obs": chi2_per_obs, "chi2_target": target, "nrmse": nrmse, "nrmse_tol": c.nrmse_tol,
              "spread_ratio": None if ratio is None else ratio.tolist(),
              "collapse_fraction": c.collapse_fraction, "max_iterations": c.max_iterations}

    def decide(stop, converged, reason, message):
        return StopDecision(stop, converged, reason, message, int(iteration), jsonable(values))

    if allow_convergence and math.isfinite(chi2_per_obs) and chi2_per_obs <= target:
        return decide(True, True, "discrepancy",
                      f"chi2 per observation {chi2_per_obs:.4g} <= target {target:.4g} (discrepancy principle)")
    if allow_convergence and c.nrmse_tol is not None and math.isfinite(nrmse) and nrmse <= c.nrmse_tol:
        return decide(True, True, "tolerance", f"nrmse {nrmse:.4g} <= tolerance {c.nrmse_tol:.4g}")
    if iteration > 0 and ratio is not None and np.any(ratio < c.collapse_fraction):
        j = int(np.argmin(ratio))
        return decide(True, False, "collapse",
                      f"ensemble collapsed: spread of parameter {j} is {ratio[j]:.3g} of its prior spread "
                      f"(< {c.collapse_fraction:.3g})")
    if iteration >= c.max_iterations:
        return decide(True, False, "max_iterations",
                      f"iteration budget spent ({iteration} of {c.max_iterations}) with chi2 per observation "
                      f"{chi2_per_obs:.4g} (target {target:.4g})")
    return decide(False, False, "continue",
                  f"chi2 per observation {chi2_per_obs:.4g} > target {target:.4g}; continue")
