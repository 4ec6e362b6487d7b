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
            form = {"posterior": bench["reported_posterior"], "self_calibrate": bench["self_calibrate"],
                    "emulator_error": bench["emulator_error"], "refine_runs": bench["refine_runs"]}
            if bench.get("approximation_pairs"):
                # the harness makes the pairs at the preset a lab's records get (init-config's block)
                from shpb.lab.init_config_yaml import APPROXIMATION_ERROR

                form["approximation_error"] = {"preset": APPROXIMATION_ERROR["preset"], "pairs": bench["approximation_pairs"],
                                               "coarse_variability": bench["coarse_variability"]}
            assert form == entry["form"], path
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
        sets = entry.get("learned_on", ("well_specified",))
        # the twins of every JSON pooled: one binomial test of the learned intervals' 90 % coverage
        assert entry["learned_holds"] == {p: pooled_learned_coverage(benches, p, sets)["p"] >= LEARNED_ALPHA
                                          for p in ("sigma_t", "E_t")}, entry["benchmark"]
        assert learned_holds({**entry["form"], "scored_by": None, "misspecified_90": None}) == entry["learned_holds"]
    assert learned_holds({"posterior": "ensemble"}) == {} and learned_holds(None) == {}


def test_each_scored_form_quotes_its_misspecified_twins():
    """SCORED's misspecified_90 is its misspecified JSONs' twins pooled (benchmarks.scores.pooled_coverage_90):
    the shipped form held 81 and 79 of 100, with the approximation error 51 and 56 of 60; a summary carries
    the counts of its form, whatever its loop."""
    from benchmarks.scores import pooled_coverage_90
    from calibration.scored import SCORED, posterior_form

    for entry in SCORED:
        benches = [json.loads((REPO / path).read_text()) for path in entry["misspecified"]]
        want = {p: pooled_coverage_90(benches, p, ("misspecified", "misspecified_rate")) for p in ("sigma_t", "E_t")}
        got = entry["misspecified_90"]
        assert (got is None and not benches) or got == {p: (q["covered"], q["n"]) for p, q in want.items()}
    shipped = next(s for s in SCORED if s["form"] == HARNESS_FORM)
    assert shipped["misspecified_90"] == {"sigma_t": (81, 100), "E_t": (79, 100)}
    marble, mexp = _spec("config.yaml:marble_loop")
    assert posterior_form(marble, mexp)["misspecified_90"] == {
        "benchmarks": list(shipped["misspecified"]), "sigma_t": {"covered": 81, "n": 100}, "E_t": {"covered": 79, "n": 100}}


def test_a_lab_config_names_its_approximation_error_and_its_scores():
    """init-config's approximation error (shpb.lab.init_config_yaml.APPROXIMATION_ERROR) is a form of its own:
    a measured experiment with it names it, points to the benchmark that scored it on the harness's loop and
    quotes that benchmark's misspecified twins, not the shipped form's."""
    from calibration.scored import SCORED, posterior_form
    from shpb.lab.init_config_yaml import APPROXIMATION_ERROR

    marble, mexp = _spec("config.yaml:marble_loop")
    obs = {**mexp["observations"], "model_error": {**mexp["observations"]["model_error"],
                                                   "approximation_error": dict(APPROXIMATION_ERROR)}}
    form = posterior_form(marble, {**mexp, "observations": obs})
    entry = next(s for s in SCORED if "approximation_error" in s["form"])
    assert form["approximation_error"] == entry["form"]["approximation_error"]
    assert form["scored_by"] is None and form["form_scored_on"]["benchmark"] == entry["benchmark"]
    assert form["misspecified_90"]["sigma_t"] == {"covered": 51, "n": 60}
    assert form["misspecified_90"]["E_t"] == {"covered": 56, "n": 60}


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
    form = posterior_form(marble, mexp)
    assert {k: v for k, v in form.items() if k != "misspecified_90"} == {
        **HARNESS_FORM, "scored_by": None, "form_scored_on": {"benchmark": shipped["benchmark"], "loop": shipped["loop"]}}


def test_summary_html_says_whether_the_intervals_were_scored():
    from calibration.report_summary import _scored

    assert "scored by the coverage harness, benchmarks/results/x.json" in _scored(
        {"posterior_form": {"posterior": "emulator_mcmc", "scored_by": "benchmarks/results/x.json"}})
    assert "no coverage benchmark has scored this form" in _scored({"posterior_form": {"posterior": "ensemble",
                                                                                        "scored_by": None}})
    assert "not recorded" in _scored({})
    # a measured record's summary says how its form fared on misspecified twins, and names the form that did
    # better where its intervals held under 90 %; a twin's does not
    from calibration.report_summary import _misspecified, _parameters

    mis = {"benchmarks": ["benchmarks/results/m.json"], "sigma_t": {"covered": 81, "n": 100},
           "E_t": {"covered": 79, "n": 100}}
    text = _misspecified({"scored_by": None, "misspecified_90": mis})
    assert "held the truth in sigma_t 81 of 100, E_t 79 of 100 (benchmarks/results/m.json)" in text
    assert "too narrow" in text and "approximation_error" in text
    post = {"sigma_t": {"mean": 3e7, "q05": 2e7, "q95": 4e7}}
    form = {"scored_by": None, "misspecified_90": mis}
    assert "misspecified" in "".join(_parameters({"posterior": post, "posterior_form": form}))
    assert "misspecified" not in "".join(_parameters({"posterior": post, "posterior_form": form,
                                                      "truth": {"sigma_t": 3e7}}))
    good = {**mis, "sigma_t": {"covered": 95, "n": 100}, "E_t": {"covered": 92, "n": 100}}
    assert "too narrow" not in _misspecified({"scored_by": None, "misspecified_90": good})
    with_term = _misspecified({"scored_by": None, "approximation_error": {"pairs": 24}, "misspecified_90": mis})
    assert "79 of 100" in with_term and "too narrow" not in with_term
    assert _misspecified({"posterior": "ensemble", "scored_by": None}) == "" and _misspecified(None) == ""
    # a summary written before the key: its form finds the scores (the committed default run's marble)
    marble = json.loads((RUN / "marble_loop" / "summary.json").read_text())
    text = _misspecified(marble["posterior_form"])
    assert "held the truth in sigma_t 81 of 100, E_t 79 of 100" in text
    assert "such twins' intervals held sigma_t 51 of 60, E_t 56 of 60" in text
    assert "the same form is scored on another loop's twins, benchmarks/results/y.json" in _scored(
        {"posterior_form": {"scored_by": None, "form_scored_on": {"benchmark": "benchmarks/results/y.json", "loop": {}}}})
