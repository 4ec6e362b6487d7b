"""Closing the loop in the workflow: the frozen protocol (:mod:`calibration.protocol`) on an experiment's
files, and leave-one-record-out over a whole series (rules/diagnosis.smk).

The order is fixed before anything is fitted (docs/closing-the-loop.md):

1. the experiment's calibration records are calibrated on FDEM (the workflow's loop); its held-out
   records are reduced for their incident wave, their sheet and their noise level only;
2. a design of FDEM runs around that posterior (every record: a held-out record's runs use its incident
   wave only) gives the emulator (:func:`emulated_model`);
3. :func:`select_effects` chooses effects by cross-validation within the calibration records on the
   emulator, with the instrument noise and the simulator's variability the calibration measured beside
   the emulator's time-correlated error (:func:`protocol_errors`);
4. real FDEM runs at every step's cross-validation points and held-out prediction points
   (:func:`check_rows`, one Snakemake job each), each on ``diagnosis.check_replicates`` mesh
   realizations of its record, realization k the same for every step, so that two steps are compared
   on common meshes;
5. :func:`assemble`: the confirmation walk on the real cross-validation runs (with replicates: the mean
   difference of the steps' squared errors over the common meshes against its measured scatter and the
   data's noise, :func:`enkf.diagnosis.compare_replicated`), and only then the held-out records' curves
   are read: their errors before (base model) and after (the confirmed model), averaged over the meshes.

With ``diagnosis: {validation: loro}`` an experiment's records are each held out once
(:func:`loro_folds`): one experiment per fold, ``<experiment>__<record>``, tabulated by :func:`loro_table`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from enkf.covariance import DenseError, ObservationError
from enkf.diagnosis import box_draws, group_text, heldout_evaluation, replicate_curve_errors
from enkf.diagnosis.band import plugin_draws, replicate_variance, residual_discrepancy, run_band
from enkf.diagnosis.crossval import seed_for
from enkf.diagnosis.protocol import step_summary
from enkf.emulator import AnchoredEmulator
from shpb import effects as fx

from .covariates import peak_error_trends
from .diagnose import EmulatedSHPB, anchored_emulators, emulators_from_design
# light, for the Snakefile's parse: re-exported here, where the rest of closing the loop lives
from .diagnosis_config import FOLD_SEPARATOR, candidate_effects, loro_folds  # noqa: F401
from .model_error import stored_error
from .observations import UNCORRECTED_COLUMN, Observations
from .protocol import check_runs, real_curves, real_group, select
from .walk import chain_of, gated, walk

__all__ = ["FOLD_SEPARATOR", "blind", "candidate_effects", "emulated_model", "protocol_errors", "select_effects",
           "base_posterior_mismatches", "calibration_discrepancy", "check_rows", "covariate_table", "assemble",
           "fit_sources", "predictive_bands", "loro_folds",
           "loro_table"]


def blind(heldout: Observations | None) -> Observations | None:
    """The held-out records as the selection may see them: their times and noise level (with the
    approximation pairs' scatter, from their incident wave), their curves replaced by NaN, the curve as
    observed too (so that any use of them before :func:`assemble` poisons the result instead of leaking it)."""
    if heldout is None:
        return None
    frame = heldout.frame.copy()
    frame[[c for c in ("stress_Pa", UNCORRECTED_COLUMN) if c in frame]] = np.nan
    return Observations(frame, heldout.error_kind, dict(heldout.corr_time), dict(heldout.meta), heldout.added_cov)


def emulated_model(X, names: Sequence[str], lower, upper, curves: Mapping[str, Sequence], model_times,
                   obs_times: Mapping[str, np.ndarray], label: str, axis=None, pair=None) -> tuple[EmulatedSHPB, dict]:
    """The selection's model of every record: with ``axis`` (and ``pair``, the anchored design's,
    design.json) the anchored one (:func:`calibration.diagnose.anchored_emulators`), else the RBF emulator
    of a space-filling design (:func:`calibration.diagnose.emulators_from_design`)."""
    if axis is not None:
        emulators, n_failed = anchored_emulators(X, axis, curves, model_times, lower, upper, names, label=label,
                                                 pair=pair)
    else:
        emulators, n_failed = emulators_from_design(X, curves, model_times, lower, upper, names, label=label)
    return EmulatedSHPB(emulators, list(names), model_times, dict(obs_times)), n_failed


def anchored(model: EmulatedSHPB) -> bool:
    """Whether ``model`` is the anchored selection model (its runs share one mesh per record)."""
    return all(isinstance(e, AnchoredEmulator) for e in model.emulators.values())


def _per_record(C: np.ndarray, obs: Observations) -> dict[str, np.ndarray]:
    return {r: C[obs.record_slice(r), obs.record_slice(r)] for r in obs.records}


def _mean_block(blocks: Sequence[np.ndarray]) -> np.ndarray:
    return sum(blocks) / len(blocks)


def protocol_errors(obs: Observations, analysis: Mapping, heldout: Observations | None) -> tuple[dict, dict]:
    """``(noise, simulator)`` per record for the protocol: the record's instrument noise, and the
    simulator's variability the calibration's replicates measured (its reported analysis).

    The discrepancy the calibration estimated is left out on purpose: it was fitted to the base model's
    residual, which holds the very effects the selection is looking for, so with it in the gate every
    effect's gain would read as chance (measured on an earlier default run's marble, 2026-11-25 code:
    ``face_gap`` lowered the cross-validated RMSE from 20.9 to 15.1 MPa at z = 0.31 against a 12.7 MPa discrepancy correlated over
    the whole window). A held-out record takes its own instrument noise and the calibration records'
    average variability (the same grid), never anything estimated from its own curve."""
    S = _per_record(stored_error(obs, analysis).S, obs)
    noise = {r: obs.of_record(r).error_model() for r in obs.records}
    sim = {r: _jittered(S[r]) for r in obs.records if np.any(S[r])}
    if heldout is not None:
        Sm = _mean_block(list(S.values()))
        for h in heldout.records:
            noise[h] = heldout.of_record(h).error_model()
            if noise[h].m != Sm.shape[0]:
                raise ValueError(f"held-out record {h} has {noise[h].m} observations, the calibration records "
                                 f"{Sm.shape[0]}: give them the same observation grid")
            if np.any(Sm):
                sim[h] = _jittered(Sm)
    return noise, sim


def calibration_discrepancy(obs: Observations, analysis: Mapping) -> dict[str, np.ndarray]:
    """Per calibration record, the per-time variance of the model discrepancy ``D`` the workflow's
    calibration estimated (its reported analysis; zero where it estimated none): the discrepancy term of
    the check's predictive bands (:func:`predictive_bands`)."""
    D = stored_error(obs, analysis).D
    return {r: np.diag(D[obs.record_slice(r), obs.record_slice(r)]).copy() for r in obs.records}


