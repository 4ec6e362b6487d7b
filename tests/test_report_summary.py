"""The summary the HTML report opens on (issue 34, item 4): ``results/<exp>/summary.html`` from
``summary.json`` (and the diagnosis's ``check.json``), shown first on the report's page through
``report/workflow.rst``. Fixtures: the committed default-run summaries of 2026-11-25."""
from __future__ import annotations

import json
from html import unescape as html_unescape
import re
from pathlib import Path

from calibration.report_summary import summary_html

REPO = Path(__file__).resolve().parents[1]
RUN = REPO / "benchmarks" / "results" / "default_run_2026-11-25"


def _cells(html: str) -> list[list[str]]:
    """The rows of every table as lists of cell texts."""
    return [re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", row) for row in re.findall(r"<tr>(.*?)</tr>", html)]


def test_the_summary_gives_verdict_intervals_misfit_per_iteration_and_the_heldout_errors():
    summary = json.loads((RUN / "marble_loop" / "summary.json").read_text())
    check = json.loads((RUN / "marble_loop" / "diagnosis_check.json").read_text())
    html = summary_html("marble_loop", summary, check)
    assert html.isascii()
    assert "<b>Verdict: not_converged</b> (flags: not_converged, misfit_unexplained)" in html
    rows = _cells(html)
    # parameters: posterior mean and 90 % interval, stresses in MPa
    assert ["sigma_t", "42.42", "[39.14, 45.12]", "MPa"] in rows
    assert ["E_t", "2.683e+04", "[2.19e+04, 3.493e+04]", "J/m^2"] in rows
    # misfit per iteration: members ok, median member chi2/obs against the noise, the stop statistic, RMSE
    assert ["0", "8", "5048", "2.31", "40.73"] in rows
    assert ["2 (reported)", "8", "890.4", "1.489", "22.73"] in rows
    assert "target 1.149" in html
    # the diagnosis: effects kept and the FDEM errors before/after, the held-out record last
    assert "effects kept: face_gap, trigger_shift" in html
    # a check made before the bands were scored: their cells say so
    assert rows[-1] == ["CaMa_SHPB_005", "held out", "18.64", "11.59", "-1.3", "+10.4", "?", "?", "?"]
    assert ["CaMa_SHPB_004", "calibration", "17.25", "13.59", "+2.1", "+11.9", "?", "?", "?"] in rows


def test_the_diagnosis_shows_each_record_s_band_coverage_and_its_score_over_the_design_box():
    check = json.loads((REPO / "benchmarks" / "results" / "loro_rerun_sandstone" / "SeeSst_SHPB_023_check.json")
                       .read_text())
    rows = _cells(summary_html("sandstone_unseen__SeeSst_SHPB_023", {"verdict": "ok"}, check))
    band = check["predictive_band"]["records"]["SeeSst_SHPB_023"]
    assert rows[-1][0] == "SeeSst_SHPB_023" and rows[-1][1] == "held out"
    assert rows[-1][-3:] == [f"{band['after']['predictive_coverage_90']:.2f}",
                             f"{band['before']['interval_score_over_box']:.2f}",
                             f"{band['after']['interval_score_over_box']:.2f}"]


def test_the_diagnosis_says_its_records_are_compared_less_the_mesh_error_only_where_they_were_corrected():
    summary = json.loads((RUN / "marble_loop" / "summary.json").read_text())
    check = json.loads((RUN / "marble_loop" / "diagnosis_check.json").read_text())
    assert "mesh's mean error" not in summary_html("marble_loop", summary, check)
    approx = {"fine_preset": "standard", "coarse_preset": "fast", "n_pairs_used": 24}
    html = html_unescape(summary_html("marble_loop", {**summary, "approximation_error": approx}, check))
    assert "the held-out records' too, are the observed stress less the fast mesh's mean error against standard" in html


def test_a_twin_shows_its_truth_against_the_interval_and_no_diagnosis():
    html = summary_html("twin_ref", json.loads((RUN / "twin_ref" / "summary.json").read_text()))
    rows = _cells(html)
    assert ["sigma_t", "43.27", "[39.7, 46.28]", "MPa", "45 (inside)"] in rows
    assert ["E_t", "561.2", "[347.3, 807.6]", "J/m^2", "500 (inside)"] in rows
    assert "Diagnosis" not in html and "Verdict: not_converged" in html


def test_odd_or_missing_values_give_question_marks_never_an_error():
    html = summary_html("x", {"verdict": "ok", "posterior": {"a": None}, "misfit": [{"iteration": 0}]})
    assert "Verdict: ok" in html and ["a", "?", "[?, ?]", ""] in _cells(html)
    assert "summary not readable" in summary_html("y", None)


def test_the_report_page_opens_on_the_summaries_in_run_order(tmp_path):
    """report/workflow.rst rendered as Snakemake renders it (Jinja2, then docutils to HTML) with two
    summary files in the "0 Summary" category: both tables appear, in the config's run order."""
    from docutils.core import publish_parts
    from docutils.writers import get_writer_class
    from jinja2 import Environment

    class Cat:
        def __init__(self, name):
            self.name = name

    class Res:
        def __init__(self, path):
            self.path = path

    results = []
    for exp in ("marble_loop", "twin_ref"):
        (tmp_path / exp).mkdir()
        (tmp_path / exp / "summary.html").write_text(summary_html(exp, json.loads((RUN / exp / "summary.json").read_text())))
        results.append(Res(tmp_path / exp / "summary.html"))

    class Snakemake:
        config = {"run": ["twin_ref", "marble_loop"], "experiments": {}}

    text = Environment(trim_blocks=True, lstrip_blocks=True).from_string(
        (REPO / "report" / "workflow.rst").read_text()).render(
        snakemake=Snakemake, categories={Cat("0 Summary"): {Cat("Other"): results}, Cat("twin_ref"): {}}, files=[])
    html = publish_parts(text, writer=get_writer_class("html")())["html_body"]  # writer_name is deprecated
    assert re.findall(r"<h3[^>]*>(\w+)</h3>", html) == ["twin_ref", "marble_loop"]
    assert "[39.14, 45.12]" in html and "[39.7, 46.28]" in html and "System Message" not in html
    assert html.index("Verdict") < html.index("Each experiment's files")


def test_a_tiny_run_logs_each_iteration_and_its_report_opens_on_the_summary(tmp_path):
    """Three members of the analytic stand-in simulator, one ES-MDA analysis, on one core (about 20 s):
    the run's output has one misfit line per analysis, the run writes summary.html, and
    `snakemake --report` puts the summary into the report's first page and its "0 Summary" category."""
    from test_workflow import snakemake, twin_config, write_config, write_stand_in

    cfg = twin_config(ensemble_size=3, esmda={"steps": 1})
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    run = snakemake(tmp_path, "--cores", "1")
    assert run.returncode == 0, run.stderr[-3000:]
    lines = [ln for ln in run.stdout.splitlines() if ln.startswith("twin iteration ")]
    assert [ln.split(":")[0] for ln in lines] == ["twin iteration 0", "twin iteration 1"], run.stdout[-2000:]
    analysis = json.loads((tmp_path / "results" / "twin" / "iter_1" / "analysis.json").read_text())
    assert f"median member chi2/obs {analysis['decision']['values']['chi2_per_obs']:.4g} " in lines[1]
    assert "3/3 members ok" in lines[1] and "-> stop: " in lines[1]
    summary = json.loads((tmp_path / "results" / "twin" / "summary.json").read_text())
    page = (tmp_path / "results" / "twin" / "summary.html").read_text()
    assert page == summary_html("twin", summary)

    rep = snakemake(tmp_path, "--cores", "1", "--report", str(tmp_path / "report.html"))
    assert rep.returncode == 0, rep.stderr[-3000:]
    html = (tmp_path / "report.html").read_text()
    desc = html[html.index("workflow_desc = "):]
    desc = desc[:desc.index("\n")]
    verdict = summary["verdict"]["verdict"]
    assert f"Verdict: {verdict}" in desc and "Misfit per iteration" in desc
    q = summary["posterior"]["sigma_t"]
    assert f"[{q['q05'] * 1e-6:.4g}, {q['q95'] * 1e-6:.4g}]" in desc
    assert "0 Summary" in html


def test_the_summary_lists_the_walk_a_refuted_choice_and_the_alternative_confirmed_after_it():
    """The default run's marble: its two confirmed steps in the page, in order; and a walk whose first
    proposal was refuted and its round's next one confirmed (the marble's check with those two steps)."""
    run = REPO / "benchmarks" / "results" / "default_run" / "marble_loop"
    check = json.loads((run / "diagnosis" / "check.json").read_text())
    summary = json.loads((run / "summary.json").read_text())

    def walk_items(chk):
        html = summary_html("marble_loop", summary, chk)
        return [html_unescape(i) for i in
                re.findall(r"<li>(.*?)</li>", html.split("The walk on real FDEM runs:")[1].split("</ol>")[0])]

    steps = check["fdem_confirmation"]["steps"]
    assert walk_items(check) == [st["text"] for st in steps]
    assert len(steps) == 2 and all(st["text"].endswith("confirmed") for st in steps)
    refuted = {**steps[0], "confirmed": False,
               "text": "gauge_gain over base: real cross-validated RMSE 2.1e+07 -> 1.6e+07; ... refuted, dropped; "
                       "the round's next proposal is tried"}
    alt = {**steps[1], "alternative_to": 1,
           "text": "face_gap (alternative to step 1) over base: ... confirmed; the walk stops (the later rounds were "
                   "chosen given the refuted one)"}
    items = walk_items({**check, "fdem_confirmation": {**check["fdem_confirmation"], "steps": [refuted, alt]}})
    assert items == [refuted["text"], alt["text"]]
    assert "refuted" in items[0] and "(alternative to step 1)" in items[1]


def test_the_errors_table_shows_the_band_score_before_and_after_beside_the_rmse():
    """A held-out record whose RMSE rises while its band's proper score falls (a planted trigger shift
    named as a baseline offset: the pre-peak fits better, the post-peak scatter rules the RMSE) shows
    both moves on the page, so a lab sees which way the prediction went on each measure."""
    errors = {"H": {"data": "heldout", "before": {"rmse": 8.16e6, "peak_rel_error": 0.072},
                    "after": {"rmse": 9.87e6, "peak_rel_error": 0.053}}}
    bands = {"H": {"before": {"predictive_coverage_90": 0.99, "interval_score_over_box": 0.665},
                   "after": {"predictive_coverage_90": 0.84, "interval_score_over_box": 0.579}}}
    html = summary_html("series", {"experiment": "series"},
                        {"verdict": "confirmed", "added": ["baseline"], "errors_per_record": errors,
                         "predictive_band": {"records": bands}})
    header, row = _cells(html[html.index("Errors of real FDEM runs"):])[:2]
    assert header[-3:] == ["band covers", "band score / box before", "band score / box after"]
    assert row == ["H", "held out", "8.16", "9.87", "+7.2", "+5.3", "0.84", "0.67", "0.58"]


def test_a_learned_parameter_the_harness_found_too_sure_is_read_as_the_prior_narrowed():
    """The default run's marble (the shipped form): its E_t expects 0.39 of the prior's score, learned by the
    flag, but the coverage harness's twins with E_t learned held the truth 10 of 16 times at 90 %
    (calibration.scored.learned_holds): the page says to read it as the prior narrowed; sigma_t, whose
    learned intervals held, reads learned; a form no benchmark scored reads learned."""
    summary = json.loads((REPO / "benchmarks" / "results" / "default_run" / "marble_loop" / "summary.json").read_text())
    rows = {r[0]: r for r in _cells(summary_html("marble_loop", summary))}
    e_t, sig = summary["posterior"]["E_t"]["score_over_prior"], summary["posterior"]["sigma_t"]["score_over_prior"]
    assert e_t <= 0.55 and sig <= 0.55
    assert rows["E_t"][4].startswith(f"{e_t:.2f} (learned, but on the coverage harness's twins") and \
        rows["E_t"][4].endswith("read it as the prior narrowed)")
    assert rows["sigma_t"][4] == f"{sig:.2f} (learned)"
    other = {**summary, "posterior_form": {**summary["posterior_form"], "refine_runs": 0}}
    assert {r[0]: r for r in _cells(summary_html("marble_loop", other))}["E_t"][4] == f"{e_t:.2f} (learned)"


def _in_short(html: str) -> str:
    return html_unescape(re.sub(r"<[^>]+>", "", re.search(r"<b>In short.*?</p>", html, re.S).group(0)))


def test_the_page_opens_on_the_answer_the_calibrated_values_and_the_shipped_model_s_beside_them():
    """The default run's planted series: the page's first paragraph after the verdict names the shipped model,
    the calibrated sigma_t and E_t with their 90 % intervals (summary.json, to the digits shown), then the
    same parameters re-fitted under the shipped model (refit.json), says which to quote, and gives the
    held-out record's RMSE before -> after and its band's coverage (check.json). The calibrated interval is
    the one to quote: here it holds the planted sigma_t (25 MPa), the re-fit's narrower one does not."""
    run = REPO / "benchmarks" / "results" / "default_run" / "planted_gap"
    summary, check, refit = (json.loads((run / f).read_text()) for f in
                             ("summary.json", "diagnosis/check.json", "diagnosis/refit.json"))
    text = _in_short(summary_html("planted_gap", summary, check, refit))
    post, fit = summary["posterior"]["sigma_t"], refit["posterior"]["sigma_t"]
    assert text.startswith("In short. This run ships base + face_gap (each effect confirmed on real FDEM runs")
    calibrated = f"sigma_t {post['mean'] / 1e6:.3g} MPa (90 %: {post['q05'] / 1e6:.3g} to {post['q95'] / 1e6:.3g})"
    shipped = f"sigma_t {fit['mean'] / 1e6:.3g} MPa (90 %: {fit['q05'] / 1e6:.3g} to {fit['q95'] / 1e6:.3g})"
    assert text.index(calibrated) < text.index("Under the shipped model") < text.index(shipped)
    assert post["q05"] <= 25e6 <= post["q95"] and not fit["q05"] <= 25e6 <= fit["q95"]
    assert "Quote the calibrated intervals" in text
    h = check["heldout"]["PlantGap_03"]
    cover = check["predictive_band"]["records"]["PlantGap_03"]["after"]["predictive_coverage_90"]
    assert (f"PlantGap_03 {h['before']['rmse'] / 1e6:.3g} -> {h['after']['rmse'] / 1e6:.3g} MPa, its 90 % band "
            f"holding {cover:.2f} of its curve") in text


def test_the_answer_says_where_an_interval_runs_into_the_prior_box_and_when_the_base_model_is_kept():
    """An interval that ends on the prior box's top is a lower bound, said so (the marble's re-fitted E_t ends
    on 50 kJ/m^2, the box's top); a base model kept quotes the calibration alone; a twin (no diagnosis) has no
    short answer; no held-out record is said, not hidden."""
    run = REPO / "benchmarks" / "results" / "default_run" / "marble_loop"
    summary, check, refit = (json.loads((run / f).read_text()) for f in
                             ("summary.json", "diagnosis/check.json", "diagnosis/refit.json"))
    assert refit["posterior"]["E_t"]["q95"] == summary["prior"]["E_t"]["upper"]
    text = _in_short(summary_html("marble_loop", summary, check, refit))
    shipped = text.split("Under the shipped model")[1]
    assert "E_t 35.1 kJ/m^2 (90 %: 15.7 to 50; it runs to the prior box's upper end: read it as a lower bound)" \
        in shipped
    # the calibrated E_t is learned by its score but the harness found such intervals too sure
    assert "read it as the prior narrowed" in text.split("Under the shipped model")[0]
    kept = _in_short(summary_html("marble_loop", summary, {**check, "added": [], "heldout": {}}, None))
    assert "ships the base model (no effect the loop tried" in kept and "Under the shipped model" not in kept
    assert "No record was held out" in kept
    assert "In short" not in summary_html("twin_ref", json.loads(
        (REPO / "benchmarks" / "results" / "default_run" / "twin_ref" / "summary.json").read_text()))


def test_the_selection_on_real_runs_is_shown_beside_the_walk_with_its_group():
    summary = json.loads((RUN / "marble_loop" / "summary.json").read_text())
    check = json.loads((RUN / "marble_loop" / "diagnosis_check.json").read_text())
    cand = {"seating": {"fit": {"sigma_t": 2.45e7, "E_t": 1.2e4, "seating.compliance_m_per_Pa@A": 1.06e-12},
                        "z": 21.78, "p": 5.6e-11},
            "rate_strength": {"fit": {"sigma_t": 1.61e7, "E_t": 1.1e4, "rate_strength.k": 0.37}, "z": 6.76,
                              "p": 6.0e-6, "interval_90": {"q05": {"rate_strength.k": 0.31}, "q95": {"rate_strength.k": 0.43}}}}
    real = {"named": "seating", "group": ["seating", "rate_strength"], "level": 0.005, "candidates": cand,
            "runs": 1251, "check_meshes": 8}
    html = summary_html("marble_loop", summary, check, None, real)
    assert html.isascii()
    assert "<b>seating</b> is named" in html and "do not tell it apart from rate_strength" in html
    assert "1251 FDEM runs" in html and "beside the walk" in html and "diagnosis/realrun.json" in html
    rows = _cells(html)
    assert ["rate_strength", "rate_strength.k 0.37 [0.31, 0.43]", "16.1", "6.76", "6e-06"] in rows
    alone = summary_html("marble_loop", summary, check, None, {**real, "group": ["seating"],
                                                                 "versus": {"rate_strength": {"z": 17.6}}})
    assert "it beats rate_strength, which passed too" in alone
    assert "no other candidate passed" in summary_html("marble_loop", summary, check, None,
                                                       {**real, "group": ["seating"], "versus": {}})
    kept = summary_html("marble_loop", summary, check, None, {**real, "named": "base_kept", "group": []})
    assert "the base model is kept" in kept and "is named" not in kept
    # without the selection on real runs, the page has no such paragraph
    assert "selection on real runs" not in summary_html("marble_loop", summary, check)
    assert "Corrected for the mesh" not in alone
    # the resolution round's corrected fit, where it ran: the values to quote
    res = {"track": "seating", "preset": "standard", "meshes": 4, "bias_rms": {"A": 2.4e6},
           "fit": {"sigma_t": 2.30e7, "seating.compliance_m_per_Pa@A": 1.04e-12},
           "interval_90": {"q05": {"sigma_t": 2.13e7}, "q95": {"sigma_t": 2.47e7}}}
    corrected = summary_html("marble_loop", summary, check, None, {**real, "resolution": res})
    assert "Corrected for the mesh: seating's fit run on 4 meshes at <code>standard</code>" in corrected
    assert "sigma_t 23 [21.3, 24.7] MPa" in corrected and "These are the values to quote" in corrected
    # the held-out records' errors at the selection's fits, where it ran them
    held = {"records": {"H1": {"before": {"rmse": 20.4e6, "peak_rel_error": 0.119},
                               "after": {"rmse": 12.1e6, "peak_rel_error": -0.021}}}, "runs": 16}
    shown = summary_html("marble_loop", summary, check, None, {**real, "heldout": held})
    assert "The held-out records predicted from these fits, made without them" in shown
    assert ["H1", "20.4", "+11.9", "12.1", "-2.1"] in _cells(shown)
    assert "held-out records predicted" not in corrected
