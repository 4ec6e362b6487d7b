"""The discrepancy loop: score-rank the candidates, re-calibrate, accept or stop
(:func:`diagnose_loop`; :mod:`enkf.diagnosis`, step 4).

:func:`diagnose_loop` calibrates the base model and runs rounds (:func:`_round`) until the residual
passes the structure tests or the loop stops; a round ranks the remaining candidates
(:func:`_rank`), re-calibrates the near-tied best (:func:`_trials`), keeps the accepted one with the
lowest BIC (:func:`_keep_best`) and re-tests the earlier additions (:func:`_backward_check`). What
stays fixed over the rounds is a :class:`_Loop`, what they change a :class:`_State`; :func:`_report`
writes the result."""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..covariance import ObservationError
from ..diagnostics import posterior_dict, rmse
from .acceptance import accept_effect, bic, curve_errors, effective_sample_size, pinned_at_bounds
from .ranking import rank_candidates
from .structure import default_windows, structure_tests, whitened_residual


VERDICTS = ("explained", "unexplained", "no structure")


@dataclass
class Candidate:
    """A generic candidate effect for :func:`diagnose_loop`: a name, its parameters' names and null values,
    optionally their prior box (used for the null tolerance). ``shpb.effects.Effect`` has the same
    attributes and can be passed directly."""

    name: str
    param_names: tuple[str, ...]
    nulls: tuple[float, ...]
    lower: tuple[float, ...] | None = None
    upper: tuple[float, ...] | None = None


@dataclass
class CalibrationResult:
    """What ``calibrate(param_names)`` returns to :func:`diagnose_loop`.

    names : the calibrated parameters, in order (the columns of ``params``).
    params : (N, n) posterior ensemble (bounded, the caller's units).
    fitted : (m,) the calibrated model's curve on the calibration observations (e.g. the response at
        the posterior mean).
    heldout : (m_h,) its prediction of the held-out observations, or None.
    responses : (N, m) the posterior ensemble's responses, if the caller wants ensemble sensitivities.
    info : anything else (JSON-ready), copied into the report.
    lower, upper : (n,) the box the calibration was confined to (prior box, or an emulator's design box),
        if it had one; the loop then refuses estimates the box, not the data, decided
        (:func:`pinned_at_bounds`).
    """

    names: list[str]
    params: np.ndarray
    fitted: np.ndarray
    heldout: np.ndarray | None = None
    responses: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def __post_init__(self):
        self.names = list(self.names)
        self.params = np.array(self.params, dtype=float, ndmin=2)
        self.fitted = np.asarray(self.fitted, dtype=float)
        if self.params.shape[1] != len(self.names):
            raise ValueError(f"params has {self.params.shape[1]} columns for {len(self.names)} names")
        if (self.lower is None) != (self.upper is None):
            raise ValueError("give both lower and upper, or neither")
        if self.lower is not None:
            self.lower, self.upper = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
            if self.lower.shape != (len(self.names),) or self.upper.shape != (len(self.names),):
                raise ValueError(f"lower/upper need {len(self.names)} entries, one per name")

    def mean(self) -> dict[str, float]:
        return dict(zip(self.names, self.params.mean(axis=0).tolist()))

    def samples(self, names: Sequence[str]) -> np.ndarray:
        idx = [self.names.index(n) for n in names]
        return self.params[:, idx]


def _candidate_tolerances(cand, fraction: float) -> np.ndarray:
    k = len(cand.param_names)
    lower, upper = getattr(cand, "lower", None), getattr(cand, "upper", None)
    if lower is None or upper is None:
        return np.zeros(k)
    return fraction * (np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float))