def _jittered(S: np.ndarray) -> DenseError:
    # a 1e-12 relative nugget: S is zero before the wave arrives and must still factorise
    return DenseError(S + 1e-12 * max(1.0, float(np.max(np.diag(S)))) * np.eye(S.shape[0]), _symmetric=True)


def select_effects(model: EmulatedSHPB, *, base_names: Sequence[str], candidates: Sequence[str], obs: Observations,
                   noise: Mapping[str, ObservationError], simulator: Mapping[str, ObservationError],
                   heldout_records: Sequence[str], settings: Mapping, mesh_mode: str = "per_run", base_fit=None):
    """:func:`calibration.protocol.select` with the experiment's ``diagnosis`` settings; reads the
    calibration records' observations only. With ``per_run`` meshes the design runs each carry their
    own realization, so the emulator's leave-one-out error already holds ``S``: it is not added again.
    Where every run of a record is on one mesh (a ``shared`` mesh, or the anchored model) ``S`` is added
    beside the surrogate's own error, and it is common to two models' predictions of that record
    (``simulator_correlation`` 1). ``base_fit``: the workflow's posterior as the base model
    (:func:`calibration.protocol.workflow_base`)."""
    one_mesh = anchored(model) or mesh_mode == "shared"
    if not one_mesh:
        simulator = {}
    return select(model, base_names=list(base_names), candidates=[fx.get_effect(c) for c in candidates],
                  calib_records=list(obs.records), obs={r: obs.values[obs.record_slice(r)] for r in obs.records},
                  noise=noise, heldout_records=list(heldout_records), simulator=simulator,
                  # one mesh per record: two models' predictions of it share its departure
                  simulator_correlation=1.0 if one_mesh else 0.0,
                  scopes=settings.get("scopes") or None, max_additions=int(settings["max_additions"]),
                  alpha=float(settings["alpha"]), seed=int(settings["seed"]), n_members=int(settings["members"]),
                  esmda_steps=int(settings["esmda_steps"]), gate=str(settings.get("emulator_gate", "improvement")),
                  base_fit=base_fit, per_model=settings["own_error"] == "per_model",
                  alternatives=int(settings["alternatives"]))


