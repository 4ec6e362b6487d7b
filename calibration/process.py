"""The workflow's side of the calibration process (:class:`enkf.process.CalibrationProcess`): the
likelihood of a measured or twin experiment and the experiment's step schedule.

The likelihood's terms are re-estimated on each ensemble (:func:`calibration.model_error.analysis_error`):
the noise ``R``, the simulator's variability ``S`` from that iteration's replicate runs, the discrepancy
``D`` estimated on its members; the misfit recorded is ``analysis.json``'s ``misfit`` block
(:func:`calibration.model_error.misfit_block`) and the stop test's statistic is its standardised median
member (:func:`stop_misfit`). The process itself is built by :func:`calibration.experiment.build_process`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from enkf import StepSchedule

from .model_error import ErrorModel, analysis_error, misfit_block
from .observations import Observations

__all__ = ["WorkflowLikelihood", "WorkflowTerms", "step_schedule", "stop_misfit"]


def step_schedule(spec) -> StepSchedule:
    """The experiment's step schedule (an :class:`calibration.experiment.ExperimentSpec`)."""
    return StepSchedule(spec.method, spec.alphas, spec.temper_base)


def stop_misfit(m: Mapping) -> dict:
    """The stop test's numbers from a ``misfit`` block: the median member against the full error model
    (R + 2S + D), standardised, with its target; the members must fit, not their mean (a blurred mean of
    step-like members can fit where none does). Also for emulated_esmda: its ``chi2_per_obs_model_error``
    (+ the emulator's leave-one-out error) is recorded but is not a stop test, because on a sparse design
    that error is interpolation error and the test cannot fail (docs/inference.md). Files written before
    the members were scored carry only the mean's."""
    chi2 = m.get("stop_chi2_per_obs", m.get("chi2_per_obs"))
    return {"rmse": m.get("rmse_Pa"), "nrmse": m.get("nrmse"), "chi2_per_obs": chi2, "target": m.get("stop_target")}


class WorkflowTerms:
    """One ensemble's error terms (:class:`calibration.model_error.ErrorModel`) as the process asks for them."""

    def __init__(self, terms: ErrorModel, model_error: dict, obs: Observations, noise):
        self.terms, self.model_error, self._obs, self._noise = terms, model_error, obs, noise

    def assimilation(self, alpha: float = 1.0):
        return self.terms.assimilation(alpha)

    def emulated(self):
        return self.terms.emulated()

    @property
    def loo_scale(self) -> np.ndarray:
        return self.terms.likelihood().std

    def score(self, Y, d, alive) -> tuple[dict, dict]:
        block = misfit_block(Y, self._obs, self._noise, self.terms, alive)
        return block, stop_misfit(block)


class WorkflowLikelihood:
    """The experiment's likelihood: ``evaluate(Y, d, alive, replicates=...)`` gives the ensemble's terms."""

    def __init__(self, spec, obs: Observations):
        self.spec, self.obs, self.noise = spec, obs, obs.error_model()

    def evaluate(self, Y, d, alive, replicates=None) -> WorkflowTerms:
        s = self.spec
        terms, model_error = analysis_error(s.discrepancy, self.obs, Y, alive, replicates=replicates,
                                            mode=s.mesh_mode, measured=s.truth is None)
        return WorkflowTerms(terms, model_error, self.obs, self.noise)
