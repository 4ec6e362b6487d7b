"""One calibration experiment as the workflow runs it: prior ensemble, per-iteration analysis, summary.

The cycle of the paper (section 4: initialization, simulation, assimilation, cycle) split into the
steps the Snakemake checkpoint loop runs as separate jobs, each a pure function of files:

1. :func:`initial_ensemble` -- Latin hypercube sample of the prior box (``iter_0/params.csv``).
2. (the simulations, one job per member and record; :func:`calibration.runner.run_member`)
3. :func:`analysis_step` -- for iteration ``k``: misfit of the ensemble and of its mean, failed members
   and their reasons, spreads, the stop decision (:func:`decide`), and the analysis ensemble for
   iteration ``k + 1`` (ES-MDA step ``alpha_k`` or the paper's EnKF, :mod:`enkf.analysis`). Written
   as ``iter_<k>/analysis.json``. The analysis ensemble is computed whenever one can be (the ES-MDA
   schedule is not exhausted), even if the decision is to stop: the decision is re-taken by the
   workflow from the stored numbers with the *current* stopping rule (:func:`decide`), so that
   changing a tolerance or the iteration budget never invalidates finished iterations.
4. :func:`summary` -- ``summary.json`` (docs/workflow.md, "What goes where") from all iterations and the forecast.

Randomness: one integer seed per experiment. Every draw uses its own generator
``default_rng(SeedSequence(seed, spawn_key=(purpose, k)))`` (:func:`rng_for`): the LHS design, the
twin's observation noise and the perturbations of each analysis ``k`` are independent streams, and a
re-run reproduces every file bit for bit.

Parameter posterior = the ensemble of the last simulated iteration (alive members): the analysis
ensemble of the last analysis, which is the one the stop decision was taken on.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from enkf import (AnalysisSettings, BoxTransform, DenseError, EmulatedSettings, FailurePolicy,
                  SeededSteps, StepSchedule, StopCriteria, StopPolicy, esmda_alphas, jsonable, latin_hypercube, localization_mask,
                  mean_misfit, misfit_table, posterior_dict, prediction_interval_dict)
from enkf.process import all_runs as _all_runs, capped_truncation  # noqa: F401 (capped_truncation: re-exported)

from .job_log import library_versions
from .diagnosis_config import diagnosis_settings  # here and re-exported; defined apart, light for the parse
from .model_error import (MESH_PURPOSE, MESH_STAGES, discrepancy_kind, mesh_mode,  # noqa: F401
                          mesh_seed, posterior_predictive, posterior_tempering, replicate_count, run_mesh_seed)
from .identifiability import linear_sensitivity
from .observations import Observations
from .process import WorkflowLikelihood, step_schedule, stop_misfit
from .scored import posterior_form
from .sensitivity import AUTO, selected_parameters
from .verdict import calibration_verdict, member_chi2, reported_iteration

if TYPE_CHECKING:  # pragma: no cover
    from enkf import CalibrationProcess

__all__ = ["PURPOSES", "MESH_STAGES", "rng_for", "mesh_seed", "run_mesh_seed", "ExperimentSpec", "initial_ensemble",
           "build_process", "analysis_step", "analysis_record", "decide", "capped_truncation",
           "all_runs", "diagnosis_settings", "final_iteration", "final_verdict", "reported_ensemble", "linear_sensitivity", "record_misfits", "summary"]

#: Independent random streams of an experiment (the ``spawn_key`` of :func:`rng_for`).
#: (``mesh``: the specimen-mesh realizations, :func:`calibration.model_error.mesh_seed`.)
PURPOSES = {"lhs": 1, "noise": 2, "analysis": 3, "posterior": 4, "predictive": 5, "mesh": MESH_PURPOSE,
            "approximation": 7, "refine": 8}


def rng_for(seed: int, purpose: str, k: int = 0) -> np.random.Generator:
    """The generator of one random stream: ``SeedSequence(seed, spawn_key=(PURPOSES[purpose], k))``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(PURPOSES[purpose], int(k))))