def covariate_table(selection, model: EmulatedSHPB, obs: Observations):
    """``(table, trends)``: per calibration record, its residual at the base model's calibration on all
    calibration records (emulated, at the posterior mean) against every covariate its sheet gives
    (:func:`calibration.covariates.record_covariates`), and the trends across records
    (:func:`calibration.covariates.covariate_table_trends`; None with fewer than three records)."""
    from .covariates import covariate_table_trends, record_covariates

    fit = selection.steps[0].final
    mean = fit.mean()
    x = np.array([mean[n] for n in fit.names])
    resid, sigma = {}, {}
    for r in obs.records:
        s = obs.record_slice(r)
        sim = model.forward(fit.names, [r])(x)[0]
        resid[r] = obs.values[s] - sim
        sigma[r] = float(np.sqrt(np.mean(obs.sigma[s] ** 2)))
    table = record_covariates(obs.meta.get("record_info", {}), resid, sigma)
    return table, covariate_table_trends(table)


def check_rows(selection, replicates: int = 1) -> list[dict]:
    """The real FDEM runs of the check (:func:`calibration.protocol.check_runs`, each point on
    ``replicates`` mesh realizations), JSON-ready."""
    rows = check_runs(selection, replicates)
    return [{k: (dict(v) if isinstance(v, Mapping) else v) for k, v in row.items()} for row in rows]


def _errors_table(selection, conf: dict, real: Mapping, obs: Observations, held: Mapping) -> dict:
    """Per record, the FDEM errors before (base model) and after (the confirmed model): a calibration
    record's at its cross-validation points (predicted without it), a held-out record's at its
    prediction points."""
    k = int(conf["confirmed"])
    out = {}
    for r in obs.records:
        s = obs.record_slice(r)
        t, y = obs.time[s], obs.values[s]
        before, after = real["cv"].get(0, {}).get(r), real["cv"].get(k, {}).get(r)
        out[r] = {"data": "calibration (cross-validated)",
                  "before": None if before is None else replicate_curve_errors(t, before, y),
                  "after": None if after is None else replicate_curve_errors(t, after, y)}
    keys = ("rmse", "nrmse", "peak_error", "peak_rel_error", "time_to_peak_error", "replicates", "rmse_per_replicate",
            "predictive_coverage_90")
    for h, ev in held.items():
        out[h] = {"data": "heldout", **{w: {k2: ev[w][k2] for k2 in keys if k2 in ev[w]} for w in ("before", "after")}}
    return out


def cv_risk(errors: Mapping, shipped_step: int, level: float = 0.90) -> dict:
    """How often the shipped model predicts a record worse than the base model, read on the calibration
    records' real cross-validation runs (each predicted by a calibration without it, as a new record is):
    ``worse`` of ``records`` with the exact binomial ``level`` interval. This is the chance, for one new
    record, that the shipped prediction is worse than the base's: the walk confirms a lower error on
    average, which a per-record effect with a wide population spread can give while some records' own
    values lie in the tail. With the base kept nothing can be worse (``records`` 0)."""
    from scipy import stats

    pairs = [(e["before"]["rmse"], e["after"]["rmse"]) for e in errors.values()
             if str(e.get("data", "")).startswith("calibration") and e.get("before") and e.get("after")]
    if int(shipped_step) == 0 or not pairs:
        return {"worse": 0, "records": 0, "fraction": None, f"ci{round(100 * level)}": None,
                "note": "base model kept: its predictions are the base's"}
    k = int(sum(a > b for b, a in pairs))
    ci = stats.binomtest(k, len(pairs)).proportion_ci(level, method="exact")
    return {"worse": k, "records": len(pairs), "fraction": k / len(pairs),
            f"ci{round(100 * level)}": [float(ci.low), float(ci.high)],
            "note": "calibration records whose real cross-validated RMSE under the shipped model exceeds the base's"}


def _band_of(pred, runs, point_runs, variances: dict, fallback_S, seed, label):
    """A record's band at one step (:func:`enkf.diagnosis.band.run_band`); None where its runs failed."""
    if runs is None:
        return None
    S, dof = replicate_variance(point_runs)
    terms = dict(variances)
    if S is not None:
        terms["simulator"] = S
    elif fallback_S is not None:
        # one run per point: the calibration's measured S (the protocol's term for the record), not the runs'
        terms["simulator"] = np.diag(fallback_S.dense()).copy()
    band = run_band(pred.draws, pred.curve, runs, terms, rng=np.random.default_rng(seed_for(seed, "band", *label)),
                    level=0.90)
    return band, {"simulator_dof": dof, "simulator_from": "check replicates" if S is not None
                  else ("calibration's replicates" if fallback_S is not None else "none")}


