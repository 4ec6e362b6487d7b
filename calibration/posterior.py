"""The reported posterior of an experiment with ``posterior: emulator_mcmc`` (issue 18).

After the loop's last iteration is simulated, every successful run of every iteration is an
emulator design point; :func:`enkf.ces.emulator_posterior` samples the box-prior posterior on that
emulator with ``R`` plus the emulator's leave-one-out error measured at the last iteration's runs, the
walkers starting from the last ensemble. ``posterior.csv`` then holds the sample and ``summary.json``'s
``posterior`` its summary; the ensembles stay what was simulated (``iter_<k>/params.csv``), and the
last one's summary is kept as ``posterior_ensemble``.

With ``posterior: ensemble`` (the default) the reported posterior is a simulated ensemble: the last, or
the best when the last made the fit markedly worse (:func:`calibration.experiment.reported_ensemble`).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from enkf.ces import EmulatorPosterior, emulator_posterior

from .experiment import ExperimentSpec, all_runs, final_iteration, reported_ensemble, rng_for
from .model_error import stored_error
from .observations import Observations

__all__ = ["POSTERIORS", "forecast_parameters", "sample_posterior", "samples_frame"]

POSTERIORS = ("ensemble", "emulator_mcmc")


def sample_posterior(spec: ExperimentSpec, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray],
                     last_analysis: Mapping, obs: Observations) -> EmulatorPosterior:
    """The emulator MCMC posterior from iterations ``0..K`` (``params``/``responses``) of the final loop."""
    alive = np.asarray(last_analysis["alive"], bool)
    X, Y, latest = all_runs(spec, params, responses, alive)
    if X.shape[0] < len(spec.names) + 2 or latest.sum() < 2:
        raise ValueError(f"{spec.name}: the emulator posterior needs at least {len(spec.names) + 2} successful runs "
                         f"and 2 in the last iteration; got {X.shape[0]} and {int(latest.sum())}")
    # R + D of the last analysis (+ S for a shared mesh); the emulator's leave-one-out error holds S
    # (calibration.model_error.ErrorModel.emulated)
    terms = stored_error(obs, last_analysis)
    error = terms.emulated()
    return emulator_posterior(X, Y, latest, obs.values, error, lower=spec.lower, upper=spec.upper,
                              times=obs.time, groups=obs.frame["record"].to_numpy(str),
                              rng=rng_for(spec.seed, "posterior"), start=X[latest], names=list(spec.names),
                              smoothing=spec.smoothing, loo_scale=terms.likelihood().std,
                              self_calibrate=spec.self_calibrate,
                              heteroscedastic=spec.emulator_error == "heteroscedastic")


def samples_frame(post: EmulatorPosterior) -> pd.DataFrame:
    """``posterior.csv`` of the sample: ``sample`` + one column per parameter (SI)."""
    df = pd.DataFrame(post.samples, columns=post.names)
    df.insert(0, "sample", np.arange(len(df)))
    return df


def forecast_parameters(spec: ExperimentSpec, analyses: Sequence[Mapping], params: Sequence[pd.DataFrame],
                        samples: pd.DataFrame | None = None) -> dict:
    """forecast/params.json: the posterior mean the forecast runs at: of the emulator MCMC sample
    (``posterior: emulator_mcmc``) or of the reported ensemble's alive members (:func:`reported_ensemble`)."""
    names = list(spec.names)
    if samples is not None:
        K = min(final_iteration(spec, analyses)[0], len(analyses) - 1)
        return {"iteration": int(analyses[K]["iteration"]), "posterior": "emulator_mcmc",
                "params": {p: float(samples[p].mean()) for p in names}}
    R, P, alive = reported_ensemble(spec, analyses, params)
    return {"iteration": int(analyses[R]["iteration"]), "posterior": "ensemble",
            "params": {p: float(P[p].to_numpy()[alive].mean()) for p in names}}
