"""Did the calibration do what it claims? The ``verdict`` block of ``summary.json``.

A calibration that leaves the fit worse than the prior, pins a parameter to its box, stops on its
budget, needs model error to explain its data or learns nothing must say so in words and numbers, not
only through a ``stop_reason``. Computed from the stored iterations only; no simulation. Every misfit
here is the members' (the median member's chi^2 per observation), never the ensemble-mean curve's: a
blurred mean can fit where no member does.

Flags, in this order; the verdict is the first that applies:

- ``worse_than_prior``: the reported ensemble's median member fits worse (against the instrument noise
  ``R``, one yardstick for every iteration; :func:`member_chi2`) than the prior ensemble's. The model lacks an effect the data carry (run the diagnosis).
- ``mcmc_not_converged``: the MCMC posterior's chain is shorter than its autocorrelation rule asks;
  its intervals are not yet a posterior.
- ``box_limited``: a posterior mean lies within ``PIN_FRACTION`` of its box width from a bound.
- ``not_converged``: the stop rule was not met (iteration budget spent or ensemble collapse).
- ``misfit_unexplained``: the median member's misfit per observation against the error model without
  the estimated discrepancy (``R + 2 S``: the instrument noise and the simulator's own variability
  between two mesh realizations, :mod:`calibration.model_error`), standardised by its variances,
  exceeds 1 by more than two of its own sampling sd under that model
  (:func:`enkf.diagnostics.member_standardized_misfit`): the fit needs model error to be explained, and the intervals are only
  as good as the discrepancy model (``summary.json``'s ``discrepancy`` gives its size).
- ``uninformative``: a parameter's posterior expects to score more than ``INFORMATIVE_RATIO`` of the prior's
  weighted interval score (``score_over_prior``, :mod:`enkf.scores`): the data did not take it far enough
  beyond the prior box for its interval to be quoted as learned (the prior's own ratio is 1; a Gaussian
  posterior's reaches the bar at a 90 % interval of about 0.53 of the box).
- ``ok``: none of the above.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from enkf.scores import INFORMATIVE_RATIO

#: A posterior mean this close to a bound, as a fraction of the box width, is pinned to the box.
PIN_FRACTION = 0.02


#: Flags in the order they decide the verdict.
FLAG_ORDER = ("worse_than_prior", "mcmc_not_converged", "box_limited", "not_converged", "misfit_unexplained",
              "uninformative")

#: The last ensemble is reported unless its chi^2 per observation exceeds the best iteration's by more
#: than this fraction. ES-MDA's intermediate ensembles are posteriors under inflated noise (wider than
#: the last), so a last step that is only a few per cent worse (sampling noise near convergence: twin
#: chi^2 0.94 -> 1.01) keeps the last; a step that made the fit markedly worse (marble: 610 -> 2,019)
#: does not get reported as the posterior (issue 17).
REPORT_TOLERANCE = 0.10

NEXT_STEP = {
    "worse_than_prior": ("the calibration made the fit worse than the prior: the model lacks something the "
                         "data carry; {diagnosis}"),
    "box_limited": "the data push {params} against the prior box: widen the box beyond {bounds}, or run the "
                   "diagnosis if the value is not physical",
    "not_converged": ("the stop rule was not met ({reason}): the median member's misfit per observation "
                      "{chi2:.4g} against the stop target {stop_target:.4g}; more iterations will not close a gap this size if the best "
                      "iteration is not the last; check the noise model or run the diagnosis"),
    "mcmc_not_converged": ("the MCMC chain did not reach its autocorrelation rule ({chain}): raise the "
                           "sampler's steps before reading its intervals"),
    "misfit_unexplained": ("the members miss the data by more than the instrument noise and the simulator's "
                           "own variability (chi^2 per observation {chi2_noise:.4g} against {target:.4g}); "
                           "the intervals include an "
                           "estimated model discrepancy{discrepancy} and are as good as that model; "
                           "{diagnosis}"),
    "uninformative": ("the data did not constrain {wide}: its posterior expects to score more than "
                      f"{INFORMATIVE_RATIO:.2f} of the prior box's weighted interval score ({{wide_scores}}), so its "
                      "interval is mostly the prior's, not a measurement; fix it or observe where it acts"),
    "ok": "none: the members fit within the error model inside the prior box and every parameter was learned",
}
#: Where the diagnosis is: a config to run, or the experiment's own report (``diagnosed``).
DIAGNOSIS_STEP = {False: "run the diagnosis (config/diagnosis.yaml) on this experiment",
                  True: "this experiment's diagnosis (diagnosis/report.json, check.json) traces it"}


def reported_iteration(chi2: Sequence[float], tolerance: float = REPORT_TOLERANCE) -> int:
    """The iteration whose ensemble is reported as the posterior (posterior.csv, summary ``posterior``,
    the forecast): the last, unless an earlier one fitted better by more than ``tolerance`` (relative
    chi^2 per observation), then the best. Non-finite entries are never best."""
    chi2 = [float(c) if c is not None else math.nan for c in chi2]
    last = len(chi2) - 1
    finite = [(c, k) for k, c in enumerate(chi2) if math.isfinite(c)]
    if not finite:
        return last
    best_chi2, best = min(finite)
    if math.isfinite(chi2[last]) and chi2[last] <= best_chi2 * (1.0 + tolerance):
        return last
    return int(best)


def pinned_parameters(posterior: Mapping[str, Mapping], lower: Sequence[float], upper: Sequence[float],
                      names: Sequence[str], fraction: float = PIN_FRACTION) -> dict:
    """``{name: 'lower' | 'upper'}`` for posterior means within ``fraction`` of the box width of a bound."""
    out = {}
    for j, p in enumerate(names):
        lo, hi = float(lower[j]), float(upper[j])
        m = float(posterior[p]["mean"])
        tol = fraction * (hi - lo)
        if m - lo <= tol:
            out[p] = "lower"
        elif hi - m <= tol:
            out[p] = "upper"
    return out


def uninformative_parameters(posterior: Mapping[str, Mapping], names: Sequence[str],
                             ratio: float = INFORMATIVE_RATIO) -> dict:
    """``{name: score_over_prior}`` for the parameters whose posterior expects to score more than ``ratio``
    of the prior's (a posterior summary without the score, one written before it, flags nothing)."""
    out = {}
    for p in names:
        score = posterior[p].get("score_over_prior")
        if score is not None and float(score) > ratio:
            out[p] = float(score)
    return out


