"""Residual diagnosis (issue 8), its parts: the whitened residual and structure tests, the score test and
candidate ranking, sensitivities, covariate trends across records, curve errors, the emulators of the FDEM
design and the FDEM check's curves. The frozen protocol is tested in test_protocol_*.py."""

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from enkf import AR1Error
from enkf.diagnosis import (covariate_trends, curve_errors, durbin_watson, ensemble_sensitivity,
                            finite_difference_sensitivity, ljung_box, rank_candidates, runs_test, score_test,
                            spearman_exact, structure_tests, whitened_residual)

CHI2_1_999 = stats.chi2.ppf(0.999, 1)  # 10.83


# ----------------------------------------------------------------------------------------------
# residual and structure tests
# ----------------------------------------------------------------------------------------------

def test_whitened_residual_is_L_inverse_of_data_minus_model():
    t = np.arange(50.0)
    err = AR1Error(2.0, t, 3.0)
    rng = np.random.default_rng(0)
    sim, obs = rng.normal(size=50), rng.normal(size=50)
    w = whitened_residual(sim, obs, err)
    L = np.linalg.cholesky(err.dense())
    assert np.allclose(w, np.linalg.solve(L, obs - sim), atol=1e-12)


def test_runs_ljung_box_and_durbin_watson_on_hand_computed_series():
    r = runs_test([1.0, 2.0, -1.0, -3.0, 0.5])  # + + - - +: 3 runs, n1 = 3, n2 = 2
    assert r["runs"] == 3 and r["expected"] == pytest.approx(3.4)
    assert r["z"] == pytest.approx(-0.4 / math.sqrt(0.84))
    alt = np.array([1.0, -1.0] * 5)  # rho_1 = -9/10
    lb = ljung_box(alt, lag=1)
    assert lb["Q"] == pytest.approx(10 * 12 * 0.81 / 9)
    assert durbin_watson(alt) == pytest.approx(4 * 9 / 10)
    assert runs_test(np.ones(20))["p"] == 0.0


def test_white_noise_passes_the_structure_tests_in_at_least_95_percent_of_200_seeds():
    t = np.arange(300) * 1e-6
    passed = [structure_tests(np.random.default_rng(seed).standard_normal(300), t)["passed"]
              for seed in range(200)]
    assert np.mean(passed) >= 0.95  # family-wise 1% (Bonferroni over the three tests): ~99% expected


def test_each_structure_test_is_calibrated_on_white_noise():
    t = np.arange(300) * 1e-6
    p = {"chi2": [], "runs": [], "ljung_box": []}
    for seed in range(1000, 2000):
        st = structure_tests(np.random.default_rng(seed).standard_normal(300), t)
        for k in p:
            p[k].append(st[k]["p"])
    for k, v in p.items():  # false-alarm rates near nominal (binomial sd 0.3% at 1%, 0.7% at 5%)
        v = np.array(v)
        assert np.mean(v < 0.01) < 0.025 and 0.03 < np.mean(v < 0.05) < 0.075, k


def test_ar1_and_sinusoidal_residuals_fail_the_structure_tests():
    rng = np.random.default_rng(1)
    t = np.arange(300) * 1e-6
    e = rng.standard_normal(300)
    ar = np.empty(300)
    ar[0] = e[0]
    for i in range(1, 300):  # unit-variance AR(1), phi = 0.6: chi2 is fine, the correlation is not
        ar[i] = 0.6 * ar[i - 1] + math.sqrt(1 - 0.36) * e[i]
    st = structure_tests(ar, t)
    assert not st["passed"] and {"runs", "ljung_box"} <= set(st["failed"])
    assert st["ljung_box"]["p"] < 1e-10 and st["durbin_watson"] < 1.3 and st["rho1"] > 0.3
    sine = rng.standard_normal(300) + 1.0 * np.sin(2 * np.pi * t / 40e-6)
    st = structure_tests(sine, t)
    assert not st["passed"] and st["ljung_box"]["p"] < 1e-10 and st["chi2"]["p"] < 1e-3


