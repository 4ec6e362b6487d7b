"""The likelihood's error model of an experiment: instrument noise, simulator variability, model discrepancy.

The data model is ``d = mu(theta) + eta + delta + e`` (:mod:`enkf.variability`): ``e ~ N(0, R)`` the
records' instrument noise (:meth:`Observations.error_model`); ``eta ~ N(0, S)`` the simulator's own
variability, what one run departs from the mean over mesh realizations, measured at every iteration
by replicate runs at the ensemble mean (``observations.model_error.simulator_replicates``); ``delta ~
N(0, D)`` the model discrepancy, an AR(1) term per record (its amplitude free before and after the
record's observed peak) estimated at every analysis from that iteration's members (:mod:`enkf.discrepancy`;
``observations.model_error.discrepancy``: ``ar1`` by default, ``none`` to leave it out).

Which combination each step uses (:class:`ErrorModel`) follows from what a member's run is. With
``simulation.mesh_realizations: per_run`` (default) every run has its own mesh realization, so a member
is a draw ``mu(theta_i) + eta_i``:

* a member against the data differs by two realizations: ``R + 2 S + D`` is what the stop test scores
  the members against, and ``R + 2 S`` is the base the discrepancy is estimated over (so ``D`` holds
  only what the simulator's variability does not);
* the ensemble's own scatter already carries ``S`` into the ES-MDA gain (a stochastic forward model),
  so analysis step ``alpha`` assimilates with ``R + D + (1 - 1/alpha) S``: its perturbations then have
  covariance ``alpha (R + D + S) - S``, and with the members' own ``S`` the steps multiply to the
  likelihood ``N(d; mu, R + S + D)`` as ES-MDA's schedule requires;
* the emulator of :mod:`enkf.emulated` is built on runs that each carry their ``eta``, and its
  leave-one-out error holds ``S``: it assimilates with ``R + D`` plus that error;
* the posterior-predictive band of the members (each a realization) adds ``R + D``.

With ``shared`` the members run on the unperturbed mesh: its departure is one fixed unknown draw, so
``S`` is added where the members do not sample it (assimilation and predictive band ``R + 2 S + D``: the
members' common departure and the data's own; emulated ``R + D + S``: the emulator's leave-one-out
error holds part of the one mesh's roughness).

Each ``analysis.json`` stores the estimates (``model_error``), so the summary rebuilds the same terms
from files alone (:func:`stored_error`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .observations import Observations

# enkf (SciPy under it) is imported by the functions that compute: the workflow's parse reads this
# module's config functions (replicate_count, run_mesh_seed) and must not pay for SciPy (issue 54)
if TYPE_CHECKING:
    from enkf import AR1Error, DenseError, ObservationError

__all__ = ["MESH_MODES", "MESH_STAGES", "mesh_seed", "run_mesh_seed", "ErrorModel", "discrepancy_kind", "mesh_mode", "replicate_count", "check_replicate_count", "analysis_error",
           "stored_error", "misfit_block", "posterior_predictive", "variability_from_replicates"]

#: ``simulation.mesh_realizations``: every run its own mesh realization, or the members on one mesh.
MESH_MODES = ("per_run", "shared")


def discrepancy_kind(exp: Mapping) -> str:
    """``"ar1"`` (default, twins included) or ``"none"``."""
    kind = ((exp.get("observations") or {}).get("model_error") or {}).get("discrepancy")
    return "ar1" if kind is None else str(kind)


def replicate_count(exp: Mapping) -> int:
    """Replicate runs per iteration at the ensemble mean that measure ``S`` (0: ``S`` is not measured)."""
    n = ((exp.get("observations") or {}).get("model_error") or {}).get("simulator_replicates")
    return 0 if n is None else int(n)


def mesh_mode(exp: Mapping) -> str:
    return str((exp.get("simulation") or {}).get("mesh_realizations") or "per_run")


def check_replicate_count(exp: Mapping) -> int:
    """Mesh realizations per point of the loop's real-FDEM check (``diagnosis.check_replicates``); 1 with
    ``simulation.mesh_realizations: shared``, where every run has the one mesh and replicates would be
    copies (whose zero scatter would confirm anything)."""
    if mesh_mode(exp) == "shared":
        return 1
    return int(exp["diagnosis"]["check_replicates"])  # the schema's default where the config gives none


#: The spawn key of the mesh realizations' stream (``calibration.experiment.PURPOSES["mesh"]``) and what a
#: simulation's realization is drawn for.
MESH_PURPOSE = 6
MESH_STAGES = {"member": 1, "truth": 2, "replicate": 3, "design": 4, "check": 5, "approximation": 6, "refine": 7,
               "realrun": 8, "realrun_coarse": 9, "realrun_fine": 10}


def mesh_seed(seed: int, stage: str, k: int = 0, index: int = 0, record: int = 0) -> int:
    """The specimen-mesh realization (``python -m shpb simulate --mesh-seed``) of one simulation: a
    31-bit integer from ``SeedSequence(seed, spawn_key=(mesh, stage, k, index, record))``, so that every
    run of an experiment (iteration ``k``, member or replicate ``index``, record position ``record``)
    has its own realization and a re-run has the same one."""
    ss = np.random.SeedSequence(int(seed), spawn_key=(MESH_PURPOSE, MESH_STAGES[stage], int(k), int(index),
                                                      int(record)))
    return int(ss.generate_state(1, np.uint32)[0] & 0x7FFFFFFF)


def run_mesh_seed(exp: Mapping, stage: str, k: int = 0, index: int = 0, record: int = 0) -> int | None:
    """:func:`mesh_seed` of a simulation of experiment ``exp`` (its config block), or None (the
    unperturbed mesh) for the members, design and check runs of ``simulation.mesh_realizations:
    shared``. A twin's reference run and the replicates always get a realization of their own: the data
    of a real test never come from the model's mesh, and replicates measure what the mesh changes."""
    if stage in ("member", "design", "check", "refine") and mesh_mode(exp) == "shared":
        return None
    return mesh_seed(int(exp["seed"]), stage, k, index, record)


