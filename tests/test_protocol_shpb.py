"""The frozen protocol on SHPB records (calibration.protocol, issue 32): the adapter around
calibration.diagnose.EmulatedSHPB, with an exact stand-in for the FDEM emulator (arrival delayed by
gap / 10 m/s, elastic rise with a 2 us rounded foot up to the strength, exponential decay) and its
'FDEM runs' at the check points.

Five calibration records at 0.6-1.4 MPa/us and a held-out one (0.85 MPa/us), face gaps planted per
record (40-150 um; held out 95 um); every record also has a measured closure before load (what
``closure_before_load_m`` would give, ``CLOSURE``), which nothing in the protocol can read.
"""

import numpy as np
import pandas as pd
import pytest

from calibration.diagnose import EmulatedSHPB, interpolation_matrix, record_params
from calibration.protocol import (ProtocolModel, check_runs, confirm, emulator_errors, protocol_model, real_curves,
                                  select)
from enkf import AR1Error
from enkf.diagnosis import heldout_evaluation
from shpb import effects as fx

MODEL_T = np.arange(0.0, 300e-6, 0.5e-6)
OBS_T = np.arange(0.0, 280e-6 + 1e-12, 2e-6)
T0, FOOT, V_FACE = 30e-6, 2e-6, 10.0
NAMES = ["sigma_p", "tau_d", "face_gap.gap_m"]
LOWER, UPPER = np.array([30e6, 30e-6, 0.0]), np.array([50e6, 60e-6, 300e-6])
K = {"A": 0.6e12, "B": 0.8e12, "C": 1.0e12, "D": 1.2e12, "E": 1.4e12, "H": 0.85e12}
GAP = {"A": 40e-6, "B": 150e-6, "C": 110e-6, "D": 75e-6, "E": 95e-6, "H": 95e-6}
CLOSURE = {"A": 30e-6, "B": 120e-6, "C": 90e-6, "D": 60e-6, "E": 80e-6, "H": 20e-6}
CALIB = list("ABCDE")
TRUTH = {"sigma_p": 40e6, "tau_d": 45e-6}
SIGMA = 0.3e6


def curve(t, sigma_p, tau_d, gap, K):
    sigma_p, tau_d, gap = (np.atleast_1d(v)[:, None] for v in (sigma_p, tau_d, gap))
    t0 = T0 + gap / V_FACE
    rise = K * FOOT * np.logaddexp(0.0, (t - t0) / FOOT)
    x = sigma_p / (K * FOOT)
    t_p = t0 + FOOT * (x + np.log(-np.expm1(-x)))
    return np.where(t < t_p, rise, sigma_p * np.exp(-(t - t_p) / tau_d))


class ExactEmulator:
    """What EmulatedSHPB and the protocol read of a CurveEmulator, exact; its leave-one-out residuals are
    smooth AR(1) curves of 0.05 MPa (a design that interpolates well)."""

    n_params, m = 3, MODEL_T.size

    def __init__(self, K, seed):
        self.K, self.lower, self.upper = K, LOWER, UPPER
        self.X = np.zeros((48, 3))
        self._loo = AR1Error(0.05e6, MODEL_T, 6e-6).sample(np.random.default_rng(seed), 48)

    def __call__(self, X):
        X = np.array(X, dtype=float, ndmin=2)
        assert np.all(X >= self.lower - 1e-12) and np.all(X <= self.upper + 1e-12), "outside the design box"
        return curve(MODEL_T, X[:, 0], X[:, 1], X[:, 2], self.K)

    def loo_residuals(self):
        return self._loo


def emulated():
    return EmulatedSHPB({r: ExactEmulator(k, i) for i, (r, k) in enumerate(K.items())}, NAMES, MODEL_T,
                        {r: OBS_T for r in K})


def data(seed=2):
    rng = np.random.default_rng(seed)
    noise = AR1Error(SIGMA, OBS_T, 3e-6)
    return {r: curve(OBS_T, TRUTH["sigma_p"], TRUTH["tau_d"], GAP[r], K[r])[0] + noise.sample(rng, 1)[0] for r in K}


NOISE = {r: AR1Error(SIGMA, OBS_T, 3e-6) for r in K}


def run(model, obs):
    return select(model, base_names=["sigma_p", "tau_d"], candidates=[fx.get_effect("face_gap"), fx.get_effect("gauge_gain")],
                  calib_records=CALIB, heldout_records=["H"], obs={r: obs[r] for r in CALIB}, noise=NOISE, seed=3,
                  n_members=80, esmda_steps=4, max_additions=1)