def test_spearman_p_is_exact_for_a_handful_of_records():
    # 3 records in perfect rank order: 2 of the 3! orderings reach |rho| = 1, p = 1/3 (not 0)
    tr = covariate_trends(pd.DataFrame({"rate": [135.0, 195.0, 257.0], "resid": [-9.0, -5.0, -1.0]}), "rate")
    assert tr.loc["resid", "rho"] == pytest.approx(1.0) and tr.loc["resid", "p_spearman"] == pytest.approx(1 / 3)
    # 5 records: 2 of 120 orderings are perfect; rho = 0.9 is reached by 10 of 120 in absolute value
    rho, p = spearman_exact([1, 2, 3, 4, 5], [1, 2, 3, 5, 4])
    assert rho == pytest.approx(0.9) and p == pytest.approx(10 / 120)


def test_covariate_trends_find_a_rate_dependence_across_records():
    rate = np.array([20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 150.0])
    rng = np.random.default_rng(3)
    table = pd.DataFrame({"strain_rate": rate, "sigma_t": 30e6 + 0.1e6 * rate + rng.normal(0, 0.2e6, rate.size),
                          "mean_white_resid": rng.normal(0, 1, rate.size)})
    tr = covariate_trends(table, "strain_rate")
    assert tr.loc["sigma_t", "slope"] == pytest.approx(0.1e6, rel=0.1)
    assert tr.loc["sigma_t", "p_pearson"] < 1e-4 and tr.loc["sigma_t", "rho"] == pytest.approx(1.0)
    assert tr.loc["mean_white_resid", "p_pearson"] > 0.05


# ----------------------------------------------------------------------------------------------
# score test on a linear-Gaussian model
# ----------------------------------------------------------------------------------------------

M = 400
TT = np.linspace(0.0, 1.0, M)
S_BASE = np.column_stack([np.ones(M), TT, np.exp(-3 * TT)])          # three base parameters
CAND = {
    "bump": np.exp(-0.5 * ((TT - 0.6) / 0.05) ** 2),                   # the planted one
    "step": (TT > 0.3).astype(float),
    "collinear": S_BASE @ np.array([0.5, -2.0, 1.0]) + 1e-3 * np.sin(2 * np.pi * 60 * TT),  # nearly in the base span
}


def linear_residual(y):
    """Whitened residual of the least-squares base fit (unit noise)."""
    theta, *_ = np.linalg.lstsq(S_BASE, y, rcond=None)
    return y - S_BASE @ theta


def test_score_test_names_the_planted_candidate_and_equals_the_chi2_drop_of_the_augmented_fit():
    rng = np.random.default_rng(4)
    delta = 1.5
    y = S_BASE @ np.array([1.0, 2.0, -1.0]) + delta * CAND["bump"] + rng.standard_normal(M)
    w = linear_residual(y)
    table = rank_candidates(w, S_BASE, CAND, param_names={"bump": ["bump.a"], "step": ["step.a"],
                                                          "collinear": ["collinear.a"]})
    assert table.loc[0, "effect"] == "bump" and table.loc[0, "score"] > CHI2_1_999 and table.loc[0, "passes"]
    res = score_test(w, S_BASE, CAND["bump"])
    # linear model: the score statistic is exactly the chi-square drop of the augmented least squares
    A = np.column_stack([S_BASE, CAND["bump"]])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    drop = w @ w - np.sum((y - A @ coef) ** 2)
    assert res["score"] == pytest.approx(drop, rel=1e-9)
    assert res["step"][0] == pytest.approx(coef[-1], rel=1e-9)
    se = 1.0 / math.sqrt(np.sum(((np.eye(M) - S_BASE @ np.linalg.pinv(S_BASE)) @ CAND["bump"]) ** 2))
    assert abs(res["step"][0] - delta) < 3 * se
    assert json.loads(table.loc[0, "step"])["bump.a"] == pytest.approx(coef[-1])
    # the nearly collinear candidate: collinearity ~1, a low score, screened out (the score test is
    # scale-free, so only its tiny own direction counts, and it does not point at the residual)
    col = table.set_index("effect").loc["collinear"]
    assert col["collinearity"] > 0.9999 and col["principal_angle_deg"] < 1.0 and not col["passes"]
    assert col["score"] < CHI2_1_999
    # exactly in the base span (to round-off): no new direction, score 0
    inside = score_test(w, S_BASE, S_BASE @ np.array([0.5, -2.0, 1.0]))
    assert inside["score"] == 0.0 and inside["collinearity"] == pytest.approx(1.0) and inside["p_value"] == 1.0


