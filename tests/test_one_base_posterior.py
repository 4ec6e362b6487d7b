"""One run, one base posterior (issue 52): the diagnosis's base model is the workflow's reported posterior
(posterior.csv with summary.json's estimates), not a second ES-MDA on the emulator.

On the exact stand-in of tests/test_protocol_shpb.py (five calibration records, one held out; the
emulator is the analytic curve itself): the workflow's posterior is given as files in the workflow's two
formats, an ensemble's member table with its t prediction intervals (``posterior: ensemble``) and an MCMC
sample (``posterior: emulator_mcmc``), each summarised by the function the workflow's summary uses.
"""

import json

import numpy as np
import pandas as pd
import pytest

from calibration.closing import assemble, base_posterior_mismatches, check_rows, fit_sources
from calibration.diagnose import base_design_box, workflow_sample
from calibration.protocol import MAX_BASE_DRAWS, select, workflow_base
from enkf import BoxTransform, member_table
from enkf.ces import interval_summary
from enkf.diagnosis import crossval, given_fit, protocol
from enkf.diagnostics import prediction_interval_dict
from shpb import effects as fx
from test_protocol_shpb import CALIB, K, LOWER, MODEL_T, NOISE, OBS_T, UPPER, curve, data, emulated

BASE = ["sigma_p", "tau_d"]
POST_FILE = "results/standin/posterior.csv"


def ensemble_files(shift=0.0, seed=4):
    """``(posterior.csv frame, summary.json dict)`` of an ensemble posterior as the workflow writes them:
    8 members, the last one dead (a failed run: its parameters are no draw and lie outside the box)."""
    rng = np.random.default_rng(seed)
    P = np.column_stack([41e6 + shift + 1.2e6 * rng.standard_normal(8), 44e-6 + 1.5e-6 * rng.standard_normal(8)])
    alive = np.ones(8, bool)
    alive[-1] = False
    P[-1] = [90e6, 5e-6]
    frame = member_table(P, BASE, alive=alive)
    post = prediction_interval_dict(P, BASE, alive, BoxTransform(np.array([20e6, 10e-6]), np.array([60e6, 100e-6])))
    summary = {"posterior_method": "ensemble", "posterior_iteration": 3, "posterior": post}
    return json.loads(json.dumps(frame.to_dict(orient="list"))), json.loads(json.dumps(summary))


def mcmc_files(n=5000, seed=5):
    rng = np.random.default_rng(seed)
    S = np.column_stack([40e6 + 1e6 * rng.standard_normal(n), 45e-6 + 1e-6 * rng.standard_normal(n)])
    frame = pd.DataFrame(S, columns=BASE)
    frame.insert(0, "sample", np.arange(n))
    return frame, {"posterior_method": "emulator_mcmc", "posterior_iteration": 3, "posterior": interval_summary(S, BASE)}


def run(model, obs, base, max_additions=0):
    return select(model, base_names=BASE, candidates=[fx.get_effect("face_gap")], calib_records=CALIB,
                  heldout_records=["H"], obs={r: obs[r] for r in CALIB}, noise=NOISE, seed=3, n_members=60,
                  esmda_steps=4, max_additions=max_additions, base_fit=base)


@pytest.fixture
def counted(monkeypatch):
    """Every ES-MDA the protocol runs, as ``(names, records)``."""
    calls = []
    real = crossval.calibrate

    def counting(model, names, records, *a, **kw):
        calls.append((tuple(names), tuple(records)))
        return real(model, names, records, *a, **kw)
    monkeypatch.setattr(crossval, "calibrate", counting)
    monkeypatch.setattr(protocol, "calibrate", counting)
    return calls