def diagnose_loop(calibrate: Callable[[list[str]], CalibrationResult],
                  sensitivities: Callable[[CalibrationResult, list[str]], np.ndarray], *,
                  base_names: Sequence[str], candidates: Sequence, obs, obs_error: ObservationError, times,
                  heldout_obs=None, heldout_times=None, max_additions: int = 2, alpha_structure: float = 0.01,
                  alpha_score: float = 1e-3, min_explained: float = 0.25, max_collinearity: float = 0.999,
                  screen_min_explained: float = 0.0,
                  bic_margin: float = 10.0, interval: float = 0.90, null_tolerance_fraction: float = 0.01,
                  n_eff: str | float = "model", max_trials: int = 3, tie_fraction: float = 0.25,
                  windows: Mapping[str, tuple[float, float]] | None = None, lag: int | None = None,
                  base_result: CalibrationResult | None = None, bound_fraction: float | None = 0.02) -> dict:
    """The discrepancy loop: calibrate the base model, test its residual, rank the candidate effects by
    score test, add the best one if re-calibration justifies it, repeat.

    Parameters
    ----------
    calibrate : ``calibrate(param_names) -> CalibrationResult``; ``param_names`` are the base names
        followed by the effect parameters added so far (effects not named are at their null).
    sensitivities : ``sensitivities(result, names) -> (m, len(names))``: ``d fitted / d theta`` at the
        calibrated estimate of ``result``, candidate parameters at their null. The loop asks for the
        current calibrated parameters followed by every remaining candidate's parameters. Unwhitened
        (the loop whitens with ``obs_error``); finite differences or :func:`ensemble_sensitivity`.
    base_names : the base model's calibrated parameters.
    candidates : effects offered, each with ``name``, ``param_names``, ``nulls`` and optionally ``lower``,
        ``upper`` (:class:`Candidate`, ``shpb.effects.Effect``). An effect estimated separately for each
        group of observations (e.g. per record) is offered with one parameter per group; its score test
        then has that many degrees of freedom and its BIC counts every copy.
    obs, obs_error, times : calibration observations, their error model and times.
    heldout_obs, heldout_times : observations not used to calibrate (another record, or the post-peak
        part), predicted by ``CalibrationResult.heldout``; None to skip the held-out criterion.
    max_additions : at most this many effects are added.
    alpha_structure : family-wise level of the structure tests; the loop stops as soon as the residual
        passes them.
    alpha_score, max_collinearity, screen_min_explained : candidate screening (:func:`rank_candidates`;
        its linearised explained share is off by default).
    bic_margin, interval, null_tolerance_fraction, min_explained : :func:`accept_effect` (the tolerance
        is this fraction of each effect parameter's box width when the candidate has one;
        ``min_explained`` is the share of the current residual's excess chi-square over its noise
        expectation ``m - n_params`` that the re-calibrated augmented model must remove).
    n_eff : ``"model"`` (from ``obs_error``), ``"residual"`` (from the base model's whitened residual) or a
        number; fixed for the whole loop so the BIC values are comparable.
    max_trials, tie_fraction : the screened candidates whose score is at least ``tie_fraction`` of the
        best one are each re-calibrated (at most ``max_trials``, best scores first) and the accepted one
        with the lowest BIC is kept. ``max_trials = 1`` is the plain "add the best candidate" rule. Near
        ties arise because effects can share their first-order signature (a one-pole low-pass of time
        constant tau is a delay by tau to first order; a gain steepens the rise as an earlier trigger
        would), which a score test at the null cannot separate.
    windows : structure-test windows (default :func:`default_windows` of the base model's curve).
    lag : Ljung-Box lag.
    base_result : an already calibrated base model (skips the first ``calibrate`` call).
    bound_fraction : for calibrations that report their box (``CalibrationResult.lower``/``upper``): an
        augmented calibration with any parameter's median within this fraction of the box width of a
        bound is refused (:func:`pinned_at_bounds`, :func:`accept_effect` criterion 5), and a base
        calibration at a bound is reported (``box_limited``) and said in ``why``. None disables it.

    After an addition, every effect added earlier whose interval now contains its null is re-tested:
    the model is re-calibrated without it and it is dropped unless it is worth the BIC margin (an early
    addition that only stood in for the later one, e.g. a trigger shift mimicking a gain's steeper rise).

    Returns
    -------
    dict (make it JSON-ready with :func:`report_to_json`):
    ``verdict`` ("explained" | "unexplained" | "no structure"), ``why``, ``added`` (effects kept),
    ``chosen`` (first effect kept or None), ``candidate_table`` (DataFrame of the first ranking),
    ``iterations`` (per round: names, structure, candidates, trials, chosen, dropped, why),
    ``structure_before``,
    ``structure_after``, ``params_before`` / ``params_after`` (posterior mean, std, q05, q95),
    ``base_shift`` (how far each base parameter's mean moved, in before-posterior std and relative),
    ``bic`` (before, after, n_eff), ``errors`` (``calibration`` and ``heldout``, each ``before``/``after``
    from :func:`curve_errors`), ``box_limited`` (``base`` and ``final``: :func:`pinned_at_bounds` of the
    base and of the final calibration, None when the calibrations report no box) and ``curves`` (arrays
    for plotting).
    """
    obs, times, ho_obs, ho_t = _check_data(obs, times, obs_error, heldout_obs, heldout_times)
    cand_by_name = {c.name: c for c in candidates}
    if len(cand_by_name) != len(candidates):
        raise ValueError("candidate names must be unique")

    base_names = list(base_names)
    base = base_result if base_result is not None else calibrate(list(base_names))
    if list(base.names) != base_names:
        raise ValueError(f"calibrate returned names {base.names}, expected {base_names}")
    loop = _Loop(calibrate=calibrate, sensitivities=sensitivities, obs=obs, times=times, obs_error=obs_error,
                 ho_obs=ho_obs, ho_t=ho_t, cand_by_name=cand_by_name,
                 effect_nulls={p: z for c in candidates for p, z in zip(c.param_names, c.nulls)},
                 max_additions=max_additions, alpha_structure=alpha_structure, alpha_score=alpha_score,
                 min_explained=min_explained, screen_min_explained=screen_min_explained,
                 max_collinearity=max_collinearity, bic_margin=bic_margin, interval=interval,
                 null_tolerance_fraction=null_tolerance_fraction, n_eff=n_eff, max_trials=max_trials,
                 tie_fraction=tie_fraction, lag=lag, bound_fraction=bound_fraction)
    base_pinned = loop.pinned(base)
    if windows is None:
        try:
            windows = default_windows(times, base.fitted)
        except ValueError:
            windows = None
    loop.windows = windows
    loop.neff = _effective_n(n_eff, obs_error, whitened_residual(base.fitted, obs, obs_error))

    state = _State(current=base, ev=loop.evaluate(base), remaining=[c.name for c in candidates])
    base_eval = state.ev
    for round_ in range(max_additions + 1):
        if _round(loop, state, round_):
            break
    if base_pinned:
        state.why = ("the base calibration is box-limited (" + "; ".join(p["text"] for p in base_pinned)
                     + "): its residual, and what the candidates are measured against, is that of a base model "
                     "held at the edge of its box. " + state.why)
    return _report(loop, state, base, base_eval, base_pinned)