@dataclass(frozen=True)
class ExperimentSpec:
    """The inference settings of one experiment (a validated ``experiments.<name>`` config block)."""

    name: str
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    ensemble_size: int
    seed: int
    method: str = "esmda"
    alphas: tuple[float, ...] = ()
    max_iterations: int = 3
    transform_kind: str = "logit"
    criteria: StopCriteria = field(default_factory=StopCriteria)
    inflation: object = AnalysisSettings.inflation
    truncation: float | None = AnalysisSettings.truncation
    max_rank: int | None = AnalysisSettings.max_rank
    min_alive_fraction: float = FailurePolicy.min_alive_fraction
    unrelated: Mapping[str, Sequence[Sequence[float]]] = field(default_factory=dict)
    truth: Mapping[str, float] | None = None
    # the process' defaults (enkf.process), stated there once
    inner_members: int = EmulatedSettings.inner_members
    inner_steps: int = EmulatedSettings.inner_steps
    temper_base: float = StepSchedule.temper_base
    # the reported posterior's form, the one the coverage harness scores (docs/inference.md); the schema
    # states the same defaults (tests/test_one_posterior.py)
    posterior: str = "emulator_mcmc"
    discrepancy: str = "none"
    mesh_mode: str = "per_run"
    replicates: int = 0
    smoothing: object = EmulatedSettings.smoothing
    self_calibrate: bool = True
    emulator_error: str = "ar1"
    tempering: str = "power"
    recalibrate: str = "none"
    refine_runs: int = 25
    refine_temper: float = 4.0

    @classmethod
    def from_config(cls, name: str, exp: Mapping, sensitivity_report: Mapping | str | None = None) -> "ExperimentSpec":
        """``parameters: auto`` takes the parameters the experiment's sensitivity report recommends
        (``sensitivity_report``: its content or path; default ``results/<name>/sensitivity/report.json``)."""
        params = exp["parameters"]
        if params == AUTO:
            params = selected_parameters(name, exp, sensitivity_report)
        names = tuple(params)
        method = exp["method"]
        if method == "esmda":
            es = exp.get("esmda", {})
            alphas = tuple(float(a) for a in (es.get("alphas") or esmda_alphas(int(es.get("steps", 3)))))
            max_it = len(alphas)
        else:
            alphas = ()
            max_it = int(exp["max_iterations"])
        emulated = exp.get("emulated") or {}
        stop = exp.get("stopping", {})
        criteria = StopCriteria(chi2_target=stop.get("chi2_target"), nrmse_tol=stop.get("nrmse_tol"),
                                collapse_fraction=float(stop.get("collapse_fraction", StopCriteria.collapse_fraction)), max_iterations=max_it)
        truth = exp.get("observations", {}).get("truth")
        return cls(name=name, names=names, lower=np.array([params[p][0] for p in names], float),
                   upper=np.array([params[p][1] for p in names], float), ensemble_size=int(exp["ensemble_size"]),
                   seed=int(exp["seed"]), method=method, alphas=alphas, max_iterations=max_it,
                   transform_kind=exp.get("transform", "logit"), criteria=criteria,
                   inflation=None if exp.get("inflation") == "none" else exp.get("inflation", "default"), truncation=exp.get("truncation"),
                   max_rank=exp.get("max_rank"),
                   min_alive_fraction=float(exp.get("min_alive_fraction", cls.min_alive_fraction)),
                   unrelated=dict(exp.get("localization") or {}),
                   truth=None if truth is None else {p: float(truth[p]) for p in truth},
                   inner_members=int(emulated.get("inner_members", cls.inner_members)),
                   inner_steps=int(emulated.get("inner_steps", cls.inner_steps)),
                   temper_base=float(emulated.get("temper_base", cls.temper_base)),
                   posterior=str(exp.get("posterior", cls.posterior)), discrepancy=discrepancy_kind(exp),
                   mesh_mode=mesh_mode(exp), replicates=replicate_count(exp),
                   smoothing=emulated.get("smoothing", cls.smoothing),
                   self_calibrate=bool(emulated.get("self_calibrate", cls.self_calibrate)),
                   emulator_error=str(emulated.get("emulator_error", cls.emulator_error)),
                   tempering=str(emulated.get("tempering", cls.tempering)),
                   recalibrate=str(emulated.get("recalibrate", cls.recalibrate)),
                   refine_runs=int(emulated.get("refine_runs", cls.refine_runs)),
                   refine_temper=float(emulated.get("refine_temper", cls.refine_temper)))

    @property
    def transform(self) -> BoxTransform:
        return BoxTransform(self.lower, self.upper, kind=self.transform_kind)

    def localization(self, obs: Observations) -> np.ndarray | None:
        """The paper's localization mask ``M`` (n x m): zero for the declared unrelated time windows."""
        if not self.unrelated:
            return None
        unrelated = {}
        t = obs.time
        for p, windows in self.unrelated.items():
            sel = np.zeros(t.size, bool)
            for t0, t1 in windows:
                sel |= (t >= t0) & (t <= t1)
            unrelated[self.names.index(p)] = sel
        return localization_mask(len(self.names), obs.m, unrelated)


