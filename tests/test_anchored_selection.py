"""The anchored selection model (diagnosis.selection_model: anchored; enkf.emulator.AnchoredEmulator,
calibration.diagnose.anchored_design / anchored_emulators): its arithmetic against exact values, the
design the workflow declares, and the selection it carries on the analytic stand-in of
tests/_protocol_standin.py, where a face gap moves each record's onset by 5-15 us, several times the
2 us rise foot: a response no first-order (linear) model of the gap reproduces."""

import numpy as np
import pandas as pd
import pytest

from _protocol_standin import BASE, BASE_BOX, OBS_T, TRUTH, StandIn, observe, record_errors
from calibration.diagnose import (EmulatedSHPB, anchored_design, anchored_emulators, design_points,
                                  emulators_from_design)
from calibration.diagnosis_config import design_size
from calibration.protocol import emulator_errors, protocol_model
from enkf.diagnosis import RecordErrors, select_effects
from enkf.emulator import AnchoredEmulator
from shpb import effects as fx

T = np.linspace(0.0, 1.0, 7)


def _f(x):
    """An additive response: linear in x0, quadratic in x1."""
    return x[0] * T + x[1] ** 2


def test_the_anchored_emulator_is_exact_at_its_runs_and_interpolates_each_axis_linearly():
    a = np.array([1.0, 0.0])
    axes = {0: ([0.5, 1.5], [_f([0.5, 0.0]), _f([1.5, 0.0])]),
            1: ([1.0, 2.0, 3.0], [_f([1.0, v]) for v in (1.0, 2.0, 3.0)])}
    emu = AnchoredEmulator(a, _f(a), axes, [0.0, 0.0], [2.0, 3.0])
    for x in ([1.0, 0.0], [0.5, 0.0], [1.5, 0.0], [1.0, 2.0], [1.5, 3.0]):  # runs, and sums of two axes' runs
        assert np.allclose(emu(np.array([x]))[0], _f(x), atol=1e-12), x
    # between the runs at 2 and 3, x1^2 is read off the chord: error (x - 2)(3 - x) = 0.25 at 2.5
    assert np.allclose(emu(np.array([[1.2, 2.5]]))[0] - _f([1.2, 2.5]), 0.25, atol=1e-12)
    # past the outermost run the last chord extends: 9 + 5 * 0.5 at 3.5 (exact 12.25)
    assert np.allclose(emu(np.array([[1.0, 3.5]]))[0] - _f([1.0, 3.5]), 11.5 - 12.25, atol=1e-12)
    # a parameter without runs is held at the anchor
    emu0 = AnchoredEmulator(a, _f(a), {0: axes[0]}, [0.0, 0.0], [2.0, 3.0])
    assert np.allclose(emu0(np.array([[1.0, 2.0]]))[0], _f(a))
    # a parameter in tiny units (a seating compliance, m/Pa) is read on its own scale
    tiny = AnchoredEmulator([0.0], np.zeros(7), {0: ([5e-13, 1e-12], [T, 2 * T])}, [0.0], [2e-12])
    assert np.allclose(tiny(np.array([[7.5e-13]]))[0], 1.5 * T)
    with pytest.raises(ValueError, match="anchor's own value"):
        AnchoredEmulator(a, _f(a), {0: ([1.0], [_f(a)])}, [0.0, 0.0], [2.0, 3.0])