def _check_data(obs, times, obs_error: ObservationError, heldout_obs, heldout_times):
    """The calibration and held-out observations as arrays (held-out ones None when not given)."""
    obs = np.asarray(obs, dtype=float)
    times = np.asarray(times, dtype=float)
    if obs_error.m != obs.size or times.shape != obs.shape:
        raise ValueError("obs, times and obs_error must describe the same m observations")
    has_ho = heldout_obs is not None
    ho_obs = np.asarray(heldout_obs, dtype=float) if has_ho else None
    ho_t = np.asarray(heldout_times, dtype=float) if has_ho else None
    if has_ho and (ho_t is None or ho_t.shape != ho_obs.shape):
        raise ValueError("heldout_times must match heldout_obs")
    return obs, times, ho_obs, ho_t


def _effective_n(n_eff: str | float, obs_error: ObservationError, w0: np.ndarray) -> float:
    """The BIC's sample size, fixed for the whole loop (``n_eff`` of :func:`diagnose_loop`)."""
    if n_eff == "model":
        return effective_sample_size(obs_error)
    if n_eff == "residual":
        return effective_sample_size(w0)
    return float(n_eff)


@dataclass
class _Loop:
    """What stays fixed over the rounds of :func:`diagnose_loop`: the model calls, the data, the
    candidates and the settings (the arguments of the same names)."""

    calibrate: Callable
    sensitivities: Callable
    obs: np.ndarray
    times: np.ndarray
    obs_error: ObservationError
    ho_obs: np.ndarray | None
    ho_t: np.ndarray | None
    cand_by_name: dict
    effect_nulls: dict
    max_additions: int
    alpha_structure: float
    alpha_score: float
    min_explained: float
    screen_min_explained: float
    max_collinearity: float
    bic_margin: float
    interval: float
    null_tolerance_fraction: float
    n_eff: str | float
    max_trials: int
    tie_fraction: float
    lag: int | None
    bound_fraction: float | None
    windows: Mapping | None = None
    neff: float = math.nan

    @property
    def has_ho(self) -> bool:
        return self.ho_obs is not None

    def pinned(self, res: CalibrationResult) -> list[dict] | None:
        if self.bound_fraction is None or res.lower is None:
            return None
        return pinned_at_bounds(res.params, res.lower, res.upper, res.names, nulls=self.effect_nulls,
                                fraction=self.bound_fraction)

    def evaluate(self, res: CalibrationResult) -> dict:
        """Whitened residual, chi-square, BIC and held-out RMSE of a calibration."""
        w = whitened_residual(res.fitted, self.obs, self.obs_error)
        c2 = float(w @ w)
        ho_rmse = None
        if self.has_ho:
            if res.heldout is None:
                raise ValueError("held-out observations given but calibrate returned no heldout prediction")
            ho_rmse = float(rmse(res.heldout, self.ho_obs))
        return {"w": w, "chi2": c2, "bic": bic(c2, len(res.names), self.neff), "heldout_rmse": ho_rmse}