def test_the_base_estimates_are_the_workflow_summary_and_its_draws_predict_the_held_out_record(counted):
    model, obs = emulated(), data()
    frame, summary = ensemble_files()
    base = workflow_base(model, BASE, CALIB, pd.DataFrame(frame), summary, file=POST_FILE)
    sel = run(model, obs, base)
    step = sel.steps[0]
    # the report's base estimates are summary.json's, exactly (its t intervals, not the members' quantiles)
    assert step.summary()["posterior"] == summary["posterior"]
    assert step.summary()["posterior_source"] == "workflow" and sel.settings["base_posterior"] == "workflow"
    q = np.quantile(workflow_sample(pd.DataFrame(frame), BASE)[:, 0], 0.05)
    assert abs(summary["posterior"]["sigma_p"]["q05"] - q) > 1e5  # the two summaries differ: the copy is tested
    # no ES-MDA of the base on every calibration record; the base's cross-validation (5 folds) stays on it
    assert (tuple(BASE), tuple(CALIB)) not in counted
    assert len(counted) == len(CALIB) and all(len(r) == len(CALIB) - 1 for _, r in counted)
    # the held-out prediction: at the workflow's mean, its band from the 7 alive members' curves
    pred = step.heldout["H"]
    alive = workflow_sample(pd.DataFrame(frame), BASE)
    assert alive.shape == (7, 2)
    assert pred.point == pytest.approx(dict(zip(BASE, alive.mean(axis=0))), rel=1e-12)
    np.testing.assert_allclose(pred.draws, model.forward(BASE, ["H"])(alive), rtol=0, atol=1e-6)
    # without the workflow's posterior the base is fitted once more on the emulator (the old second posterior)
    counted.clear()
    run(model, obs, None)
    assert counted.count((tuple(BASE), tuple(CALIB))) == 1 and len(counted) == len(CALIB) + 1


def test_another_workflow_posterior_moves_the_base_prediction_and_not_the_emulator_fits(counted):
    model, obs = emulated(), data()
    a = run(model, obs, workflow_base(model, BASE, CALIB, pd.DataFrame(ensemble_files()[0]), ensemble_files()[1],
                                      file=POST_FILE))
    frame, summary = ensemble_files(shift=3e6)
    b = run(model, obs, workflow_base(model, BASE, CALIB, pd.DataFrame(frame), summary, file=POST_FILE))
    pa, pb = a.steps[0].heldout["H"], b.steps[0].heldout["H"]
    # strength 3 MPa higher: the prediction point moves by exactly that, its curve (after the peak, where the
    # strength sets the stress) by nearly as much, and so does the draws' mean curve
    assert pb.point["sigma_p"] - pa.point["sigma_p"] == pytest.approx(3e6, rel=1e-9)
    assert pb.point["tau_d"] == pytest.approx(pa.point["tau_d"], rel=1e-12)
    assert np.max(np.abs(pb.curve - pa.curve)) > 2.5e6
    assert np.max(np.abs(pb.draws.mean(axis=0) - pa.draws.mean(axis=0))) > 2.5e6
    # the emulator's fits (the base's cross-validation) are the same ES-MDAs, and no base refit ran in either
    for j in CALIB:
        np.testing.assert_array_equal(a.steps[0].cv.curve(j), b.steps[0].cv.curve(j))
    assert (tuple(BASE), tuple(CALIB)) not in counted and len(counted) == 2 * len(CALIB)


def test_a_model_with_an_added_effect_is_fitted_on_the_emulator_and_the_report_names_each_source():
    model, obs = emulated(), data()
    frame, summary = ensemble_files()
    sel = run(model, obs, workflow_base(model, BASE, CALIB, pd.DataFrame(frame), summary, file=POST_FILE),
              max_additions=1)
    assert [s.spec.effect_names for s in sel.steps] == [[], ["face_gap"]]
    assert [s.final.source for s in sel.steps] == ["workflow", "emulator"]
    src = fit_sources(sel)
    assert src["base_posterior"] == "workflow" and src["base_posterior_file"] == POST_FILE
    assert src["base_posterior_method"] == "ensemble"
    assert src["base_estimates"] == {n: {k: summary["posterior"][n][k] for k in ("mean", "q05", "q95")} for n in BASE}
    assert "emulator" in src["fits"]["base_cross_validation"] and "emulator" in src["fits"]["added_effects"]


