"""The simulator's own variability S (enkf.variability), the error terms each step uses
(calibration.model_error.ErrorModel) and the reported intervals (enkf.prediction_interval_dict)."""

import math

import numpy as np
import pytest

from calibration.model_error import ErrorModel
from enkf import AR1Error, BoxTransform, DiagonalError, esmda_update, prediction_interval_dict
from enkf.variability import simulator_variability


def _planted(M, rng, t, sd, tau):
    return AR1Error(sd, t, tau).sample(rng, M)


def test_replicates_recover_a_planted_heteroscedastic_ar1_variability():
    """Zero before an arrival, 0.2 MPa on the rise, 5 MPa after the 'peak', correlated over 8 us:
    pooled over 40 sets of six replicates, the rms after the peak within 10 % and the correlation time
    within 25 %; nothing before the arrival."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 160e-6, 1e-6)
    sd = np.where(t < 20e-6, 0.0, np.where(t < 100e-6, 0.2e6, 5.0e6)) + 1e-3
    base = 30e6 * np.clip((t - 20e-6) / 80e-6, 0, 1)
    post, taus, pre = [], [], []
    for _ in range(40):
        reps = base + _planted(6, rng, t, sd, 8e-6)
        S, info = simulator_variability(reps, t, split_times={0: 100e-6})
        g = info["groups"]["0"]
        post.append(g["rms_post_peak_Pa"])
        pre.append(float(np.sqrt(np.mean(S.std[t < 17e-6] ** 2))))  # the 5-sample average reaches 2 samples back
        taus.append(info["corr_time_s"])
    assert np.mean(post) == pytest.approx(5.0e6, rel=0.10)
    assert np.median(taus) == pytest.approx(8e-6, rel=0.25)
    assert max(pre) < 1e4  # no variability where every replicate agrees


def test_fewer_than_two_replicates_or_identical_ones_give_no_term():
    t = np.arange(0.0, 50e-6, 1e-6)
    y = np.sin(t * 1e5)
    assert simulator_variability(y[None, :], t)[0] is None
    assert simulator_variability(np.vstack([y, y, y]), t)[0] is None
    bad = np.vstack([y, y + 0.1, np.full(t.size, np.nan)])
    S, info = simulator_variability(bad, t)
    assert info["n_replicates"] == 2 and S is not None


def _terms(measured=True, mode="per_run"):
    m = 5
    R, S, D = np.eye(m) * 1.0, np.eye(m) * 4.0, np.eye(m) * 9.0
    return ErrorModel(R=R, S=S, D=D, mode=mode, measured=measured)


def test_each_step_uses_its_combination_of_noise_variability_and_discrepancy():
    """The member-vs-data test holds two realizations (2S); a twin's stop test leaves out the fitted
    discrepancy (it would absorb any misfit); an ES-MDA step alpha assimilates with R + D + (1 - 1/alpha)
    S, so that with the members' own S its perturbed innovation has alpha (R + S + D)."""
    t = _terms()
    assert np.diag(t.stop().dense())[0] == pytest.approx(1 + 8 + 9)
    assert np.diag(_terms(measured=False).stop().dense())[0] == pytest.approx(1 + 8)
    assert np.diag(t.simulator_only().dense())[0] == pytest.approx(9)
    assert np.diag(t.likelihood().dense())[0] == pytest.approx(14)
    for alpha in (1.0, 1.75, 7.0):
        assert alpha * np.diag(t.assimilation(alpha).dense())[0] + 4.0 == pytest.approx(alpha * 14.0)
    assert np.diag(t.predictive().dense())[0] == pytest.approx(10)
    shared = _terms(mode="shared")
    assert np.diag(shared.assimilation(3.5).dense())[0] == pytest.approx(1 + 8 + 9)
    assert np.diag(shared.predictive().dense())[0] == pytest.approx(1 + 8 + 9)


