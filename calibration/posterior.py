"""The reported posterior of an experiment with ``posterior: emulator_mcmc`` (issue 18).

After the loop's last iteration is simulated, every successful run of every iteration is an
emulator design point; :func:`enkf.ces.emulator_posterior` samples the box-prior posterior on that
emulator with ``R`` plus the emulator's leave-one-out error measured at the last iteration's runs, the
walkers starting from the last ensemble. ``posterior.csv`` then holds the sample and ``summary.json``'s
``posterior`` its summary; the ensembles stay what was simulated (``iter_<k>/params.csv``), and the
last one's summary is kept as ``posterior_ensemble``.

With ``emulated.refine_runs`` > 0 (the default twin) the loop's runs first give a tempered emulator
posterior, a batch of that many runs is simulated at its k-means centroids (:func:`refine_design`,
:mod:`enkf.refine`; ``results/<exp>/refine/``), and the reported posterior is sampled on every run with
the batch as its latest runs: the emulator's error and the self-calibration measured over the region the
posterior may reach, not only at the loop's last ensemble.

With ``posterior: ensemble`` (the default) the reported posterior is a simulated ensemble: the last, or
the best when the last made the fit markedly worse (:func:`calibration.experiment.reported_ensemble`).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from enkf.ces import EmulatorPosterior, emulator_posterior
from enkf.refine import refinement_design

from .experiment import ExperimentSpec, all_runs, final_iteration, reported_ensemble, rng_for
from .model_error import stored_error
from .observations import Observations

__all__ = ["POSTERIORS", "forecast_parameters", "refine_batch", "refine_design", "sample_posterior", "samples_frame"]

POSTERIORS = ("ensemble", "emulator_mcmc")

def sample_posterior(spec: ExperimentSpec, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray],
                     last_analysis: Mapping, obs: Observations, refine: tuple | None = None, *,
                     temper: float = 1.0, recalibrate: str | None = None) -> EmulatorPosterior:
    """The emulator MCMC posterior from iterations ``0..K`` (``params``/``responses``) of the final loop;
    ``refine``: ``(params (r, n) or frame, responses (r, m))`` of the refinement batch (failed runs NaN),
    then the latest runs; ``temper``: :func:`enkf.ces.emulator_posterior`'s; ``recalibrate``: its, by
    default the experiment's ``emulated.recalibrate``."""
    alive = np.asarray(last_analysis["alive"], bool)
    if refine is not None:
        P_ref, Y_ref = refine
        P_ref = pd.DataFrame(np.asarray(P_ref, float) if not isinstance(P_ref, pd.DataFrame)
                             else P_ref[list(spec.names)].to_numpy(float), columns=list(spec.names))
        Y_ref = np.asarray(Y_ref, float)
        params, responses = [*params, P_ref], [*responses, Y_ref]
        alive = np.all(np.isfinite(Y_ref), axis=1)
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
                              heteroscedastic=spec.emulator_error == "heteroscedastic", temper=temper,
                              tempering=spec.tempering,
                              recalibrate=spec.recalibrate if recalibrate is None else recalibrate)


def refine_batch(spec: ExperimentSpec, params: pd.DataFrame, status: pd.DataFrame, Y: np.ndarray) -> tuple:
    """``(refine, record)`` of the batch's ``refine/params.csv`` frame and ``refine/responses.csv``
    (``status``, ``Y``): ``refine`` the ``sample_posterior`` argument, a failed run's curve NaN (no design
    point); ``record`` ``sampler.json``'s ``refine``: runs, failures, tempering and summed wall time (s),
    which ``summary.json`` counts with the simulations."""
    Y = np.array(Y, float)
    ok = (status["status"].to_numpy(str) == "ok") & np.all(np.isfinite(Y), axis=1)
    Y[~ok] = np.nan
    record = {"runs": int(len(status)), "failed": int(np.sum(~ok)), "temper": float(spec.refine_temper),
              "wall_s": float(pd.to_numeric(status["wall_s"], errors="coerce").fillna(0.0).sum())}
    return (params, Y), record


def refine_design(spec: ExperimentSpec, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray],
                  last_analysis: Mapping, obs: Observations) -> pd.DataFrame:
    """``refine/params.csv``: ``spec.refine_runs`` points (``member`` + one column per parameter, SI) at
    the k-means centroids of the loop's emulator posterior tempered by ``spec.refine_temper``."""
    if spec.refine_runs < 1:
        raise ValueError(f"{spec.name}: emulated.refine_runs is 0; there is no refinement batch to design")
    # where the runs go, not a reported interval: not recalibrated, so that the batch is the same whatever
    # emulated.recalibrate says (and a form scored on kept runs is what the workflow would report)
    tempered = sample_posterior(spec, params, responses, last_analysis, obs, temper=spec.refine_temper,
                                recalibrate="none")
    P = refinement_design(tempered.samples, spec.lower, spec.upper, spec.refine_runs, rng_for(spec.seed, "refine"))
    df = pd.DataFrame(P, columns=list(spec.names))
    df.insert(0, "member", np.arange(len(df)))
    return df


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
