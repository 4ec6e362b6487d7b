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

__all__ = ["POSTERIORS", "SCORED", "forecast_parameters", "posterior_form", "refine_batch", "refine_design",
           "sample_posterior", "samples_frame"]

POSTERIORS = ("ensemble", "emulator_mcmc")

#: The reported posteriors the coverage harness (benchmarks/bench_coverage.py) has scored, each with the loop
#: it was scored on (the default twin's: geometry, preset, loop, prior box, window) and the committed JSON of
#: its well-specified twins. An experiment's summary.json says whether its own form and loop are one of these
#: (:func:`posterior_form`): a lab's intervals come from a scored form or say that they do not
#: (tests/test_one_posterior.py keeps each entry equal to its JSON and to config/config.yaml's twin_ref).
SCORED = (
    {"form": {"posterior": "emulator_mcmc", "self_calibrate": True, "emulator_error": "heteroscedastic",
              "refine_runs": 25},
     "loop": {"geometry": "brazilian_disc", "preset": "fast", "method": "emulated_esmda", "ensemble_size": 25,
              "max_iterations": 3, "parameters": {"sigma_t": [4.0e6, 6.0e7], "E_t": [200.0, 2400.0]},
              "window_s": [0.0, 1.6e-4]},
     "benchmark": "benchmarks/results/coverage_well_specified.json"},
)


def _form_of(spec: ExperimentSpec) -> dict:
    if spec.posterior != "emulator_mcmc":
        return {"posterior": spec.posterior}
    return {"posterior": spec.posterior, "self_calibrate": bool(spec.self_calibrate),
            "emulator_error": spec.emulator_error, "refine_runs": int(spec.refine_runs)}


def _loop_of(spec: ExperimentSpec, exp: Mapping) -> dict:
    o = exp.get("observations") or {}
    return {"geometry": exp.get("geometry"), "preset": exp.get("preset"), "method": spec.method,
            "ensemble_size": int(spec.ensemble_size), "max_iterations": int(spec.max_iterations),
            "parameters": {p: [float(lo), float(hi)] for p, lo, hi in zip(spec.names, spec.lower, spec.upper)},
            "window_s": [float(o.get("t_start", 0.0)), float(o.get("t_end", float("nan")))]}


def posterior_form(spec: ExperimentSpec, exp: Mapping) -> dict:
    """summary.json's ``posterior_form``: the reported posterior's form (``posterior`` and, for the emulator
    MCMC, its self-calibration, emulator error and refinement runs); ``scored_by``, the benchmark JSON of
    the coverage harness that scored this form on this loop (:data:`SCORED`), or None: intervals no
    coverage benchmark has scored; ``form_scored_on``, where another loop's twins scored the same form
    (``{"benchmark", "loop"}``), or None."""
    form, loop = _form_of(spec), _loop_of(spec, exp)
    same_form = [s for s in SCORED if s["form"] == form]
    scored = next((s["benchmark"] for s in same_form if _same_loop(s["loop"], loop)), None)
    other = next(({"benchmark": s["benchmark"], "loop": s["loop"]} for s in same_form
                  if not _same_loop(s["loop"], loop)), None)
    return {**form, "scored_by": scored, "form_scored_on": None if scored else other}


def _same_loop(a: Mapping, b: Mapping) -> bool:
    """The same loop: equal settings, the same parameters with boxes and the same window to 1e-12."""
    def numbers(loop):
        box = loop["parameters"]
        return [x for p in sorted(box) for x in box[p]] + list(loop["window_s"])
    rest = [k for k in a if k not in ("parameters", "window_s")]
    return (set(a) == set(b) and all(a[k] == b[k] for k in rest) and sorted(a["parameters"]) == sorted(b["parameters"])
            and np.allclose(numbers(a), numbers(b), rtol=1e-12, atol=0.0))


def sample_posterior(spec: ExperimentSpec, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray],
                     last_analysis: Mapping, obs: Observations, refine: tuple | None = None, *,
                     temper: float = 1.0) -> EmulatorPosterior:
    """The emulator MCMC posterior from iterations ``0..K`` (``params``/``responses``) of the final loop;
    ``refine``: ``(params (r, n) or frame, responses (r, m))`` of the refinement batch (failed runs NaN),
    then the latest runs; ``temper``: :func:`enkf.ces.emulator_posterior`'s."""
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
                              heteroscedastic=spec.emulator_error == "heteroscedastic", temper=temper)


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
    tempered = sample_posterior(spec, params, responses, last_analysis, obs, temper=spec.refine_temper)
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
