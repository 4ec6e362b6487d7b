"""The discrepancy loop end to end (issue 8): ES-MDA on a cheap analytic surrogate of an SHPB stress curve,
planted effects found and recovered, the null case, out-of-catalogue structure (the unit tests of its
parts are in test_diagnosis.py).

end-to-end loop with ES-MDA on a cheap analytic surrogate of an SHPB stress curve.

Surrogate (stand-in for the FDEM specimen stress): an elastic rise of fixed slope K (the modulus and
loading rate are known, as in the paper's calibrations) from the arrival at t0 = 30 us with a 2 us
rounded foot, until the stress reaches the strength ``sigma_p``; then an exponential post-peak decay with
time constant ``tau_d``. Base parameters ``sigma_p`` (truth 40 MPa, box 20-60) and ``tau_d`` (45 us,
box 10-100). The catalogue's measurement effects are applied with ``shpb.effects.apply_measurement``.
Calibration record: K = 1 MPa/us; held-out record: K = 0.7 MPa/us (a second test at another rate,
same gauges). 600 samples at 0.5 us, white noise 0.3 MPa (0.75% of the peak).

Reliability of the loop as configured here, measured on 20 other seeds (101-120) per case, ``N = 100``
members, 4 ES-MDA steps: the planted gain (1.1), shift (3 us) and low-pass (tau = 2 us) were each named
20/20 times with the verdict "explained", their 90% intervals covered the planted value 20/20, and the
calibration and held-out RMSE fell by more than half 20/20; a planted baseline offset (1 MPa) was named
20/20 and covered 19/20. The null case added nothing and said "no structure" 20/20; a ringing no
catalogue effect can produce (1 MPa at 40 kHz, 1.5 MPa at 20 or 80 kHz) ended "unexplained" with
nothing added 60/60.
"""

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from enkf import AR1Error, BoxTransform, DiagonalError, assimilate, esmda_alphas, latin_hypercube
from enkf.diagnosis import (Candidate, CalibrationResult, accept_effect, covariate_trends, default_windows, diagnose_loop,
                            ensemble_sensitivity, finite_difference_sensitivity, pinned_at_bounds,
                            report_to_json, structure_tests, write_report)
from shpb import effects as fx

CHI2_1_999 = stats.chi2.ppf(0.999, 1)  # 10.83

# ----------------------------------------------------------------------------------------------
# end-to-end loop: ES-MDA on the surrogate with the catalogue's measurement effects
# ----------------------------------------------------------------------------------------------

T = np.arange(0.0, 300e-6, 0.5e-6)
T0, FOOT = 30e-6, 2e-6
K_CAL, K_HELD = 1.0e12, 0.7e12  # elastic loading slope [Pa/s] of the calibration and held-out records
BASE = ["sigma_p", "tau_d"]
BASE_LO, BASE_HI = np.array([20e6, 10e-6]), np.array([60e6, 100e-6])
TRUTH = {"sigma_p": 40e6, "tau_d": 45e-6}
SIGMA = 0.3e6
N_MEMBERS, N_STEPS = 100, 4


def surrogate(t, sigma_p, tau_d, K):
    """Rows of stress curves [Pa]: rise K * softplus(t - t0) up to sigma_p, then sigma_p exp(-(t - t_p)/tau_d)."""
    sigma_p = np.atleast_1d(sigma_p)[:, None]
    tau_d = np.atleast_1d(tau_d)[:, None]
    rise = K * FOOT * np.logaddexp(0.0, (t - T0) / FOOT)
    x = sigma_p / (K * FOOT)
    t_p = T0 + FOOT * (x + np.log(-np.expm1(-x)))  # where the rise reaches sigma_p exactly
    return np.where(t < t_p, rise, sigma_p * np.exp(-(t - t_p) / tau_d))