#: The time over which the check's bands average the square of the cross-validated residuals into a
#: discrepancy (enkf.diagnosis.band.residual_discrepancy). Chosen on calibration records only, every
#: record's band from the other calibration records' residuals, over the folds of both re-run series:
#: the lowest mean interval score of 5, 11, 21, 41, 81 and 161 samples of 2 us (studies/band_discrepancy.py).
BAND_DISCREPANCY_WINDOW_S = 160e-6


def _window_samples(times: np.ndarray) -> int:
    dt = float(np.median(np.diff(times))) if times.size > 1 else BAND_DISCREPANCY_WINDOW_S
    return int(round(BAND_DISCREPANCY_WINDOW_S / dt)) | 1  # odd: centred on each time


def _cv_residuals(selection, real: Mapping, step: int, obs: Observations, noise: Mapping, simulator: Mapping,
                  model) -> dict:
    """``{record: (residual, counted)}`` of the calibration records with real runs at their cross-validation
    point of ``step``: the data less the runs' mean, and the variance the band's other terms give it there
    (parameters, with plugin_draws' per-record values; simulator ``S (1 + 1/K)``, the record's noise)."""
    out, st, seed = {}, selection.step(step), int(selection.settings.get("seed", 0))
    for r in obs.records:
        runs = real["cv"].get(step, {}).get(r)
        if runs is None:
            continue
        Y = np.array(runs, dtype=float, ndmin=2)
        draws = plugin_draws(model, st.spec, st.cv.folds[r], seed=seed)
        S, _ = replicate_variance([c[r] for c in real["cv"].values() if c.get(r) is not None])
        if S is None:
            S = np.diag(simulator[r].dense()) if r in simulator else np.zeros(Y.shape[1])
        counted = (np.var(draws - np.asarray(st.cv.folds[r]["prediction"].curve, float), axis=0)
                   + S * (1.0 + 1.0 / Y.shape[0]) + np.diag(noise[r].dense()))
        out[r] = (obs.values[obs.record_slice(r)] - Y.mean(axis=0), counted)
    return out


def _discrepancy_from(cv: Mapping, leave_out: str | None, window: int, fallback: np.ndarray):
    """``(D, source)``: the discrepancy of a band from the other records' residuals (:func:`_cv_residuals`),
    or the calibration's estimate where no other record has them or their grids differ."""
    use = [v for r, v in cv.items() if r != leave_out]
    if not use or len({v[0].size for v in use} | {fallback.size}) != 1:
        return fallback, "calibration's estimate"
    return (residual_discrepancy([v[0] for v in use], [v[1] for v in use], window),
            f"cross-validated residuals of {len(use)} calibration record(s)")