def initial_ensemble(spec: ExperimentSpec) -> pd.DataFrame:
    """``iter_0/params.csv``: LHS of the prior box, one row per member (``member`` + parameter columns)."""
    P = latin_hypercube(spec.lower, spec.upper, spec.ensemble_size, rng_for(spec.seed, "lhs"))
    return params_frame(P, spec.names)


def params_frame(P: np.ndarray, names: Sequence[str]) -> pd.DataFrame:
    df = pd.DataFrame(np.asarray(P, float), columns=list(names))
    df.insert(0, "member", np.arange(len(df)))
    return df


def decide(spec: ExperimentSpec, k: int, misfit: Mapping, n_obs: int, spread, prior_spread) -> dict:
    """The stop decision after ``k`` analyses: the process' stop policy with the experiment's rule
    (:class:`enkf.StopPolicy`; the convergence tests where the method's posterior is defined,
    :meth:`enkf.StepSchedule.converges_at`)."""
    return StopPolicy(spec.criteria).decide(step_schedule(spec), k, misfit, n_obs, spread, prior_spread).to_dict()


def build_process(spec: ExperimentSpec, obs: Observations, params: pd.DataFrame | None = None, *,
                  prior_params: pd.DataFrame | None = None, iteration: int = 0,
                  history: Sequence[tuple[pd.DataFrame, np.ndarray]] = ()) -> CalibrationProcess:
    """The experiment's calibration process at analysis ``iteration``, rebuilt from its iteration files:
    ``params`` (``iter_<k>/params.csv``; default the prior ensemble, :func:`initial_ensemble`),
    ``prior_params`` (``iter_0/params.csv``, the reference spread of the collapse guard and inflation;
    default ``params``) and ``history``, the ``(params, responses)`` of iterations ``0 .. k-1`` (the
    emulated ES-MDA's emulator is built on every run so far). Each analysis ``k`` draws from its own
    stream, ``rng_for(seed, "analysis", k)``."""
    names = list(spec.names)
    params = initial_ensemble(spec) if params is None else params
    prior = params if prior_params is None else prior_params
    if spec.method == "emulated_esmda" and len(history) != iteration:
        raise ValueError(f"{spec.name}, iteration {iteration}: emulated_esmda needs the runs of iterations "
                         f"0..{iteration - 1}, got {len(history)} of them")
    runs = [(hp[names].to_numpy(float), np.asarray(hy, float)) for hp, hy in history] \
        if spec.method == "emulated_esmda" else []
    # imported here: the process brings the emulators (SciPy's interpolation, 0.8 s of a job's start) that
    # the jobs reading an experiment's settings (lhs, observations, summary) never use
    from enkf import CalibrationProcess

    return CalibrationProcess(
        params[names].to_numpy(float), obs.values, WorkflowLikelihood(spec, obs),
        rng=SeededSteps(spec.seed, PURPOSES["analysis"]), schedule=step_schedule(spec), stop=StopPolicy(spec.criteria),
        failure=FailurePolicy(spec.min_alive_fraction),
        analysis=AnalysisSettings(spec.inflation, spec.truncation, spec.max_rank, spec.localization(obs)),
        emulated=EmulatedSettings(spec.inner_members, spec.inner_steps, spec.smoothing, obs.time,
                                  obs.frame["record"].to_numpy(str)),
        transform=spec.transform, names=names, iteration=iteration, runs=runs,
        prior_spread=spec.transform.to_unbounded(prior[names].to_numpy(float)).std(axis=0, ddof=1), label=spec.name)