def forward(names, K, extra=None):
    """``(N, n) params -> (N, m)`` curves: the surrogate, then the measurement chain of the named effects."""
    def f(P):
        P = np.atleast_2d(P)
        cols = {n: P[:, j] for j, n in enumerate(names)}
        Y = surrogate(T, cols["sigma_p"], cols["tau_d"], K)
        meas = [n for n in names if "." in n]
        for i in range(Y.shape[0]):
            Y[i] = fx.apply_measurement(T, Y[i], {n: cols[n][i] for n in meas})
        return Y if extra is None else Y + extra(T)
    return f


def box(names):
    eff = [n for n in names if "." in n]
    lo, hi = fx.bounds(eff) if eff else (np.zeros(0), np.zeros(0))
    return np.concatenate([BASE_LO, lo]), np.concatenate([BASE_HI, hi])


def esmda_calibration(names, f, f_held, obs, err, rng):
    """ES-MDA of the surrogate in the box of ``names``; the result at the posterior mean on the
    calibration (f) and held-out (f_held) records."""
    lo, hi = box(names)
    res = assimilate(f, latin_hypercube(lo, hi, N_MEMBERS, rng), obs, err, rng=rng, method="esmda",
                     alphas=esmda_alphas(N_STEPS), transform=BoxTransform(lo, hi), names=names)
    mean = res.params.mean(axis=0)
    return CalibrationResult(names, res.params, f(mean)[0], heldout=f_held(mean)[0], responses=res.responses,
                             info={"stop_reason": res.decision.reason}, lower=lo, upper=hi)


def run_loop(planted, seed, extra=None, candidates=None, **kw):
    """Twin data with ``planted`` effect parameters (undeclared), then the loop with the measurement catalogue."""
    rng = np.random.default_rng(seed)
    truth = {**TRUTH, **planted}
    names_t = list(truth)
    x_t = np.array([truth[n] for n in names_t])
    err = DiagonalError(SIGMA, m=T.size)
    clean = forward(names_t, K_CAL, extra)(x_t)[0]
    clean_held = forward(names_t, K_HELD, extra)(x_t)[0]
    obs = clean + err.sample(rng, 1)[0]
    obs_held = clean_held + err.sample(rng, 1)[0]

    def calibrate(names):
        return esmda_calibration(names, forward(names, K_CAL), forward(names, K_HELD), obs, err, rng)

    def sensitivities(result, names):
        # calibrated parameters: regression over the posterior ensemble (no extra run); candidates:
        # finite differences of the measurement chain on the fitted base curve (no new simulation)
        S_cur = ensemble_sensitivity(result.params, result.responses)
        mean = result.mean()
        base_curve = surrogate(T, mean["sigma_p"], mean["tau_d"], K_CAL)[0]
        meas = {n: v for n, v in mean.items() if "." in n}
        new = [n for n in names if n not in result.names]
        lo, hi = fx.bounds(new)
        x0 = np.array([fx.null_values([n])[n] for n in new])

        def chain(X):
            return np.array([fx.apply_measurement(T, base_curve, {**meas, **dict(zip(new, x))}) for x in X])
        S_new = finite_difference_sensitivity(chain, x0, 1e-3 * (hi - lo), lower=lo, upper=hi)
        return np.column_stack([S_cur[:, [result.names.index(n) for n in names[:len(result.names)]]], S_new])

    report = diagnose_loop(calibrate, sensitivities, base_names=BASE, candidates=candidates or fx.candidates(kind="measurement"),
                           obs=obs, obs_error=err, times=T, heldout_obs=obs_held, heldout_times=T, **kw)
    return report, clean


def assert_planted_effect_found(report, planted):
    effect = next(iter(planted)).split(".")[0]
    assert report["chosen"] == effect and report["added"] == [effect], report["why"]
    assert report["verdict"] == "explained", report["why"]
    for name, value in planted.items():
        post = report["params_after"][name]
        assert post["q05"] <= value <= post["q95"], (name, post)
    for data in ("calibration", "heldout"):
        before, after = report["errors"][data]["before"], report["errors"][data]["after"]
        assert after["rmse"] <= 0.5 * before["rmse"], (data, before, after)
        assert abs(after["peak_error"]) < abs(before["peak_error"]) + 2 * SIGMA
    assert not report["structure_before"]["passed"] and report["structure_after"]["passed"]
    for p in BASE:  # the base parameters come back to the truth once the effect carries its share
        assert report["params_after"][p]["q05"] <= TRUTH[p] <= report["params_after"][p]["q95"]


