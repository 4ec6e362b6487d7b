"""Ensemble inference for model calibration (NumPy, SciPy, pandas, emcee; knows nothing about FDEM).

Sees parameter matrices ``(N, n)`` and response matrices ``(N, m)``, one row per ensemble member.

* :mod:`enkf.sampling`    Latin hypercube initial ensemble in the prior box.
* :mod:`enkf.transforms`  bounded box <-> unbounded space (logit, probit).
* :mod:`enkf.covariance`  observation error models (diagonal, AR(1), squared exponential, dense) and
  the pre-trigger noise estimate.
* :mod:`enkf.analysis`    the paper's EnKF smoother (eqs. 3-5, localization) and ES-MDA.
* :mod:`enkf.inflation`   parameter inflation (eq. 5): multiplicative and the paper's spread floor.
* :mod:`enkf.stopping`    discrepancy principle, tolerance, collapse guard, iteration budget.
* :mod:`enkf.diagnostics` misfits and spreads as numbers, dicts and DataFrames.
* :mod:`enkf.process`     the calibration process, ask and tell: EnKF, ES-MDA and emulated ES-MDA behind one
  interface, its stop, failure and step-schedule policies, its state saved and loaded.
* :mod:`enkf.loop`        the process' in-process driver for forward models run in one program.
* :mod:`enkf.emulated`    emulator-assisted ES-MDA: each analysis an ES-MDA on an emulator of all runs so far
  (a step of the process: :mod:`enkf.emulated_step`).

Reference: Godinez & Rougier (2021), Appl. Sci. 11, 2898, section 4.
"""

from .analysis import (AnalysisResult, EnsembleFailure, enkf_update, esmda_alphas, esmda_update,
                       localization_mask, truncation_rank)
from .covariance import (AR1Error, DenseError, DiagonalError, NoiseEstimate, ObservationError,
                         SquaredExponentialError, estimate_noise, observation_error)
from .diagnostics import (chi2_per_obs, jsonable, mean_misfit, member_table, misfit_table, nrmse,
                          parameter_summary, posterior_dict, prediction_interval_dict, rmse)
from .inflation import Multiplicative, SpreadFloor, as_inflation, inflate
from .loop import AssimilationResult, assimilate
from .sampling import latin_hypercube, latin_hypercube_unit, stratum_index
from .stopping import StopCriteria, StopDecision, check_stop
from .transforms import BoxTransform, IdentityTransform

__all__ = [
    "AR1Error", "AnalysisResult", "AssimilationResult", "BoxTransform", "DenseError", "DiagonalError",
    "EnsembleFailure", "IdentityTransform", "Multiplicative", "NoiseEstimate", "ObservationError",
    "SpreadFloor", "SquaredExponentialError", "StopCriteria", "StopDecision", "as_inflation", "assimilate",
    "check_stop", "chi2_per_obs", "enkf_update", "esmda_alphas", "esmda_update", "estimate_noise", "inflate",
    "jsonable", "latin_hypercube", "latin_hypercube_unit", "localization_mask", "mean_misfit",
    "member_table", "misfit_table", "nrmse", "observation_error", "parameter_summary", "posterior_dict", "prediction_interval_dict",
    "rmse", "stratum_index", "truncation_rank",
]

# Diagnosis of the calibrated model's residual and choice of model extensions (issue 8; the frozen
# protocol, issue 32, is in enkf.diagnosis).
from .diagnosis import (covariate_trends, curve_errors, default_windows, ensemble_sensitivity,
                        finite_difference_sensitivity, rank_candidates, score_test, structure_tests,
                        whitened_residual)

__all__ += [
    "covariate_trends", "curve_errors", "default_windows", "ensemble_sensitivity",
    "finite_difference_sensitivity", "rank_candidates", "score_test", "structure_tests", "whitened_residual",
]

# Emulator-assisted ES-MDA (the twin experiments' analysis, issue 6).
from .emulated import EmulatedAnalysis, emulated_esmda_update, emulator_error_model

__all__ += ["EmulatedAnalysis", "emulated_esmda_update", "emulator_error_model"]

# The calibration process (issue 54): one object the workflow, the benchmarks and the tests drive. Importing
# emulated_step registers the emulated ES-MDA's analysis with it.
from . import emulated_step  # noqa: E402,F401
from .process import (AnalysisSettings, CalibrationProcess, EmulatedSettings, FailurePolicy, FixedError,  # noqa: E402
                      SeededSteps, StepSchedule, StopPolicy)

__all__ += ["AnalysisSettings", "CalibrationProcess", "EmulatedSettings", "FailurePolicy", "FixedError",
            "SeededSteps", "StepSchedule", "StopPolicy"]