@dataclass
class _State:
    """What the rounds of :func:`diagnose_loop` change: the current calibration and its evaluation, the
    effects added and still offered, the rounds so far, the first ranking, the verdict and why."""

    current: CalibrationResult
    ev: dict
    remaining: list[str]
    added: list[str] = field(default_factory=list)
    iterations: list[dict] = field(default_factory=list)
    first_table: object = None
    verdict: str = "unexplained"
    why: str = ""


def _round(loop: _Loop, s: _State, round_: int) -> bool:
    """One round: test the residual's structure; stop (True) if it passes, the budget is spent or nothing
    is left to offer; else rank the candidates, re-calibrate the near-tied best, keep the best accepted
    one and re-test the earlier additions. True when the loop ends."""
    st = structure_tests(s.ev["w"], loop.times, loop.windows, n_params=len(s.current.names), lag=loop.lag,
                         alpha=loop.alpha_structure)
    step = {"round": round_, "names": list(s.current.names), "bic": s.ev["bic"], "structure": st,
            "candidates": None, "trials": [], "chosen": None, "dropped": [], "why": ""}
    s.iterations.append(step)
    if st["passed"]:
        s.verdict = "explained" if s.added else "no structure"
        s.why = ("the residual passes the structure tests" +
                 (f" after adding {', '.join(s.added)}" if s.added else " of the base model; nothing to add"))
        return True
    if round_ == loop.max_additions:
        s.why = (f"the residual still fails {', '.join(st['failed'])} after {len(s.added)} addition(s) "
                 f"(maximum {loop.max_additions})")
        return True
    if not s.remaining:
        s.why = f"the residual fails {', '.join(st['failed'])} and no candidate is left"
        return True

    table = _rank(loop, s)
    step["candidates"] = table
    if s.first_table is None:
        s.first_table = table
    passing = table[table["passes"]]
    if passing.empty:
        s.why = (f"the residual fails {', '.join(st['failed'])} but no candidate passes the score screening "
                 f"(p < {loop.alpha_score:g}, collinearity <= {loop.max_collinearity:g}"
                 + (f", linearised share >= {loop.screen_min_explained:.0%}" if loop.screen_min_explained > 0 else "")
                 + ")")
        step["why"] = s.why
        return True
    best_score = float(passing["score"].iloc[0])
    trial_names = [r.effect for r in passing.itertuples() if r.score >= loop.tie_fraction * best_score][:loop.max_trials]

    accepted = _trials(loop, s, step, trial_names)
    if not accepted:
        s.why = ("the best candidate(s) " + ", ".join(trial_names) + " did not earn their place: "
                 + " | ".join(f"{t['effect']}: " + "; ".join(r for r in t["reasons"] if r.startswith("fail"))
                              for t in step["trials"]))
        step["why"] = s.why
        return True
    name = _keep_best(s, step, table, trial_names, accepted)
    _backward_check(loop, s, step, name)
    return False