def test_loop_names_a_planted_gauge_gain_and_recovers_it():
    planted = {"gauge_gain.g": 1.1}
    report, _ = run_loop(planted, 100)
    assert_planted_effect_found(report, planted)
    # the gain is not the top score (a steeper rise also looks like an earlier trigger to first order),
    # the re-calibration of the near-tied candidates decides by BIC
    first = report["iterations"][0]
    assert {t["effect"] for t in first["trials"]} >= {"gauge_gain", "trigger_shift"}
    # the base strength had absorbed part of the gain; it moves back by many posterior sd
    shift = report["base_shift"]["sigma_p"]
    assert shift["shift_in_sd"] < -10 and abs(shift["mean_after"] - 40e6) < abs(shift["mean_before"] - 40e6)


def test_loop_names_a_planted_trigger_shift_and_recovers_it():
    planted = {"trigger_shift.dt_s": 3e-6}
    report, _ = run_loop(planted, 100)
    assert_planted_effect_found(report, planted)
    table = report["candidate_table"].set_index("effect")
    # shift and low-pass share their first-order signature: both screened, BIC separates them
    assert table.loc["trigger_shift", "candidate_collinearity"] > 0.95
    assert table.loc["trigger_shift", "score"] > CHI2_1_999


def test_loop_names_a_planted_amplifier_lowpass_and_recovers_it():
    planted = {"lowpass.tau_s": 2e-6}
    report, _ = run_loop(planted, 100)
    assert_planted_effect_found(report, planted)
    trials = {t["effect"]: t for t in report["iterations"][0]["trials"]}
    assert trials["lowpass"]["bic"] < trials["trigger_shift"]["bic"]


def test_loop_names_a_planted_baseline_drift_and_leaves_the_offset_at_zero():
    planted = {"baseline.drift_Pa_per_s": 4e9}  # 1.2 MPa over the record
    report, _ = run_loop(planted, 100)
    assert report["added"] == ["baseline"] and report["verdict"] == "explained", report["why"]
    drift, offset = report["params_after"]["baseline.drift_Pa_per_s"], report["params_after"]["baseline.offset_Pa"]
    assert drift["q05"] <= 4e9 <= drift["q95"] and offset["q05"] <= 0.0 <= offset["q95"]
    assert report["errors"]["heldout"]["after"]["rmse"] < 0.6 * report["errors"]["heldout"]["before"]["rmse"]


def test_loop_refuses_an_effect_whose_estimate_the_box_decided():
    # a gain of 1.35 lies beyond the catalogue's box [0.8, 1.2]. The base strength absorbs it up to its
    # own upper bound (60 MPa for a 40 MPa truth), which the report flags; a trigger shift then takes part
    # of the excess with every estimate inside its box; the gain, tried next, piles up at 1.2, which says
    # only that the answer lies outside the box, and is refused. The residual stays unexplained.
    report, _ = run_loop({"gauge_gain.g": 1.35}, 100)
    assert [p["name"] for p in report["box_limited"]["base"]] == ["sigma_p"]
    assert report["box_limited"]["base"][0]["side"] == "upper" and "box-limited" in report["why"]
    trials = [t for it in report["iterations"] for t in it["trials"] if t["effect"] == "gauge_gain"]
    assert trials and not any(t["accepted"] for t in trials)
    box_reason = [r for r in trials[0]["reasons"] if "set by the box" in r]
    assert box_reason and box_reason[0].startswith("fail") and "gauge_gain.g" in box_reason[0], trials[0]["reasons"]
    assert trials[0]["posterior"]["gauge_gain.g"]["mean"] > 1.19
    assert "gauge_gain" not in report["added"] and report["verdict"] == "unexplained", report["why"]
    assert report["box_limited"]["final"] == []