def test_the_anchored_emulators_leave_one_out_error_is_each_axis_run_against_its_neighbours_chord():
    a = np.array([1.0, 0.0])
    axes = {0: ([0.5, 1.5], [_f([0.5, 0.0]), _f([1.5, 0.0])]),
            1: ([1.0, 2.0, 3.0], [_f([1.0, v]) for v in (1.0, 2.0, 3.0)])}
    R = AnchoredEmulator(a, _f(a), axes, [0.0, 0.0], [2.0, 3.0]).loo_residuals()
    assert R.shape == (5, T.size)
    # x0 is linear: its two runs are each predicted exactly from the anchor and the other
    assert np.allclose(R[:2], 0.0, atol=1e-12)
    # x1^2 from the other two of {0, 1, 2, 3}: at 1 the chord of 0 and 2 gives 2 (error -1); at 2 the chord
    # of 1 and 3 gives 5 (error -1); at 3 the line through 1 and 2 extended gives 7 (error 2)
    assert np.allclose(R[2:], np.array([-1.0, -1.0, 2.0])[:, None] * np.ones(T.size), atol=1e-12)
    # an axis of one run: the anchor alone predicts no change, the whole change is the error
    one = AnchoredEmulator(a, _f(a), {1: ([2.0], [_f([1.0, 2.0])])}, [0.0, 0.0], [2.0, 3.0]).loo_residuals()
    assert np.allclose(one, 4.0)


def test_the_anchored_design_moves_one_parameter_per_run_inside_the_box():
    X, axis, pair = anchored_design([30e6, 5e3], [20e6, 1e3], [50e6, 2e4], [0.0, 0.0], [0.6, 2e-4],
                                    base_step=0.25, sweep=3)
    assert np.all(pair == -1)  # no interactions asked
    assert X.shape == (1 + 2 * 2 + 3 * 2, 4) and axis[0] == -1
    assert np.allclose(X[0], [30e6, 5e3, 0.0, 0.0])
    moved = (X[1:] != X[0]).sum(axis=1)
    assert np.all(moved == 1) and np.all(np.argmax(X[1:] != X[0], axis=1) == axis[1:])
    # sigma_t + 7.5 MPa (a quarter of the 30 MPa box) and - 5 MPa (half way to the box's edge, 10 MPa
    # below); E_t likewise
    assert sorted(X[axis == 0, 0]) == pytest.approx([25e6, 37.5e6])
    assert sorted(X[axis == 1, 1]) == pytest.approx([3e3, 5e3 + 0.25 * 1.9e4])
    assert sorted(X[axis == 3, 3]) == pytest.approx([0.5e-4, 1e-4, 1.5e-4])  # inside: an upper bound may be open
    lo, hi = np.array([20e6, 1e3, 0.0, 0.0]), np.array([50e6, 2e4, 0.6, 2e-4])
    assert np.all(X >= lo) and np.all(X <= hi)


def test_the_workflow_declares_as_many_design_runs_as_the_anchored_design_makes():
    exp = {"kind": "measured", "seed": 1, "parameters": {"sigma_t": [1e6, 6e7], "E_t": [10.0, 5e4]},
           "diagnosis": {"exclude": ["damping", "seating", "interface_friction"], "sweep_points": 3}}
    phys = [p for c in ("rate_strength", "face_gap", "closure") for p in fx.get_effect(c).params]
    assert design_size(exp) == 1 + 2 * 2 + 3 * len(phys) == 14
    assert design_size({**exp, "diagnosis": {**exp["diagnosis"], "selection_model": "emulator",
                                             "design_points": 24}}) == 24
    with pytest.raises(ValueError, match="parameters listed"):
        design_size({**exp, "parameters": "auto"})


GAP_K = {"A": 0.6e12, "B": 0.85e12, "C": 1.1e12, "D": 1.4e12}
GAPS = {"A": 50e-6, "B": 150e-6, "C": 90e-6, "D": 120e-6}  # onsets 5-15 us late


