"""Model discrepancy, member-based misfit and posterior-predictive coverage on stand-in models.

The stand-in is a smooth pulse ``y(t) = A exp(-((t - t0)/w)^2)`` (a stress history's rise, peak and
fall), observed on several records with white instrument noise; the discrepancy is planted as an
AR(1) process of known variance and correlation time.
"""

import math

import numpy as np
import pytest

from enkf import AR1Error, DiagonalError
from enkf.diagnostics import member_misfit, member_standardized_misfit
from enkf.discrepancy import (ar1_covariance, combined_error, estimate_discrepancy, fit_record_discrepancy,
                              inflated_noise_factor, record_loglik)
from enkf.predictive import predictive_coverage

DT = 1.0e-6
M = 300
SIGMA_E = 1.0          # instrument noise (white)
SIGMA_D = 4.0          # planted discrepancy std
TAU_D = 3.0e-6         # planted correlation time (3 observation steps)


def pulse(theta, t):
    A, t0 = theta
    return A * np.exp(-((t - t0) / 80e-6) ** 2)


def planted(n_records, sigma_d, rng):
    """Observations of ``n_records`` records: pulse at the truth + AR(1) discrepancy + white noise."""
    t1 = np.arange(M) * DT
    times = np.tile(t1, n_records)
    groups = np.repeat(np.arange(n_records), M)
    truth = np.array([100.0, 200e-6])
    y_true = np.concatenate([pulse(truth, t1)] * n_records)
    delta = AR1Error(sigma_d, times, TAU_D, groups).sample(rng, 1)[0] if sigma_d > 0 else 0.0
    d = y_true + delta + SIGMA_E * rng.standard_normal(times.size)
    return t1, times, groups, truth, d


def members(truth, t1, n_records, rng, n=8, spread=0.01):
    thetas = truth * (1.0 + spread * rng.standard_normal((n, 2)))
    return thetas, np.array([np.concatenate([pulse(th, t1)] * n_records) for th in thetas])


def test_planted_ar1_discrepancy_variance_recovered_within_30_percent():
    rng = np.random.default_rng(7)
    n_rec = 4
    t1, times, groups, truth, d = planted(n_rec, SIGMA_D, rng)
    _, Y = members(truth, t1, n_rec, rng)
    noise = DiagonalError(SIGMA_E, m=d.size)
    est = estimate_discrepancy(d - Y, noise, times, groups)
    var = np.array([est.records[g].sigma ** 2 for g in range(n_rec)])
    tau = np.array([est.records[g].corr_time for g in range(n_rec)])
    # Pooled over the records (each ~50 independent correlation times, so one record's variance has a
    # sampling std of ~20 %; the mean of four, ~10 %): 30 % is 3 sampling stds.
    assert np.mean(var) == pytest.approx(SIGMA_D ** 2, rel=0.30)
    assert np.all(np.abs(var / SIGMA_D ** 2 - 1.0) < 0.6)
    assert np.median(tau) == pytest.approx(TAU_D, rel=0.5)
    # The AR(1) term explains the residual far better than the noise alone
    assert all(r.loglik - r.loglik_noise_only > 50.0 for r in est.records.values())


def test_a_discrepancy_that_lives_after_the_peak_is_recovered_there_and_not_before():
    """The simulator's crack-path variability lives after the failure peak: planted std 0.5 before
    the split and 6 after it; the fit with the split recovers both, the stationary fit smears them."""
    rng = np.random.default_rng(2)
    t1 = np.arange(M) * DT
    split = 100e-6     # 200 observations after it, ~50 correlation times: the variance's std ~20 %
    D = ar1_covariance(0.5, 2.0e-6, t1, sigma_post=6.0, split_time=split)
    delta = np.linalg.cholesky(D + 1e-12 * np.eye(M)) @ rng.standard_normal(M)
    r = delta + SIGMA_E * rng.standard_normal(M)
    noise = np.eye(M) * SIGMA_E ** 2
    fit = fit_record_discrepancy(r, noise, t1, split_time=split)
    assert fit.sigma_post ** 2 == pytest.approx(36.0, rel=0.5)
    assert fit.sigma_pre < 1.5
    flat = fit_record_discrepancy(r, noise, t1)
    assert flat.sigma_pre == flat.sigma_post and 2.0 < flat.sigma_pre < 5.5
    assert fit.loglik > flat.loglik + 20.0


