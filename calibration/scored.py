"""Whether the coverage harness scored an experiment's reported posterior (issue 52): summary.json's
``posterior_form``. A lab's intervals come from a form the harness (benchmarks/bench_coverage.py) scored on
this loop, or say that they do not, and where the same form was scored on another loop."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["LEARNED_ALPHA", "SCORED", "approximation_form", "learned_holds", "misspecified_90", "posterior_form"]

#: The reported posteriors the coverage harness (benchmarks/bench_coverage.py) has scored, each with the loop
#: it was scored on (the default twin's: geometry, preset, loop, prior box, window) and the committed JSON of
#: its twins (``benchmark``). An experiment's summary.json says whether its own form and loop are one of these
#: (:func:`posterior_form`): a lab's intervals come from a scored form or say that they do not
#: (tests/test_one_posterior.py keeps each entry equal to its JSON and to config/config.yaml's twin_ref).
_TWIN_REF_LOOP = {"geometry": "brazilian_disc", "preset": "fast", "method": "emulated_esmda", "ensemble_size": 25,
                  "max_iterations": 3, "parameters": {"sigma_t": [4.0e6, 6.0e7], "E_t": [200.0, 2400.0]},
                  "window_s": [0.0, 1.6e-4]}
_SHIPPED = {"posterior": "emulator_mcmc", "self_calibrate": True, "emulator_error": "ar1", "refine_runs": 25}
#: ``learned_on``: the sets ``learned_holds`` pools (``("well_specified",)`` where absent).
#: ``confirmed_by``: further benchmark JSONs that scored the same form on the same loop, on fresh planned twins.
#: ``learned_holds``: per parameter, whether the well-specified twins of all these JSONs, pooled, on which the
#: product calls the parameter learned (no ``uninformative`` flag) held the truth in their 90 % intervals as
#: often as stated (the harness's ``product_flag`` split, benchmarks/scores.py: not rejected at 1 % against
#: 90 %). Pooled because each benchmark alone has about 15 such twins for ``E_t``: 10 of 16 in the first,
#: 13 of 15 in the second, 23 of 31 together (p 0.0096).
#: ``misspecified``: the JSONs whose misspecified twins (data the model cannot reproduce: made on the finer
#: ``standard`` mesh, or with a rate dependence the calibration does not declare) this form was scored on;
#: ``misspecified_90``: per parameter, how many of those twins' 90 % intervals held the truth, out of how
#: many (a failed sampler a miss; benchmarks.scores.pooled_coverage_90): what a measured record's intervals
#: may expect, since a lab's data are never the model's own.
SCORED = (
    # the shipped form, every experiment's default (config/schema.yaml)
    {"form": _SHIPPED,
     "loop": _TWIN_REF_LOOP,
     "benchmark": "benchmarks/results/coverage_one_posterior.json",
     "confirmed_by": ("benchmarks/results/coverage_location.json",),
     "learned_holds": {"sigma_t": True, "E_t": False},
     "misspecified": ("benchmarks/results/coverage_one_posterior.json", "benchmarks/results/coverage_location.json"),
     "misspecified_90": {"sigma_t": (81, 100), "E_t": (79, 100)}},
    # the same with the approximation error from 24 paired runs at `standard` (what init-config writes for a
    # lab's records): scored on misspecified twins only, where it is meant to act, so its learned_holds is
    # their split
    {"form": {**_SHIPPED, "approximation_error": {"preset": "standard", "pairs": 24, "coarse_variability": "subtracted"}},
     "loop": _TWIN_REF_LOOP,
     "benchmark": "benchmarks/results/coverage_misspecified_approximation.json",
     "confirmed_by": (),
     "learned_on": ("misspecified", "misspecified_rate"),
     "learned_holds": {"sigma_t": True, "E_t": True},
     "misspecified": ("benchmarks/results/coverage_misspecified_approximation.json",),
     "misspecified_90": {"sigma_t": (51, 60), "E_t": (56, 60)}},
    # the twins' form before: it returned the prior box on measured records (studies/posterior_forms_measured.py)
    {"form": {"posterior": "emulator_mcmc", "self_calibrate": True, "emulator_error": "heteroscedastic",
              "refine_runs": 25},
     "loop": _TWIN_REF_LOOP,
     "benchmark": "benchmarks/results/coverage_well_specified.json",
     "confirmed_by": (),
     "learned_holds": {"sigma_t": True, "E_t": True},
     "misspecified": (),
     "misspecified_90": None},
)
#: posterior_form's keys that say where a form was scored, not what it is
_NOT_FORM = ("scored_by", "form_scored_on", "misspecified_90")
#: the level at which a learned parameter's coverage counts as not holding (the harness's rank-test level)
LEARNED_ALPHA = 0.01


def _form_of(spec, exp: Mapping) -> dict:
    if spec.posterior != "emulator_mcmc":
        return {"posterior": spec.posterior}
    form = {"posterior": spec.posterior, "self_calibrate": bool(spec.self_calibrate),
            "emulator_error": spec.emulator_error, "refine_runs": int(spec.refine_runs)}
    # a data model with the mesh's approximation error is another form: named only where it is on
    block = ((exp.get("observations") or {}).get("model_error") or {}).get("approximation_error") or {}
    if block.get("pairs"):
        form["approximation_error"] = approximation_form(block)
    # every benchmark in SCORED ran the power tempering, before the key existed: the form names its
    # tempering only where it is another, so that such a form matches none of them
    if spec.tempering != "power":
        form["tempering"] = spec.tempering
    # likewise the recalibration, which no benchmark in SCORED used
    if spec.recalibrate != "none":
        form["recalibrate"] = spec.recalibrate
    return form


def approximation_form(block: Mapping) -> dict:
    """The settings of an ``approximation_error`` block that make a form (its defaults filled in)."""
    return {"preset": block.get("preset"), "pairs": int(block["pairs"]),
            "coarse_variability": block.get("coarse_variability", "subtracted")}


def _loop_of(spec, exp: Mapping) -> dict:
    o = exp.get("observations") or {}
    return {"geometry": exp.get("geometry"), "preset": exp.get("preset"), "method": spec.method,
            "ensemble_size": int(spec.ensemble_size), "max_iterations": int(spec.max_iterations),
            "parameters": {p: [float(lo), float(hi)] for p, lo, hi in zip(spec.names, spec.lower, spec.upper)},
            "window_s": [float(o.get("t_start", 0.0)), float(o.get("t_end", float("nan")))]}


def posterior_form(spec, exp: Mapping) -> dict:
    """summary.json's ``posterior_form``: the reported posterior's form (``posterior`` and, for the emulator
    MCMC, its self-calibration, emulator error and refinement runs, and the approximation error where it is
    on); ``scored_by``, the benchmark JSON of
    the coverage harness that scored this form on this loop (:data:`SCORED`), or None: intervals no
    coverage benchmark has scored; ``form_scored_on``, where another loop's twins scored the same form
    (``{"benchmark", "loop"}``), or None; ``misspecified_90`` (where the form was scored on misspecified
    twins), their benchmarks and per parameter the 90 % intervals that held the truth."""
    form, loop = _form_of(spec, exp), _loop_of(spec, exp)
    same_form = [s for s in SCORED if s["form"] == form]
    scored = next((s["benchmark"] for s in same_form if _same_loop(s["loop"], loop)), None)
    other = next(({"benchmark": s["benchmark"], "loop": s["loop"]} for s in same_form
                  if not _same_loop(s["loop"], loop)), None)
    out = {**form, "scored_by": scored, "form_scored_on": None if scored else other}
    mis = misspecified_90(form)
    return {**out, "misspecified_90": mis} if mis else out


def misspecified_90(posterior_form_: Mapping | None) -> dict | None:
    """How the harness's misspecified twins' 90 % intervals held under the scored form equal to
    ``posterior_form_`` (its form keys; :data:`SCORED`'s ``misspecified_90``): ``{"benchmarks": [...],
    parameter: {"covered", "n"}}``, None for a form never scored on such twins."""
    if not isinstance(posterior_form_, Mapping):
        return None
    form = {k: v for k, v in posterior_form_.items() if k not in _NOT_FORM}
    mis = next((s for s in SCORED if s["form"] == form and s.get("misspecified_90")), None)
    if mis is None:
        return None
    return {"benchmarks": list(mis["misspecified"]),
            **{p: {"covered": k, "n": n} for p, (k, n) in mis["misspecified_90"].items()}}


def learned_holds(posterior_form_: Mapping | None) -> dict:
    """``{parameter: bool}`` of the first scored form equal to summary.json's ``posterior_form`` (its form keys;
    :data:`SCORED`'s ``learned_holds``), ``{}`` for a form no benchmark scored. Where it is False, the
    harness's twins showed that this form's intervals for that parameter are too sure exactly where the
    product calls it learned."""
    if not isinstance(posterior_form_, Mapping):
        return {}
    form = {k: v for k, v in posterior_form_.items() if k not in _NOT_FORM}
    return dict(next((s["learned_holds"] for s in SCORED if s["form"] == form), {}))


def _same_loop(a: Mapping, b: Mapping) -> bool:
    """The same loop: equal settings, the same parameters with boxes and the same window to 1e-12."""
    def numbers(loop):
        box = loop["parameters"]
        return [x for p in sorted(box) for x in box[p]] + list(loop["window_s"])
    rest = [k for k in a if k not in ("parameters", "window_s")]
    return (set(a) == set(b) and all(a[k] == b[k] for k in rest) and sorted(a["parameters"]) == sorted(b["parameters"])
            and np.allclose(numbers(a), numbers(b), rtol=1e-12, atol=0.0))