def _anchored_standin(anchor, sweep=3):
    """The stand-in's records as the anchored model sees them: its runs at the anchored design (base box
    BASE_BOX, face_gap and rate_strength up to their catalogue bounds), the measurement chain applied on
    top by calibration.diagnose.EmulatedSHPB as in the workflow."""
    names = BASE + ["face_gap.gap_m", "rate_strength.k"]
    stand = StandIn(GAP_K)
    lo, hi = stand.box(names)
    X, axis, _ = anchored_design(anchor, lo[:2], hi[:2], lo[2:], hi[2:], base_step=0.25, sweep=sweep)
    curves = {}
    for r in GAP_K:
        Y = stand.forward(names, [r])(X)
        curves[r] = [pd.DataFrame({"time_s": OBS_T, "stress_Pa": y}) for y in Y]
    emus, failed = anchored_emulators(X, axis, curves, OBS_T, lo, hi, names)
    assert failed == {r: 0 for r in GAP_K}
    return protocol_model(EmulatedSHPB(emus, names, OBS_T, {r: OBS_T for r in GAP_K}))


def _rbf_standin(anchor, n):
    """The same records as an RBF emulator of ``n`` space-filling runs per record (the base box +-15 % of
    the anchor, the effects from null to their catalogue bounds): the emulator selection model."""
    names = BASE + ["face_gap.gap_m", "rate_strength.k"]
    stand = StandIn(GAP_K)
    lo, hi = stand.box(names)
    blo, bhi = 0.85 * np.asarray(anchor), 1.15 * np.asarray(anchor)
    X = design_points(blo, bhi, lo[2:], hi[2:], n, seed=0)
    curves = {r: [pd.DataFrame({"time_s": OBS_T, "stress_Pa": y}) for y in stand.forward(names, [r])(X)]
              for r in GAP_K}
    emus, _ = emulators_from_design(X, curves, OBS_T, np.r_[blo, lo[2:]], np.r_[bhi, hi[2:]], names)
    return protocol_model(EmulatedSHPB(emus, names, OBS_T, {r: OBS_T for r in GAP_K}))


def _select(model, seed=3, errors=None):
    obs = observe(StandIn(GAP_K), {r: {**TRUTH, "gap": GAPS[r]} for r in GAP_K}, seed=seed)
    return select_effects(model, base_names=BASE, candidates=[fx.get_effect(c) for c in
                                                              ("face_gap", "rate_strength", "gauge_gain")],
                          calib_records=list(GAP_K), obs=obs,
                          errors=errors or record_errors(list(GAP_K), model_error=False),
                          seed=seed, n_members=60, esmda_steps=4, max_additions=1, gate="improvement")


def _with_own_error(model):
    """The stand-in's noise beside the anchored model's own error, as the workflow builds it
    (calibration.protocol.emulator_errors: its leave-one-out residuals along each axis)."""
    noise = record_errors(list(GAP_K), model_error=False).noise
    return RecordErrors(dict(noise), emulator_errors(model.emulated, list(GAP_K)))


ANCHOR = [1.05 * TRUTH["sigma_p"], 0.95 * TRUTH["tau_d"]]


def test_on_the_anchored_model_the_selection_names_a_planted_face_gap():
    """Per-record gaps of 50-150 um (onsets 5-15 us late, against a 2 us rise foot), the anchor at the base
    parameters 5 % off the truth (a base calibration that absorbed part of the effect): the anchored model
    (1 + 4 + 3 x 2 = 11 runs per record) cross-validates face_gap, rate_strength and gauge_gain and chooses
    the face gap: cross-validated RMSE 4.2 -> 2.1 MPa (rate_strength 4.0, gauge_gain 3.2; the rest of the
    error is the unseen record's own gap, predicted from the others' spread). Seeds 3 and 4 measured alike;
    6 runs per axis instead of 3 change the errors by 0.05 MPa."""
    sel = _select(_anchored_standin(ANCHOR))
    assert sel.rounds[0]["chosen"] == "face_gap", sel.rounds[0]["trials"]
    trials = {t["effect"]: t for t in sel.rounds[0]["trials"]}
    assert trials["face_gap"]["cv_rmse"] < 0.6 * sel.rounds[0]["current_cv_rmse"], trials
    assert trials["face_gap"]["cv_rmse"] < 0.75 * min(trials["rate_strength"]["cv_rmse"], trials["gauge_gain"]["cv_rmse"])
    # the fitted gaps of the calibration records come back 10-16 um short of the planted ones (the chords
    # between the runs at 0, 100 and 200 um blend two onsets rather than move one): within 20 um
    post = sel.steps[1].final.posterior()
    for r in GAP_K:
        assert abs(post[f"face_gap.gap_m@{r}"]["mean"] - GAPS[r]) < 20e-6, (r, post[f"face_gap.gap_m@{r}"])