def test_pinned_at_bounds_flags_a_median_at_a_bound_but_not_at_the_null_bound():
    rng = np.random.default_rng(0)
    S = np.column_stack([1.2 - np.abs(rng.normal(0, 0.002, 200)),  # piled against the upper bound 1.2
                         np.abs(rng.normal(0, 1e-8, 200)),          # low-pass tau at its null bound 0
                         rng.normal(0.0, 1e6, 200)])                # interior
    names = ["gauge_gain.g", "lowpass.tau_s", "baseline.offset_Pa"]
    lo, hi = [0.8, 0.0, -5e6], [1.2, 5e-6, 5e6]
    nulls = {"gauge_gain.g": 1.0, "lowpass.tau_s": 0.0, "baseline.offset_Pa": 0.0}
    hits = pinned_at_bounds(S, lo, hi, names, nulls=nulls)
    assert [(h["name"], h["side"]) for h in hits] == [("gauge_gain.g", "upper")]
    assert hits[0]["bound"] == 1.2 and abs(hits[0]["median"] - 1.2) < 0.01
    # without the null exemption tau at 0 is at its lower bound; 1 % of the width tolerates a median
    # 0.008 below 1.2 only down to 1.196
    assert len(pinned_at_bounds(S, lo, hi, names)) == 2
    assert pinned_at_bounds(S[:, :1] - 0.01, lo[:1], hi[:1], names[:1], fraction=0.01) == []
    ok, why = accept_effect(1000.0, 900.0, S[:, 0], 1.0, 2.0, 1.0, pinned=hits)
    assert not ok and why[-1].startswith("fail: set by the box") and "gauge_gain.g" in why[-1]
    ok, why = accept_effect(1000.0, 900.0, S[:, 0], 1.0, 2.0, 1.0, pinned=[])
    assert ok and why[-1] == "pass: no estimate at a bound of its box"


def test_loop_adds_nothing_in_the_null_case():
    report, _ = run_loop({}, 100)
    assert report["added"] == [] and report["chosen"] is None
    assert report["verdict"] == "no structure"
    assert report["params_before"] == report["params_after"]
    for p in BASE:
        assert report["params_after"][p]["q05"] <= TRUTH[p] <= report["params_after"][p]["q95"]


def test_loop_flags_an_out_of_catalogue_oscillation_as_unexplained_without_claiming_an_effect():
    def ringing(t):  # a 40 kHz ringing after the arrival, which no measurement effect can produce
        return 1.0e6 * np.sin(2 * np.pi * 40e3 * (t - T0)) * (t > T0)
    report, _ = run_loop({}, 100, extra=ringing)
    assert report["verdict"] == "unexplained" and report["added"] == []
    assert not report["structure_before"]["passed"]
    # candidates project a sliver of the ringing (significant score tests), are re-calibrated, and each
    # removes only a few percent of the excess chi-square: none is claimed
    trials = report["iterations"][0]["trials"]
    assert trials and not any(t["accepted"] for t in trials)
    assert all(t["explained"] < 0.05 for t in trials)
    assert (report["candidate_table"]["explained_excess"] < 0.05).all()
    assert "did not earn their place" in report["why"]


def test_report_is_json_ready_and_written_with_tables_and_plots(tmp_path):
    report, _ = run_loop({"trigger_shift.dt_s": 3e-6}, 100)
    js = report_to_json(report)
    text = json.dumps(js, allow_nan=False)
    assert json.loads(text)["verdict"] == report["verdict"]
    paths = write_report(report, tmp_path / "diagnosis")
    names = {p.name for p in paths}
    assert names == {"report.json", "candidates.csv", "params.csv", "errors.csv", "fit.png", "candidates.png"}
    assert all(p.stat().st_size > 0 for p in paths)
    cand = pd.read_csv(tmp_path / "diagnosis" / "candidates.csv")
    assert {"round", "effect", "score", "p_value", "collinearity", "passes"} <= set(cand.columns)
    err = pd.read_csv(tmp_path / "diagnosis" / "errors.csv")
    assert set(err["data"]) == {"calibration", "heldout"} and set(err["when"]) == {"before", "after"}