def _dense(C: np.ndarray) -> DenseError:
    from enkf import DenseError

    return DenseError(C, _symmetric=True)


@dataclass(frozen=True)
class ErrorModel:
    """The terms of one analysis as dense matrices on the observation vector (``S``, ``D`` zero where
    not measured or not estimated) and how the members relate to the mesh (``per_run``/``shared``)."""

    R: np.ndarray
    S: np.ndarray
    D: np.ndarray
    mode: str = "per_run"
    measured: bool = True

    def _shared(self) -> float:
        return 1.0 if self.mode == "shared" else 0.0

    def stop(self) -> DenseError:
        """A member's run against the data: ``R + 2 S + D`` for measured data, ``R + 2 S`` for a twin.

        A twin's data come from the simulator itself, so its declared error model is the noise and the
        simulator's variability: a discrepancy fitted to the members' residuals would absorb any misfit
        and a stop test against it could not fail. Measured data need ``D`` (a model never fits them to
        the noise), and the verdict's ``misfit_unexplained`` says so."""
        return _dense(self.R + 2.0 * self.S + (self.D if self.measured else 0.0))

    def simulator_only(self) -> DenseError:
        """``R + 2 S``: what a member misses the data by when the model lacks nothing."""
        return _dense(self.R + 2.0 * self.S)

    def likelihood(self) -> DenseError:
        """The data about the mean over realizations: ``R + S + D``."""
        return _dense(self.R + self.S + self.D)

    def assimilation(self, alpha: float = 1.0) -> DenseError:
        """The error an ES-MDA step ``alpha`` (1: ES, EnKF) assimilates with (module docstring)."""
        if self.mode == "shared":
            return _dense(self.R + 2.0 * self.S + self.D)
        return _dense(self.R + self.D + (1.0 - 1.0 / float(alpha)) * self.S)

    def emulated(self) -> DenseError:
        """What the emulated analysis adds its emulator error to: ``R + D`` (``+ S`` for a shared mesh)."""
        return _dense(self.R + self.D + self._shared() * self.S)

    def predictive(self) -> DenseError:
        """What the members' predictive band adds: ``R + D`` (``+ 2 S`` for a shared mesh: the members'
        common departure and the data's own, as in its assimilation)."""
        return _dense(self.R + self.D + 2.0 * self._shared() * self.S)


def variability_from_replicates(obs: Observations, replicates) -> tuple[AR1Error | None, dict | None]:
    """``S`` from the replicate curves ``(M, m)`` on the observation grid (None without replicates)."""
    from enkf.variability import simulator_variability

    if replicates is None or np.size(replicates) == 0:
        return None, None
    peaks = peak_times(obs)
    S, info = simulator_variability(replicates, obs.time, obs.frame["record"].to_numpy(str),
                                    split_times={rec: peaks[g] for g, rec in enumerate(obs.records)})
    return S, info


