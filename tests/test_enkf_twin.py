"""Twin experiments with a cheap nonlinear two-parameter model, vectorised over members.

Damped pulse (a stand-in for a specimen stress-time curve): a sin^2 rise to the peak amplitude ``A`` at
``t_r = 20 us``, then an exponential decay with time constant ``tau``:

    y(t) = A sin^2(pi t / (2 t_r))           for t <= t_r
    y(t) = A exp(-(t - t_r) / tau)           for t >  t_r

The peak depends on ``A`` only, the decay on ``tau`` only (nonlinearly). Truth A = 37 MPa, tau = 42 us,
prior box A in [20, 60] MPa, tau in [10, 100] us, 200 samples at 1 us, noise std 0.35 MPa (~1% of peak).
"""

import json

import numpy as np

from enkf import AR1Error, BoxTransform, DiagonalError, StopCriteria, assimilate, latin_hypercube

T = np.arange(0.0, 200.0, 1.0)  # us
T_R = 20.0
LOWER, UPPER = np.array([20e6, 10.0]), np.array([60e6, 100.0])
TRUTH = np.array([37e6, 42.0])
TF = BoxTransform(LOWER, UPPER)
SIGMA = 0.35e6


def damped_pulse(P):
    P = np.atleast_2d(P)
    amplitude, tau = P[:, :1], P[:, 1:2]
    rise = np.sin(0.5 * np.pi * np.minimum(T, T_R) / T_R) ** 2
    return amplitude * rise * np.exp(-np.maximum(T - T_R, 0.0) / tau)


def _twin(seed, err, method="esmda", **kw):
    rng = np.random.default_rng(seed)
    d = damped_pulse(TRUTH)[0] + err.sample(rng, 1)[0]
    P0 = latin_hypercube(LOWER, UPPER, 25, rng)
    return assimilate(damped_pulse, P0, d, err, rng=rng, method=method, transform=TF, names=["A", "tau"], **kw)


def _scores(results):
    P = np.array([r.params for r in results])  # (seeds, N, 2)
    rel_err = np.abs(P.mean(axis=1) / TRUTH - 1.0)
    q05, q95 = np.quantile(P, 0.05, axis=1), np.quantile(P, 0.95, axis=1)
    covered = (q05 <= TRUTH) & (TRUTH <= q95)
    return rel_err, covered


def test_esmda_with_25_members_recovers_the_truth_within_2_percent_and_its_90_percent_interval_covers_it():
    err = DiagonalError(SIGMA, m=T.size)
    results = [_twin(seed, err) for seed in range(50)]
    assert max(r.iterations for r in results) <= 3
    rel_err, covered = _scores(results)
    assert rel_err.max() < 0.02, rel_err.max(axis=0)  # every one of the 50 seeds
    assert np.all(covered.mean(axis=0) >= 0.80), covered.mean(axis=0)
    assert sum(r.decision.converged for r in results) >= 45  # discrepancy principle met at the end


def test_esmda_twin_with_ar1_correlated_noise_is_calibrated_too():
    err = AR1Error(SIGMA, T, 3.0)
    results = [_twin(seed, err) for seed in range(50)]
    rel_err, covered = _scores(results)
    assert np.all(np.median(rel_err, axis=0) < 0.01), np.median(rel_err, axis=0)
    assert np.all(covered.mean(axis=0) >= 0.80), covered.mean(axis=0)


def test_paper_enkf_with_its_spread_floor_converges_on_the_mean_in_three_iterations():
    err = DiagonalError(SIGMA, m=T.size)
    results = [_twin(seed, err, method="enkf", criteria=StopCriteria(max_iterations=3)) for seed in range(50)]
    rel_err, covered = _scores(results)
    # the floor keeps the ensemble wide, so the mean is less accurate than ES-MDA's but close
    assert np.all(rel_err.mean(axis=0) < 0.05), rel_err.mean(axis=0)
    assert np.all(covered.mean(axis=0) >= 0.95)
    for r in results:  # the floor: 45% of the initial ensemble's spread, in the logit space
        sd = TF.to_unbounded(r.params).std(axis=0, ddof=1)
        assert np.all(sd >= 0.45 * r.prior_spread * (1 - 1e-12))
        assert np.allclose(r.prior_spread, np.pi / np.sqrt(3.0), rtol=0.25)  # 25 LHS members, logistic tails
    # the misfit of the ensemble-mean response at least halves from the prior in every seed
    ratio = [r.history[-1]["misfit_mean"]["rmse"] / r.history[0]["misfit_mean"]["rmse"] for r in results]
    assert max(ratio) < 0.5


def test_the_whole_twin_loop_is_bit_identical_for_the_same_seed():
    err = AR1Error(SIGMA, T, 3.0)
    a, b, c = _twin(7, err), _twin(7, err), _twin(8, err)
    assert np.array_equal(a.params, b.params)
    assert np.array_equal(a.responses, b.responses)
    assert json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)
    assert json.dumps(a.history, sort_keys=True) == json.dumps(b.history, sort_keys=True)
    assert not np.array_equal(a.params, c.params)
    summary = json.loads(json.dumps(a.to_dict(), allow_nan=False))
    assert summary["stop_reason"] in ("discrepancy", "max_iterations")
    assert summary["n_simulations"] == 25 * (summary["iterations"] + 1)
    tau = summary["posterior"]["tau"]
    assert tau["q05"] <= tau["mean"] <= tau["q95"]
    assert a.misfit_table()["chi2_per_obs"].iloc[-1] < a.misfit_table()["chi2_per_obs"].iloc[0]


def test_a_failing_forward_member_is_replaced_and_the_loop_goes_on():
    err = DiagonalError(SIGMA, m=T.size)

    def flaky(P):
        Y = damped_pulse(P)
        Y[P[:, 1] > 90.0] = np.nan  # "simulations" with a very long decay crash
        return Y

    rng = np.random.default_rng(3)
    d = damped_pulse(TRUTH)[0] + err.sample(rng, 1)[0]
    P0 = latin_hypercube(LOWER, UPPER, 25, rng)
    res = assimilate(flaky, P0, d, err, rng=rng, transform=TF)
    assert res.history[0]["n_alive"] == 22  # 3 of 25 LHS strata lie above 90 us
    assert np.all(np.abs(res.params.mean(axis=0) / TRUTH - 1.0) < 0.02)
