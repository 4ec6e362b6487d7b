"""Failed simulations: the update proceeds with the survivors while enough of them are alive."""

import numpy as np
import pytest

from enkf import BoxTransform, DiagonalError, EnsembleFailure, enkf_update, esmda_update, latin_hypercube

LOWER, UPPER = np.array([0.0, 1.0, 10.0, -1.0]), np.array([1.0, 3.0, 50.0, 1.0])
N, M = 25, 40
G = np.random.default_rng(1).normal(size=(M, 4))
TF = BoxTransform(LOWER, UPPER)


def _forward(P):
    return np.tanh(TF.to_unbounded(P)) @ G.T


def _setup():
    rng = np.random.default_rng(2)
    P = latin_hypercube(LOWER, UPPER, N, rng)
    d = _forward(np.array([[0.3, 2.5, 20.0, 0.4]]))[0] + rng.normal(0.0, 0.1, M)
    return P, _forward(P), d, DiagonalError(0.1, m=M)


def test_with_20_percent_of_members_failed_the_update_runs_and_stays_full_rank():
    P, Y, d, err = _setup()
    dead = np.array([3, 8, 11, 19, 24])  # 5 of 25
    Y[dead] = np.nan  # a failed simulation has no curve
    alive = np.ones(N, bool)
    alive[dead] = False
    res = esmda_update(P, Y, d, err, alpha=2.0, rng=4, transform=TF, alive=alive)
    assert res.params.shape == (N, 4) and np.all(np.isfinite(res.params))
    assert res.diagnostics["n_alive"] == 20
    assert res.replaced_members == dead.tolist()
    assert np.all((res.params >= LOWER) & (res.params <= UPPER))
    Z = res.params_unbounded
    assert np.linalg.matrix_rank(Z - Z.mean(axis=0)) == 4
    assert np.linalg.matrix_rank(Z[dead] - Z[dead].mean(axis=0)) == 4  # replacements are distinct draws
    assert np.all(np.isnan(res.responses[dead])) and np.all(np.isfinite(res.responses[alive]))
    assert res.diagnostics["misfit_members"]["chi2_per_obs"][3] is None  # JSON null for a dead member


def test_survivors_get_exactly_the_update_of_the_ensemble_without_the_dead_members():
    P, Y, d, err = _setup()
    Y[20:] = np.nan  # the last five failed: the survivors' perturbation rows are the first 20 draws
    res = enkf_update(P, Y, d, err, rng=9, transform=TF, inflation=None)
    ref = enkf_update(P[:20], Y[:20], d, err, rng=9, transform=TF, inflation=None)
    assert np.array_equal(res.params[:20], ref.params)


def test_replaced_members_are_drawn_from_the_survivors_analysis_mean_and_covariance():
    rng = np.random.default_rng(6)
    n_big = 4000
    P = latin_hypercube(LOWER, UPPER, n_big, rng)
    Y = _forward(P)
    d = _forward(np.array([[0.3, 2.5, 20.0, 0.4]]))[0]
    dead = np.arange(n_big) >= 1000  # 3000 replacements from 1000 survivors
    Y[dead] = np.nan
    res = enkf_update(P, Y, d, DiagonalError(0.3, m=M), rng=rng, transform=TF, inflation=None,
                      min_alive_fraction=0.25)
    survivors, drawn = res.params_unbounded[~dead], res.params_unbounded[dead]
    C_s, C_d = np.cov(survivors.T), np.cov(drawn.T)
    sd = np.sqrt(np.diag(C_s))
    assert np.all(np.abs(drawn.mean(axis=0) - survivors.mean(axis=0)) < 0.06 * sd)
    assert np.all(np.abs(C_d - C_s) < 0.10 * np.outer(sd, sd))


def test_below_the_minimum_fraction_alive_the_update_raises_a_clear_error():
    P, Y, d, err = _setup()
    Y[:13] = np.nan  # 12 of 25 alive, 48% < 50%
    with pytest.raises(EnsembleFailure, match=r"only 12 of 25 members alive"):
        esmda_update(P, Y, d, err, alpha=1.0, rng=1, transform=TF, min_alive_fraction=0.5)
    # exactly at the threshold it still runs
    Y2 = _forward(P)
    Y2[:5] = np.nan
    res = esmda_update(P, Y2, d, err, alpha=1.0, rng=1, transform=TF, min_alive_fraction=0.8)
    assert res.diagnostics["alive_fraction"] == pytest.approx(0.8)
    with pytest.raises(EnsembleFailure):
        esmda_update(P, Y2, d, err, alpha=1.0, rng=1, transform=TF, min_alive_fraction=0.81)


def test_an_alive_flag_on_a_member_with_a_non_finite_curve_is_overridden():
    P, Y, d, err = _setup()
    Y[7, 10] = np.inf
    res = esmda_update(P, Y, d, err, alpha=1.0, rng=1, transform=TF, alive=np.ones(N, bool))
    assert res.diagnostics["dead_members"] == [7]