def predictive_bands(selection, real: Mapping, k: int, obs: Observations, heldout: Observations | None,
                     noise: Mapping, simulator: Mapping, discrepancy: Mapping[str, np.ndarray], model):
    """``({record: {"data", "before", "after"}}, frame)``: each record's 90 % predictive band of its curve
    under the base model (step 0) and the shipped one (step ``k``), centred on the mean of the real FDEM
    runs at its prediction point, with :func:`enkf.diagnosis.band.run_band`'s terms:

    (a) the posterior members x population draws through the emulator of the record (its design runs are
        simulations driven by its incident wave);
    (b) the simulator's variability, measured on the record's replicated check runs (pooled over the
        steps' points; with one run per point the protocol's ``simulator`` term);
    (c) the model discrepancy of that step's model, read off the calibration records' residuals against
        their real runs at their cross-validation points (each fitted without the record), less what
        (a) (its per-record values from the plug-in population), (b) and (d) give them, averaged over
        BAND_DISCREPANCY_WINDOW_S
        (:func:`enkf.diagnosis.band.residual_discrepancy`): large where the model errs, none where it
        does not, and smaller after the loop where the shipped model errs less. A calibration record's
        band takes the other calibration records' residuals only. Without another record's residuals,
        the calibration's estimate (``discrepancy``, their mean; fitted to the base model);
    (d) the instrument noise: the calibration records' pooled level (mean of their noise variances).

    A held-out record's band takes nothing computed from its response: not its curve, nor its own
    pre-trigger noise (``noise[h]``, which the selection gave it), nor its onset or its modulus. Its
    band is fixed before its curve is read; the curve only scores it (``frame`` holds the bands, SI).
    A calibration record's curve enters its band only through the posterior (a) and the pooled noise (d).

    ``model``: the emulated forward model. Each band is scored against the design box's: the same
    band with the posterior's draws in (a) replaced by draws uniform over the emulator's design box
    (:func:`enkf.diagnosis.box_draws`: the base posterior's neighbourhood, clipped to the prior box, and
    the candidates' ranges; the emulator holds nowhere else, so the prior box itself cannot be drawn).
    ``interval_score_over_box`` near 1: knowing the parameters better than that box does not improve the
    prediction; below :data:`enkf.diagnosis.band.SCORE_RATIO_BAR`, it does."""
    calib = list(obs.records)
    fallback = _mean_block([np.asarray(discrepancy[r], float) for r in calib])
    pooled_noise = _mean_block([np.diag(noise[r].dense()) for r in calib])
    window = _window_samples(obs.time[obs.record_slice(calib[0])])
    cv = {step: _cv_residuals(selection, real, step, obs, noise, simulator, model) for step in {0, k}}
    seed = int(selection.settings.get("seed", 0))
    jobs = [(r, "cv", "calibration (cross-validated; its band's discrepancy from the other calibration records)",
             obs) for r in calib]
    if heldout is not None:
        jobs += [(h, "heldout", "heldout", heldout) for h in heldout.records]
    out, frames = {}, []
    for rec, role, data, src in jobs:
        pts = [c[rec] for c in real[role].values() if c.get(rec) is not None]
        entry = {"data": data}
        # every band is built before the record's curve is read below
        bands = {}
        for when, step in (("before", 0), ("after", k)):
            st = selection.step(step)
            pred = st.heldout[rec] if role == "heldout" else st.cv.folds[rec]["prediction"]
            D, source = _discrepancy_from(cv[step], rec if role == "cv" else None, window, fallback)
            terms = {"discrepancy": D, "noise": pooled_noise}
            got = _band_of(pred, real[role].get(step, {}).get(rec), pts, terms, simulator.get(rec), seed, (rec, step))
            box = None if got is None else _band_of(
                replace(pred, draws=box_draws(model, st.spec, rec, pred.draws.shape[0], seed=seed)),
                real[role][step][rec], pts, terms, simulator.get(rec), seed, (rec, step, "box"))[0]
            bands[when] = None if got is None else (got[0], {**got[1], "discrepancy_from": source}, box)
        s = src.record_slice(rec)
        t, y = src.time[s], src.values[s]
        for when, got in bands.items():
            if got is None:
                entry[when] = None
                continue
            band, info, box = got
            entry[when] = {**band.summary(y), **info}
            if box is not None:
                entry[when]["box_interval_score_Pa"] = box.score(y)
                entry[when]["interval_score_over_box"] = band.score(y) / box.score(y)
            frames.append(pd.DataFrame({"record": rec, "data": role, "model": when, "time_s": t,
                                        "centre_Pa": band.centre, "lower_Pa": band.lower, "upper_Pa": band.upper}))
        out[rec] = entry
    cols = ["record", "data", "model", "time_s", "centre_Pa", "lower_Pa", "upper_Pa"]
    return out, (pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols))


def fit_sources(selection) -> dict:
    """``{"base_posterior", "base_estimates", "fits"}`` of report.json: where the base model's posterior comes
    from (``"workflow"``: posterior.csv with summary.json's estimates; ``"emulator"``: an ES-MDA on the
    emulator) and the source of every other fit of the protocol."""
    base = selection.steps[0].final
    src = base.source
    out = {"base_posterior": src,
           "base_estimates": {n: {k: v[k] for k in ("mean", "q05", "q95") if k in v} for n, v in base.posterior().items()}}
    if src == "workflow":
        out["base_posterior_file"] = base.info.get("file")
        out["base_posterior_method"] = base.info.get("method")
        base_text = (f"the workflow's posterior ({base.info.get('file')}, posterior_method "
                     f"{base.info.get('method')}; {base.info.get('draws_used')} of its {base.info.get('draws')} draws "
                     "predict): it is reported, predicts the held-out records and is what the effects are compared "
                     "against; not re-fitted on the emulator")
    else:
        base_text = "ES-MDA on the emulator of the FDEM design, on every calibration record"
    out["fits"] = {"base": base_text,
                   "base_cross_validation": "ES-MDA on the emulator, each calibration record left out in turn (the "
                                            "workflow's posterior holds every calibration record)",
                   "added_effects": "ES-MDA on the emulator (cross-validation and the calibration on every "
                                    "calibration record of each model with an added effect)",
                   "check": "real FDEM runs at the cross-validation points and the held-out prediction points"}
    return out