def _rank(loop: _Loop, s: _State):
    """Score-test ranking of the remaining candidates against the current residual (:func:`rank_candidates`)."""
    m, cand_by_name = loop.obs.size, loop.cand_by_name
    cand_params = [p for name in s.remaining for p in cand_by_name[name].param_names]
    S = np.asarray(loop.sensitivities(s.current, list(s.current.names) + cand_params), dtype=float)
    n_cur = len(s.current.names)
    if S.shape != (m, n_cur + len(cand_params)):
        raise ValueError(f"sensitivities returned shape {S.shape}, expected {(m, n_cur + len(cand_params))}")
    Sw = loop.obs_error.whiten(S)
    cols, j = {}, n_cur
    for name in s.remaining:
        k = len(cand_by_name[name].param_names)
        cols[name] = Sw[:, j:j + k]
        j += k
    return rank_candidates(s.ev["w"], Sw[:, :n_cur], cols,
                           param_names={n: cand_by_name[n].param_names for n in s.remaining},
                           alpha=loop.alpha_score, min_explained=loop.screen_min_explained,
                           max_collinearity=loop.max_collinearity)


def _trials(loop: _Loop, s: _State, step: dict, trial_names: list[str]) -> list[tuple]:
    """Re-calibrate with each trial candidate added; record every trial in ``step``; return the accepted
    ones as ``(bic, name, result, evaluation, reasons)`` (:func:`accept_effect`)."""
    m = loop.obs.size
    accepted = []
    for name in trial_names:
        cand = loop.cand_by_name[name]
        res = loop.calibrate(list(s.current.names) + list(cand.param_names))
        ev = loop.evaluate(res)
        excess = s.ev["chi2"] - (m - len(s.current.names))
        explained = (s.ev["chi2"] - ev["chi2"]) / excess if excess > 0 else math.nan
        ok, reasons = accept_effect(s.ev["bic"], ev["bic"], res.samples(cand.param_names), cand.nulls,
                                    s.ev["heldout_rmse"], ev["heldout_rmse"], margin=loop.bic_margin,
                                    interval=loop.interval,
                                    null_tolerance=_candidate_tolerances(cand, loop.null_tolerance_fraction),
                                    explained=explained, min_explained=loop.min_explained, pinned=loop.pinned(res))
        step["trials"].append({"effect": name, "accepted": ok, "reasons": reasons, "bic": ev["bic"],
                               "explained": explained,
                               "chi2": ev["chi2"], "heldout_rmse": ev["heldout_rmse"],
                               "posterior": posterior_dict(res.params, res.names), "info": res.info})
        if ok:
            accepted.append((ev["bic"], name, res, ev, reasons))
    return accepted


def _keep_best(s: _State, step: dict, table, trial_names: list[str], accepted: list[tuple]) -> str:
    """Keep the accepted candidate with the lowest BIC: it becomes the current model. Returns its name."""
    accepted.sort(key=lambda a: a[0])
    _, name, res, ev, reasons = accepted[0]
    row = table[table["effect"] == name].iloc[0]
    step["chosen"] = name
    step["why"] = (f"{name}: score {row['score']:.4g} (p = {row['p_value']:.3g}, rank {int(row['rank'])}), "
                   f"collinearity with the base {row['collinearity']:.3f}; " + "; ".join(reasons)
                   + (f"; lowest BIC of the {len(trial_names)} re-calibrated near-tied candidates "
                      f"({', '.join(trial_names)})" if len(trial_names) > 1 else ""))
    s.added.append(name)
    s.remaining.remove(name)
    s.current, s.ev = res, ev
    return name


