"""The refit's identification gate (calibration.walk.identified, calibration.refit): a confirmed effect is
shipped only if real runs place at least one of its parameters away from its null. On the analytic
stand-in of tests/_protocol_standin.py (four records with planted face gaps), records carrying a 15 %
gauge loss as well make the selection add `gauge_gain` after `face_gap`; re-fitted on runs that fit
records with the gain, the gain is kept (every g in [0.83, 0.87] for 0.85), on the same records without it
(what a false second addition looks like on real runs) every g's interval holds 1, the gain is dropped and
the face-gap model re-fitted and kept. The interval arithmetic against exact quantiles; the check ships
the gate's step."""

import numpy as np
import pytest

from _protocol_standin import BASE, TRUTH, StandIn, noise_model, observe
from calibration.refit import first_round, first_round_after_walk, next_round, refit_summary
from calibration.report_summary import _refit as refit_html
from calibration.walk import chain_of, check_runs_of, gated, identified
from enkf.diagnosis import select_effects
from shpb import effects as fx
from test_anchored_selection import ANCHOR, GAP_K, GAPS, _anchored_standin, _with_own_error
from test_heldout_band import _obs, loop  # noqa: F401  (loop: the held-out band's stand-in walk, a fixture)
from test_protocol_shpb import CALIB, NOISE, OBS_T, emulated
from test_refit import SETTINGS, _runs

#: the gauges' gain of the records the selection sees (the catalogue's box is [0.8, 1.2])
GAIN = 0.85


@pytest.fixture(scope="module")
def two_steps():
    model = _anchored_standin(ANCHOR)
    clean = observe(StandIn(GAP_K), {r: {**TRUTH, "gap": GAPS[r]} for r in GAP_K}, seed=3)
    lossy = {r: GAIN * v for r, v in clean.items()}
    sel = select_effects(model, base_names=BASE, candidates=[fx.get_effect(c) for c in
                                                              ("face_gap", "rate_strength", "gauge_gain")],
                         calib_records=list(GAP_K), obs=lossy, errors=_with_own_error(model), seed=3,
                         n_members=60, esmda_steps=4, max_additions=2, gate="improvement")
    assert [s.spec.effect_names for s in sel.steps] == [[], ["face_gap"], ["face_gap", "gauge_gain"]]
    return sel, model.emulated, clean, lossy


def _refit(sel, model, obs, level=0.9):
    state, curves = first_round(sel, 2, model, chain=[0, 1, 2], level=level), {}
    while state["phase"] != "done":
        curves[state["round"]] = _runs(state["rows"])
        state = next_round(state, curves.__getitem__, model, obs, {r: noise_model() for r in GAP_K}, {}, SETTINGS,
                           rounds=3, replicates=1, selection=sel)
    return refit_summary(state)


def test_a_second_effect_real_runs_place_off_its_null_is_kept(two_steps):
    sel, model, _, lossy = two_steps
    out = _refit(sel, model, lossy)
    assert out["step"] == 2 and out["gated"] == [] and out["identification"]["identified"]
    gains = {p["name"]: p for p in out["identification"]["parameters"]}
    assert sorted(gains) == [f"gauge_gain.g@{r}" for r in sorted(GAP_K)]
    for p in gains.values():
        # Bonferroni over four copies: each interval at 97.5 %, all excluding 1 and holding the planted gain
        assert p["null"] == 1.0 and p["excludes"] and p["lower"] < GAIN < p["upper"] < 0.9
    # the earlier effect through the same test on the same refit (reported, not gated): the planted gaps
    [gap] = out["earlier_identification"]
    assert gap["effect"] == "face_gap" and gap["identified"] and gap["level"] == 0.9
    assert all(p["excludes"] and p["lower"] > 0.0 for p in gap["parameters"]) and len(gap["parameters"]) == len(GAP_K)
    assert "In this refit none of" not in "".join(refit_html(out))
    # were the gaps left at zero, summary.html would say so and ship the model as walked
    held = {**gap, "identified": False, "parameters": [{**p, "lower": 0.0, "excludes": False} for p in gap["parameters"]]}
    html = "".join(refit_html({**out, "earlier_identification": [held]}))
    assert "In this refit none of face_gap's parameters lies away from its null (face_gap.gap_m@A [0, " in html
    assert "each interval at 97.5%" in html and "the model without face_gap was never walked" in html
    # a gain whose interval reaches the catalogue's lowest gain (0.8, away from its null 1) is named as taken
    # as far as the catalogue allows; the gaps' lower ends at zero are their null, not an edge to report
    assert "reach an end of their catalogue range" not in "".join(refit_html(out))
    name = f"gauge_gain.g@{sorted(GAP_K)[0]}"
    post = {**out["posterior"], name: {**out["posterior"][name], "q05": 0.8},
            f"face_gap.gap_m@{sorted(GAP_K)[0]}": {"mean": 1e-6, "q05": 0.0, "q95": 2e-6}}
    html = "".join(refit_html({**out, "posterior": post}))
    assert f"away from the effect's null: {name} (lower end 0.8, the catalogue's 0.8). The effect is taken" in html