def test_no_discrepancy_when_the_model_fits_to_the_noise():
    rng = np.random.default_rng(3)
    t1, times, groups, truth, d = planted(2, 0.0, rng)
    Y = np.array([np.concatenate([pulse(truth, t1)] * 2)])
    est = estimate_discrepancy(d - Y, DiagonalError(SIGMA_E, m=d.size), times, groups)
    assert all(r.sigma < 0.5 * SIGMA_E for r in est.records.values())


def test_profile_picks_the_member_that_fits_and_zero_is_a_candidate():
    rng = np.random.default_rng(11)
    t1 = np.arange(M) * DT
    truth = np.array([100.0, 200e-6])
    d = pulse(truth, t1) + SIGMA_E * rng.standard_normal(M)
    Y = np.array([pulse(truth * np.array([1.2, 1.0]), t1), pulse(truth, t1)])
    est = estimate_discrepancy(d - Y, DiagonalError(SIGMA_E, m=M), t1)
    assert est.member == 1
    fit = fit_record_discrepancy(d - Y[0], np.eye(M) * SIGMA_E ** 2, t1)
    assert fit.sigma > 5.0 * SIGMA_E and fit.loglik > fit.loglik_noise_only


def test_ar1_discrepancy_beats_the_inflated_noise_baseline_in_likelihood():
    rng = np.random.default_rng(5)
    t1, times, groups, truth, d = planted(1, SIGMA_D, rng)
    r = d - pulse(truth, t1)
    noise = DiagonalError(SIGMA_E, m=M)
    fit = fit_record_discrepancy(r, noise.dense(), t1)
    s2 = inflated_noise_factor(r, noise)
    ll_inflated = record_loglik(r, s2 * noise.dense(), t1, 0.0, 0.0)
    assert s2 == pytest.approx((SIGMA_D ** 2 + SIGMA_E ** 2) / SIGMA_E ** 2, rel=0.35)
    assert fit.loglik > ll_inflated + 50.0


def test_combined_error_adds_the_term_only_inside_its_record():
    t1 = np.arange(5) * DT
    times, groups = np.tile(t1, 2), np.repeat([0, 1], 5)
    C = combined_error(DiagonalError(1.0, m=10), times, groups, {1: (2.0, 2.0, DT, None)}, as_matrix=True)
    assert np.allclose(C[:5, :5], np.eye(5))
    assert C[5, 5] == pytest.approx(5.0) and C[5, 6] == pytest.approx(4.0 * math.exp(-1.0))
    assert np.all(C[:5, 5:] == 0.0)


def test_member_based_misfit_does_not_pass_step_members_whose_mean_fits():
    """The review's toy: 1,000 step members at random times, smooth data with sd 0.05; the mean of the
    steps is a smooth ramp that fits, no member does."""
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 200)
    steps = rng.uniform(0.2, 0.8, 1000)
    Y = (t[None, :] >= steps[:, None]).astype(float)
    ramp = np.clip((t - 0.2) / 0.6, 0.0, 1.0)
    d = ramp + 0.05 * rng.standard_normal(t.size)
    err = DiagonalError(0.05, m=t.size)
    mm = member_misfit(Y, d, err)
    target = 1.0 + 2.0 * math.sqrt(2.0 / t.size)
    assert mm["mean_curve_chi2_per_obs"] < 1.5           # the blurred mean nearly passes
    assert mm["median_chi2_per_obs"] > 10.0 * target     # the members do not
    assert mm["best_chi2_per_obs"] > target
    # the stop test's standardised statistic, against white noise and against an error correlated over
    # 10 samples (whose target is wider): the members still fail it
    for model in (err, AR1Error(0.05, t, 0.05)):
        ms = member_standardized_misfit(Y, d, model)
        assert ms["median"] > 10.0 * ms["target"] and ms["best"] > ms["target"]