def analysis_error(kind: str, obs: Observations, Y: np.ndarray, alive: np.ndarray, *, replicates=None,
                   mode: str = "per_run", measured: bool = True) -> tuple[ErrorModel, dict]:
    """``(terms, model_error block of analysis.json)`` for one analysis on the members ``Y`` (alive rows);
    ``measured``: the data are measured (not a twin's), so the stop test includes ``D``."""
    from enkf.discrepancy import estimate_discrepancy, inflated_noise_factor

    R = obs.error_model()
    block = {"noise": R.describe(), "discrepancy": None, "mesh_realizations": mode, "measured_data": bool(measured)}
    approx = obs.meta.get("approximation_error")
    if approx:  # in R already (calibration.observations.Observations.added_cov): reported, not added again
        block["approximation_error"] = {k: v for k, v in approx.items() if k != "sd_Pa"}
    S_err, s_info = variability_from_replicates(obs, replicates)
    block["simulator_variability"] = s_info
    Rd = R.dense()
    Sd = np.zeros_like(Rd) if S_err is None else S_err.dense()
    if kind != "none":
        est = estimate_discrepancy(obs.values[None, :] - Y, _dense(Rd + 2.0 * Sd), obs.time, obs.groups, alive,
                                   split_times=phase_bounds(obs))
        block["discrepancy"] = est.to_dict(obs.records)
        best = obs.values - Y[est.member]
        # The simplest honest alternative, for comparison: R inflated until the same member's chi^2/m is 1.
        block["inflated_noise_baseline"] = {
            rec: {"factor": inflated_noise_factor(best[obs.record_slice(rec)], obs.of_record(rec).error_model())}
            for rec in obs.records}
    return stored_error(obs, {"model_error": block}), block


#: A record's onset: where its observed stress first passes this fraction of its peak.
ONSET_FRACTION = 0.1


def phase_bounds(obs: Observations) -> dict:
    """``{group: (onset, peak)}``: where the discrepancy's amplitude may change (the foot before the
    onset, the rise, the fracture after the peak), from each record's own observed curve (a calibration
    record's data: the discrepancy is a property of the fit to them)."""
    out = {}
    for g, rec in enumerate(obs.records):
        sl = obs.record_slice(rec)
        t, y = obs.time[sl], np.abs(obs.values[sl])
        k = int(np.argmax(y))
        above = np.flatnonzero(y[:k + 1] >= ONSET_FRACTION * y[k])
        out[g] = (float(t[above[0]]), float(t[k])) if above.size and above[0] > 0 else (float(t[k]),)
    return out


def peak_times(obs: Observations) -> dict:
    """``{group: time of the record's largest observed |stress|}``: where the discrepancy's amplitude may
    change (the elastic rise before, the fracture after)."""
    out = {}
    for g, rec in enumerate(obs.records):
        sl = obs.record_slice(rec)
        out[g] = float(obs.time[sl][int(np.argmax(np.abs(obs.values[sl])))])
    return out


def stored_error(obs: Observations, analysis: Mapping) -> ErrorModel:
    """The terms as stored in an ``analysis.json`` (``S`` and ``D`` zero where it has none)."""
    from enkf import AR1Error
    from enkf.discrepancy import combined_error, stored_term

    block = analysis.get("model_error") or {}
    R = obs.error_model().dense()
    s_info = block.get("simulator_variability") or {}
    if s_info.get("sd_Pa"):
        S = AR1Error(np.asarray(s_info["sd_Pa"], float), obs.time, float(s_info["corr_time_s"]),
                     groups=obs.groups).dense()
    else:
        S = np.zeros_like(R)
    disc = block.get("discrepancy")
    D = np.zeros_like(R)
    if disc:
        labels = {rec: i for i, rec in enumerate(obs.records)}
        terms = {labels[rec]: stored_term(v) for rec, v in disc["records"].items()}
        D = combined_error(_dense(R), obs.time, obs.groups, terms, as_matrix=True) - R
    return ErrorModel(R=R, S=S, D=D, mode=str(block.get("mesh_realizations") or "per_run"),
                      measured=bool(block.get("measured_data", True)))