def test_a_second_effect_real_runs_leave_at_its_null_is_dropped_and_the_model_before_it_refitted(two_steps):
    sel, model, clean, _ = two_steps
    out = _refit(sel, model, clean)
    assert out["step"] == 1 and out["model"] == "base + face_gap" and out["chain"] == [0, 1]
    [dropped] = out["gated"]
    assert dropped["step"] == 2 and not dropped["identification"]["identified"]
    for p in dropped["identification"]["parameters"]:
        assert p["lower"] < 1.0 < p["upper"] and p["upper"] - p["lower"] < 0.03
    # the face-gap model's own refit: its gaps off zero and on the planted ones within 6 um
    assert out["identification"]["effect"] == "face_gap" and out["identification"]["identified"]
    assert out["earlier_identification"] == []  # the face-gap model has no effect before its last
    for r in GAP_K:
        assert out["posterior"][f"face_gap.gap_m@{r}"]["mean"] == pytest.approx(GAPS[r], abs=6e-6)
    # both models' runs are counted: the dropped one's rounds, then the kept one's
    assert out["runs"] == dropped["runs"] + sum(h["runs"] for h in out["history"]) and dropped["runs"] > 0
    # the walk's text for a report: the face-gap model shipped, the gain named with its intervals
    conf = {"confirmed": 2, "steps": [{"step": 1, "confirmed": True}, {"step": 2, "confirmed": True}],
            "real_cv_rmse": {0: 3e6, 1: 2e6, 2: 1.9e6}, "real_cv_loss": {0: 9.0, 1: 4.0, 2: 3.8}, "weighted": True,
            "text": "shipped: base + face_gap + gauge_gain"}
    assert chain_of(conf) == [0, 1, 2]
    g = gated(conf, sel, out)
    assert g["confirmed"] == 1 and g["effects"] == ["face_gap"] and g["identification_gate"]["dropped"][0]["step"] == 2
    assert g["text"].startswith("shipped: base + face_gap (real cross-validated RMSE 3e+06 -> 2e+06; weighted error")
    assert "gauge_gain was confirmed by the walk but not identified on real runs (gauge_gain.g@A [" in g["text"]
    # summary.html says what was dropped and why, beside the kept model's table
    html = "".join(refit_html(out))
    assert "The walk also confirmed gauge_gain (base + face_gap + gauge_gain), but re-fitted on real runs (" in html
    # the kept model's own runs and rounds, the dropped model's beside its sentence
    kept_runs = sum(h["runs"] for h in out["history"])
    assert f"({kept_runs} runs on the calibration records, {len(out['history'])} rounds;" in html
    assert f"re-fitted on real runs ({dropped['runs']} runs)" in html
    assert "gauge_gain.g@A [" in html and "holds its null 1; each interval at 97.5%" in html
    assert "".join(refit_html({**out, "posterior": None})).startswith('<p style="margin:0.4em 0 0 0">The walk also')
    # without a gate (no refit) or with the walk's model kept, the walk's result stands
    assert gated(conf, sel, None)["confirmed"] == 2 and gated(conf, sel, {**out, "gated": []})["confirmed"] == 2