def _gap_coverage(sel):
    post = sel.steps[1].final.posterior()
    return [post[f"face_gap.gap_m@{r}"]["q05"] <= GAPS[r] <= post[f"face_gap.gap_m@{r}"]["q95"] for r in GAP_K]


def test_the_anchored_models_own_error_makes_the_fitted_gaps_intervals_hold_the_planted_ones():
    """Without its own error the anchored model's 90 % intervals of the fitted gaps are 3-5 um wide and
    lie wholly 1-18 um below the planted gaps: none of the 12 (seeds 3, 4, 5) covers. With its
    leave-one-out error along the axes (the workflow's form) they are 7-39 um wide and 11 of the 12 cover
    (seed 3's B, 140-149 um for 150, misses; asserted: at least 10, one more left to floating point), and
    the choice and its cross-validated error stay as they were (face_gap, 2.1 MPa)."""
    model = _anchored_standin(ANCHOR)
    errors = _with_own_error(model)
    sure_covered, covered = 0, 0
    for seed in (3, 4, 5):
        sure = _select(model, seed)
        assert sure.rounds[0]["chosen"] == "face_gap"
        sure_covered += sum(_gap_coverage(sure))
        sel = _select(model, seed, errors=errors)
        assert sel.rounds[0]["chosen"] == "face_gap", sel.rounds[0]["trials"]
        trials = {t["effect"]: t for t in sel.rounds[0]["trials"]}
        assert trials["face_gap"]["cv_rmse"] < 0.6 * sel.rounds[0]["current_cv_rmse"], trials
        covered += sum(_gap_coverage(sel))
    assert sure_covered == 0 and covered >= 10


def test_an_error_per_model_sums_the_axes_it_moves_and_still_names_the_face_gap():
    """diagnosis.own_error: per_model. Each axis's own error is the rms of its leave-one-out residuals
    (calibration.protocol.emulator_axis_errors); a model's is the sum over the axes it moves. On seed 3
    the selection still chooses the face gap (cross-validated RMSE 4.15 -> 2.43 MPa; pooled 4.22 -> 2.15)
    and every fitted gap's 90 % interval holds the planted one (4 of 4; seeds 3-5: 12 of 12, pooled 11 of
    12); the group it cannot tell apart grows (rate_strength joins it, z 0.23 of the round), the common
    axes' error being large beside the gaps' own: studies/results/own_error_per_model.json."""
    from calibration.protocol import emulator_axis_errors
    model = _anchored_standin(ANCHOR)
    axes = emulator_axis_errors(model.emulated, list(GAP_K))
    by_axis = model.emulated.emulators["A"].loo_residuals_by_axis()
    assert set(axes["A"]) == set(by_axis) == {"sigma_p", "tau_d", "face_gap.gap_m", "rate_strength.k"}
    for name, res in by_axis.items():  # the stand-in observes at the model's own times: no interpolation
        assert np.allclose(np.sqrt(np.diag(axes["A"][name].dense())), np.sqrt(np.mean(res ** 2, axis=0)), rtol=1e-9,
                           atol=1e-9 * np.abs(res).max())
    noise = record_errors(list(GAP_K), model_error=False).noise
    errors = RecordErrors(dict(noise), emulator_errors(model.emulated, list(GAP_K)), {}, 0.0, 0.0, axes)
    sel = _select(model, 3, errors=errors)
    assert sel.rounds[0]["chosen"] == "face_gap", sel.rounds[0]["trials"]
    assert sum(_gap_coverage(sel)) == 4