def misfit_block(Y: np.ndarray, obs: Observations, noise: ObservationError, terms: ErrorModel,
                 alive: np.ndarray) -> dict:
    """The ``misfit`` block of ``analysis.json``.

    ``chi2_per_obs`` / ``rmse_Pa`` / ``nrmse``: the ensemble-mean curve against ``R`` (kept for the
    plots and for comparison); ``median_chi2_per_obs`` and ``best_chi2_per_obs``: the members against
    ``R``; ``median_chi2_per_obs_simulator``: the median member against ``R + 2 S`` (what a member misses
    by when the model lacks nothing but the mesh); ``*_total``: the members against the stop test's
    model (:meth:`ErrorModel.stop`), whitened by it. The stop test: ``stop_chi2_per_obs``, the median
    member against the stop test's model standardised by its variances, and ``stop_target``, that
    statistic's mean plus two sd under the model (:func:`enkf.diagnostics.member_standardized_misfit`);
    ``standardized_chi2_per_obs_simulator`` / ``standardized_target_simulator``: the same against
    ``R + 2 S`` (the verdict's ``misfit_unexplained``).
    """
    from enkf.diagnostics import member_misfit, member_standardized_misfit, mean_misfit

    mean = mean_misfit(Y, obs.values, noise, alive)
    mem = member_misfit(Y, obs.values, noise, alive)
    out = {"rmse_Pa": mean["rmse"], "nrmse": mean["nrmse"], "chi2_per_obs": mean["chi2_per_obs"],
           "median_chi2_per_obs": mem["median_chi2_per_obs"], "best_chi2_per_obs": mem["best_chi2_per_obs"],
           "median_rmse_Pa": mem["median_rmse"], "median_nrmse": mem["median_nrmse"]}
    sim_err, stop_err = terms.simulator_only(), terms.stop()  # each a dense Cholesky: made once
    sim = member_misfit(Y, obs.values, sim_err, alive)
    tot = member_misfit(Y, obs.values, stop_err, alive)
    stop = member_standardized_misfit(Y, obs.values, stop_err, alive)
    sim_std = member_standardized_misfit(Y, obs.values, sim_err, alive)
    out.update({"median_chi2_per_obs_simulator": sim["median_chi2_per_obs"],
                "median_chi2_per_obs_total": tot["median_chi2_per_obs"],
                "best_chi2_per_obs_total": tot["best_chi2_per_obs"],
                "stop_chi2_per_obs": stop["median"], "stop_target": stop["target"],
                "standardized_chi2_per_obs_simulator": sim_std["median"],
                "standardized_target_simulator": sim_std["target"]})
    return out


def posterior_predictive(obs: Observations, Y: np.ndarray, alive: np.ndarray, analysis: Mapping,
                         rng: np.random.Generator, level: float = 0.9) -> tuple[dict, dict]:
    """``({record: coverage}, {record: check})``: the fraction of each record's observations inside the
    ``level`` posterior-predictive band of the members ``Y`` with the full error model of
    ``analysis``, and the check of that fraction against its spread for data drawn from the
    predictive itself (``expected_5_95``; ``consistent`` when the fraction lies inside)."""
    from enkf.predictive import predictive_coverage

    C = stored_error(obs, analysis).predictive()
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
    """The workflow's error model (``R + 2 S + D`` of ``analysis`` for a member's residual) against the simplest honest baseline, ``R``
    inflated per record until the carrying member's chi^2 per observation is 1: log-likelihood of that
    member's residual and 90 % predictive coverage, per record."""
    from enkf.discrepancy import inflated_noise_factor, record_loglik
    from enkf.predictive import predictive_coverage

    disc = (analysis.get("model_error") or {}).get("discrepancy")
    if not disc:
        raise ValueError("this analysis has no estimated discrepancy to compare")
    member = int(disc["member"])
    terms = stored_error(obs, analysis)
    # a member's residual against R + 2S + D; the members' band with R + D (per_run meshes)
    Cd, Cp, Rd = terms.stop().dense(), terms.predictive().dense(), obs.error_model().dense()
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
        ar1 = predictive_coverage(Y[:, sl], obs.values[sl], _dense(Cp[sl, sl]), rng, 0.9, alive=alive)
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


def _scaled(err: ObservationError, factor: float):
    return _dense(factor * err.dense())