def test_the_intervals_are_bonferroni_over_the_copies_and_a_clipped_end_holds_the_null():
    # 1001 draws from -0.04 to 0.96, clipped at the box's 0 (where rate_strength.k's null lies)
    k = np.clip(np.linspace(-0.04, 0.96, 1001), 0.0, None)
    assert np.quantile(k, 0.05) > 0.0 and np.quantile(k, 0.025) == 0.0
    one = identified(["sigma_t", "rate_strength.k"], np.column_stack([np.ones(1001), k]), "rate_strength", 0.9)
    assert one["identified"] and one["parameters"][0]["lower"] == pytest.approx(np.quantile(k, 0.05))
    # the same draws for two records' face gaps: each interval at 95 %, whose lower end is the null itself
    two = identified(["face_gap.gap_m@A", "face_gap.gap_m@B"], np.column_stack([k, k]), "face_gap", 0.9)
    assert not two["identified"] and [p["lower"] for p in two["parameters"]] == [0.0, 0.0]
    # a gain's null (1) inside the box: excluded from above
    g = np.linspace(0.90, 0.99, 101)
    assert identified(["gauge_gain.g@A"], g[:, None], "gauge_gain", 0.9)["parameters"][0]["excludes"]
    with pytest.raises(ValueError, match="no parameter of 'lowpass'"):
        identified(["sigma_t"], np.ones((3, 1)), "lowpass", 0.9)


def test_the_check_ships_the_gate_s_step_and_says_why(loop):  # noqa: F811
    """On the held-out band's stand-in loop (tests/test_heldout_band.py), whose walk confirms the face gap:
    a refit that dropped it makes the check ship the base, its held-out error after equal to before."""
    from calibration.closing import assemble

    obs, sel, rows, runs = loop
    cal, held = _obs({r: obs[r] for r in CALIB}, 0.3e6), _obs({"H": obs["H"]}, 0.3e6)
    disc = {r: np.full(OBS_T.size, (0.5e6) ** 2) for r in CALIB}
    args = (sel, rows, runs, emulated(), cal, held, NOISE, {}, disc)
    walked = assemble(*args)[0]
    assert walked["shipped_step"] == 1 and walked["confirmation"]["identification_gate"] is None
    # the refit starts from the same walk on the same runs, before any held-out record is read
    start = first_round_after_walk(sel, rows, runs, emulated(), cal, NOISE, {}, level=0.9)
    assert start["step"] == 1 and start["chain"] == [0, 1] and start["gate_level"] == 0.9 and start["phase"] == "locate"
    ident = {"effect": "face_gap", "identified": False, "level": 0.9,
             "parameters": [{"name": "face_gap.gap_m@A", "null": 0.0, "lower": 0.0, "upper": 1e-5, "excludes": False}]}
    refit = {"step": 0, "gate_level": 0.9, "identification": None,
             "gated": [{"step": 1, "model": "base + face_gap", "identification": ident}]}
    report = assemble(*args, refit)[0]
    assert report["shipped_step"] == 0 and report["verdict"] == "base_kept" and report["added"] == []
    assert report["why"].startswith("shipped: base (") and "face_gap was confirmed by the walk but not" in report["why"]
    assert report["heldout"]["H"]["after"]["rmse"] == report["heldout"]["H"]["before"]["rmse"]
    assert report["heldout"]["H"]["before"]["rmse"] == walked["heldout"]["H"]["before"]["rmse"]
    assert report["confirmation"]["identification_gate"]["dropped"][0]["model"] == "base + face_gap"


def test_the_check_s_runs_are_read_in_their_rows_order_and_a_failed_run_is_empty(tmp_path):
    import json

    import pandas as pd

    rows = [{"record": "A", "step": 0}, {"record": "A", "step": 1}]
    (tmp_path / "check_runs.json").write_text(json.dumps({"rows": rows}))
    (tmp_path / "check" / "0").mkdir(parents=True)
    pd.DataFrame({"time_s": [0.0, 1e-6], "stress_Pa": [0.0, 2e6]}).to_csv(tmp_path / "check" / "0" / "curve.csv",
                                                                          index=False)
    (tmp_path / "check" / "1").mkdir()
    (tmp_path / "check" / "1" / "curve.csv").write_text("")  # a failed run's curve file
    got_rows, runs = check_runs_of(tmp_path)
    assert got_rows == rows and runs[1].empty and list(runs[0]["stress_Pa"]) == [0.0, 2e6]