def test_es_mda_with_stochastic_members_and_the_alpha_correction_has_the_exact_posterior():
    """A linear model d = g theta + eta + e whose members each carry their own eta ~ N(0, S) (a
    stochastic simulator): three ES-MDA steps (7, 3.5, 1.75) with R + (1 - 1/alpha) S give the exact
    posterior under R + S (mean within 3 % of the prior sd, sd within 8 %); with R alone, as if the
    members were exact, the spread comes out too narrow by the factor the repeated S costs."""
    rng = np.random.default_rng(7)
    m, N = 4, 4000
    g = np.array([1.0, 0.5, -0.3, 0.8])
    r2, s2 = 0.05, 0.4
    theta_true = 0.7
    d = g * theta_true + rng.normal(0, math.sqrt(s2), m) + rng.normal(0, math.sqrt(r2), m)
    C = (r2 + s2) * np.eye(m)
    prec = 1.0 + g @ np.linalg.solve(C, g)
    post_sd = math.sqrt(1.0 / prec)
    post_mean = (g @ np.linalg.solve(C, d)) / prec
    terms = ErrorModel(R=r2 * np.eye(m), S=s2 * np.eye(m), D=np.zeros((m, m)), measured=False)

    def run(error_of):
        P = rng.normal(0.0, 1.0, (N, 1))
        for alpha in (7.0, 3.5, 1.75):
            Y = P * g + rng.normal(0, math.sqrt(s2), (N, m))
            P = esmda_update(P, Y, d, error_of(alpha), alpha=alpha, rng=rng, truncation=1.0).params
        return P[:, 0]

    right = run(terms.assimilation)
    assert right.mean() == pytest.approx(post_mean, abs=0.03)
    assert right.std() == pytest.approx(post_sd, rel=0.08)
    naive = run(lambda a: DiagonalError(math.sqrt(r2), m))
    assert naive.std() < 0.85 * post_sd


def test_prediction_intervals_hold_one_more_draw_at_their_level_where_sample_quantiles_do_not():
    """Members and truth as N + 1 draws of one distribution (Gaussian in the logit space of a box): over
    4,000 trials the t prediction intervals cover the truth 90 % / 50 % (within 1.5 / 2.5 points) at N = 8
    and 25, where the members' 5-95 % sample quantiles cover about 0.9 (N - 1) / (N + 1) (73 % measured
    at N = 8, 83 % at N = 25: interpolating between order statistics is not exactly linear in
    probability)."""
    rng = np.random.default_rng(3)
    tr = BoxTransform(np.array([10.0]), np.array([60.0]))
    for N in (8, 25):
        hit90 = hit50 = hit_q = 0
        n = 4000
        for _ in range(n):
            z = rng.normal(rng.normal(), 0.4, N + 1)[:, None]
            x = tr.to_bounded(z)
            iv = prediction_interval_dict(x[:N], ["p"], transform=tr)["p"]
            hit90 += iv["q05"] <= x[N, 0] <= iv["q95"]
            hit50 += iv["q25"] <= x[N, 0] <= iv["q75"]
            lo, hi = np.quantile(x[:N, 0], [0.05, 0.95])
            hit_q += lo <= x[N, 0] <= hi
        assert hit90 / n == pytest.approx(0.90, abs=0.015)
        assert hit50 / n == pytest.approx(0.50, abs=0.025)
        assert hit_q / n == pytest.approx(0.9 * (N - 1) / (N + 1), abs=0.04)
        assert hit_q / n < 0.87


def test_the_correlation_time_holds_with_the_few_replicates_the_measured_configs_use():
    """Three replicates (config/diagnosis.yaml) or four (marble_loop): the pooled lag-1 estimate of a
    planted 8 us AR(1) around a jump of the amplitude stays within 20 % (median of 40 sets; averaging
    per-time correlations gave 4.3 us at three)."""
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 160e-6, 1e-6)
    sd = np.where(t < 20e-6, 0.0, np.where(t < 100e-6, 0.2e6, 5.0e6)) + 1e-3
    for M in (3, 4):
        taus = [simulator_variability(_planted(M, rng, t, sd, 8e-6), t)[1]["corr_time_s"] for _ in range(40)]
        assert np.median(taus) == pytest.approx(8e-6, rel=0.2), M