def identification(selection, k: int) -> list[dict]:
    """Per effect kept (the rounds that chose the shipped step ``k``'s effects), its group: the candidates
    of its round that the calibration records do not tell apart from it
    (:func:`enkf.diagnosis.identification_group`), with the evidence and a sentence. For an alternative
    shipped, its own group in its round. This is the emulator's evidence; :func:`assemble` adds, to each
    kept effect's group, the real FDEM runs' comparison of that effect with the other models of its round
    that were run (its choice and alternatives, :func:`real_group_text`)."""
    step = selection.step(k)
    chain = step.index if step.alternative_to is None else step.alternative_to - 1
    groups = [rnd["group"] for rnd in selection.rounds[:chain] if rnd.get("group")]
    if step.alternative_to is not None:
        groups.append(selection.rounds[step.alternative_to - 1]["alternative_groups"][step.spec.effect_names[-1]])
    return [{**g, "text": group_text(g)} for g in groups]


def real_group_text(name: str, evidence: Sequence[Mapping]) -> str:
    """One sentence on the kept effect against the other models of its round run on real FDEM."""
    told = [f"{e['effect']} (z = {e['z']:.2f})" for e in evidence if e["told_apart"]]
    better = [f"{e['effect']} (z = {-e['z']:.2f})" for e in evidence if e.get("other_better")]
    alike = [f"{e['effect']} (z = {e['z']:.2f})" for e in evidence if not (e["told_apart"] or e.get("other_better"))]
    parts = []
    if told:
        parts.append(f"on real FDEM runs {name} predicts better than {', '.join(told)}")
    if better:
        parts.append(f"on real FDEM runs {', '.join(better)} predict{'s' if len(better) == 1 else ''} better "
                     f"than {name}, which the walk kept as its round's first confirmed proposal")
    if alike:
        parts.append(f"real FDEM runs do not tell it apart from {', '.join(alike)}")
    return "; ".join(parts) + f" (one-sided, Bonferroni over {len(evidence)})"


def base_posterior_mismatches(summary: Mapping, report: Mapping) -> list[str]:
    """What keeps a run's diagnosis from having the workflow's base posterior: ``report`` (diagnosis/report.json)
    not naming ``"workflow"`` with summary.json's ``posterior_method``, or a base estimate (mean, q05, q95 of
    each base parameter, in ``base_estimates`` and in the selection's step 0) that differs from ``summary``'s
    (summary.json) as printed. Empty: one run, one base posterior."""
    out = []
    if report.get("base_posterior") != "workflow":
        out.append(f"base_posterior is {report.get('base_posterior')!r}, not 'workflow'")
    if report.get("base_posterior_method") != summary.get("posterior_method"):
        out.append(f"base_posterior_method {report.get('base_posterior_method')!r} against summary.json's "
                   f"{summary.get('posterior_method')!r}")
    steps = (report.get("selection") or {}).get("steps") or [{}]
    for where, est in (("base_estimates", report.get("base_estimates") or {}),
                       ("selection step 0", steps[0].get("posterior") or {})):
        for n, v in summary["posterior"].items():
            for k in ("mean", "q05", "q95"):
                got = (est.get(n) or {}).get(k)
                if got != v[k]:
                    out.append(f"{where}: {n} {k} {got!r} against summary.json's {v[k]!r}")
    return out