def analysis_step(spec: ExperimentSpec, k: int, params: pd.DataFrame, responses: np.ndarray,
                  member_status: pd.DataFrame, obs: Observations, prior_params: pd.DataFrame,
                  history: Sequence[tuple[pd.DataFrame, np.ndarray]] = (), replicates: np.ndarray | None = None) -> dict:
    """The ``iter_<k>/analysis.json`` dict: misfits, failures, spread, decision, analysis ensemble. One
    workflow job: the experiment's process rebuilt from its iteration files (:func:`build_process`) and
    told this iteration's responses.

    Parameters
    ----------
    params : ``iter_<k>/params.csv`` (``member`` + parameter columns).
    responses : (N, m) member curves on the observation grid (NaN rows/blocks = failed).
    member_status : one row per member: ``member, status ("ok"/"failed"), reason``.
    prior_params : ``iter_0/params.csv`` (the reference spread of the collapse guard and inflation).
    history : ``(params, responses)`` of iterations ``0 .. k-1`` (failed members as NaN rows); used by
        ``emulated_esmda``, whose emulator is built on every run so far.
    replicates : (M, m) curves of the replicate runs at this iteration's ensemble mean, each on its own
        mesh realization (failed: NaN rows), which measure the simulator's variability ``S``
        (:mod:`calibration.model_error`); None or empty: ``S`` is not measured.

    Raises
    ------
    EnsembleFailure
        If fewer than ``min_alive_fraction`` of the members survived (the message lists why they failed).
    """
    Y = np.asarray(responses, float)
    N = len(params)
    if Y.shape != (N, obs.m):
        raise ValueError(f"responses have shape {Y.shape}, expected ({N}, {obs.m})")
    process = build_process(spec, obs, params, prior_params=prior_params, iteration=k, history=history)
    step = process.tell(Y, ok=member_status["status"].to_numpy(str) == "ok",
                        reasons={i: member_status.iloc[i].get("reason") for i in range(N)},
                        member_ids=member_status["member"].to_numpy(int), replicates=replicates)
    return analysis_record(spec, obs, step, params["member"].to_numpy(int))


def analysis_record(spec: ExperimentSpec, obs: Observations, step, member_ids=None) -> dict:
    """The ``iter_<k>/analysis.json`` dict of one :meth:`enkf.CalibrationProcess.tell` (``step``) of the
    experiment's process (:func:`build_process`); ``member_ids``: the ``member`` column (default 0..N-1)."""
    names, k = list(spec.names), step.iteration
    Y, N = step.responses, step.params.shape[0]
    err, d, alive, res = obs.error_model(), obs.values, step.alive, step.result
    misfit_out = step.misfit
    members = misfit_table(Y, d, err, alive).rename(columns={"rmse": "rmse_Pa"})
    members["member"] = np.arange(N) if member_ids is None else np.asarray(member_ids, int)
    update = None if res is None else res.to_dict()
    if spec.method == "emulated_esmda":
        if res.error is not None:
            # A diagnostic, not the stop test (calibration.process.stop_misfit): the fit measured against R
            # plus the emulator's leave-one-out error, which holds the simulator's ruggedness once the
            # design is dense where the posterior is.
            C = DenseError(step.terms.emulated().dense() + res.error.dense(), _symmetric=True)
            misfit_out["chi2_per_obs_model_error"] = mean_misfit(Y, d, C, alive)["chi2_per_obs"]
    elif update is not None:
        update.pop("misfit_members", None)  # the same numbers are in "members" below
        update["max_rank"] = spec.max_rank
    spread = step.spread
    return jsonable({
        "experiment": spec.name,
        "iteration": k,
        "method": spec.method,
        "alpha_next": step.alpha,
        "n_members": N,
        "n_alive": int(alive.sum()),
        "alive": alive.tolist(),
        "failed_members": step.failed,
        "n_obs": obs.m,
        "obs_error": err.describe(),
        "model_error": step.terms.model_error,
        "misfit": misfit_out,
        "misfit_per_record": record_misfits(Y, obs, alive),
        "members": members.to_dict(orient="records"),
        "posterior": posterior_dict(step.params, names, alive),
        "spread_unbounded": None if spread is None else dict(zip(names, spread.tolist())),
        "prior_spread_unbounded": dict(zip(names, step.prior_spread.tolist())),
        "decision": step.decision.to_dict(),
        "stop_criteria": spec.criteria.to_dict(),
        "update": update,
        "next_params": None if step.next_params is None else {"names": names, "values": step.next_params.tolist()},
    })