def test_predictive_coverage_is_calibrated_with_the_full_error_model_and_not_without_it():
    rng = np.random.default_rng(21)
    n_rec = 2
    t1, times, groups, truth, d = planted(n_rec, SIGMA_D, rng)
    _, Y = members(truth, t1, n_rec, rng, spread=0.002)
    noise = DiagonalError(SIGMA_E, m=d.size)
    est = estimate_discrepancy(d - Y, noise, times, groups)
    full = predictive_coverage(Y, d, est.error_model(noise, times, groups), 1, groups=groups)
    bare = predictive_coverage(Y, d, noise, 1, groups=groups)
    assert 0.80 <= full["all"] <= 0.98
    assert all(0.75 <= v <= 0.99 for v in full["groups"].values())
    assert bare["all"] < 0.5


def test_the_predictive_check_judges_coverage_against_its_own_spread():
    """With an error correlated over the whole record (tau = 100 steps), a correct model's coverage
    fraction is nearly all-or-nothing: the reference range is wide and holds the observed fraction;
    an error model 5 times too small is caught."""
    rng = np.random.default_rng(4)
    t1 = np.arange(M) * DT
    from enkf import DenseError
    C = DenseError(np.eye(M) * SIGMA_E ** 2 + ar1_covariance(SIGMA_D, 100 * DT, t1), _symmetric=True)
    Y = pulse(np.array([100.0, 200e-6]), t1)[None, :] * (1.0 + 0.001 * rng.standard_normal((8, 1)))
    d = Y[0] + C.sample(rng, 1)[0]
    ok = predictive_coverage(Y, d, C, 1, n_replicates=400)
    lo, hi = ok["reference"][0]
    assert lo <= ok["all"] <= hi and hi - lo > 0.2
    small = DenseError(C.dense() / 25.0, _symmetric=True)
    bad = predictive_coverage(Y, d, small, 1, n_replicates=400)
    assert not (bad["reference"][0][0] <= bad["all"] <= bad["reference"][0][1])


def test_a_structured_foot_residual_gets_its_own_amplitude_and_the_band_covers_it():
    """The marble's case: a model that loads the specimen before the record's face closes misses the
    foot by a smooth 40-unit bump and fits the rise to within a few units, the whole residual correlated
    over most of the record. Fitted by maximum likelihood with one amplitude before and one after the
    peak, the likelihood cannot pin a variance from one or two correlation lengths and the 90 %
    predictive band misses much of the foot; with one amplitude per phase (foot, rise, post-peak) set
    by moments it holds the foot and 0.8-0.98 of the record, and each phase's amplitude is within 25 % of
    its residual's rms."""
    rng = np.random.default_rng(11)
    t1 = np.arange(M) * DT
    onset, peak = 120e-6, 200e-6
    foot = -40.0 * np.sin(np.pi * np.clip(t1 / onset, 0, 1)) ** 2 * (t1 < onset)
    rise = 3.0 * np.sin(2 * np.pi * t1 / 60e-6) * ((t1 >= onset) & (t1 < peak))
    post = 8.0 * np.sin(2 * np.pi * (t1 - peak) / 90e-6) * (t1 >= peak)
    y = pulse(np.array([100.0, 200e-6]), t1)
    d = y + foot + rise + post + SIGMA_E * rng.standard_normal(M)
    Y = y[None, :] + 0.3 * rng.standard_normal((12, 1))
    noise = np.eye(M) * SIGMA_E ** 2
    resid = d - y

    def coverage(fit):
        from enkf import DenseError

        C = noise + ar1_covariance(fit.sigmas, fit.corr_time, t1, split_time=fit.splits)
        groups = (t1 >= onset).astype(int)  # the foot, then the rest
        cov = predictive_coverage(Y, d, DenseError(C, _symmetric=True), 3, groups=groups)
        return cov["all"], cov["groups"][0]

    two = fit_record_discrepancy(resid, noise, t1, split_time=peak, method="ml")
    phased = fit_record_discrepancy(resid, noise, t1, split_time=(onset, peak))
    (all_two, foot_two), (all_phased, foot_phased) = coverage(two), coverage(phased)
    assert foot_two < 0.6 and all_two < 0.85       # measured: foot 0.51, record 0.80; phased 0.94, 0.95
    assert 0.8 <= all_phased <= 0.98 and foot_phased >= 0.85
    for k, sel in enumerate((t1 < onset, (t1 >= onset) & (t1 < peak), t1 >= peak)):
        assert phased.sigmas[k] == pytest.approx(math.sqrt(max(np.mean(resid[sel] ** 2) - 1.0, 0.0)), rel=0.25)