def member_chi2(m: Mapping) -> float:
    """The median member's chi^2 per observation against ``R`` (the mean curve's for files written before
    the members were scored): one yardstick for every iteration. (``S`` is measured anew at each
    iteration's mean from a few replicates, so chi^2 against each iteration's own ``R + 2 S`` would
    compare iterations on different scales.)"""
    v = m.get("median_chi2_per_obs", m.get("chi2_per_obs"))
    return float(v) if v is not None else math.nan


def member_chi2_simulator(m: Mapping) -> tuple[float, float | None]:
    """``(statistic, target)``: the median member's misfit per observation against ``R + 2 S`` of its own
    iteration (the noise and the simulator's variability between two mesh realizations), standardised
    by its variances, and that statistic's own target (:func:`enkf.diagnostics.member_standardized_misfit`):
    the absolute test of ``misfit_unexplained``. Files written before the standardised statistic carry
    the whitened one (target None: the caller's noise level)."""
    v = m.get("standardized_chi2_per_obs_simulator")
    if v is not None:
        return float(v), m.get("standardized_target_simulator")
    v = m.get("median_chi2_per_obs_simulator")
    return (float(v) if v is not None else member_chi2(m)), None


def calibration_verdict(*, misfits: Sequence[Mapping], decision: Mapping, posterior: Mapping[str, Mapping],
                        lower: Sequence[float], upper: Sequence[float], names: Sequence[str],
                        diagnosed: bool = False, sampler: Mapping | None = None, n_obs: int | None = None,
                        discrepancy: Mapping | None = None) -> dict:
    """The ``verdict`` block.

    ``misfits``: the per-iteration list of ``summary.json`` (0 = prior ensemble), with the members'
    ``median_chi2_per_obs`` against ``R``; ``posterior``: the reported one; ``decision``: the stop
    decision; ``sampler``: the MCMC diagnostics (``posterior: emulator_mcmc``); ``n_obs``: the
    observation count (the noise level's sampling uncertainty); ``discrepancy``: the estimated model
    discrepancy per record (for the words); ``diagnosed``: the experiment runs its own diagnosis.
    """
    chi2 = [member_chi2(m) for m in misfits]
    finite = [(c, k) for k, c in enumerate(chi2) if math.isfinite(c)]
    best_chi2, best = min(finite) if finite else (math.nan, len(chi2) - 1)
    reported = reported_iteration(chi2)
    prior, last, final = chi2[0], chi2[-1], chi2[reported]
    final_sim, sim_target = member_chi2_simulator(misfits[reported])
    target = (decision.get("values") or {}).get("chi2_target")
    if sim_target is not None:
        noise_target = float(sim_target)
    else:  # files written before the standardised statistic
        noise_target = 1.0 + 2.0 * math.sqrt(2.0 / n_obs) if n_obs else (float(target) if target else math.nan)
    pinned = pinned_parameters(posterior, lower, upper, names)
    wide = uninformative_parameters(posterior, names)
    checks = {
        "worse_than_prior": math.isfinite(prior) and math.isfinite(last) and last > prior,
        "mcmc_not_converged": sampler is not None and not bool(sampler.get("converged_chain", True)),
        "box_limited": bool(pinned),
        "not_converged": not decision.get("converged", False),
        "misfit_unexplained": math.isfinite(final_sim) and math.isfinite(noise_target) and final_sim > noise_target,
        "uninformative": bool(wide),
    }
    flags = [f for f in FLAG_ORDER if checks[f]]
    verdict = flags[0] if flags else "ok"
    text = NEXT_STEP[verdict].format(
        diagnosis=DIAGNOSIS_STEP[bool(diagnosed)], params=", ".join(pinned),
        bounds=", ".join(f"its {side} bound" if len(pinned) == 1 else f"{p}'s {side} bound" for p, side in pinned.items()),
        reason=decision.get("reason"), chi2=float((decision.get("values") or {}).get("chi2_per_obs") or last),
        target=noise_target, chi2_noise=final_sim, stop_target=float(target) if target is not None else math.nan,
        chain=_chain_words(sampler), wide=", ".join(wide),
        wide_scores=", ".join(f"{p} {r:.2f}" for p, r in wide.items()), discrepancy=_discrepancy_words(discrepancy))
    if reported != len(chi2) - 1:
        text += (f"; the posterior reported (and forecast) is iteration {reported}'s ensemble (median member chi^2 "
                 f"per observation {final:.4g}), not the last ({last:.4g})")
    return {
        "verdict": verdict,
        "flags": flags,
        "chi2_per_obs": {"statistic": "median member against R", "prior": prior, "final": last,
                         "reported": final, "best": best_chi2, "best_iteration": int(best),
                         "final_over_prior": last / prior if prior and math.isfinite(prior) else None,
                         "reported_against_noise_and_simulator": final_sim,
                         "noise_level": noise_target, "stop_target": target},
        "best_is_last": int(best) == len(chi2) - 1,
        "reported_iteration": reported,
        "pinned_to_box": pinned,
        "pin_fraction": PIN_FRACTION,
        "interval_over_box": {p: (float(posterior[p]["q95"]) - float(posterior[p]["q05"])) /
                              (float(upper[j]) - float(lower[j])) for j, p in enumerate(names)},
        "score_over_prior": {p: posterior[p].get("score_over_prior") for p in names},
        "informative_ratio": INFORMATIVE_RATIO,
        "next_step": text,
    }


def _chain_words(sampler: Mapping | None) -> str:
    if not sampler:
        return ""
    tau = sampler.get("autocorr_time") or {}
    return f"{sampler.get('steps')} steps, autocorrelation times {', '.join(f'{k} {v:.3g}' for k, v in tau.items())}"


def _discrepancy_words(discrepancy: Mapping | None) -> str:
    if not discrepancy:
        return " (none was estimated: declare observations.model_error.discrepancy: ar1)"
    parts = [f"{rec} {v['sigma'] / 1e6:.3g} MPa over {v['corr_time_s'] * 1e6:.3g} us"
             for rec, v in (discrepancy.get("records") or {}).items()]
    return " (" + "; ".join(parts) + ")"
