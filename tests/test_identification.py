"""Identification, not just improvement (issue 53, item 3): the effect a selection round chooses comes with
its group, the candidates the calibration records do not tell apart from it
(enkf.diagnosis.identification), on the vectorised stand-in of tests/_protocol_standin.py.

In the stand-in a face gap and a trigger shift act identically on the data (the onset moves by
gap / V_FACE + dt), as they do to first order on an SHPB record: planted as a face gap, either may come out
first, and the report must name both. A gauge gain scales the curve instead and is told apart."""

import numpy as np
import pytest

from _protocol_standin import BASE, TRUTH, StandIn, observe, record_errors
from enkf.diagnosis import ModelSpec, ModelStep, Selection, group_text, select_effects
from shpb import effects as fx

RECORDS = {"A": 0.6e12, "B": 0.85e12, "C": 1.1e12, "D": 1.4e12}
GAP_M = 5.0e-5  # a 5 us later onset in every record (V_FACE 10 m/s), inside both effects' boxes


@pytest.fixture(scope="module")
def onset_round():
    model = StandIn(RECORDS)
    obs = observe(model, {r: dict(**TRUTH, gap=GAP_M) for r in RECORDS}, seed=11)
    cands = [fx.get_effect(n) for n in ("face_gap", "trigger_shift", "gauge_gain")]
    sel = select_effects(model, base_names=BASE, candidates=cands, calib_records=list(RECORDS), obs=obs,
                         errors=record_errors(list(RECORDS)), seed=0, n_members=60, esmda_steps=4, max_additions=1)
    return sel.rounds[0]


def test_effects_that_act_alike_on_the_onset_are_reported_as_one_group(onset_round):
    rnd = onset_round
    assert rnd["chosen"] in ("face_gap", "trigger_shift")
    group = rnd["group"]
    assert group["chosen"] == rnd["chosen"]
    assert sorted(group["effects"]) == ["face_gap", "trigger_shift"], group
    ev = {e["effect"]: e for e in group["evidence"]}
    alike = ({"face_gap", "trigger_shift"} - {rnd["chosen"]}).pop()
    # identical predictions up to the two calibrations' own scatter: far below the critical z
    assert not ev[alike]["told_apart"] and abs(ev[alike]["z"]) < 1.0, ev[alike]
    # a gain cannot move the onset: the chosen effect beats it by many sd
    assert ev["gauge_gain"]["told_apart"] and ev["gauge_gain"]["z"] > 5.0, ev["gauge_gain"]
    # Bonferroni over the two compared candidates at the round's 5 %
    assert group["z_critical"] == pytest.approx(1.959964, abs=1e-5) and group["not_tried"] == []
    text = group_text(group)
    assert f"do not tell {rnd['chosen']} apart from {alike}" in text and "gauge_gain" not in text


def test_an_effect_the_data_single_out_has_a_group_of_one(onset_round):
    """The same sentence when nothing is alike: the chosen effect alone, every other told apart."""
    group = dict(onset_round["group"])
    group["evidence"] = [dict(e, told_apart=True, z=6.0) for e in group["evidence"]]
    group["effects"] = [group["chosen"]]
    assert group_text(group).startswith(f"{group['chosen']} is told apart from every other candidate tried")
    assert "not ruled out: rate_strength" in group_text(dict(group, not_tried=["rate_strength"]))


def test_the_report_names_the_group_of_every_kept_effect():
    """calibration.closing.identification: one entry per effect kept (the rounds that chose them), none for a
    round that chose nothing; summary.html prints each sentence."""
    from calibration.closing import identification
    from calibration.report_summary import _diagnosis

    g = {"chosen": "face_gap", "effects": ["face_gap", "trigger_shift"], "level": 0.05, "z_critical": 1.96,
         "evidence": [{"effect": "trigger_shift", "delta_sq_error": 0.1, "sd": 1.0, "z": 0.1, "told_apart": False}],
         "not_tried": []}

    g_alt = {**g, "chosen": "closure", "effects": ["closure"], "evidence": []}
    specs = [ModelSpec.of(["sigma_t"]), ModelSpec.of(["sigma_t"], [fx.get_effect("face_gap")])]
    sel = Selection([ModelStep(i, sp, None, None, {}, {}, i) for i, sp in enumerate(specs)],
                    [{"chosen": "face_gap", "group": g, "alternative_groups": {"closure": g_alt}},
                     {"chosen": None, "group": None}], "", ["A"], [], {},
                    [ModelStep(2, ModelSpec.of(["sigma_t"], [fx.get_effect("closure")]), None, None, {}, {}, 1,
                               alternative_to=1)])
    ident = identification(sel, 1)
    assert [i["chosen"] for i in ident] == ["face_gap"] and identification(sel, 0) == []
    # a refuted choice's alternative kept: the group of its own round is reported, not the choice's
    assert [i["chosen"] for i in identification(sel, 2)] == ["closure"]
    html = "".join(_diagnosis({"added": ["face_gap"], "verdict": "confirmed", "identification": ident}))
    assert "Identification: the calibration records do not tell face_gap apart from trigger_shift (z = 0.10)" in html
    assert np.isfinite(ident[0]["z_critical"])
