"""Did the calibration do what it claims? The ``verdict`` block of ``summary.json``.

A calibration that leaves the fit worse than the prior, or pins a parameter to its box, or stops on
its budget far from the noise level, must say so in words and numbers, not only through a
``stop_reason`` (issue 17). Computed from the stored iterations only; no simulation.

Verdicts, the first that applies:

- ``worse_than_prior``: the last iteration's ensemble fits worse (chi^2 per observation) than the
  prior ensemble. The reported posterior is then the best iteration's (:func:`reported_iteration`). The linear-Gaussian update pushed the ensemble where the model
  cannot follow the data: the model lacks an effect the data carry (run the diagnosis).
- ``box_limited``: a posterior mean lies within ``PIN_FRACTION`` of its box width from a bound; the
  data want a value the prior box excludes (widen the box, or the parameter stands in for a missing
  effect).
- ``not_converged``: the stop rule was not met (iteration budget spent or ensemble collapse).
- ``ok``: the tolerance was met and none of the above.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

#: A posterior mean this close to a bound, as a fraction of the box width, is pinned to the box.
PIN_FRACTION = 0.02

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
    "not_converged": ("the stop rule was not met ({reason}): chi^2 per observation {chi2:.4g} against the "
                      "target {target:.4g}; more iterations will not close a gap this size if the best "
                      "iteration is not the last; check the noise model or run the diagnosis"),
    "ok": "none: the fit reached the noise level inside the prior box",
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


def calibration_verdict(*, misfits: Sequence[Mapping], decision: Mapping, posterior: Mapping[str, Mapping],
                        lower: Sequence[float], upper: Sequence[float], names: Sequence[str],
                        diagnosed: bool = False) -> dict:
    """The ``verdict`` block (``diagnosed``: the experiment runs the diagnosis itself, so the next step
    points at its report rather than at config/diagnosis.yaml): misfits is the per-iteration list of ``summary.json`` (``iteration``,
    ``chi2_per_obs``, ``rmse_Pa``), 0 = prior ensemble; posterior the reported one (of the ensemble
    :func:`reported_iteration` picks, or the MCMC sample); decision the stop decision taken on the last."""
    chi2 = [float(m["chi2_per_obs"]) if m.get("chi2_per_obs") is not None else math.nan for m in misfits]
    finite = [(c, k) for k, c in enumerate(chi2) if math.isfinite(c)]
    best_chi2, best = min(finite) if finite else (math.nan, len(chi2) - 1)
    prior, final = chi2[0], chi2[-1]
    pinned = pinned_parameters(posterior, lower, upper, names)
    flags = []
    if math.isfinite(prior) and math.isfinite(final) and final > prior:
        flags.append("worse_than_prior")
    if pinned:
        flags.append("box_limited")
    if not decision.get("converged", False):
        flags.append("not_converged")
    verdict = flags[0] if flags else "ok"
    target = (decision.get("values") or {}).get("chi2_target")
    reported = reported_iteration(chi2)
    text = NEXT_STEP[verdict].format(
        diagnosis=DIAGNOSIS_STEP[bool(diagnosed)], params=", ".join(pinned),
        bounds=", ".join(f"its {side} bound" if len(pinned) == 1 else f"{p}'s {side} bound" for p, side in pinned.items()),
        reason=decision.get("reason"), chi2=final, target=math.nan if target is None else float(target))
    if verdict == "worse_than_prior" and reported != len(chi2) - 1:
        text += (f"; the posterior reported (and forecast) is iteration {reported}'s ensemble (chi^2 per "
                 f"observation {chi2[reported]:.4g}), not the last ({final:.4g})")
    return {
        "verdict": verdict,
        "flags": flags,
        "chi2_per_obs": {"prior": prior, "final": final, "best": best_chi2, "best_iteration": int(best),
                         "final_over_prior": final / prior if prior and math.isfinite(prior) else None,
                         "target": target},
        "best_is_last": int(best) == len(chi2) - 1,
        "reported_iteration": reported,
        "pinned_to_box": pinned,
        "pin_fraction": PIN_FRACTION,
        "next_step": text,
    }
