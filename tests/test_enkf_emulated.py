"""Emulator-assisted ES-MDA (enkf.emulated): the emulator-error model and the analysis.

* The AR(1) emulator-error model recovers the rms and the correlation time of residuals drawn from a
  known AR(1) process, and never correlates two records.
* On a splitting-disc-like model (load rise to a peak whose time moves with sigma_t, a drop whose
  width grows with E_t, plus a post-peak wiggle that jumps with sigma_t, the rugged part of the FDEM
  response), three analyses put the ensemble mean within 1 % (sigma_t) and two posterior sd (E_t, whose sd is
  under 10 %) of the truth, with the 90 % interval containing it. (On this smooth-ish stand-in plain ES-MDA does as well; where it
  does not, on the FDEM twins themselves, is shown by the twin runs in the README.)
* Reproducible, and bad input is refused with a message.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from enkf import DiagonalError, emulated_esmda_update, emulator_error_model, latin_hypercube

T = np.linspace(0.0, 1.0e-4, 101)
LO, HI = np.array([4.0e6, 200.0]), np.array([6.0e7, 2400.0])


def splitting_disc(P, rugged=0.05):
    """Stress curve of a disc that splits at ``t_f(sigma_t)`` and unloads over ``w(E_t)``, in Pa."""
    P = np.atleast_2d(P)
    s, E = P[:, :1] / 1e6, P[:, 1:] / 1e3
    t_f = 10e-6 + 1.5e-6 * s
    w = 2e-6 + 6e-6 * E
    peak = 0.25e6 * s
    y = peak * np.minimum(T / t_f, 1.0) * 0.5 * (1.0 - np.tanh((T - t_f) / w))
    wiggle = np.sin(2.1 * np.floor(s / 0.4)) * (T > t_f) * np.exp(-(T - t_f) / 20e-6)
    return y + rugged * peak * wiggle


def twin(truth, seed):
    y = splitting_disc(truth)[0]
    sigma = 0.01 * y.max()
    d = y + sigma * np.random.default_rng(seed).standard_normal(T.size)
    return d, DiagonalError(np.full(T.size, sigma))


def run_emulated(truth, seed, n_members=25, analyses=3, temper_base=4.0):
    d, err = twin(truth, seed)
    P = latin_hypercube(LO, HI, n_members, np.random.default_rng(seed + 1))
    X, Y = np.empty((0, 2)), np.empty((0, T.size))
    for k in range(analyses):
        latest = np.r_[np.zeros(len(X), bool), np.ones(len(P), bool)]
        X, Y = np.vstack([X, P]), np.vstack([Y, splitting_disc(P)])
        res = emulated_esmda_update(X, Y, latest, d, err, lower=LO, upper=HI, n_members=n_members,
                                    rng=np.random.default_rng([seed, k]), times=T,
                                    temper=temper_base ** (analyses - 1 - k), names=["sigma_t", "E_t"])
        P = res.params
    return P, res


def covered(P, truth):
    q05, q95 = np.quantile(P, [0.05, 0.95], axis=0)
    return bool(np.all((q05 <= truth) & (truth <= q95)))


# --------------------------------------------------------------------------------------------------
def test_the_emulator_error_model_recovers_an_ar1_process():
    rng = np.random.default_rng(0)
    rho, n_curves = 0.8, 400
    sd = 1.0e5 * (1.0 + T / T[-1])  # rms growing along the curve
    e = np.empty((n_curves, T.size))
    e[:, 0] = rng.standard_normal(n_curves)
    for i in range(1, T.size):
        e[:, i] = rho * e[:, i - 1] + math.sqrt(1 - rho ** 2) * rng.standard_normal(n_curves)
    err, info = emulator_error_model(e * sd, T)
    # 400 curves: the per-time rms is known to sqrt(1/800) = 3.5 %, its mean square to < 1 %; the pooled
    # lag-1 correlation from 40 000 pairs to about (1 - rho^2)/200 = 0.002.
    assert info["rms"] == pytest.approx(float(np.sqrt(np.mean(sd ** 2))), rel=0.02)
    assert np.all(np.abs(err.std / sd - 1.0) < 0.15)
    assert info["lag1_correlation"] == pytest.approx(rho, abs=0.01)
    assert info["corr_time"] == pytest.approx(-1.0e-6 / math.log(rho), rel=0.05)
    # two records: no covariance across them
    groups = np.r_[np.zeros(50, int), np.ones(51, int)]
    err2, _ = emulator_error_model(e * sd, T, groups)
    C = err2.dense()
    assert np.all(C[:50, 50:] == 0.0) and C[0, 1] > 0.5 * C[0, 0]


def test_no_residuals_gives_no_error_model_and_a_wrong_grid_is_refused():
    assert emulator_error_model(np.empty((0, T.size)), T)[0] is None
    with pytest.raises(ValueError, match="101 times"):
        emulator_error_model(np.ones((3, 10)), T)


@pytest.mark.parametrize("truth,seed", [((3.0e7, 800.0), 5), ((4.0e7, 1200.0), 7)])
def test_three_emulated_analyses_find_a_splitting_disc_twin(truth, seed):
    truth = np.array(truth)
    P, res = run_emulated(truth, seed)
    mean, sd = P.mean(axis=0), P.std(axis=0, ddof=1)
    assert abs(mean[0] / truth[0] - 1.0) < 0.01
    # E_t: the smoothed emulator's leave-one-out error is part of the likelihood, so E_t's posterior sd is
    # 6-8 % of the truth here (the prior box's is 80 %); a bound on the mean tighter than the posterior's
    # own width would test luck. The mean within two posterior sd, and the posterior a tenth of the prior:
    assert abs(mean[1] - truth[1]) < 2.0 * sd[1] and sd[1] < 0.1 * truth[1]
    assert covered(P, truth)
    info = res.diagnostics
    assert info["design_points"] == 75 and info["latest_points"] == 25 and info["temper"] == 1.0
    assert info["emulator_error"]["rms"] < 5 * info["obs_sigma_rms"]


def test_the_same_random_stream_gives_identical_ensembles():
    """Two analyses from the same random stream agree bit for bit; one from another stream does not."""
    truth = np.array([3.0e7, 800.0])
    a, _ = run_emulated(truth, 5, analyses=1)
    b, _ = run_emulated(truth, 5, analyses=1)
    c, _ = run_emulated(truth, 6, analyses=1)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_bad_input_is_refused():
    d, err = twin(np.array([3.0e7, 800.0]), 1)
    X = latin_hypercube(LO, HI, 10, np.random.default_rng(0))
    Y = splitting_disc(X)
    latest = np.ones(10, bool)
    kw = dict(lower=LO, upper=HI, rng=0, times=T)
    with pytest.raises(ValueError, match="n_members"):
        emulated_esmda_update(X, Y, latest, d, err, n_members=500, **kw)
    with pytest.raises(ValueError, match="temper"):
        emulated_esmda_update(X, Y, latest, d, err, n_members=10, temper=0.5, **kw)
    with pytest.raises(ValueError, match="latest"):
        emulated_esmda_update(X, Y, latest[:5], d, err, n_members=10, **kw)
    with pytest.raises(ValueError, match="at least 4 runs"):
        emulated_esmda_update(X[:3], Y[:3], latest[:3], d, err, n_members=3, **kw)
    with pytest.raises(ValueError, match="observations"):
        emulated_esmda_update(X, Y[:, :50], latest, d, err, n_members=10, **kw)


def test_the_analysis_falls_back_to_gesvd_where_gesdd_does_not_converge(monkeypatch):
    """LAPACK's gesdd raised "SVD did not converge" on finite, well-scaled anomalies of an emulated
    ES-MDA (a seed sweep of the twins); the analysis must then use gesvd and give the same update."""
    import enkf.analysis as analysis
    from enkf import esmda_update

    rng = np.random.default_rng(4)
    P = latin_hypercube(LO, HI, 30, rng)
    d, err = twin(np.array([3.0e7, 800.0]), 2)
    expected = esmda_update(P, splitting_disc(P), d, err, alpha=2.0, rng=9).params
    real_svd = analysis.linalg.svd
    calls = []

    def flaky_svd(a, *args, lapack_driver="gesdd", **kwargs):
        calls.append(lapack_driver)
        if lapack_driver == "gesdd":
            raise np.linalg.LinAlgError("SVD did not converge")
        return real_svd(a, *args, lapack_driver=lapack_driver, **kwargs)

    monkeypatch.setattr(analysis.linalg, "svd", flaky_svd)
    got = esmda_update(P, splitting_disc(P), d, err, alpha=2.0, rng=9).params
    assert calls == ["gesdd", "gesvd"]
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_a_repeated_run_is_used_once():
    """A parameter set simulated twice (deterministic simulator) would make the RBF system singular."""
    d, err = twin(np.array([3.0e7, 800.0]), 1)
    X = latin_hypercube(LO, HI, 30, np.random.default_rng(3))
    Y = splitting_disc(X)
    latest = np.arange(30) >= 20
    kw = dict(lower=LO, upper=HI, n_members=10, times=T, inner_members=100)
    once = emulated_esmda_update(X, Y, latest, d, err, rng=1, **kw)
    twice = emulated_esmda_update(np.vstack([X, X[25:26]]), np.vstack([Y, Y[25:26]]), np.r_[latest, True], d, err,
                                  rng=1, **kw)
    np.testing.assert_array_equal(once.params, twice.params)
    assert twice.diagnostics["design_points"] == 30 and twice.diagnostics["latest_points"] == 10