def all_runs(spec: ExperimentSpec, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray], last_alive):
    """Every successful run of iterations ``0..K``: ``(X (k, n), Y (k, m), latest (k,) bool)``
    (:func:`enkf.process.all_runs` on the experiment's parameter columns)."""
    names = list(spec.names)
    return _all_runs([p[names].to_numpy(float) for p in params], responses, last_alive)


def record_misfits(Y: np.ndarray, obs: Observations, alive=None) -> dict:
    """Misfit of the ensemble-mean response per record: ``{record: {rmse_Pa, nrmse, chi2_per_obs}}``."""
    Y = np.atleast_2d(np.asarray(Y, float))
    alive = np.all(np.isfinite(Y), axis=1) if alive is None else np.asarray(alive, bool) & np.all(np.isfinite(Y), axis=1)
    out = {}
    for rec in obs.records:
        sl = obs.record_slice(rec)
        sub = Observations(obs.frame.iloc[sl].reset_index(drop=True), obs.error_kind, obs.corr_time)
        m = mean_misfit(Y[:, sl], sub.values, sub.error_model(), alive)
        out[rec] = {"rmse_Pa": m["rmse"], "nrmse": m["nrmse"], "chi2_per_obs": m["chi2_per_obs"]}
    return out


def final_iteration(spec: ExperimentSpec, analyses: Sequence[Mapping]) -> tuple[int, dict]:
    """Re-take the stop decision over the stored iterations with the current rule: ``(K, decision)`` for
    the first ``K`` that stops, or ``(len(analyses), None)`` if all of them continue (run another)."""
    for a in analyses:
        k = int(a["iteration"])
        spread = a.get("spread_unbounded")
        spread = None if spread is None else np.array([spread[p] for p in spec.names])
        prior = np.array([a["prior_spread_unbounded"][p] for p in spec.names])
        d = decide(spec, k, stop_misfit(a["misfit"]), int(a["n_obs"]), spread, prior)
        if d["stop"]:
            return k, d
        if a.get("next_params") is None:
            return k, {**d, "stop": True, "reason": "no_update",
                       "message": "the stored analysis has no update to continue from; re-run the analysis"}
    return len(analyses), None


