"""A reference driver for the iterate-until-stop cycle (paper, section 4: initialization, simulation,
assimilation, cycle), for callers that can run the whole ensemble in-process (tests, twin experiments).

The Snakemake workflow runs the same cycle one step per checkpoint with :func:`enkf_update` /
:func:`esmda_update`, :func:`check_stop` and the diagnostics; this function is that cycle in a loop:

    k = 0; p = p_0
    loop: y = forward(p)                      # one simulation per member, NaN rows = failed members
          decision = check_stop(k, misfit of the median member, spread(p))
          if decision.stop: break
          p = analysis(p, y, alpha_k); k += 1

``method="enkf"``: the paper's EnKF repeated (``alpha = 1`` each time, inflation ``"paper"`` by
default), stopped by the criteria. ``method="esmda"``: the schedule ``alphas`` (default
:func:`esmda_alphas` (3)) sets the number of analyses; the convergence tests (discrepancy, tolerance)
are only taken at its end, the collapse guard at every step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ._rng import RngLike, as_generator
from .analysis import enkf_update, esmda_alphas, esmda_update
from .covariance import ObservationError
from .diagnostics import default_names, jsonable, mean_misfit, member_misfit, posterior_dict
from .stopping import StopCriteria, StopDecision, check_stop
from .transforms import BoxTransform, IdentityTransform


@dataclass
class AssimilationResult:
    """Final ensemble, its responses, the per-iteration history and the stop decision."""

    params: np.ndarray
    responses: np.ndarray
    alive: np.ndarray
    history: list[dict]
    decision: StopDecision
    n_simulations: int
    names: list[str]
    prior_spread: np.ndarray  # std of the initial ensemble in the unbounded space, per parameter

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
    inflation : ``"default"`` = ``"paper"`` for EnKF and none for ES-MDA; else as in :func:`enkf_update`.
    truncation : SVD truncation; default 1.0 for EnKF (exact eq. 4), 0.99 for ES-MDA.
    Other arguments as :func:`enkf_update` and :func:`check_stop`.
    """
    if method not in ("esmda", "enkf"):
        raise ValueError("method must be 'esmda' or 'enkf'")
    rng = as_generator(rng)
    transform = IdentityTransform() if transform is None else transform
    criteria = criteria or StopCriteria()
    P = np.array(params0, dtype=float, ndmin=2)
    names = default_names(P.shape[1], names)
    d = np.asarray(obs, dtype=float)
    if method == "esmda":
        schedule = esmda_alphas(3) if alphas is None else np.asarray(alphas, dtype=float)
        criteria = replace(criteria, max_iterations=int(schedule.size))
        infl = None if inflation == "default" else inflation
        trunc = 0.99 if truncation is None else truncation
    else:
        schedule = None
        infl = "paper" if inflation == "default" else inflation
        trunc = 1.0 if truncation is None else truncation
    prior_spread = transform.to_unbounded(P).std(axis=0, ddof=1)

    history: list[dict] = []
    n_sim = 0
    k = 0
    while True:
        Y = np.array(forward(P), dtype=float, ndmin=2)
        n_sim += P.shape[0]
        alive = np.all(np.isfinite(Y), axis=1)
        misfit = mean_misfit(Y, d, obs_error, alive)
        members = member_misfit(Y, d, obs_error, alive)
        spread = transform.to_unbounded(P[alive]).std(axis=0, ddof=1) if alive.sum() > 1 else None
        # the members must fit, not their (possibly blurred) mean
        decision = check_stop(k, chi2_per_obs=members["median_chi2_per_obs"], nrmse=members["median_nrmse"], n_obs=d.size,
                              spread=spread, prior_spread=prior_spread, criteria=criteria,
                              allow_convergence=(method == "enkf" or k == criteria.max_iterations))
        history.append(jsonable({"iteration": k, "n_alive": int(alive.sum()), "misfit_mean": misfit, "misfit_members": members,
                                 "posterior": posterior_dict(P, names, alive), "decision": decision.to_dict()}))
        if decision.stop:
            return AssimilationResult(P, Y, alive, history, decision, n_sim, names, prior_spread)
        common = dict(rng=rng, transform=transform, localization=localization, inflation=infl,
                      prior_std=prior_spread, alive=alive, min_alive_fraction=min_alive_fraction,
                      truncation=trunc, names=names)
        if method == "esmda":
            result = esmda_update(P, Y, d, obs_error, alpha=float(schedule[k]), **common)
        else:
            result = enkf_update(P, Y, d, obs_error, **common)
        history[-1]["analysis"] = result.to_dict()
        P = result.params
        k += 1
