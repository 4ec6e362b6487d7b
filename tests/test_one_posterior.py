"""The reported posterior (issue 52): every experiment of the shipped configs, twin or measured, reports the
form the validation harness (benchmarks/bench_coverage.py) scores, `emulator_mcmc` with the AR(1) emulator
error, self-calibration and a refinement batch (the schema's default, stated once in config/schema.yaml and
in calibration.experiment.ExperimentSpec); the default run's summaries say so; and a measured experiment's
closing-the-loop diagnosis starts from the workflow's own posterior (one base posterior per run).

The heteroscedastic emulator error, the twins' form before, returned the prior box on the default run's
measured marble: its log-determinant, not the fit, set the self-calibration factor
(studies/posterior_forms_measured.py)."""
from __future__ import annotations

import json

import pytest

from _shipped import REPO, shipped_experiments
from calibration.closing import base_posterior_mismatches

HARNESS_FORM = {"posterior": "emulator_mcmc", "self_calibrate": True, "emulator_error": "ar1", "refine_runs": 25}
RUN = REPO / "benchmarks" / "results" / "default_run"


def _spec(key):
    from calibration.experiment import ExperimentSpec

    name, exp = shipped_experiments()[key]
    return ExperimentSpec.from_config(name, exp), exp


def _form(spec) -> dict:
    return {"posterior": spec.posterior, "self_calibrate": spec.self_calibrate,
            "emulator_error": spec.emulator_error, "refine_runs": spec.refine_runs}


def test_every_shipped_experiment_reports_the_harness_form():
    keys = [k for k, (_, exp) in shipped_experiments().items() if exp.get("parameters") != "auto"]
    kinds = {shipped_experiments()[k][1]["kind"] for k in keys}
    assert len(keys) >= 10 and kinds == {"twin", "measured"}
    for key in keys:
        assert _form(_spec(key)[0]) == HARNESS_FORM, key


def test_the_schema_and_the_spec_state_the_same_default_form():
    """The form is stated twice, for the config (the schema's defaults) and for code that builds a spec
    from a bare experiment dict: both say the same."""
    from calibration.experiment import ExperimentSpec
    from calibration.workflow_io import load_yaml

    props = load_yaml(REPO / "config" / "schema.yaml")["properties"]["experiments"]["additionalProperties"]["properties"]
    em = props["emulated"]["properties"]
    assert {"posterior": props["posterior"]["default"], "self_calibrate": em["self_calibrate"]["default"],
            "emulator_error": em["emulator_error"]["default"], "refine_runs": em["refine_runs"]["default"]} == HARNESS_FORM
    assert _form(ExperimentSpec) == HARNESS_FORM
    assert em["refine_temper"]["default"] == ExperimentSpec.refine_temper
    from enkf.selfcal import TEMPERINGS

    assert em["tempering"]["enum"] == list(TEMPERINGS) and em["tempering"]["default"] == ExperimentSpec.tempering
    from enkf.selfcal import RECALIBRATIONS

    assert em["recalibrate"]["enum"] == list(RECALIBRATIONS)
    assert em["recalibrate"]["default"] == ExperimentSpec.recalibrate == "none"


@pytest.mark.parametrize("exp", ["twin_ref", "marble_loop", "planted_gap"])
def test_the_default_runs_summaries_name_their_posterior(exp):
    summary = json.loads((RUN / exp / "summary.json").read_text())
    assert summary["posterior_method"] == "emulator_mcmc"
    assert {k: summary["posterior_form"][k] for k in HARNESS_FORM} == HARNESS_FORM


@pytest.mark.parametrize("exp", ["marble_loop", "planted_gap"])
def test_the_default_runs_diagnosis_base_model_is_its_posterior(exp):
    summary = json.loads((RUN / exp / "summary.json").read_text())
    report = json.loads((RUN / exp / "diagnosis" / "report.json").read_text())
    assert report["base_posterior"] == "workflow"
    assert base_posterior_mismatches(summary, report) == []