def summary(*, spec: ExperimentSpec, exp: Mapping, analyses: Sequence[Mapping], decision: Mapping,
            final_params: pd.DataFrame, final_alive, forecast_misfit: Mapping, n_simulations: int,
            wall_s: float | None, simulation_wall_s: float, sensitivity: Mapping | None = None,
            iteration_params: Sequence[pd.DataFrame] | None = None, posterior_samples: pd.DataFrame | None = None,
            posterior_sampler: Mapping | None = None, predictive: Mapping | None = None) -> dict:
    """``summary.json`` (docs/workflow.md, "What goes where"): experiment, iterations, converged, stop_reason,
    n_simulations, posterior, truth (twins), misfit per iteration, wall_s, per-record before/after
    misfits (before = prior ensemble mean, after = forecast with the posterior mean), and the
    ``verdict`` (calibration.verdict: ok, box_limited, worse_than_prior or not_converged, with the numbers and
    what to do next)."""
    names = list(spec.names)
    K = int(decision["iteration"])
    misfits = [{"iteration": int(a["iteration"]), "n_alive": int(a["n_alive"]), **a["misfit"]} for a in analyses[:K + 1]]
    # The ensemble reported as the posterior: the last, or the best when the last made the fit markedly
    # worse (calibration.verdict.reported_iteration).
    R = K if iteration_params is None else reported_iteration([member_chi2(m) for m in misfits])
    P, alive_R = (final_params, final_alive) if R == K else (iteration_params[R], analyses[R]["alive"])
    # the reported intervals hold one more draw of the members' distribution (enkf.prediction_interval_dict)
    post_ensemble = prediction_interval_dict(P[names].to_numpy(float), names, np.asarray(alive_R, bool), spec.transform)
    post = reported_posterior(spec, post_ensemble, posterior_samples)
    out = {
        "experiment": spec.name,
        "kind": exp["kind"],
        "geometry": exp["geometry"],
        "preset": exp["preset"],
        "method": spec.method,
        "alphas": list(spec.alphas) if spec.method == "esmda" else None,
        "ensemble_size": spec.ensemble_size,
        "seed": spec.seed,
        "iterations": K,
        "converged": bool(decision["converged"]),
        "stop_reason": decision["reason"],
        "stop_message": decision["message"],
        "n_simulations": int(n_simulations),
        "posterior_method": "ensemble" if posterior_samples is None else "emulator_mcmc",
        "posterior_form": posterior_form(spec, exp),
        "posterior": post,
        "prior": {p: {"lower": float(spec.lower[j]), "upper": float(spec.upper[j])} for j, p in enumerate(names)},
        "posterior_iteration": int(R),
        "misfit": misfits,
        "failed_members": {str(a["iteration"]): a["failed_members"] for a in analyses[:K + 1] if a["failed_members"]},
        "misfit_per_record": {
            rec: {"before": analyses[0]["misfit_per_record"][rec],
                  "posterior_ensemble_mean": analyses[R]["misfit_per_record"][rec],
                  "after": forecast_misfit.get(rec)}
            for rec in analyses[0]["misfit_per_record"]
        },
        "spread_ratio": {p: _ratio(analyses[R], p) for p in names},
        "wall_s": wall_s,
        "simulation_wall_s": simulation_wall_s,
        "environment": library_versions(),
    }
    out["posterior_ensemble_info"] = posterior_tempering(spec, R, K)
    out["discrepancy"] = (analyses[R].get("model_error") or {}).get("discrepancy")
    svar = (analyses[R].get("model_error") or {}).get("simulator_variability")
    out["simulator_variability"] = None if svar is None else {k: v for k, v in svar.items() if k != "sd_Pa"}
    out["inflated_noise_baseline"] = (analyses[R].get("model_error") or {}).get("inflated_noise_baseline")
    out["approximation_error"] = (analyses[R].get("model_error") or {}).get("approximation_error")
    if predictive is not None:
        out["predictive_coverage_90"] = predictive
    out["verdict"] = calibration_verdict(misfits=out["misfit"], decision=decision, posterior=post,
                                         lower=spec.lower, upper=spec.upper, names=names,
                                         diagnosed=_diagnosed(exp), sampler=posterior_sampler,
                                         n_obs=int(analyses[0]["n_obs"]), discrepancy=out["discrepancy"])
    best = out["verdict"]["chi2_per_obs"]["best_iteration"]
    if iteration_params is not None and best != K:
        # When an earlier ensemble fitted better it is kept beside the reported one (which is the best
        # itself when the last step made the fit markedly worse).
        Pb = iteration_params[best][names].to_numpy(float)
        out["best_ensemble"] = {"iteration": int(best), "chi2_per_obs": out["misfit"][best]["chi2_per_obs"],
                                "rmse_Pa": out["misfit"][best]["rmse_Pa"],
                                "posterior": posterior_dict(Pb, names, np.asarray(analyses[best]["alive"], bool))}
    if posterior_samples is not None:
        out["posterior_ensemble"] = post_ensemble
        out["posterior_sampler"] = dict(posterior_sampler or {})
    if spec.truth is not None:
        out["truth"] = {p: spec.truth[p] for p in names}
        out["accuracy"] = {
            p: {"rel_error": post[p]["mean"] / spec.truth[p] - 1.0,
                "in_90_interval": bool(post[p]["q05"] <= spec.truth[p] <= post[p]["q95"]),
                **({"in_50_interval": bool(post[p]["q25"] <= spec.truth[p] <= post[p]["q75"])} if "q25" in post[p]
                   else {})}
            for p in names
        }
    if sensitivity is not None:
        out["sensitivity"] = sensitivity
    return jsonable(out)