def test_score_statistic_is_chi2_distributed_under_the_null_and_invariant_to_scaling():
    scores1, scores2 = [], []
    for seed in range(1000):
        w = linear_residual(np.random.default_rng(seed).standard_normal(M))
        scores1.append(score_test(w, S_BASE, CAND["bump"])["score"])
        scores2.append(score_test(w, S_BASE, np.column_stack([CAND["bump"], CAND["step"]]))["score"])
    assert stats.kstest(scores1, stats.chi2(1).cdf).pvalue > 0.01
    assert stats.kstest(scores2, stats.chi2(2).cdf).pvalue > 0.01
    w = linear_residual(np.random.default_rng(5).standard_normal(M) + 0.3 * CAND["step"])
    a = score_test(w, S_BASE, CAND["step"])
    b = score_test(w, S_BASE @ np.array([[2.0, 1, 0], [0, 1e3, 0], [0, 0, -1]]), 1e6 * CAND["step"])
    assert a["score"] == pytest.approx(b["score"], rel=1e-9)
    assert a["collinearity"] == pytest.approx(b["collinearity"], rel=1e-9)
    exact = score_test(w, S_BASE, S_BASE[:, 1] - 2 * S_BASE[:, 0])
    assert exact["score"] == 0.0 and exact["dof"] == 0 and exact["collinearity"] == pytest.approx(1.0)


def test_null_case_no_candidate_passes():
    w = linear_residual(S_BASE @ np.array([1.0, 2.0, -1.0]) + np.random.default_rng(6).standard_normal(M))
    table = rank_candidates(w, S_BASE, CAND)
    assert not table["passes"].any() and (table["score"] < CHI2_1_999).all()


def test_out_of_catalogue_structure_is_significant_for_no_candidate_that_explains_it():
    # a 12-cycle oscillation: every candidate projects a sliver of it, none explains it
    y = np.random.default_rng(7).standard_normal(M) + 0.8 * np.sin(2 * np.pi * 12 * TT)
    w = linear_residual(y)
    assert not structure_tests(w, TT)["passed"]
    table = rank_candidates(w, S_BASE, CAND)
    assert not table["passes"].any() and (table["explained_excess"] < 0.05).all()


def test_candidate_collinearity_flags_candidates_that_are_first_order_twins():
    twin = CAND["bump"] + 0.02 * CAND["step"]
    table = rank_candidates(linear_residual(np.random.default_rng(8).standard_normal(M)), S_BASE,
                            {"bump": CAND["bump"], "twin": twin, "step": CAND["step"]}).set_index("effect")
    assert table.loc["bump", "nearest_candidate"] == "twin" and table.loc["bump", "candidate_collinearity"] > 0.99
    assert table.loc["step", "candidate_collinearity"] < 0.5


# ----------------------------------------------------------------------------------------------
# sensitivities, curve errors, the emulated model's design and the FDEM check's curves
# ----------------------------------------------------------------------------------------------