def test_plotted_curves_break_between_concatenated_records():
    from enkf.diagnosis.report import _split_records
    t, y = _split_records([0.0, 1.0, 2.0, 0.0, 1.0], [5.0, 6.0, 7.0, 8.0, 9.0])
    np.testing.assert_array_equal(np.isnan(t), [False, False, False, True, False, False])
    np.testing.assert_array_equal(y[~np.isnan(y)], [5.0, 6.0, 7.0, 8.0, 9.0])


def test_loop_takes_generic_candidates_and_respects_max_additions():
    # the loop reads only name / param_names / nulls (and lower / upper) from a candidate
    gain = Candidate("gauge_gain", ("gauge_gain.g",), (1.0,), (0.8,), (1.2,))
    shift = Candidate("trigger_shift", ("trigger_shift.dt_s",), (0.0,))
    report, _ = run_loop({"gauge_gain.g": 1.1}, 100, candidates=[gain, shift])
    assert report["added"] == ["gauge_gain"] and report["verdict"] == "explained"
    # the plain rule "add the top-scoring candidate" (max_trials = 1) first keeps the shift, which scores
    # highest and removes 77% of the excess chi-square; the gain follows in round 2, after which the
    # shift's interval contains 0 and the backward check drops it
    report, _ = run_loop({"gauge_gain.g": 1.1}, 100, candidates=[gain, shift], max_trials=1)
    assert [it["chosen"] for it in report["iterations"][:2]] == ["trigger_shift", "gauge_gain"]
    assert report["iterations"][1]["dropped"][0]["effect"] == "trigger_shift"
    assert report["added"] == ["gauge_gain"] and report["verdict"] == "explained"
    assert "trigger_shift.dt_s" not in report["params_after"]
    report, _ = run_loop({"gauge_gain.g": 1.1}, 100, max_additions=0)
    assert report["verdict"] == "unexplained" and report["added"] == [] and "maximum 0" in report["why"]


# ----------------------------------------------------------------------------------------------
# a physical effect across records: rate-dependent strength, two calibration records at two rates
# ----------------------------------------------------------------------------------------------

E_SPECIMEN = 35e9  # the surrogate's strain rate is K / E: 28.6 /s and 14.3 /s, held-out 57 /s
K_RECORDS = (1.0e12, 0.5e12)
K_HELD_RATE = 2.0e12  # held out: a faster test, outside the calibrated range


def multi_record_forward(names, Ks):
    """Records at loading slopes ``Ks`` concatenated; ``rate_strength.k`` scales the strength by
    DIF = max(1, 1 + k log10(rate / rate0)) (the catalogue's law), measurement effects per record."""
    def f(P):
        P = np.atleast_2d(P)
        cols = {n: P[:, j] for j, n in enumerate(names)}
        k = cols.get("rate_strength.k", np.zeros(P.shape[0]))
        meas = [n for n in names if "." in n and fx.effect_of(n).kind == "measurement"]
        out = []
        for K in Ks:
            dif = np.maximum(1.0, 1.0 + k * np.log10(K / E_SPECIMEN / fx.RATE0_PER_S))
            Y = surrogate(T, cols["sigma_p"] * dif, cols["tau_d"], K)
            for i in range(Y.shape[0]):
                Y[i] = fx.apply_measurement(T, Y[i], {n: cols[n][i] for n in meas})
            out.append(Y)
        return np.hstack(out)
    return f