def reported_posterior(spec: ExperimentSpec, ensemble: Mapping, posterior_samples: pd.DataFrame | None) -> dict:
    """The ``posterior`` block the summary reports and the verdict reads: with ``posterior: emulator_mcmc``
    the MCMC sample's summary (calibration.posterior), else the reported ensemble's intervals
    (``ensemble``, :func:`enkf.diagnostics.prediction_interval_dict`)."""
    if posterior_samples is None:
        return dict(ensemble)
    from enkf.ces import interval_summary  # the MCMC's summary; SciPy's statistics only where used

    names = list(spec.names)
    return interval_summary(posterior_samples[names].to_numpy(float), names, spec.lower, spec.upper)


def reported_ensemble(spec: ExperimentSpec, analyses: Sequence[Mapping],
                      params: Sequence[pd.DataFrame]) -> tuple[int, pd.DataFrame, np.ndarray]:
    """``(R, params[R], alive[R])``: the ensemble reported as the posterior (posterior.csv, summary.json,
    the forecast, the plots) among iterations 0..K of the final loop (:func:`final_iteration`): the
    last, unless it fits markedly worse than the best (:func:`calibration.verdict.reported_iteration`)."""
    K = min(final_iteration(spec, analyses)[0], len(analyses) - 1)
    R = reported_iteration([member_chi2(a["misfit"]) for a in analyses[:K + 1]])
    return R, params[R], np.asarray(analyses[R]["alive"], bool)


def final_verdict(spec: ExperimentSpec, analyses: Sequence[Mapping], params: Sequence[pd.DataFrame],
                  exp: Mapping | None = None, posterior_samples: pd.DataFrame | None = None,
                  posterior_sampler: Mapping | None = None) -> dict | None:
    """The ``verdict`` block of ``summary.json`` from the stored iterations and, with ``posterior:
    emulator_mcmc``, the posterior sample and its sampler's record (for the plots, which run beside the
    summary: the same verdict on the same posterior): None while the stored iterations never stop."""
    K, decision = final_iteration(spec, analyses)
    if decision is None:
        return None
    misfits = [{"iteration": int(a["iteration"]), **a["misfit"]} for a in analyses[:K + 1]]
    R, P, alive = reported_ensemble(spec, analyses, params)
    names = list(spec.names)
    post = reported_posterior(spec, prediction_interval_dict(P[names].to_numpy(float), names, alive, spec.transform),
                              posterior_samples)
    return calibration_verdict(misfits=misfits, decision=decision, posterior=post, lower=spec.lower,
                               upper=spec.upper, names=spec.names, diagnosed=_diagnosed(exp),
                               sampler=posterior_sampler, n_obs=int(analyses[0]["n_obs"]),
                               discrepancy=(analyses[R].get("model_error") or {}).get("discrepancy"))


def _diagnosed(exp: Mapping | None) -> bool:
    return diagnosis_settings(exp) is not None


def _ratio(a: Mapping, p: str):
    s = a.get("spread_unbounded")
    if s is None:
        return None
    return s[p] / a["prior_spread_unbounded"][p]


