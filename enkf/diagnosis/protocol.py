"""The frozen protocol of closing the loop (issue 32): choose effects by cross-validation within the
calibration records, confirm them on the real simulator, and only then read the held-out records.

Order, fixed before anything is fitted (every step generic: a :class:`~.crossval.ForwardModel`, records,
candidates; nothing about FDEM or SHPB):

1. The records are split into calibration records and held-out records. :func:`select_effects` reads
   the observations of the calibration records only (it copies them at the start and never indexes
   the mapping again), so a held-out record's curve cannot reach a choice.
2. Greedy forward selection (:func:`select_effects`): starting from the base model M0, each round
   cross-validates (:func:`~.crossval.cross_validate`) the current model plus each remaining candidate
   over the calibration records, and adds the candidate whose cross-validated squared error falls by
   more than its own uncertainty (:func:`~.crossval.compare_cv`), one-sided, Holm-corrected over the K
   candidates in play that round (every remaining one, tried or not: when a score-test ranking picked
   which to try, it had looked at all of them). The score test (``max_trials``) only orders the
   candidates; it is not a gate, and by default every remaining candidate is tried: the score test is
   linearised and in-sample, and on the stand-in it ranks a per-record gain (which fits every
   calibration record's peak and predicts none it has not seen) above a rate law (which predicts
   them); see tests/test_protocol_selection.py. The result is a nested sequence M0 < M1 < ... (:class:`ModelStep`),
   each with its cross-validation (per calibration record the parameter point its prediction was made
   at, for a real-simulator check there), its calibration on all calibration records (for M0 it may be
   given, ``base_fit``: a posterior sampled elsewhere, e.g. on the real simulator), the populations
   of its per-record parameters, and the held-out records' prediction points and bands.
3. :func:`confirm_additions`: given the real simulator's curves at those cross-validation points,
   walk M1, M2, ...: confirm M_r over the last confirmed model when its real cross-validated squared
   error (each time weighted by :func:`walk_weights` where given) is lower by more than the uncertainty
   (noise and the simulator's variability; one-sided,
   level ``alpha / K`` with K of the round that chose it); the first refuted addition is dropped, and
   its round's alternatives (``alternatives``: the round's next proposals by the emulated gain, each the
   same model with that effect instead) are tried in order at the same level, so that one wrong
   proposal of the emulator does not end the walk; the walk stops at the first refuted step after its
   alternatives (what followed was chosen given it). Each candidate walked is tested at ``alpha / K``:
   by Bonferroni over the round's K candidates, every one of them tried keeps the round's family-wise
   level. The model shipped is never worse on real cross-validation than the base model (in the error
   compared).
4. :func:`heldout_evaluation`: the held-out records' observed curves, read here for the first time:
   RMSE, peak and time-to-peak errors of the base and of the final model, and the coverage of the
   predictive band (posterior members x population draws).

:func:`leave_one_record_out` runs 1-4 once per record of a series (that record held out) and tabulates
the folds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..diagnostics import jsonable
from ..predictive import predictive_band
from .acceptance import replicate_curve_errors
from .crossval import (CVResult, Fit, ForwardModel, ModelSpec, Prediction, RecordErrors, calibrate, compare_cv,
                       compare_replicated, cross_validate, fit_populations, holm, predict_record, scope_of)
from .identification import identification_group
from .population import Population, record_name
from .ranking import finite_difference_sensitivity, rank_candidates
from .structure import structure_tests
from .weights import Weighted, walk_weights

__all__ = ["ModelStep", "Selection", "confirm_additions", "heldout_evaluation", "leave_one_record_out",
           "real_identification", "replicated", "select_effects", "walk_weights"]


@dataclass
class ModelStep:
    """One model of the nested sequence: ``spec``, its cross-validation ``cv``, its calibration on all
    calibration records ``final`` with the ``populations`` of its per-record parameters, the held-out
    records' predictions ``heldout``, and ``in_play``: the number of candidates of the round that chose
    it (0 for the base model)."""

    index: int
    spec: ModelSpec
    cv: CVResult
    final: Fit
    populations: dict[str, Population]
    heldout: dict[str, Prediction]
    in_play: int = 0
    structure: dict = field(default_factory=dict)
    alternative_to: int | None = None

    def check_points(self) -> dict:
        """``{"cv": {record: point}, "heldout": {record: point}}``: where a real-simulator check runs
        (names: shared ones and the record's own copies ``<param>@<record>``)."""
        return {"cv": self.cv.points(), "heldout": {h: dict(p.point) for h, p in self.heldout.items()}}

    def summary(self) -> dict:
        return {"index": self.index, "model": self.spec.label(), "effects": self.spec.effect_names,
                "in_play": self.in_play, "cv": self.cv.summary(), "posterior": self.final.posterior(),
                "posterior_source": self.final.source, "cv_source": "emulator",
                "populations": {p: pop.to_dict() for p, pop in self.populations.items()},
                "heldout": {h: p.summary() for h, p in self.heldout.items()},
                "structure": {k: self.structure.get(k) for k in ("passed", "failed", "chi2")},
                **({} if self.alternative_to is None else {"alternative_to": self.alternative_to})}


@dataclass
class Selection:
    """What :func:`select_effects` returns: the nested ``steps`` (M0 first), the ``rounds`` (per round the
    candidates tried, their numbers and a sentence each), ``why`` the selection stopped, and the split."""

    steps: list[ModelStep]
    rounds: list[dict]
    why: str
    calib_records: list[str]
    heldout_records: list[str]
    settings: dict
    alternatives: list[ModelStep] = field(default_factory=list)

    @property
    def last(self) -> ModelStep:
        return self.steps[-1]

    def step(self, index: int) -> ModelStep:
        """The model of step ``index``: one of the nested ``steps`` or an alternative."""
        for st in (*self.steps, *self.alternatives):
            if st.index == int(index):
                return st
        raise KeyError(f"no step {index}")

    def alternatives_to(self, index: int) -> list[ModelStep]:
        """The alternatives of the round that chose step ``index``, in the order the walk tries them."""
        return [a for a in self.alternatives if a.alternative_to == int(index)]

    def to_dict(self) -> dict:
        return jsonable({"calib_records": self.calib_records, "heldout_records": self.heldout_records,
                         "steps": [s.summary() for s in self.steps], "rounds": self.rounds, "why": self.why,
                         "settings": self.settings, "alternatives": [a.summary() for a in self.alternatives]})


def step_summary(selection: Mapping, index: int) -> dict:
    """Step ``index`` of a selection's ``to_dict()`` (a report's ``selection``): a nested step (its
    position where it carries no index) or an alternative the walk confirmed in its place (whose index
    follows the nested steps')."""
    steps = [(st.get("index", i), st) for i, st in enumerate(selection["steps"])]
    for i, st in (*steps, *((a["index"], a) for a in selection.get("alternatives", []))):
        if int(i) == int(index):
            return st
    raise KeyError(f"no step {index} in the selection (steps and alternatives)")


def _final_step(model, spec: ModelSpec, cv: CVResult, index: int, in_play: int, calib: list, heldout: list,
                obs: Mapping, errors: RecordErrors, kw: dict, fit: Fit | None = None) -> ModelStep:
    """Calibrate ``spec`` on all calibration records (or take ``fit``, a posterior given on them) and
    predict the held-out records from it."""
    if fit is None:
        fit = calibrate(model, spec.names(calib), calib, obs, errors, seed=kw["seed"], n_members=kw["n_members"],
                        esmda_steps=kw["esmda_steps"])
    elif list(fit.names) != spec.names(calib) or list(fit.records) != list(calib):
        raise ValueError(f"the given posterior is of {list(fit.names)} on {list(fit.records)}; the step needs "
                         f"{spec.names(calib)} on {list(calib)}")
    pops = fit_populations(model, spec, fit, scales=kw["scales"], **(kw["population_kw"] or {}))
    held = {h: predict_record(model, spec, fit, h, pops, seed=kw["seed"], band_level=kw["band_level"])
            for h in heldout}
    y = np.concatenate([obs[r] for r in calib])
    mean = fit.mean()
    sim = model.forward(fit.names, calib)(np.array([mean[n] for n in fit.names]))[0]
    w = errors.calibration_error(calib, fit.names).whiten(y - sim)
    return ModelStep(index, spec, cv, fit, pops, held, in_play, structure_tests(w, n_params=len(fit.names)))


def _ranked(model, spec: ModelSpec, step: ModelStep, remaining: list, calib: list, obs: Mapping,
            errors: RecordErrors, scopes, fd_fraction: float) -> list:
    """The remaining candidates ordered by the score test at the current calibration (an order, not a gate)."""
    names = spec.names(calib)
    mean = step.final.mean()
    cols, x0_c, all_c = {}, [], []
    for c in remaining:
        per = scope_of(c, scopes) == "per_record"
        pn = [record_name(p, r) for r in calib for p in c.param_names] if per else list(c.param_names)
        nulls = list(c.nulls) * (len(calib) if per else 1)
        cols[c.name] = (len(names) + len(all_c), len(pn))
        all_c += pn
        x0_c += nulls
    all_names = names + all_c
    x0 = np.array([mean[n] for n in names] + x0_c)
    lo, hi = model.box(all_names)
    f = model.forward(all_names, calib)
    S = finite_difference_sensitivity(f, x0, fd_fraction * (np.asarray(hi) - np.asarray(lo)), lower=lo, upper=hi)
    err = errors.calibration_error(calib, names)
    Sw = err.whiten(S)
    w = err.whiten(np.concatenate([obs[r] for r in calib]) - f(x0)[0])
    table = rank_candidates(w, Sw[:, :len(names)], {k: Sw[:, a:a + n] for k, (a, n) in cols.items()},
                            alpha=1.0, max_collinearity=1.0)
    by_name = {c.name: c for c in remaining}
    return [by_name[e] for e in table["effect"]]


def _trial_text(name: str, cur: CVResult, new: CVResult, cmp: dict, level: float, K: int, ok: bool,
                gate: str = "significance") -> str:
    verdict = (("proposed for the real-simulator check" if ok else "not proposed (the error does not fall)")
               if gate == "improvement" else ("accepted" if ok else "not accepted"))
    return (f"{name}: cross-validated RMSE {cur.rmse:.4g} -> {new.rmse:.4g}; the squared-error sum falls by "
            f"{cmp['delta']:.4g} with sd {cmp['sd']:.4g} (z = {cmp['z']:.2f}, one-sided p = {cmp['p']:.3g}, "
            f"Holm level {level:.3g} over {K} candidate(s)): " + verdict)


def _round(model, state: dict, remaining: list, calib: list, obs: Mapping, errors: RecordErrors, kw: dict) -> dict:
    """One round of the greedy forward selection: cross-validate the candidates, test, pick the best."""
    spec, cur = state["spec"], state["cv"]
    if kw["max_trials"] is not None:
        order = _ranked(model, spec, state["step"], remaining, calib, obs, errors, kw["scopes"], kw["fd_fraction"])
        tried = order[:kw["max_trials"]]
    else:
        tried = list(remaining)
    K = len(remaining)
    trials = []
    for c in tried:
        cv = cross_validate(model, spec.add(c, kw["scopes"]), calib, obs, errors, **_cv_kw(kw))
        spreads = ({"spread_current": {j: cur.spread(j) for j in calib},
                    "spread_candidate": {j: cv.spread(j) for j in calib}} if kw["prediction_spread"] else {})
        cmp = compare_cv(obs, {j: cur.curve(j) for j in calib}, {j: cv.curve(j) for j in calib}, errors, **spreads,
                         names_current=cur.spec.names(calib), names_candidate=cv.spec.names(calib))
        trials.append({"candidate": c, "cv": cv, "cmp": cmp})
    accepted, levels = holm([t["cmp"]["p"] for t in trials] + [1.0] * (K - len(tried)), kw["alpha"])
    if kw["gate"] == "improvement":
        # the emulator only proposes: a candidate goes on when its cross-validated squared error falls at
        # all; the real-simulator walk (confirm_additions) is then the test, Holm-level per round
        accepted = [t["cmp"]["delta"] > 0 for t in trials]
    rows = []
    for t, ok, lev in zip(trials, accepted, levels):
        t["accepted"] = ok
        rows.append({"effect": t["candidate"].name, "cv_rmse": t["cv"].rmse, "cv_lpd": t["cv"].lpd,
                     "delta_sq_error": t["cmp"]["delta"], "sd": t["cmp"]["sd"], "z": t["cmp"]["z"],
                     "p": t["cmp"]["p"], "level": lev, "accepted": bool(ok),
                     "text": _trial_text(t["candidate"].name, cur, t["cv"], t["cmp"], lev, K, ok,
                                         kw["gate"])})
    # the proposals, the largest gain first: the first is the round's choice, the next ones its
    # alternatives (tried on the real simulator if the choice is refuted)
    passing = sorted((t for t in trials if t["accepted"]), key=lambda t: -t["cmp"]["delta"])
    best = passing[0] if passing else None
    alts = passing[1:1 + int(kw["alternatives"])]

    def group_of(t):
        return identification_group(t, trials, obs, errors, level=kw["alpha"],
                                    not_tried=[c.name for c in remaining if c not in tried],
                                    spreads=kw["prediction_spread"])

    return {"current": spec.label(), "current_cv_rmse": cur.rmse, "in_play": K,
            "tried": [c.name for c in tried], "ranked_by_score_test": kw["max_trials"] is not None,
            "trials": rows, "chosen": best["candidate"].name if best else None,
            "group": group_of(best) if best else None,
            "alternatives": [t["candidate"].name for t in alts],
            "alternative_groups": {t["candidate"].name: group_of(t) for t in alts}, "_best": best, "_alts": alts}


def _cv_kw(kw: dict) -> dict:
    return {k: kw[k] for k in ("seed", "n_members", "esmda_steps", "scales", "band_level", "population_kw")}


def select_effects(model: ForwardModel, *, base_names: Sequence[str], candidates: Sequence,
                   calib_records: Sequence[str], obs: Mapping[str, np.ndarray], errors: RecordErrors,
                   heldout_records: Sequence[str] = (), scopes: Mapping[str, str] | None = None,
                   max_additions: int = 2, alpha: float = 0.05, seed: int = 0, n_members: int = 80,
                   esmda_steps: int = 4, scales: Mapping[str, str] | None = None, band_level: float = 0.90,
                   population_kw: Mapping | None = None, max_trials: int | None = None,
                   fd_fraction: float = 1e-3, prediction_spread: bool = False,
                   gate: str = "significance", base_fit: Fit | None = None, alternatives: int = 0) -> Selection:
    """Greedy forward selection of effects by cross-validation within the calibration records (module
    docstring, step 2).

    model : :class:`~.crossval.ForwardModel` covering every record (calibration and held-out).
    candidates : effects offered (``name``, ``param_names``, ``nulls``; ``scope`` or ``scopes[name]``:
        ``per_record`` or ``shared``, default shared).
    obs : observations; only ``obs[r]`` for ``r`` in ``calib_records`` is read.
    errors : :class:`~.crossval.RecordErrors` for every record (noise, time-correlated model error,
        simulator variability).
    alpha : family-wise one-sided level per round (Holm over the candidates in play).
    max_trials : None tries every remaining candidate; a number tries that many, ordered by the score
        test (:func:`~.ranking.rank_candidates`) at the current calibration.
    scales : per per-record parameter, ``"linear"`` or ``"log"`` (:func:`~.population.fit_population`);
    population_kw : further arguments of :func:`~.population.fit_population` (``method``,
        ``floor_fraction``, ``min_records``, ``predictive``).
    prediction_spread : add each cross-validated prediction's own calibration spread to the uncertainty
        of the difference (:mod:`.crossval`; more cautious, less power).
    gate : ``"significance"`` (default): a candidate is added when its gain passes the Holm-corrected
        test on the forward model given; ``"improvement"``: when its cross-validated squared error falls
        at all, the best one first. Use ``"improvement"`` when the forward model is an emulator too coarse
        to resolve the gains (its error dominates the difference's sd) and every addition is then
        confirmed on the real simulator (:func:`confirm_additions`), which carries the test.
    base_fit : the base model's posterior on all calibration records, given (:func:`~.crossval.given_fit`:
        e.g. the workflow's, sampled on the real simulator): step 0 reports it and predicts the held-out
        records with its draws, and no calibration of the base on all records is run here. The fits it
        cannot provide stay on ``model``: the base's cross-validation (each calibration record left
        out in turn) and every model with an added effect. None: the base is calibrated on ``model``.
    alternatives : per round, how many of the next proposals (by the gain, after the chosen one) are kept
        as alternatives: the round's model with that effect instead (:attr:`Selection.alternatives`,
        numbered after the nested steps), which :func:`confirm_additions` tries on the real simulator,
        in order, when the round's choice is refuted.
    """
    if gate not in ("significance", "improvement"):
        raise ValueError(f"gate must be 'significance' or 'improvement', got {gate!r}")
    calib, heldout = list(calib_records), list(heldout_records)
    if set(calib) & set(heldout):
        raise ValueError(f"records both calibration and held-out: {sorted(set(calib) & set(heldout))}")
    cal_obs = {r: np.array(obs[r], dtype=float) for r in calib}  # the only read of the observations
    kw = {"seed": seed, "n_members": n_members, "esmda_steps": esmda_steps, "scales": scales,
          "band_level": band_level, "population_kw": population_kw, "max_trials": max_trials, "alpha": alpha,
          "scopes": scopes, "fd_fraction": fd_fraction, "prediction_spread": prediction_spread, "gate": gate,
          "alternatives": int(alternatives)}
    spec = ModelSpec.of(base_names)
    cv = cross_validate(model, spec, calib, cal_obs, errors, **_cv_kw(kw))
    steps = [_final_step(model, spec, cv, 0, 0, calib, heldout, cal_obs, errors, kw, fit=base_fit)]
    remaining, rounds, pending = list(candidates), [], []
    why = f"the maximum of {max_additions} addition(s) was reached"
    for _ in range(max_additions):
        if not remaining:
            why = "no candidate is left"
            break
        state = {"spec": spec, "cv": cv, "step": steps[-1]}
        rnd = _round(model, state, remaining, calib, cal_obs, errors, kw)
        best, alts = rnd.pop("_best"), rnd.pop("_alts")
        rounds.append(rnd)
        if best is None:
            why = (f"no candidate lowers the cross-validated error of {spec.label()}" if gate == "improvement" else
                   f"no candidate lowers the cross-validated error of {spec.label()} by more than its "
                   f"uncertainty (one-sided, family-wise {alpha:g} over {rnd['in_play']} candidate(s))")
            rnd["text"] = why
            break
        c = best["candidate"]
        pending += [(len(steps), spec, t, rnd["in_play"]) for t in alts]
        spec, cv = spec.add(c, scopes), best["cv"]
        remaining = [r for r in remaining if r.name != c.name]
        steps.append(_final_step(model, spec, cv, len(steps), rnd["in_play"], calib, heldout, cal_obs, errors, kw))
        rnd["text"] = next(t["text"] for t in rnd["trials"] if t["effect"] == c.name)
    alt_steps = []
    for i, (of, before, t, in_play) in enumerate(pending):
        st = _final_step(model, before.add(t["candidate"], scopes), t["cv"], len(steps) + i, in_play, calib, heldout,
                         cal_obs, errors, kw)
        st.alternative_to = of
        alt_steps.append(st)
    settings = {k: v for k, v in kw.items() if k not in ("scopes",)}
    settings.update(max_additions=max_additions, scopes=dict(scopes or {}), model_correlation=errors.model_correlation,
                    base_posterior=steps[0].final.source)
    return Selection(steps, rounds, why, calib, heldout, settings, alt_steps)


def confirm_additions(selection: Selection, real: Mapping[int, Mapping[str, np.ndarray | None]],
                      obs: Mapping[str, np.ndarray], errors: RecordErrors, *, alpha: float | None = None,
                      use_model_error: bool = False, weights: Mapping[str, np.ndarray] | None = None) -> dict:
    """The confirmation walk on the real simulator (module docstring, step 3).

    real : ``real[r][j]``: the real simulator's curve (on record ``j``'s observation times, through the
        same measurement chain) at step ``r``'s cross-validation point of calibration record ``j``
        (:meth:`ModelStep.check_points`); None for a failed run. A ``(K, m)`` array holds ``K >= 2``
        replicated runs, row ``k`` of every step on record ``j``'s realization ``k``: the steps are then
        compared by :func:`~.crossval.compare_replicated` (the simulator's variability of the difference
        measured, ``simulator`` unused); one run per point is compared by :func:`~.crossval.compare_cv`
        with ``simulator`` on each run, taken independent (cautious: a real gain can be refuted).
    obs : the calibration records' observations.
    errors : noise and the simulator's variability at those points (``simulator``); the model error is
        left out unless ``use_model_error`` (the curves are real runs, not the emulator).
    alpha : one-sided level (default the selection's); step ``r`` is held to ``alpha / K_r``.
    weights : per calibration record, a weight per observation time (:func:`walk_weights`): the steps
        are compared by their weighted squared errors, ``sum_t w_t (y_t - f_t)^2``, in the test and in
        the rule that the shipped model is never worse than the base (None: the plain sum).

    Returns ``confirmed`` (index of the last confirmed step), ``effects``, ``steps`` (per addition: the
    numbers and a sentence), ``real_cv_rmse`` per step walked (plain, for reading), ``real_cv_loss`` per
    step walked (the compared error per observation: weighted where ``weights`` are given), and ``text``.
    """
    alpha = selection.settings["alpha"] if alpha is None else alpha
    calib = selection.calib_records
    y = {j: np.asarray(obs[j], dtype=float) for j in calib}

    weighted = None if weights is None else Weighted(errors, calib, weights)

    def mean_square(r, w=None):
        """Step r's squared error per observation, averaged over its runs (a (K, m) array of replicates),
        each time weighted by w[j] if given; None if a run failed."""
        curves = real.get(r, {})
        if any(curves.get(j) is None for j in calib):
            return None
        total = 0.0
        for j in calib:
            per_time = np.mean(np.atleast_2d((y[j] - np.asarray(curves[j], float)) ** 2), axis=0)
            total += float(per_time.sum() if w is None else per_time @ w[j])
        return total / sum(y[j].size for j in calib)

    def rmse_of(r):
        ms = mean_square(r)
        return None if ms is None else math.sqrt(ms)

    def loss_of(r):
        return mean_square(r, weights)

    base_rmse = rmse_of(0)
    if base_rmse is None:
        raise ValueError("the base model's real cross-validation curves are needed (real[0][record])")
    rmses = {0: base_rmse}
    losses = {0: loss_of(0)}
    what = ("the squared-error sum" if weights is None else
            "the squared-error sum, each time weighted by 1 / (noise^2 + mesh scatter^2),")

    def walk(step: ModelStep, confirmed: int, then: str) -> tuple[dict, bool]:
        r, prev = step.index, selection.step(confirmed)
        name = step.spec.effect_names[-1]
        label = name if step.alternative_to is None else f"{name} (alternative to step {step.alternative_to})"
        rmses[r] = rmse_of(r)
        losses[r] = loss_of(r)
        level = alpha / max(step.in_play, 1)
        if rmses[r] is None:
            return {"step": r, "effect": name, "confirmed": False, "alternative_to": step.alternative_to,
                    "text": f"{label}: refuted, a real run at its cross-validation points failed; {then}"}, False
        cmp = _compare_real(y, real[confirmed], real[r], calib, errors, use_model_error, weighted)
        how = (f"; paired over {_replicates(real[r], calib)} mesh realizations, t on {cmp['dof']:.1f} dof"
               if "dof" in cmp else "")
        ok = cmp["p"] <= level
        return {"step": r, "effect": name, "confirmed": bool(ok), "alternative_to": step.alternative_to,
                "real_cv_rmse_before": rmses[confirmed], "real_cv_rmse_after": rmses[r],
                "delta_sq_error": cmp["delta"], "sd": cmp["sd"], "z": cmp["z"], "p": cmp["p"], "level": level,
                **{k: cmp[k] for k in ("sd_realizations", "sd_noise", "dof", "test") if k in cmp},
                "text": (f"{label} over {prev.spec.label()}: real cross-validated RMSE {rmses[confirmed]:.4g} -> "
                         f"{rmses[r]:.4g}; {what} falls by {cmp['delta']:.4g} with sd "
                         f"{cmp['sd']:.4g} (z = {cmp['z']:.2f}, p = {cmp['p']:.3g}{how}, level {level:.3g} = "
                         f"{alpha:g} / {step.in_play}): " + ("confirmed" if ok else f"refuted, dropped; {then}"))}, ok

    confirmed, out = 0, []
    for step in selection.steps[1:]:
        alts = selection.alternatives_to(step.index)
        entry, ok = walk(step, confirmed, "the round's next proposal is tried" if alts else
                         "the walk stops (the additions after it were chosen given it)")
        out.append(entry)
        if ok:
            confirmed = step.index
            continue
        # the round's choice is refuted: its alternatives, in order, over the same model, each at the
        # round's level (Bonferroni over the round's candidates covers every one of them tried)
        for i, alt in enumerate(alts):
            last = i == len(alts) - 1
            entry, ok = walk(alt, confirmed, "the walk stops" if last else "the round's next proposal is tried")
            if ok:
                entry["text"] += "; the walk stops (the later rounds were chosen given the refuted one)"
            out.append(entry)
            if ok:
                confirmed = alt.index
                break
        break
    if losses[confirmed] > losses[0]:  # pragma: no cover - a confirmed step lowers the error; kept as the rule
        confirmed = 0
    spec = selection.step(confirmed).spec
    return {"confirmed": confirmed, "model": spec.label(), "effects": spec.effect_names, "steps": out,
            "real_cv_rmse": rmses, "real_cv_loss": losses, "weighted": weights is not None,
            "text": (f"shipped: {spec.label()} (real cross-validated RMSE {base_rmse:.4g} -> {rmses[confirmed]:.4g}"
                     + ("" if weights is None else f"; weighted error per observation {losses[0]:.4g} -> "
                                                   f"{losses[confirmed]:.4g}") + ")")}


def real_identification(selection: Selection, real: Mapping[int, Mapping[str, np.ndarray | None]],
                        obs: Mapping[str, np.ndarray], errors: RecordErrors, step: int, *,
                        level: float | None = None, weights: Mapping[str, np.ndarray] | None = None) -> list[dict]:
    """The kept step's round on the real simulator: step ``step`` (confirmed by :func:`confirm_additions`)
    against every other model of its round with real runs at its cross-validation points (the round's
    choice and its alternatives: each the same model with another effect added), as the walk compares
    (paired over replicates where there are, else :func:`~.crossval.compare_cv`). ``told_apart``: the kept
    effect predicts better at one-sided ``level`` (default the selection's alpha), Bonferroni over those
    compared; ``other_better``: the other model predicts better at that level (the other tail; the walk
    keeps its round's first confirmed model, not the best); ``weights`` as the walk's
    (:func:`confirm_additions`). Empty for the base model or a round without another model run."""
    if int(step) == 0:
        return []
    kept = selection.step(step)
    chain = kept.index if kept.alternative_to is None else kept.alternative_to
    others = [m for m in (selection.step(chain), *selection.alternatives_to(chain)) if m.index != kept.index]
    calib = selection.calib_records
    others = [m for m in others if all(real.get(m.index, {}).get(j) is not None for j in calib)]
    if not others:
        return []
    level = (selection.settings["alpha"] if level is None else level) / len(others)
    y = {j: np.asarray(obs[j], dtype=float) for j in calib}
    weighted = None if weights is None else Weighted(errors, calib, weights)
    out = []
    for m in others:
        cmp = _compare_real(y, real[m.index], real[kept.index], calib, errors, False, weighted)
        out.append({"effect": m.spec.effect_names[-1], "step": m.index, "delta_sq_error": cmp["delta"], "sd": cmp["sd"],
                    "z": cmp["z"], "p": cmp["p"], "level": level, "told_apart": bool(cmp["p"] <= level),
                    # the other tail at the same level: the other model predicts better than the kept one
                    "other_better": bool(1.0 - cmp["p"] <= level),
                    **{k: cmp[k] for k in ("dof", "test") if k in cmp}})
    return out


def _compare_real(y: Mapping, current: Mapping, candidate: Mapping, calib: Sequence[str], errors: RecordErrors,
                  use_model_error: bool, weighted: Weighted | None = None) -> dict:
    """Two models' real runs at the cross-validation points, as the walk compares them: paired over
    common mesh realizations where both are replicated (:func:`~.crossval.compare_replicated`), else
    :func:`~.crossval.compare_cv`; each time weighted where ``weighted`` (:class:`~.weights.Weighted`, the
    walk's weights applied to ``errors``) is given."""
    if weighted is not None:
        if use_model_error:
            raise ValueError("weights apply to real runs, which carry no model error")
        y, current, candidate, errors = (weighted.scale(y), weighted.scale(current), weighted.scale(candidate),
                                         weighted.errors)
    if replicated(current, calib) and replicated(candidate, calib):
        return compare_replicated(y, {j: current[j] for j in calib}, {j: candidate[j] for j in calib}, errors.noise)
    return compare_cv(y, current, candidate, errors, use_model_error=use_model_error)


def replicated(curves: Mapping, records: Sequence[str]) -> bool:
    """Whether ``curves[j]`` of every record is a ``(K, m)`` array of ``K >= 2`` replicated runs (the
    walk then compares steps in pairs, :func:`~.crossval.compare_replicated`)."""
    return all(np.ndim(curves[j]) == 2 and np.shape(curves[j])[0] >= 2 for j in records)


def _replicates(curves: Mapping, records: Sequence[str]) -> int:
    return min(int(np.shape(curves[j])[0]) for j in records)


def heldout_evaluation(selection: Selection, obs: Mapping[str, np.ndarray], times: Mapping[str, np.ndarray], *,
                       final: int | None = None, errors: RecordErrors | None = None,
                       real: Mapping[str, Mapping[str, np.ndarray]] | None = None, seed: int = 0) -> dict:
    """The held-out records' errors, base model (``before``) and final model (``after``, step ``final``,
    default the last; the confirmed one after :func:`confirm_additions`): ``curve_errors`` (RMSE, peak
    error, time-to-peak error), the fraction of the observed curve inside the model band (posterior
    members x population draws) and, with ``errors``, inside the predictive band (the band plus a draw of
    the error model); per-record values predicted and their intervals. ``real={"before": {h: curve},
    "after": {h: curve}}`` scores real-simulator runs at the held-out points instead of the model's (a
    ``(K, m)`` curve: replicated runs, :func:`~.acceptance.replicate_curve_errors`)."""
    final = len(selection.steps) - 1 if final is None else int(final)
    out = {}
    for h in selection.heldout_records:
        y, t = np.asarray(obs[h], dtype=float), np.asarray(times[h], dtype=float)
        rec = {"final_model": selection.step(final).spec.label()}
        for when, step in (("before", selection.steps[0]), ("after", selection.step(final))):
            pred = step.heldout[h]
            curve = pred.curve if real is None else np.asarray(real[when][h], dtype=float)
            lo, hi = pred.band
            e = replicate_curve_errors(t, curve, y)  # (K, m) replicated runs: their mean errors
            e["band_coverage"] = float(np.mean((y >= lo) & (y <= hi)))
            if errors is not None:
                plo, phi = predictive_band(pred.draws, errors.total(h, list(pred.point)), seed, level=pred.band_level)
                e["predictive_coverage"] = float(np.mean((y >= plo) & (y <= phi)))
            e["point"] = dict(pred.point)
            e["intervals"] = {k: list(v) for k, v in pred.intervals().items()}
            rec[when] = e
        rec["rmse_change"] = rec["after"]["rmse"] - rec["before"]["rmse"]
        out[h] = rec
    return out


def leave_one_record_out(model: ForwardModel, records: Sequence[str], obs: Mapping[str, np.ndarray],
                         times: Mapping[str, np.ndarray], errors: RecordErrors, *, base_names: Sequence[str],
                         candidates: Sequence, confirm: Callable[[Selection], int] | None = None,
                         **select_kw) -> dict:
    """The protocol once per record of a series, that record held out (:func:`select_effects` on the
    others, ``confirm(selection) -> final step index`` if given (e.g. :func:`confirm_additions` on real
    runs), else the last step; then :func:`heldout_evaluation`).

    Returns ``table`` (one row per fold: held-out record, effects kept, the final calibration's estimates
    with their 90 % intervals, the held-out RMSE before and after and its change), ``totals`` (mean
    change, its sd across folds and standard error, folds improved, how often each effect was kept) and
    the ``selections``."""
    records = list(records)
    rows, selections = [], {}
    for h in records:
        calib = [r for r in records if r != h]
        sel = select_effects(model, base_names=base_names, candidates=candidates, calib_records=calib,
                             heldout_records=[h], obs={r: obs[r] for r in calib}, errors=errors, **select_kw)
        final = confirm(sel) if confirm is not None else len(sel.steps) - 1
        ev = heldout_evaluation(sel, {h: obs[h]}, times, final=final, errors=errors)[h]
        step = sel.step(final)
        row = {"heldout": h, "effects": ",".join(step.spec.effect_names), "n_effects": len(step.spec.effects),
               "rmse_before": ev["before"]["rmse"], "rmse_after": ev["after"]["rmse"], "rmse_change": ev["rmse_change"],
               "peak_error_before": ev["before"]["peak_error"], "peak_error_after": ev["after"]["peak_error"],
               "time_to_peak_error_before": ev["before"]["time_to_peak_error"],
               "time_to_peak_error_after": ev["after"]["time_to_peak_error"],
               "band_coverage_after": ev["after"]["band_coverage"]}
        for n, p in step.final.posterior().items():
            if n in step.spec.shared:
                row.update({f"{n}_mean": p["mean"], f"{n}_q05": p["q05"], f"{n}_q95": p["q95"]})
        for n, (a, b) in ev["after"]["intervals"].items():
            row.update({f"{n}_pred": ev["after"]["point"][n], f"{n}_q05": a, f"{n}_q95": b})
        rows.append(row)
        selections[h] = sel
    table = pd.DataFrame(rows)
    ch = table["rmse_change"].to_numpy(float)
    n = ch.size
    kept = {c.name: float(np.mean([c.name in s.split(",") for s in table["effects"]])) for c in candidates}
    totals = {"folds": n, "mean_rmse_change": float(ch.mean()),
              "sd_rmse_change": float(ch.std(ddof=1)) if n > 1 else math.nan,
              "se_mean_rmse_change": float(ch.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan,
              "folds_improved": int(np.sum(ch < 0)), "kept_fraction": kept,
              "mean_rmse_before": float(table["rmse_before"].mean()), "mean_rmse_after": float(table["rmse_after"].mean())}
    return {"table": table, "totals": totals, "selections": selections}
