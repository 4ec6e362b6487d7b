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

# Names are imported on first use (PEP 562): a job that needs one transform or one error model does not
# pay for SciPy's statistics, the emulators and the diagnosis (about 1.5 s of a job's start, measured with
# python -X importtime). ``from enkf import X`` and ``enkf.X`` work as before.
import importlib

_EXPORTS = {
    "analysis": ("AnalysisResult", "EnsembleFailure", "enkf_update", "esmda_alphas", "esmda_update",
                 "localization_mask", "truncation_rank"),
    "covariance": ("AR1Error", "DenseError", "DiagonalError", "NoiseEstimate", "ObservationError",
                   "SquaredExponentialError", "estimate_noise", "observation_error"),
    "diagnostics": ("chi2_per_obs", "jsonable", "mean_misfit", "member_table", "misfit_table", "nrmse",
                    "parameter_summary", "posterior_dict", "prediction_interval_dict", "rmse"),
    "inflation": ("Multiplicative", "SpreadFloor", "as_inflation", "inflate"),
    "loop": ("AssimilationResult", "assimilate"),
    "sampling": ("latin_hypercube", "latin_hypercube_unit", "stratum_index"),
    "stopping": ("StopCriteria", "StopDecision", "check_stop"),
    "transforms": ("BoxTransform", "IdentityTransform"),
    # diagnosis of the calibrated model's residual and choice of model extensions (issues 8 and 32)
    "diagnosis": ("covariate_trends", "curve_errors", "default_windows", "ensemble_sensitivity",
                  "finite_difference_sensitivity", "rank_candidates", "score_test", "structure_tests",
                  "whitened_residual"),
    # emulator-assisted ES-MDA (the twin experiments' analysis, issue 6)
    "emulated": ("EmulatedAnalysis", "emulated_esmda_update", "emulator_error_model"),
    # the calibration process (issue 54): one object the workflow, the benchmarks and the tests drive
    "process": ("AnalysisSettings", "CalibrationProcess", "EmulatedSettings", "FailurePolicy", "FixedError",
                "SeededSteps", "StepSchedule", "StopPolicy"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        if name == "CalibrationProcess":  # the emulated ES-MDA registers its analysis with the process
            importlib.import_module(".emulated_step", __name__)
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    try:  # a submodule, as ``import enkf`` followed by ``enkf.ces`` found it when every module was loaded
        return importlib.import_module(f".{name}", __name__)
    except ModuleNotFoundError as err:
        if err.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