def test_each_scored_form_is_its_benchmarks_and_the_default_twins():
    """calibration.scored.SCORED names the form and loop its benchmark JSONs scored: each JSON records the
    same form and loop settings, and the loop is config/config.yaml's twin_ref (the harness's twin), whose
    summary names the benchmark of the form it reports."""
    from calibration.scored import SCORED, posterior_form

    spec, exp = _spec("config.yaml:twin_ref")
    for entry in SCORED:
        for path in (entry["benchmark"], *entry["confirmed_by"]):
            bench = json.loads((REPO / path).read_text())
            assert bench["experiment"] == "twin_ref"
            assert {"posterior": bench["reported_posterior"], "self_calibrate": bench["self_calibrate"],
                    "emulator_error": bench["emulator_error"], "refine_runs": bench["refine_runs"]} == entry["form"]
            # the keys the form names only where they differ from these (calibration.scored._form_of)
            assert (bench.get("tempering", "power"), bench.get("recalibrate", "none")) == ("power", "none"), path
            loop = entry["loop"]
            assert (bench["method"], bench["ensemble_size"], bench["window_s"]) == (
                loop["method"], loop["ensemble_size"], loop["window_s"]), path
    shipped = [s for s in SCORED if s["form"] == HARNESS_FORM]
    assert len(shipped) == 1
    assert posterior_form(spec, exp)["scored_by"] == shipped[0]["benchmark"]


def test_each_scored_form_says_where_its_learned_intervals_held():
    """SCORED's learned_holds is its benchmark's split by the product's flag (benchmarks/scores.py): a
    parameter's learned intervals hold unless their 90 % coverage is rejected at LEARNED_ALPHA."""
    from benchmarks.scores import pooled_learned_coverage
    from calibration.scored import LEARNED_ALPHA, SCORED, learned_holds

    for entry in SCORED:
        benches = [json.loads((REPO / path).read_text()) for path in (entry["benchmark"], *entry["confirmed_by"])]
        # the twins of every JSON pooled: one binomial test of the learned intervals' 90 % coverage
        assert entry["learned_holds"] == {p: pooled_learned_coverage(benches, p)["p"] >= LEARNED_ALPHA
                                          for p in ("sigma_t", "E_t")}, entry["benchmark"]
        assert learned_holds({**entry["form"], "scored_by": None}) == entry["learned_holds"]
    assert learned_holds({"posterior": "ensemble"}) == {} and learned_holds(None) == {}


def test_a_summary_says_whether_its_form_was_scored():
    """Another ensemble size, another prior box, another preset or another form is not the scored loop:
    its summary says so (scored_by None) and names where the same form was scored, as every measured
    experiment's does."""
    from dataclasses import replace

    from calibration.scored import SCORED, posterior_form

    shipped = next(s for s in SCORED if s["form"] == HARNESS_FORM)
    spec, exp = _spec("config.yaml:twin_ref")
    other = posterior_form(replace(spec, ensemble_size=24), exp)
    assert other["scored_by"] is None and other["form_scored_on"]["benchmark"] == shipped["benchmark"]
    assert other["form_scored_on"]["loop"]["ensemble_size"] == 25
    assert posterior_form(spec, exp)["form_scored_on"] is None
    assert posterior_form(replace(spec, upper=spec.upper * 1.1), exp)["scored_by"] is None
    assert posterior_form(spec, {**exp, "preset": "standard"})["scored_by"] is None
    assert posterior_form(replace(spec, refine_runs=0), exp)["scored_by"] is None
    # the curvature tempering was scored on development twins only: no benchmark's form
    assert posterior_form(replace(spec, tempering="curvature"), exp) == {
        **HARNESS_FORM, "tempering": "curvature", "scored_by": None, "form_scored_on": None}
    # the location recalibration is under test (benchmarks/coverage_plan_location.json): no benchmark's form yet
    assert posterior_form(replace(spec, recalibrate="location"), exp) == {
        **HARNESS_FORM, "recalibrate": "location", "scored_by": None, "form_scored_on": None}
    assert posterior_form(replace(spec, emulator_error="heteroscedastic"), exp)["scored_by"] == \
        "benchmarks/results/coverage_well_specified.json"
    assert posterior_form(replace(spec, posterior="ensemble"), exp) == {
        "posterior": "ensemble", "scored_by": None, "form_scored_on": None}
    marble, mexp = _spec("config.yaml:marble_loop")
    assert posterior_form(marble, mexp) == {**HARNESS_FORM, "scored_by": None,
                                            "form_scored_on": {"benchmark": shipped["benchmark"], "loop": shipped["loop"]}}


def test_summary_html_says_whether_the_intervals_were_scored():
    from calibration.report_summary import _scored

    assert "scored by the coverage harness, benchmarks/results/x.json" in _scored(
        {"posterior_form": {"posterior": "emulator_mcmc", "scored_by": "benchmarks/results/x.json"}})
    assert "no coverage benchmark has scored this form" in _scored({"posterior_form": {"posterior": "ensemble",
                                                                                        "scored_by": None}})
    assert "not recorded" in _scored({})
    assert "the same form is scored on another loop's twins, benchmarks/results/y.json" in _scored(
        {"posterior_form": {"scored_by": None, "form_scored_on": {"benchmark": "benchmarks/results/y.json", "loop": {}}}})