def assemble(selection, rows: Sequence[Mapping], runs: Sequence, model: EmulatedSHPB, obs: Observations,
             heldout: Observations | None, noise: Mapping, simulator: Mapping,
             discrepancy: Mapping[str, np.ndarray],
             refit: Mapping | None = None) -> tuple[dict, dict, dict, pd.DataFrame]:
    """``(report, check, curves, bands)`` of the loop: the confirmation walk on the real cross-validation
    runs, then (read here for the first time) the held-out records' errors before and after on the real
    held-out runs, and every record's predictive band (:func:`predictive_bands`; ``bands`` the csv beside
    check.json). ``runs[i]``: the FDEM curve (DataFrame, or None if it failed) of ``rows[i]``;
    ``discrepancy``: :func:`calibration_discrepancy` of the calibration records; ``refit``: diagnosis/refit.json
    where the shipped model was re-fitted, whose identification gate can ship an earlier step of the walk
    (:func:`calibration.walk.gated`)."""
    real = real_curves(rows, runs, model)
    y = {r: obs.values[obs.record_slice(r)] for r in obs.records}
    walked = walk(selection, real, obs, noise, simulator)
    conf = gated(walked["conf"], selection, refit)
    walk_noise, walk_sim, weights = walked["noise"], walked["simulator"], walked["weights"]
    k = int(conf["confirmed"])
    held = {}
    if heldout is not None and heldout.records:
        hv = {h: heldout.values[heldout.record_slice(h)] for h in heldout.records}
        ht = {h: heldout.time[heldout.record_slice(h)] for h in heldout.records}
        missing = [h for h in heldout.records for st in (0, k) if real["heldout"].get(st, {}).get(h) is None]
        if missing:
            raise RuntimeError(f"the held-out FDEM runs of {sorted(set(missing))} failed; no held-out error to report")
        held = heldout_evaluation(selection, hv, ht, final=k,
                                  real={"before": real["heldout"][0], "after": real["heldout"][k]})
    bands, band_frame = predictive_bands(selection, real, k, obs, heldout if held else None, noise, simulator,
                                         discrepancy, model)
    for h in held:
        for w in ("before", "after"):
            held[h][w].update({key: bands[h][w][key] for key in ("predictive_coverage_90", "interval_score_over_box")
                               if key in bands[h][w]})
    shipped = selection.step(k)
    if k == 0:
        verdict = "base_kept"
        why = (conf["text"] if (conf.get("identification_gate") or {}).get("dropped") else
               "no addition survived: " + (conf["steps"][-1]["text"] if conf["steps"] else selection.why))
    else:
        verdict = "confirmed"
        why = conf["text"]
    errors = _errors_table(selection, conf, real, obs, held)
    risk = cv_risk(errors, k)
    ident, chain = identification(selection, k), chain_of(conf)
    # each kept effect against the other models of its round run on real FDEM (one group per kept step)
    for i, st in enumerate(chain[1:chain.index(k) + 1]):
        real_ev = real_group(selection, real["cv"], y, walk_noise, st, simulator=walk_sim, weights=weights)
        if i < len(ident) and real_ev:
            ident[i] = {**ident[i], "real_evidence": real_ev,
                        "text": ident[i]["text"] + "; " + real_group_text(ident[i]["chosen"], real_ev)}
    report = {"protocol": "frozen (docs/closing-the-loop.md): effects chosen by cross-validation within the "
                          "calibration records on the emulator, confirmed on real FDEM runs at the "
                          "cross-validation points, the held-out records read last",
              "verdict": verdict, "why": why, **fit_sources(selection), "calib_records": list(obs.records),
              "heldout_records": [] if heldout is None else list(heldout.records),
              "added": list(shipped.spec.effect_names), "identification": ident, "shipped_step": k,
              "selection": selection.to_dict(), "confirmation": conf, "heldout": held,
              "errors_per_record": errors, "cv_risk_worse_than_base": risk}
    check = {"added": list(shipped.spec.effect_names), "identification": ident, "verdict": verdict,
             "fdem_confirmation": {"status": verdict, "text": why, "steps": conf["steps"],
                                   "real_cv_rmse_Pa": conf["real_cv_rmse"],
                                   "real_cv_weighted_error": conf["real_cv_loss"]},
             "errors_per_record": errors, "heldout": held, "cv_risk_worse_than_base": risk,
             "covariate_trends": peak_error_trends(errors, obs.meta.get("record_info", {}), list(obs.records)),
             "predictive_band": {"level": 0.90, "records": bands, "file": "check_band.csv",
                                 "terms": "posterior members x population draws on the emulator of the record, "
                                          "the simulator's variability from the check's replicates, the model "
                                          "discrepancy of each step's model from the calibration records' "
                                          "cross-validated residuals on real runs, and the instrument noise pooled "
                                          "over the calibration records; centred on the mean of the real FDEM "
                                          "runs at the prediction point",
                                 "note": "held-out records: nothing from their response enters their band; "
                                         "calibration records: their discrepancy from the other calibration "
                                         "records, their own curve only through the posterior and the pooled "
                                         "noise"},
             "note": "real FDEM runs: calibration records at their cross-validation points (each predicted by a "
                     "calibration without it), held-out records at their prediction points; before = base "
                     "model, after = the confirmed model"}
    curves = {}
    for r in obs.records:
        s = obs.record_slice(r)
        curves[r] = {"data": "calibration (cross-validated)", "time": obs.time[s], "obs": obs.values[s],
                     "observed": obs.as_observed(r), "before": real["cv"].get(0, {}).get(r),
                     "after": real["cv"].get(k, {}).get(r)}
    for h in held:
        s = heldout.record_slice(h)
        curves[h] = {"data": "heldout", "time": heldout.time[s], "obs": heldout.values[s],
                     "observed": heldout.as_observed(h), "before": real["heldout"][0][h],
                     "after": real["heldout"][k][h]}
    return report, check, curves, band_frame