def _backward_check(loop: _Loop, s: _State, step: dict, name: str) -> None:
    """An earlier effect whose interval now contains its null, and whose removal costs less than the BIC
    margin, was standing in for the new one ``name``: drop it (it may come back later)."""
    interval = loop.interval
    for old in [e for e in s.added if e != name]:
        cand = loop.cand_by_name[old]
        X = s.current.samples(cand.param_names)
        q_lo, q_hi = np.quantile(X, 0.5 - interval / 2, axis=0), np.quantile(X, 0.5 + interval / 2, axis=0)
        tol = _candidate_tolerances(cand, loop.null_tolerance_fraction)
        nulls = np.asarray(cand.nulls, dtype=float)
        if np.any((q_lo - nulls > tol) | (nulls - q_hi > tol)):
            continue
        res_wo = loop.calibrate([n for n in s.current.names if n not in cand.param_names])
        ev_wo = loop.evaluate(res_wo)
        drop = ev_wo["bic"] < s.ev["bic"] + loop.bic_margin
        step["dropped"].append({"effect": old, "dropped": bool(drop), "bic_with": s.ev["bic"],
                                "bic_without": ev_wo["bic"],
                                "reason": f"its {100 * interval:.0f}% interval contains the null after adding "
                                          f"{name}; BIC without it {ev_wo['bic']:.6g} vs {s.ev['bic']:.6g} "
                                          f"with it (margin {loop.bic_margin:g})"})
        if drop:
            s.added.remove(old)
            s.remaining.append(old)
            s.current, s.ev = res_wo, ev_wo
            step["why"] += f"; dropped {old} (" + step["dropped"][-1]["reason"] + ")"


def _report(loop: _Loop, s: _State, base: CalibrationResult, base_eval: dict, base_pinned) -> dict:
    """The report of :func:`diagnose_loop` (its Returns section)."""
    current, cur_eval, iterations = s.current, s.ev, s.iterations
    times, obs, ho_t, ho_obs, has_ho = loop.times, loop.obs, loop.ho_t, loop.ho_obs, loop.has_ho
    before_post = posterior_dict(base.params, base.names)
    after_post = posterior_dict(current.params, current.names)
    shift = {}
    for p in base.names:
        b, a = before_post[p], after_post[p]
        shift[p] = {"mean_before": b["mean"], "mean_after": a["mean"],
                    "shift_in_sd": (a["mean"] - b["mean"]) / b["std"] if b["std"] > 0 else math.nan,
                    "relative": (a["mean"] - b["mean"]) / abs(b["mean"]) if b["mean"] != 0 else math.nan}
    errors = {"calibration": {"before": curve_errors(times, base.fitted, obs),
                              "after": curve_errors(times, current.fitted, obs)}}
    if has_ho:
        errors["heldout"] = {"before": curve_errors(ho_t, base.heldout, ho_obs),
                             "after": curve_errors(ho_t, current.heldout, ho_obs)}
    return {
        "verdict": s.verdict, "why": s.why, "added": s.added, "chosen": s.added[0] if s.added else None,
        "candidate_table": s.first_table, "iterations": iterations,
        "structure_before": iterations[0]["structure"], "structure_after": iterations[-1]["structure"],
        "params_before": before_post, "params_after": after_post, "base_shift": shift,
        "bic": {"before": base_eval["bic"], "after": cur_eval["bic"], "n_eff": loop.neff},
        "errors": errors,
        "box_limited": {"base": base_pinned, "final": loop.pinned(current)},
        "settings": {"max_additions": loop.max_additions, "alpha_structure": loop.alpha_structure,
                     "alpha_score": loop.alpha_score, "min_explained": loop.min_explained,
                     "screen_min_explained": loop.screen_min_explained, "max_collinearity": loop.max_collinearity,
                     "bic_margin": loop.bic_margin, "interval": loop.interval,
                     "null_tolerance_fraction": loop.null_tolerance_fraction, "n_eff": loop.n_eff,
                     "max_trials": loop.max_trials, "tie_fraction": loop.tie_fraction, "windows": loop.windows,
                     "bound_fraction": loop.bound_fraction},
        "curves": {"times": times, "obs": obs, "fitted_before": base.fitted, "fitted_after": current.fitted,
                   "white_before": base_eval["w"], "white_after": cur_eval["w"],
                   "heldout_times": ho_t, "heldout_obs": ho_obs,
                   "heldout_before": base.heldout if has_ho else None,
                   "heldout_after": current.heldout if has_ho else None},
    }