def test_ensemble_and_finite_difference_sensitivities_recover_a_known_jacobian():
    A = np.random.default_rng(11).normal(size=(30, 3))
    P = np.random.default_rng(12).normal(size=(40, 3))
    Y = P @ A.T + 5.0
    assert np.allclose(ensemble_sensitivity(P, Y), A, atol=1e-10)

    def quad(X):
        return np.column_stack([X[:, 0] ** 2, X[:, 0] * X[:, 1], np.exp(X[:, 1])])
    J = finite_difference_sensitivity(quad, [1.0, 0.5], 1e-4)
    assert np.allclose(J, [[2.0, 0.0], [0.5, 1.0], [0.0, math.exp(0.5)]], atol=1e-7)
    # at a bound, the one-sided difference that stays in the box
    J = finite_difference_sensitivity(quad, [0.0, 0.5], 1e-6, lower=[0.0, -1.0], upper=[1.0, 1.0])
    assert J[0, 0] == pytest.approx(1e-6, abs=1e-9) and J[1, 0] == pytest.approx(0.5, rel=1e-6)


def test_curve_errors():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    e = curve_errors(t, [0.0, 1.0, 3.0, 1.0], [0.0, 2.0, 1.0, 0.0])
    assert e["rmse"] == pytest.approx(math.sqrt((1 + 4 + 1) / 4))
    assert e["peak_error"] == pytest.approx(1.0) and e["peak_rel_error"] == pytest.approx(0.5)
    assert e["time_to_peak_error"] == pytest.approx(1.0)


def test_emulators_from_design_leave_failed_runs_out_and_refuse_too_few():
    from calibration.diagnose import emulators_from_design
    t = np.linspace(0.0, 1e-4, 41)
    X = np.array([[a, b] for a in np.linspace(1.0, 3.0, 4) for b in np.linspace(0.5, 1.5, 4)])
    runs = [pd.DataFrame({"time_s": t, "stress_Pa": x[0] * 1e6 * np.sin(x[1] * t / 1e-4)}) for x in X]
    runs[3] = pd.DataFrame({"time_s": [], "stress_Pa": []})  # a failed member's empty curve
    runs[5] = runs[5].iloc[:20]  # stops before the end of the grid
    em, failed = emulators_from_design(X, {"r": runs}, t, [1.0, 0.5], [3.0, 1.5], ["a", "b"])
    assert failed == {"r": 2}
    x = np.array([[2.2, 1.1]])  # a point off the design: the thin-plate interpolant of a smooth field
    exact = 2.2e6 * np.sin(1.1 * t / 1e-4)
    assert np.max(np.abs(em["r"](x)[0] - exact)) < 0.02 * np.max(np.abs(exact))
    with pytest.raises(RuntimeError, match=r"diagnosis of x: only 3 of 16 design runs of r succeeded"):
        emulators_from_design(X, {"r": runs[:3] + [None] * 13}, t, [1.0, 0.5], [3.0, 1.5], ["a", "b"],
                              label="diagnosis of x")