# --------------------------------------------------------------------------------------------------
# leave one record out
# --------------------------------------------------------------------------------------------------
def loro_table(folds: Mapping[str, Mapping], record_info: Mapping[str, Mapping] | None = None) -> dict:
    """Per fold (``{fold: report.json}``) and in total: the effects kept and their estimates, the held-out
    record's FDEM errors before and after (RMSE, peak, time to peak) and its 90 % predictive band's coverage
    (:func:`predictive_bands`), and the mean change with its spread across folds."""
    rows = []
    for fold, rep in folds.items():
        for h, ev in (rep.get("heldout") or {}).items():
            step = step_summary(rep["selection"], rep["shipped_step"])
            shared = {n: v for n, v in (step.get("posterior") or {}).items()}
            row = {"fold": fold, "heldout": h, "calib_records": rep["calib_records"], "effects": rep["added"],
                   # per kept effect, the group the fold's calibration records could not split (None: a fold
                   # run before the report carried it)
                   "groups": ([g["effects"] for g in rep["identification"]] if "identification" in rep else None),
                   "verdict": rep["verdict"], "estimates": shared,
                   "heldout_values": ev["after"].get("point"), "heldout_intervals": ev["after"].get("intervals")}
            for w in ("before", "after"):
                for key in ("rmse", "peak_error", "peak_rel_error", "time_to_peak_error", "predictive_coverage_90",
                            "interval_score_over_box"):
                    row[f"{key}_{w}"] = ev[w].get(key)
            row["rmse_change"] = ev["after"]["rmse"] - ev["before"]["rmse"]
            info = (record_info or {}).get(h, {})
            row["strain_rate_per_s"] = info.get("strain_rate_at_peak_per_s")
            rows.append(row)
    ch = np.array([r["rmse_change"] for r in rows], float)
    n = ch.size
    risks = [cv_risk(rep.get("errors_per_record") or {}, int(rep["shipped_step"])) for rep in folds.values()]
    totals = {"folds": n, "mean_rmse_before": float(np.mean([r["rmse_before"] for r in rows])) if n else None,
              "mean_rmse_after": float(np.mean([r["rmse_after"] for r in rows])) if n else None,
              "mean_rmse_change": float(ch.mean()) if n else None,
              "sd_rmse_change": float(ch.std(ddof=1)) if n > 1 else None,
              "se_mean_rmse_change": float(ch.std(ddof=1) / math.sqrt(n)) if n > 1 else None,
              "folds_worse": int(np.sum(ch > 0)), "folds_better": int(np.sum(ch < 0)),
              "effects_kept": {e: sum(e in r["effects"] for r in rows) for e in sorted({e for r in rows for e in r["effects"]})},
              "cv_risk_worse_than_base": pooled_risk(risks, n)}
    for w in ("before", "after"):
        # the held-out records' 90 % band coverage (None for folds run before the check reported it)
        cov = [r[f"predictive_coverage_90_{w}"] for r in rows if r.get(f"predictive_coverage_90_{w}") is not None]
        totals[f"mean_predictive_coverage_90_{w}"] = float(np.mean(cov)) if cov else None
        totals[f"folds_with_predictive_coverage_{w}"] = len(cov)
        # the bands' interval score over the design box's (None for folds run before the check scored it)
        ratio = [r[f"interval_score_over_box_{w}"] for r in rows if r.get(f"interval_score_over_box_{w}") is not None]
        totals[f"mean_interval_score_over_box_{w}"] = float(np.mean(ratio)) if ratio else None
    return {"rows": rows, "totals": totals}


def pooled_risk(risks: Sequence[Mapping], folds: int, level: float = 0.90) -> dict:
    """The folds' :func:`cv_risk` pooled: calibration records predicted worse than the base over all folds
    that shipped an addition, and what that rate says of a series: the chance that none of ``folds``
    held-out records is worse, ``(1 - p)^folds``, at the rate and at its interval's ends. The folds reuse
    records (each record is a calibration record in all folds but its own), so the pooled count is not
    of independent trials: its interval is a guide, not a test."""
    from scipy import stats

    k, m = sum(r["worse"] for r in risks), sum(r["records"] for r in risks)
    if m == 0:
        return {"worse": 0, "records": 0, "fraction": None, "p_no_fold_worse": None,
                "note": "no fold shipped an addition"}
    ci = stats.binomtest(k, m).proportion_ci(level, method="exact")
    p = k / m
    return {"worse": k, "records": m, "fraction": p, f"ci{round(100 * level)}": [float(ci.low), float(ci.high)],
            "p_no_fold_worse": (1.0 - p) ** folds,
            f"p_no_fold_worse_ci{round(100 * level)}": [(1.0 - float(ci.high)) ** folds, (1.0 - float(ci.low)) ** folds],
            "note": ("calibration records predicted worse than the base on real cross-validation runs, over the folds "
                     "that shipped an addition (records reused across folds: not independent trials)")}