def experiment_outcome(*, name: str, exp: Mapping, params: Sequence[pd.DataFrame], responses: Sequence[np.ndarray],
                       analyses: Sequence[Mapping], obs: Observations, forecast_curves: Mapping[str, pd.DataFrame],
                       forecast_runs: Mapping[str, Mapping], n_records: int, started: float | None,
                       finished: float | None, member_wall_s: float = 0.0,
                       extra_runs: Sequence[Mapping] = (), posterior_samples: pd.DataFrame | None = None,
                       posterior_sampler: Mapping | None = None) -> tuple[dict, pd.DataFrame]:
    """``(summary.json dict, posterior.csv frame)`` of a finished experiment.

    ``params``, ``responses``, ``analyses``: iterations 0..K of the final loop. The decision is
    re-taken with the current stopping rule (:func:`final_iteration`). ``forecast_curves``: the
    forecast run per record. ``started``/``finished``: epoch seconds for ``wall_s`` (the experiment's
    elapsed time from its prior ensemble to its summary). ``extra_runs``: run.json of other
    simulations (the twin's reference) counted in ``n_simulations``; ``member_wall_s``: the members'
    summed simulation wall time (``simulation_wall_s`` adds the forecast and extra runs).
    """
    from enkf import member_table

    from .observations import response_matrix

    spec = ExperimentSpec.from_config(name, exp)
    K, decision = final_iteration(spec, analyses)
    if decision is None:
        raise ValueError(f"{name}: the stored iterations never stop under the current rule; run the loop further")
    analyses, params, responses = list(analyses[:K + 1]), list(params[:K + 1]), list(responses[:K + 1])
    alive = np.asarray(analyses[K]["alive"], bool)
    Yf = response_matrix([forecast_curves], obs)
    ok_fc = {rec: forecast_runs[rec].get("status") == "ok" for rec in obs.records}
    fc_misfit = {rec: (v if ok_fc[rec] else None) for rec, v in record_misfits(Yf, obs, np.ones(1, bool)).items()}
    refine = (posterior_sampler or {}).get("refine") or {}  # calibration.posterior.refine_batch
    sim_wall = member_wall_s + sum(float(r.get("wall_s") or 0.0) for r in extra_runs) + sum(
        float(r.get("wall_s") or 0.0) for r in forecast_runs.values()) + float(refine.get("wall_s") or 0.0)
    sens = {"initial_ensemble": linear_sensitivity(params[0], spec.names, spec.lower, spec.upper, responses[0], obs,
                                                   np.asarray(analyses[0]["alive"], bool))}
    if K > 0:
        sens["final_ensemble"] = linear_sensitivity(params[K], spec.names, spec.lower, spec.upper, responses[K], obs,
                                                    alive)
    R = reported_ensemble(spec, analyses, params)[0]
    # The band of the reported ensemble's members (also under posterior: emulator_mcmc, whose samples
    # have no simulated curves) with the full error model of its analysis.
    predictive, predictive_check = posterior_predictive(obs, np.asarray(responses[R], float), np.asarray(analyses[R]["alive"], bool),
                                      analyses[R], rng_for(spec.seed, "predictive"))
    out = summary(spec=spec, exp=exp, analyses=analyses, decision=decision, final_params=params[K],
                  final_alive=alive, forecast_misfit=fc_misfit,
                  n_simulations=(K + 1) * (spec.ensemble_size + spec.replicates) * n_records + len(forecast_runs)
                  + len(extra_runs) + int(refine.get("runs") or 0) * n_records,
                  wall_s=None if started is None or finished is None else finished - started,
                  simulation_wall_s=sim_wall, sensitivity=sens, iteration_params=params,
                  posterior_samples=posterior_samples, posterior_sampler=posterior_sampler, predictive=predictive)
    out["predictive_check_90"] = predictive_check
    if posterior_samples is not None:
        return out, posterior_samples
    R = int(out["posterior_iteration"])
    table = member_table(params[R][list(spec.names)].to_numpy(float), list(spec.names), responses=responses[R],
                         obs=obs.values, obs_error=obs.error_model(), alive=np.asarray(analyses[R]["alive"], bool))
    return out, table