@pytest.fixture(scope="module")
def selected():
    obs = data()
    return obs, run(emulated(), obs)


def test_the_adapter_takes_no_records_measured_closure_and_a_time_correlated_emulator_error():
    model = emulated()
    pm = protocol_model(model)
    assert isinstance(pm, ProtocolModel) and pm.emulated is model
    # the emulated model has no way to take a record's measurement of a per-record parameter
    with pytest.raises(TypeError, match="record_centres"):
        EmulatedSHPB(model.emulators, NAMES, MODEL_T, model.obs_times, record_centres={"A": {"face_gap.gap_m": 30e-6}})
    # the design's box for every record's copy, never one centred on a record's measurement
    lo, hi = pm.box(["face_gap.gap_m@A", "face_gap.gap_m@H", "sigma_p"])
    assert lo.tolist() == [0.0, 0.0, 30e6] and hi.tolist() == [300e-6, 300e-6, 50e6]
    # a record without its own copy is an error, not a fallback to its closure
    with pytest.raises(ValueError, match="record C has no copy of"):
        pm.forward(["sigma_p", "tau_d", "face_gap.gap_m@A"], ["A", "C"])
    err = emulator_errors(model, ["A", "H"])
    for r in ("A", "H"):
        assert err[r].kind == "ar1" and err[r].corr_time > 3e-6 and err[r].m == OBS_T.size
        W = interpolation_matrix(MODEL_T, OBS_T)
        rms = np.sqrt(np.mean((model.emulators[r].loo_residuals() @ W.T) ** 2, axis=0))
        np.testing.assert_allclose(err[r].std, rms, rtol=1e-9)


def test_each_record_reads_only_its_own_copy_of_a_per_record_parameter():
    model = emulated()
    names = ["sigma_p", "tau_d", "face_gap.gap_m@A", "face_gap.gap_m@B", "gauge_gain.g@A", "gauge_gain.g@B"]
    x = np.array([40e6, 45e-6, 40e-6, 120e-6, 1.0, 1.1])
    y = model.forward(names, ["A", "B"])(x)[0]
    np.testing.assert_allclose(y[:OBS_T.size], curve(OBS_T, 40e6, 45e-6, 40e-6, K["A"])[0], atol=1e-6)
    np.testing.assert_allclose(y[OBS_T.size:], 1.1 * curve(OBS_T, 40e6, 45e-6, 120e-6, K["B"])[0], atol=1e-6)
    np.testing.assert_allclose(model.forward(names, ["A"])(x)[0], y[:OBS_T.size])
    # a record with no copy reads the null (ForwardModel's contract); the protocol refuses it
    np.testing.assert_allclose(model.forward(names, ["C"])(x)[0], curve(OBS_T, 40e6, 45e-6, 0.0, K["C"])[0], atol=1e-6)
    with pytest.raises(ValueError, match="record C has no copy of"):
        protocol_model(model).forward(names, ["C"])
    # an FDEM run of one record: its own copies under their plain names, never another record's
    point = dict(zip(names, x))
    assert record_params(point, "A") == {"sigma_p": 40e6, "tau_d": 45e-6, "face_gap.gap_m": 40e-6, "gauge_gain.g": 1.0}
    with pytest.raises(ValueError, match="has no value for record 'C'"):
        record_params(point, "C")
    with pytest.raises(ValueError, match="per record"):
        record_params(point, None)


def test_the_population_gap_predicts_the_heldout_record_and_its_closure_is_never_read(selected):
    obs, sel = selected
    assert [s.spec.effect_names for s in sel.steps] == [[], ["face_gap"]]
    pop = sel.last.populations["face_gap.gap_m"]
    assert pop.tau_source == "reml" and abs(pop.mu_work - np.mean([GAP[r] for r in CALIB])) < 5e-6
    pred = sel.last.heldout["H"]
    lo, hi = pred.intervals()["face_gap.gap_m@H"]
    assert lo <= GAP["H"] <= hi and pred.point["face_gap.gap_m@H"] == pop.median()
    # the removed loop would have given H its measured closure (20 um); the protocol gives the population's
    assert abs(pred.point["face_gap.gap_m@H"] - CLOSURE["H"]) > 50e-6
    # another held-out curve: the same prediction, bit for bit
    other = run(emulated(), {**obs, "H": -obs["H"]})
    assert np.array_equal(other.last.heldout["H"].curve, pred.curve) and other.last.heldout["H"].point == pred.point


