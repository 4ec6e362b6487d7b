"""The anchored emulator's second-order terms (diagnosis.interactions; enkf.emulator.AnchoredEmulator's
pairs, calibration.diagnose.anchored_design's cross runs): exact for a response whose effect scales with
the strength, where the first-order form is wrong by the interaction, and the design the workflow
declares for them."""

import numpy as np
import pandas as pd
import pytest

from calibration.diagnose import anchored_design, anchored_emulators
from calibration.diagnosis_config import design_size
from enkf.emulator import AnchoredEmulator
from shpb import effects as fx

T = np.linspace(0.0, 1.0, 9)
KNOTS = np.array([0.0, 0.125, 0.25, 0.375])  # the friction's null and its three sweep values


def _hat(m):
    """A piecewise-linear function of the friction with knots at KNOTS (0 at 0): the emulator's chords
    reproduce it exactly between the knots and, past them, along the last segment."""
    return np.interp(m, KNOTS, [0.0, 0.2, 0.55, 0.7]) + (m > KNOTS[-1]) * 1.2 * (m - KNOTS[-1])


def response(x):
    """A cylinder-like peak: strength s [MPa] times (1 + the friction's confinement), the confinement's
    increment proportional to the strength (an interaction), plus a curve shape from E (x[1])."""
    s, e, m = x
    return s * (1.0 + _hat(m)) * T + e * T ** 2


def _runs(X):
    return [response(x) for x in X]


def test_a_strength_scaled_effect_is_exact_with_the_pair_term_and_wrong_without_it():
    a = np.array([44.0, 3.0, 0.0])
    axes = {0: ([34.0, 54.0], _runs([[34.0, 3.0, 0.0], [54.0, 3.0, 0.0]])),
            1: ([2.0, 4.0], _runs([[44.0, 2.0, 0.0], [44.0, 4.0, 0.0]])),
            2: (KNOTS[1:], _runs([[44.0, 3.0, m] for m in KNOTS[1:]]))}
    lo, hi = [10.0, 1.0, 0.0], [80.0, 5.0, 0.5]
    pairs = {(0, 2): (34.0, KNOTS[1:], _runs([[34.0, 3.0, m] for m in KNOTS[1:]]))}
    first = AnchoredEmulator(a, response(a), axes, lo, hi)
    second = AnchoredEmulator(a, response(a), axes, lo, hi, pairs=pairs)
    truth = np.array([25.0, 3.5, 0.3])  # a lower strength, another E, a friction between the sweep values
    # the response is linear in s and E-additive, so the pair term makes it exact anywhere in the box
    assert np.allclose(second(truth[None])[0], response(truth), rtol=0, atol=1e-12)
    assert np.allclose(second(np.array([[60.0, 2.5, 0.45]]))[0], response([60.0, 2.5, 0.45]), atol=1e-12)
    # first order: the friction's increment measured at 44 MPa, (44 - 25) * hat(0.3) too large at the peak
    err = first(truth[None])[0] - response(truth)
    assert err[-1] == pytest.approx((44.0 - 25.0) * _hat(0.3), rel=1e-12)
    # on the axes through the anchor the pair adds nothing: the first-order emulator's values there
    for x in ([34.0, 3.0, 0.0], [44.0, 3.0, 0.25], [60.0, 3.0, 0.0]):
        assert np.allclose(second(np.array([x]))[0], first(np.array([x]))[0], atol=1e-12), x
    with pytest.raises(ValueError, match="off the anchor"):
        AnchoredEmulator(a, response(a), axes, lo, hi, pairs={(0, 2): (44.0, KNOTS[1:], pairs[(0, 2)][2])})
    with pytest.raises(ValueError, match="each with axis runs"):
        AnchoredEmulator(a, response(a), {0: axes[0], 1: axes[1]}, lo, hi, pairs=pairs)


def test_the_design_crosses_every_physical_sweep_with_the_lower_strength_and_the_emulators_read_it():
    anchor, blo, bhi = [44.0, 3.0], [24.0, 1.0], [64.0, 5.0]
    X, axis, pair = anchored_design(anchor, blo, bhi, [0.0, 0.0], [0.5, 0.5], base_step=0.25, sweep=3, cross=[0])
    assert X.shape == (1 + 2 * 2 + 2 * 3 * 2, 4)
    cross = pair >= 0
    assert cross.sum() == 6 and np.all(pair[cross] == 0)
    # the cross rows: sigma_t at its lower step (44 - 0.25 x 40 = 34), E at the anchor, one physical moved
    assert np.all(X[cross, 0] == 34.0) and np.all(X[cross, 1] == 3.0)
    for r in np.flatnonzero(cross):
        moved = [k for k in (2, 3) if X[r, k] != 0.0]
        assert moved == [axis[r]]
    assert sorted(X[cross & (axis == 2), 2]) == pytest.approx([0.125, 0.25, 0.375])
    names = ["s", "e", "m", "other"]
    curves = {"R": [pd.DataFrame({"time_s": T, "stress_Pa": response(x[:3])}) for x in X]}
    emus, failed = anchored_emulators(X, axis, curves, T, blo + [0.0, 0.0], bhi + [0.5, 0.5], names, pair=pair)
    assert failed == {"R": 0}
    x = np.array([[25.0, 3.5, 0.3, 0.0]])
    assert np.allclose(emus["R"](x)[0], response(x[0, :3]), atol=1e-9)
    # without the pair information the same runs give the first-order model (the cross rows unused)
    emus1, _ = anchored_emulators(X[~cross], axis[~cross], {"R": [c for c, k in zip(curves["R"], cross) if not k]},
                                  T, blo + [0.0, 0.0], bhi + [0.5, 0.5], names)
    assert not np.allclose(emus1["R"](x)[0], response(x[0, :3]), atol=1e-3)
    with pytest.raises(ValueError, match="distinct base parameter"):
        anchored_design(anchor, blo, bhi, [0.0], [0.5], base_step=0.25, sweep=3, cross=[2])


def test_the_workflow_declares_the_cross_runs_and_refuses_an_unknown_name():
    exp = {"kind": "measured", "seed": 1, "parameters": {"sigma_t": [1e6, 6e7], "E_t": [10.0, 5e4]},
           "diagnosis": {"exclude": ["damping", "seating", "interface_friction"], "sweep_points": 3,
                         "interactions": ["sigma_t"]}}
    phys = [p for c in ("rate_strength", "face_gap", "closure") for p in fx.get_effect(c).params]
    assert design_size(exp) == 1 + 2 * 2 + 2 * 3 * len(phys) == 23
    with pytest.raises(ValueError, match=r"interactions names \['sigma_n'\]"):
        design_size({**exp, "diagnosis": {**exp["diagnosis"], "interactions": ["sigma_n"]}})


def test_an_emulator_pickled_before_pairs_existed_still_evaluates():
    import pickle

    a = np.array([44.0, 3.0, 0.0])
    axes = {0: ([34.0], _runs([[34.0, 3.0, 0.0]])), 2: ([0.25], _runs([[44.0, 3.0, 0.25]]))}
    emu = AnchoredEmulator(a, response(a), axes, [10.0, 1.0, 0.0], [80.0, 5.0, 0.5])
    old = pickle.loads(pickle.dumps(emu))
    del old.__dict__["_pairs"]  # what an earlier run's selection.pkl holds
    x = np.array([[39.0, 3.0, 0.125]])
    assert np.array_equal(old(x), emu(x))
