"""The likelihood's error model of an experiment: instrument noise plus, where declared, model error.

``C = R + D``: ``R`` is the records' instrument noise (:meth:`Observations.error_model`); ``D`` is the
model discrepancy, an AR(1) term per record (its amplitude free to differ before and after the
record's observed peak) estimated at every analysis from that iteration's members
(:mod:`enkf.discrepancy`; ``observations.model_error.discrepancy``: ``ar1`` by default, ``none`` to
assimilate against the instrument noise alone). ``C`` is what the analysis assimilates with, what the stop test and the
verdict score the members against, and what the posterior-predictive band adds to the members' curves.

Each ``analysis.json`` stores the estimate (``model_error``), so the summary rebuilds the same ``C``
from files alone (:func:`stored_error`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from enkf import DenseError, ObservationError
from enkf.diagnostics import member_misfit, mean_misfit
from enkf.discrepancy import combined_error, estimate_discrepancy, inflated_noise_factor, record_loglik
from enkf.predictive import predictive_coverage

from .observations import Observations

__all__ = ["discrepancy_kind", "analysis_error", "stored_error", "misfit_block", "posterior_predictive"]


def discrepancy_kind(exp: Mapping) -> str:
    """``"ar1"`` (default, twins included: the simulator's own post-peak variability is a model error
    the noise does not hold) or ``"none"``."""
    kind = ((exp.get("observations") or {}).get("model_error") or {}).get("discrepancy")
    return "ar1" if kind is None else str(kind)


def analysis_error(kind: str, obs: Observations, Y: np.ndarray, alive: np.ndarray) -> tuple[ObservationError, dict]:
    """``(C, model_error block of analysis.json)`` for one analysis on the members ``Y`` (alive rows)."""
    R = obs.error_model()
    block = {"noise": R.describe(), "discrepancy": None}
    if kind == "none":
        return R, block
    est = estimate_discrepancy(obs.values[None, :] - Y, R, obs.time, obs.groups, alive,
                               split_times=peak_times(obs))
    block["discrepancy"] = est.to_dict(obs.records)
    best = obs.values - Y[est.member]
    # The simplest honest alternative, for comparison: R inflated until the same member's chi^2/m is 1.
    block["inflated_noise_baseline"] = {
        rec: {"factor": inflated_noise_factor(best[obs.record_slice(rec)], obs.of_record(rec).error_model())}
        for rec in obs.records}
    return stored_error(obs, {"model_error": block}), block


def peak_times(obs: Observations) -> dict:
    """``{group: time of the record's largest observed |stress|}``: where the discrepancy's amplitude may
    change (the elastic rise before, the fracture after)."""
    out = {}
    for g, rec in enumerate(obs.records):
        sl = obs.record_slice(rec)
        out[g] = float(obs.time[sl][int(np.argmax(np.abs(obs.values[sl])))])
    return out


def stored_error(obs: Observations, analysis: Mapping) -> ObservationError:
    """``R + D`` as stored in an ``analysis.json`` (``R`` alone where it has no discrepancy)."""
    R = obs.error_model()
    disc = (analysis.get("model_error") or {}).get("discrepancy")
    if not disc:
        return R
    labels = {rec: i for i, rec in enumerate(obs.records)}
    terms = {labels[rec]: (float(v["sigma_pre"]), float(v["sigma_post"]), float(v["corr_time_s"]),
                           None if v.get("split_time_s") is None else float(v["split_time_s"]))
             for rec, v in disc["records"].items()}
    return combined_error(R, obs.time, obs.groups, terms)


def misfit_block(Y: np.ndarray, obs: Observations, noise: ObservationError, total: ObservationError,
                 alive: np.ndarray) -> dict:
    """The ``misfit`` block of ``analysis.json``.

    ``chi2_per_obs`` / ``rmse_Pa`` / ``nrmse``: the ensemble-mean curve against ``R`` (kept for the
    plots and for comparison); ``median_chi2_per_obs`` and ``best_chi2_per_obs``: the members against
    ``R``; ``*_total``: the members against the full error model; ``stop_chi2_per_obs``: the median
    member against the full error model, the stop test's statistic.
    """
    mean = mean_misfit(Y, obs.values, noise, alive)
    mem = member_misfit(Y, obs.values, noise, alive)
    out = {"rmse_Pa": mean["rmse"], "nrmse": mean["nrmse"], "chi2_per_obs": mean["chi2_per_obs"],
           "median_chi2_per_obs": mem["median_chi2_per_obs"], "best_chi2_per_obs": mem["best_chi2_per_obs"],
           "median_rmse_Pa": mem["median_rmse"], "median_nrmse": mem["median_nrmse"]}
    tot = mem if total is noise else member_misfit(Y, obs.values, total, alive)
    out.update({"median_chi2_per_obs_total": tot["median_chi2_per_obs"],
                "best_chi2_per_obs_total": tot["best_chi2_per_obs"],
                "stop_chi2_per_obs": tot["median_chi2_per_obs"]})
    return out


def posterior_predictive(obs: Observations, Y: np.ndarray, alive: np.ndarray, analysis: Mapping,
                         rng: np.random.Generator, level: float = 0.9) -> tuple[dict, dict]:
    """``({record: coverage}, {record: check})``: the fraction of each record's observations inside the
    ``level`` posterior-predictive band of the members ``Y`` with the full error model of
    ``analysis``, and the check of that fraction against its spread for data drawn from the
    predictive itself (``expected_5_95``; ``consistent`` when the fraction lies inside)."""
    C = stored_error(obs, analysis)
    cov = predictive_coverage(Y, obs.values, C, rng, level, groups=obs.groups, alive=alive, n_replicates=400)
    fractions = {rec: cov["groups"][i] for i, rec in enumerate(obs.records)}
    checks = {}
    for i, rec in enumerate(obs.records):
        lo, hi = cov["reference"][i]
        checks[rec] = {"coverage": fractions[rec], "expected_5_95": [lo, hi],
                       "consistent": bool(lo <= fractions[rec] <= hi)}
    return fractions, checks



def posterior_tempering(spec, R: int, K: int) -> dict:
    """Which ensemble is reported and under which tempering: iteration ``R`` of the final ``K`` is, for
    a linear-Gaussian model, the posterior of the likelihood with its error covariance multiplied by
    ``covariance_factor`` (1 = the full posterior; None = the prior, nothing assimilated)."""
    if R == 0:
        factor = None
    elif spec.method == "esmda":
        factor = 1.0 / sum(1.0 / a for a in spec.alphas[:R])
    elif spec.method == "emulated_esmda":
        factor = float(spec.temper_base ** max(0, spec.max_iterations - R))
    else:  # the paper's EnKF re-uses the same data with alpha = 1 at every analysis
        factor = 1.0 / R
    what = ("the prior ensemble" if factor is None else "the full posterior" if abs(factor - 1.0) < 1e-9
            else f"a tempered posterior (error covariance x {factor:.3g})")
    return {"iteration": int(R), "final_iteration": int(K), "is_last": R == K, "covariance_factor": factor,
            "reads_as": what}


def compare_with_inflated_noise(obs: Observations, Y: np.ndarray, alive: np.ndarray, analysis: Mapping,
                                rng: np.random.Generator) -> dict:
    """The workflow's error model (``R + D`` of ``analysis``) against the simplest honest baseline, ``R``
    inflated per record until the carrying member's chi^2 per observation is 1: log-likelihood of that
    member's residual and 90 % predictive coverage, per record."""
    disc = (analysis.get("model_error") or {}).get("discrepancy")
    if not disc:
        raise ValueError("this analysis has no estimated discrepancy to compare")
    member = int(disc["member"])
    C = stored_error(obs, analysis)
    Cd, Rd = C.dense(), obs.error_model().dense()
    out = {}
    for g, rec in enumerate(obs.records):
        sl = obs.record_slice(rec)
        r = obs.values[sl] - Y[member, sl]
        t = obs.time[sl]
        factor = inflated_noise_factor(r, obs.of_record(rec).error_model())
        ll_inf = record_loglik(r, factor * Rd[sl, sl], t, 0.0, 0.0)
        ll_ar1 = record_loglik(r, Cd[sl, sl], t, 0.0, 0.0)
        sub = obs.of_record(rec)
        infl = predictive_coverage(Y[:, sl], obs.values[sl], _scaled(sub.error_model(), factor), rng, 0.9, alive=alive)
        ar1 = predictive_coverage(Y[:, sl], obs.values[sl], _dense(Cd[sl, sl]), rng, 0.9, alive=alive)
        bare = predictive_coverage(Y[:, sl], obs.values[sl], sub.error_model(), rng, 0.9, alive=alive)
        out[rec] = {"inflation_factor": factor, "loglik_inflated": ll_inf, "loglik_ar1": ll_ar1,
                    "coverage_90_inflated": infl["all"], "coverage_90_ar1": ar1["all"],
                    "coverage_90_noise_only": bare["all"],
                    "discrepancy_sigma": disc["records"][rec]["sigma"],
                    "discrepancy_corr_time_s": disc["records"][rec]["corr_time_s"]}
    return out


def linear_posterior_std(P: np.ndarray, Y: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The Gauss-linear posterior std of each parameter, ``sqrt(diag((G^T C^-1 G)^-1))``, with ``G`` the
    least-squares sensitivity of the members' responses to their parameters (flat prior): how wide an
    error model ``C`` makes the intervals, other things equal."""
    X = np.hstack([np.ones((P.shape[0], 1)), P - P.mean(axis=0)])
    G = np.linalg.lstsq(X, Y, rcond=None)[0][1:].T
    L = np.linalg.cholesky(C)
    W = np.linalg.solve(L, G)
    return np.sqrt(np.diag(np.linalg.inv(W.T @ W)))


def _dense(C: np.ndarray) -> DenseError:
    return DenseError(C, _symmetric=True)


def _scaled(err: ObservationError, factor: float):
    return _dense(factor * err.dense())