def test_check_runs_real_curves_confirmation_and_heldout_evaluation(selected):
    obs, sel = selected
    rows = check_runs(sel)
    assert len(rows) == 2 * (len(CALIB) + 1)
    row = next(r for r in rows if r["step"] == 1 and r["role"] == "heldout")
    assert set(row["simulator"]) == {"sigma_p", "tau_d", "face_gap.gap_m"} and row["measurement"] == {}
    assert row["simulator"]["face_gap.gap_m"] == sel.last.heldout["H"].point["face_gap.gap_m@H"]
    assert set(next(r for r in rows if r["step"] == 0)["simulator"]) == {"sigma_p", "tau_d"}

    def fdem(row):  # the stand-in's 'FDEM run' at the row's simulator parameters
        p = {**{"face_gap.gap_m": 0.0}, **row["simulator"]}
        y = curve(MODEL_T, p["sigma_p"], p["tau_d"], p["face_gap.gap_m"], K[row["record"]])[0]
        return pd.DataFrame({"time_s": MODEL_T, "stress_Pa": y})
    curves = real_curves(rows, [fdem(r) for r in rows], emulated())
    assert set(curves["cv"]) == {0, 1} and set(curves["cv"][1]) == set(CALIB)
    # the stand-in emulator is exact: the real curve at a CV point is the CV prediction
    np.testing.assert_allclose(curves["cv"][1]["B"], sel.last.cv.curve("B"), atol=1.0)
    out = confirm(sel, curves["cv"], obs, NOISE)
    assert out["confirmed"] == 1 and out["effects"] == ["face_gap"] and out["steps"][0]["z"] > 20
    assert out["real_cv_rmse"][1] < 0.5 * out["real_cv_rmse"][0]
    ev = heldout_evaluation(sel, obs, {r: OBS_T for r in K}, final=out["confirmed"],
                            real={"before": curves["heldout"][0], "after": curves["heldout"][1]})["H"]
    assert ev["after"]["rmse"] < 0.5 * ev["before"]["rmse"] and ev["final_model"] == "base + face_gap"


def test_replicated_check_runs_pair_the_steps_on_common_meshes(selected):
    """Three mesh realizations per check point: rows per (step, record) x 3, replicate k common to every
    step; real_curves stacks them (K, m); the walk compares the steps in pairs (a mesh departure of 1 MPa,
    the same on a record's mesh k whatever the step), and the held-out errors are the replicates' means."""
    obs, sel = selected
    rows = check_runs(sel, 3)
    assert len(rows) == 3 * 2 * (len(CALIB) + 1)
    assert sorted({r["replicate"] for r in rows}) == [0, 1, 2]
    with pytest.raises(ValueError, match="replicates must be >= 1"):
        check_runs(sel, 0)
    departure = AR1Error(1e6, MODEL_T, 10e-6)
    mesh = {(rec, k): departure.sample(np.random.default_rng(100 * ord(rec) + k), 1)[0] for rec in K for k in range(3)}

    def fdem(row):
        p = {**{"face_gap.gap_m": 0.0}, **row["simulator"]}
        y = curve(MODEL_T, p["sigma_p"], p["tau_d"], p["face_gap.gap_m"], K[row["record"]])[0]
        return pd.DataFrame({"time_s": MODEL_T, "stress_Pa": y + mesh[(row["record"], row["replicate"])]})
    runs = [fdem(r) for r in rows]
    curves = real_curves(rows, runs, emulated())
    assert curves["cv"][1]["B"].shape == (3, OBS_T.size)
    # a failed run of one replicate fails the point
    i = next(i for i, r in enumerate(rows) if r["step"] == 1 and r["record"] == "B" and r["replicate"] == 2)
    assert real_curves(rows, runs[:i] + [None] + runs[i + 1:], emulated())["cv"][1]["B"] is None
    out = confirm(sel, curves["cv"], obs, NOISE)
    s = out["steps"][0]
    assert out["confirmed"] == 1 and s["test"].startswith("paired replicates") and s["sd_realizations"] > 0
    assert 2.0 <= s["dof"] <= 10.0  # between one record's K - 1 and five records' 5 (K - 1)
    ev = heldout_evaluation(sel, obs, {r: OBS_T for r in K}, final=1,
                            real={"before": curves["heldout"][0], "after": curves["heldout"][1]})["H"]
    assert ev["after"]["replicates"] == 3 and len(ev["after"]["rmse_per_replicate"]) == 3
    assert ev["after"]["rmse"] == pytest.approx(np.sqrt(np.mean(np.square(ev["after"]["rmse_per_replicate"]))))
    assert ev["after"]["rmse"] < 0.5 * ev["before"]["rmse"]