def test_report_json_names_the_workflow_posterior_and_prints_its_estimates(tmp_path):
    """The diagnosis check's report.json on the stand-in: base_posterior "workflow", the file and the method
    of an MCMC sample (thinned to MAX_BASE_DRAWS draws for prediction), its estimates summary.json's as
    written (a JSON round trip of both files compares equal)."""
    model, obs = emulated(), data()
    frame, summary = mcmc_files()
    base = workflow_base(model, BASE, CALIB, frame, summary, file=POST_FILE)
    assert base.info["draws"] == 5000 and base.params.shape == (MAX_BASE_DRAWS, 2)
    sel = run(model, obs, base)
    rows = check_rows(sel, 1)
    runs = [pd.DataFrame({"time_s": MODEL_T, "stress_Pa": curve(MODEL_T, r["simulator"]["sigma_p"],
                                                                r["simulator"]["tau_d"], 0.0, K[r["record"]])[0]})
            for r in rows]
    from test_heldout_band import _obs
    cal, held = _obs({r: obs[r] for r in CALIB}, 0.3e6), _obs({"H": obs["H"]}, 0.3e6)
    disc = {r: np.full(OBS_T.size, 0.5e6 ** 2) for r in CALIB}
    report = assemble(sel, rows, runs, model, cal, held, NOISE, {}, disc)[0]
    (tmp_path / "report.json").write_text(json.dumps(report, default=float))
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    rep, summ = (json.loads((tmp_path / f).read_text()) for f in ("report.json", "summary.json"))
    assert rep["base_posterior"] == "workflow" and rep["base_posterior_file"] == POST_FILE
    assert rep["base_posterior_method"] == "emulator_mcmc"
    for n in BASE:
        for k in ("mean", "q05", "q95"):
            assert rep["base_estimates"][n][k] == summ["posterior"][n][k]
            assert rep["selection"]["steps"][0]["posterior"][n][k] == summ["posterior"][n][k]
    assert base_posterior_mismatches(summ, rep) == []
    # the check a re-run's files are held to fails a diagnosis with its own base fit or another method
    summ["posterior"]["sigma_p"]["q95"] += 1.0
    assert base_posterior_mismatches(summ, rep) == [
        f"base_estimates: sigma_p q95 {rep['base_estimates']['sigma_p']['q95']!r} against summary.json's "
        f"{summ['posterior']['sigma_p']['q95']!r}",
        f"selection step 0: sigma_p q95 {rep['base_estimates']['sigma_p']['q95']!r} against summary.json's "
        f"{summ['posterior']['sigma_p']['q95']!r}"]
    assert len(base_posterior_mismatches({**summ, "posterior_method": "ensemble"},
                                         {**rep, "base_posterior": "emulator"})) == 4
    # the held-out record's base prediction point is the workflow's mean (of the thinned draws: within 0.1 sd)
    point = rep["heldout"]["H"]["before"]["point"]
    assert point["sigma_p"] == pytest.approx(summ["posterior"]["sigma_p"]["mean"], abs=0.1e6)


def test_the_design_box_holds_every_draw_and_a_draw_outside_the_model_box_is_refused():
    rng = np.random.default_rng(0)
    S = np.column_stack([40e6 + 1e6 * rng.standard_normal(400), 45e-6 + 1e-6 * rng.standard_normal(400)])
    S[0, 0] = 47e6  # a tail draw 7 sd out (MCMC): beyond mean + 4 sd and 15 % of the mean (46 MPa)
    lo, hi = base_design_box(pd.DataFrame(S, columns=BASE), BASE, [20e6, 10e-6], [60e6, 100e-6], width_sd=4.0,
                             min_rel_width=0.15)
    assert hi[0] == 47e6 and lo[0] == pytest.approx(40e6 - 0.15 * S[:, 0].mean(), rel=1e-3)
    # an ensemble's dead member is no draw: it sets nothing
    frame = pd.DataFrame(S[:10], columns=BASE).assign(alive=[True] * 9 + [False])
    frame.loc[9, "sigma_p"] = 59e6
    box = base_design_box(frame, BASE, [20e6, 10e-6], [60e6, 100e-6], width_sd=4.0, min_rel_width=0.15)
    alive_only = base_design_box(frame.iloc[:9].drop(columns="alive"), BASE, [20e6, 10e-6], [60e6, 100e-6],
                                 width_sd=4.0, min_rel_width=0.15)
    np.testing.assert_array_equal(box[0], alive_only[0])
    np.testing.assert_array_equal(box[1], alive_only[1])
    assert box[1][0] < 55e6
    model = emulated()
    out = np.array([[40e6, 45e-6], [55e6, 45e-6]])  # 55 MPa: above the stand-in's design box (30-50 MPa)
    with pytest.raises(ValueError, match="outside the model's box"):
        given_fit(model, BASE, CALIB, out, summary={n: {"mean": 0.0} for n in BASE})
    assert LOWER[0] == 30e6 and UPPER[0] == 50e6
