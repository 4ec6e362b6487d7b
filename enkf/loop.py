"""The in-process driver of the calibration process (paper, section 4: initialization, simulation,
assimilation, cycle), for callers that can run the whole ensemble in one program (tests, twin
experiments, the emulated ES-MDA's inner loop, the cross-validation's fits).

It is the loop a caller of :class:`enkf.process.CalibrationProcess` writes, with a fixed observation error
(:class:`enkf.process.FixedError`) and no update after the stop (a generator shared with the caller is
left where the last analysis left it); the Snakemake workflow drives the same process one ``tell`` per
analysis job:

    process = CalibrationProcess(p_0, obs, FixedError(R), ...)
    while not process.done:
        process.tell(forward(process.ask()))  # NaN rows = failed members

``method="enkf"``: the paper's EnKF repeated (``alpha = 1`` each time, inflation ``"paper"`` by
default), stopped by the criteria. ``method="esmda"``: the schedule ``alphas`` (default
:func:`esmda_alphas` (3)) sets the number of analyses; the convergence tests (discrepancy, tolerance)
are only taken at its end, the collapse guard at every step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ._rng import RngLike, as_generator
from .covariance import ObservationError
from .diagnostics import jsonable, posterior_dict
from .process import AnalysisSettings, CalibrationProcess, FailurePolicy, FixedError, StepSchedule, StopPolicy
from .stopping import StopCriteria, StopDecision
from .transforms import BoxTransform, IdentityTransform


@dataclass
class AssimilationResult:
    """Final ensemble, its responses, the per-iteration history and the stop decision."""

    params: np.ndarray
    responses: np.ndarray
    alive: np.ndarray
    process: CalibrationProcess  # the process that ran: its history is made when first read
    decision: StopDecision
    n_simulations: int
    names: list[str]
    prior_spread: np.ndarray  # std of the initial ensemble in the unbounded space, per parameter

    @property
    def history(self) -> list[dict]:
        """One dict per simulated ensemble (:attr:`enkf.process.CalibrationProcess.history`)."""
        return self.process.history

    @property
    def iterations(self) -> int:
        """Number of analyses performed."""
        return self.decision.iteration

    def misfit_table(self) -> pd.DataFrame:
        """One row per simulated ensemble: iteration, n_alive, rmse, nrmse, chi2_per_obs, decision."""
        return pd.DataFrame([{"iteration": h["iteration"], "n_alive": h["n_alive"], **h["misfit_mean"],
                              "reason": h["decision"]["reason"]} for h in self.history])

    def to_dict(self) -> dict:
        """JSON-ready summary: iterations, converged, stop_reason, n_simulations, posterior, misfit."""
        return jsonable({
            "iterations": self.iterations,
            "converged": self.decision.converged,
            "stop_reason": self.decision.reason,
            "stop_message": self.decision.message,
            "n_simulations": self.n_simulations,
            "posterior": posterior_dict(self.params, self.names, self.alive),
            "misfit": [h["misfit_mean"] for h in self.history],
        })


def assimilate(forward: Callable[[np.ndarray], np.ndarray], params0, obs, obs_error: ObservationError, *,
               rng: RngLike, method: str = "esmda", alphas: Sequence[float] | None = None,
               transform: BoxTransform | IdentityTransform | None = None,
               criteria: StopCriteria | None = None, localization=None, inflation="default",
               min_alive_fraction: float = 0.5, truncation: float | None = None,
               names: Sequence[str] | None = None) -> AssimilationResult:
    """Iterate simulation and analysis until a stopping criterion fires.

    Parameters
    ----------
    forward : callable ``(N, n) params -> (N, m) responses``; NaN rows mark failed simulations.
    params0 : (N, n) initial ensemble (e.g. :func:`latin_hypercube`).
    method : ``"esmda"`` (default) or ``"enkf"`` (the paper's iteration).
    alphas : ES-MDA schedule (default ``esmda_alphas(3)``), ignored for ``"enkf"``.
    inflation, truncation : as :class:`enkf.process.AnalysisSettings` (the method's defaults).
    Other arguments as :func:`enkf_update` and :func:`check_stop`.
    """
    if method not in ("esmda", "enkf"):
        raise ValueError("method must be 'esmda' or 'enkf'")
    process = CalibrationProcess(
        params0, obs, FixedError(obs_error), rng=as_generator(rng),
        schedule=StepSchedule(method, () if alphas is None else tuple(alphas)),
        stop=StopPolicy(criteria or StopCriteria()), failure=FailurePolicy(min_alive_fraction),
        analysis=AnalysisSettings(inflation=inflation, truncation=truncation, localization=localization),
        transform=transform, names=names, update_on_stop=False)
    while True:
        step = process.tell(np.array(forward(process.ask()), dtype=float, ndmin=2))
        if process.done:
            return AssimilationResult(step.params, step.responses, step.alive, process, process.decision,
                                      process.n_simulations, process.names, process.prior_spread)