def test_loop_finds_a_rate_dependent_strength_from_two_records_at_two_rates():
    rng = np.random.default_rng(7)
    truth = {"sigma_p": 30e6, "tau_d": 45e-6, "rate_strength.k": 0.3}
    names_t = list(truth)
    x_t = np.array([truth[n] for n in names_t])
    times = np.concatenate([T, T])
    groups = np.repeat([0, 1], T.size)
    err = AR1Error(SIGMA, times, 0.0, groups=groups)  # white, two independent records
    obs = multi_record_forward(names_t, K_RECORDS)(x_t)[0] + err.sample(rng, 1)[0]
    obs_held = multi_record_forward(names_t, (K_HELD_RATE,))(x_t)[0] + SIGMA * rng.standard_normal(T.size)
    candidates = [fx.get_effect("rate_strength"), fx.get_effect("gauge_gain"), fx.get_effect("trigger_shift")]

    def calibrate(names):
        return esmda_calibration(names, multi_record_forward(names, K_RECORDS),
                                 multi_record_forward(names, (K_HELD_RATE,)), obs, err, rng)

    def sensitivities(result, names):  # finite differences of the whole model (for FDEM: new runs)
        mean = result.mean()
        x0 = np.array([mean[n] if n in mean else fx.null_values([n])[n] for n in names])
        lo, hi = box(names)
        return finite_difference_sensitivity(multi_record_forward(names, K_RECORDS), x0, 1e-3 * (hi - lo),
                                             lower=lo, upper=hi)

    # the base model, one strength for both records, misses both peaks in opposite directions
    axis = np.arange(times.size) * 0.5e-6  # one running axis for the structure tests, a window per record
    report = diagnose_loop(calibrate, sensitivities, base_names=BASE, candidates=candidates, obs=obs,
                           obs_error=err, times=axis, heldout_obs=obs_held, heldout_times=T,
                           windows={"record_28_per_s": (0.0, T[-1] + 0.25e-6), "record_14_per_s": (T[-1] + 0.25e-6, 1.0)})
    assert report["chosen"] == "rate_strength" and report["verdict"] == "explained", report["why"]
    post = report["params_after"]["rate_strength.k"]
    assert post["q05"] <= 0.3 <= post["q95"]
    assert report["candidate_table"].loc[0, "effect"] == "rate_strength"
    # the gain and the shift were significant too and were re-calibrated, but remove only a few percent
    # of the excess chi-square (the rate law removes all of it): rejected
    trials = {t["effect"]: t for t in report["iterations"][0]["trials"]}
    assert trials["rate_strength"]["explained"] > 0.9
    assert not trials["gauge_gain"]["accepted"] and trials["gauge_gain"]["explained"] < 0.1
    windows = report["structure_before"]["windows"]
    assert windows["record_28_per_s"]["n"] == windows["record_14_per_s"]["n"] == T.size
    for data in ("calibration", "heldout"):
        e = report["errors"][data]
        assert e["after"]["rmse"] <= 0.5 * e["before"]["rmse"]
    # across records: per-record base strength fitted separately rises with the strain rate
    per_record = []
    for K in (0.5e12, 0.7e12, 1.0e12, 1.4e12):
        y = multi_record_forward(names_t, (K,))(x_t)[0] + SIGMA * rng.standard_normal(T.size)
        grid = np.linspace(20e6, 60e6, 401)
        sse = [np.sum((y - surrogate(T, s, 45e-6, K)[0]) ** 2) for s in grid]
        per_record.append({"strain_rate": K / E_SPECIMEN, "sigma_p_fit": grid[int(np.argmin(sse))]})
    trend = covariate_trends(pd.DataFrame(per_record), "strain_rate")
    assert trend.loc["sigma_p_fit", "slope"] > 0 and trend.loc["sigma_p_fit", "rho"] == pytest.approx(1.0)


def test_window_rms_points_at_the_window_where_the_structure_is():
    t = np.arange(0.0, 300e-6, 0.5e-6)
    curve = surrogate(t, 40e6, 45e-6, K_CAL)[0]
    win = default_windows(t, curve)
    assert list(win) == ["before_arrival", "rise", "peak", "post_peak"]
    assert T0 - 2e-6 < win["rise"][0] < T0 + 3e-6  # arrival at 5% of the peak, just after the foot
    assert win["peak"][0] < t[np.argmax(curve)] < win["peak"][1]
    w = np.random.default_rng(2).standard_normal(t.size)
    sel = (t >= win["peak"][0]) & (t < win["peak"][1])
    w[sel] += 3.0
    st = structure_tests(w, t, win)
    rms = {k: v["rms"] for k, v in st["windows"].items()}
    assert max(rms, key=rms.get) == "peak" and rms["peak"] > 2.5 and rms["post_peak"] < 1.3
    assert sum(v["n"] for v in st["windows"].values()) == t.size