def test_measured_curve_applies_the_measurement_chain_on_the_model_grid_and_the_check_plots_it(tmp_path):
    from calibration.diagnose import measured_curve, model_grid
    from calibration.plots import plot_diagnosis_check
    post = {"sigma_t": {"mean": 4e7}, "face_gap.gap_m": {"mean": 2e-4}, "gauge_gain.g@r1": {"mean": 1.1},
            "gauge_gain.g@r2": {"mean": 0.9}, "baseline.offset_Pa": {"mean": -1e6}}
    # a run sampled from before the arrival (negative times), as FDEM writes it; the chain acts on the
    # model grid from t = 0, exactly as on the emulated curve: y = 1.1 s - 1 MPa at the observation times
    # (record r1's own gain; physical parameters are the simulator's, not the chain's)
    t_run = np.arange(-50e-6, 300e-6 + 1e-12, 0.5e-6)
    s = 1e12 * np.clip(t_run, 0.0, None)  # 1 MPa/us ramp from the arrival
    model_t = np.arange(0.0, 280e-6 + 1e-12, 0.5e-6)
    np.testing.assert_array_equal(model_grid({"t_end": 280e-6, "sample_dt": 0.5e-6}), model_t)
    obs_t = np.arange(0.0, 280e-6 + 1e-12, 2e-6)
    run = pd.DataFrame({"time_s": t_run, "stress_Pa": s})
    y = measured_curve(run, model_t, post, obs_t, record="r1")
    np.testing.assert_allclose(y, 1.1 * 1e12 * obs_t - 1e6, rtol=0, atol=1e-3)
    with pytest.raises(ValueError, match="has no value for record 'r3'"):
        measured_curve(run, model_t, post, obs_t, record="r3")  # never another record's gain
    assert measured_curve(pd.DataFrame({"time_s": [], "stress_Pa": []}), model_t, post, obs_t, record="r1") is None
    # the check's figure: per record the data, the run before (failed here) and after, with their RMSE
    obs = 1.1e12 * obs_t - 1e6
    curves = {"r1": {"data": "heldout", "time": obs_t, "obs": obs, "before": None, "after": y}}
    errors = {"r1": {"data": "heldout", "before": None, "after": curve_errors(obs_t, y, obs)}}
    assert errors["r1"]["after"]["rmse"] < 1e-3
    png = plot_diagnosis_check(tmp_path / "check.png", curves, errors, ["face_gap"], "face_gap: confirmed")
    assert png.stat().st_size > 1000
    # a replicated check: three mesh realizations per point, one line each, the errors their means
    from enkf.diagnosis import replicate_curve_errors
    reps = np.vstack([y, y + 2e6, y - 2e6])
    e = replicate_curve_errors(obs_t, reps, obs)
    assert e["replicates"] == 3 and e["rmse"] == pytest.approx(np.sqrt(8e12 / 3), rel=1e-6)
    curves["r1"]["after"], errors["r1"]["after"] = reps, e
    png = plot_diagnosis_check(tmp_path / "check3.png", curves, errors, ["face_gap"], "face_gap: confirmed")
    assert png.stat().st_size > 1000
    # the shipped model's 90 % band, shaded from check_band.csv's edges, its coverage in the legend; the
    # base model's band is not drawn when an effect was added
    from calibration.plots import check_figure
    bands = pd.DataFrame({"record": "r1", "data": "heldout", "model": ["after"] * obs_t.size + ["before"] * obs_t.size,
                          "time_s": np.r_[obs_t, obs_t], "centre_Pa": np.r_[y, y],
                          "lower_Pa": np.r_[y - 5e6, y - 9e6], "upper_Pa": np.r_[y + 5e6, y + 9e6]})
    fig = check_figure(curves, errors, ["face_gap"], None, bands, {"r1": {"after": {"predictive_coverage_90": 0.87}}})
    (ax,) = fig.axes
    (poly,) = ax.collections
    v = poly.get_paths()[0].vertices  # MPa, us: the band's upper and lower edges
    assert v[:, 1].max() == pytest.approx((y + 5e6).max() / 1e6) and v[:, 1].min() == pytest.approx((y - 5e6).min() / 1e6)
    assert "90 % predictive band (covers 0.87)" in [x.get_text() for x in ax.get_legend().get_texts()]
    assert "data" in [x.get_text() for x in ax.get_legend().get_texts()]
    # data corrected by an approximation error: both drawn, each named, the corrected one where obs says
    curves["r1"]["observed"] = obs + 3e6
    fig2 = check_figure(curves, errors, ["face_gap"])
    (ax2,) = fig2.axes
    lines = {ln.get_label(): ln.get_ydata() for ln in ax2.get_lines()}
    np.testing.assert_allclose(lines["data as observed"], (obs + 3e6) / 1e6)
    np.testing.assert_allclose(lines["data less the coarse mesh's mean error"], obs / 1e6)
    import matplotlib.pyplot as plt
    plt.close(fig)
    plt.close(fig2)
