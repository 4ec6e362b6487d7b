"""Gauss-linear problems, where the Kalman posterior is exact and analytic.

Prior x ~ N(mu0, C0), responses y = G x, observations d = G x_true + e, e ~ N(0, R):
    C_post = (C0^{-1} + G^T R^{-1} G)^{-1},   mu_post = C_post (C0^{-1} mu0 + G^T R^{-1} d).
"""

import numpy as np
import pytest

from enkf import (AR1Error, DiagonalError, enkf_update, esmda_alphas, esmda_update, localization_mask,
                  truncation_rank)

N_PARAMS, N_OBS = 3, 12
MU0 = np.array([1.0, -2.0, 0.5])
X_TRUE = np.array([2.0, -1.0, 1.5])


def _problem(error_kind, seed=1):
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(N_OBS, N_PARAMS))
    A = 0.5 * rng.normal(size=(N_PARAMS, N_PARAMS))
    C0 = A @ A.T + 0.5 * np.eye(N_PARAMS)
    t = np.arange(N_OBS, dtype=float)
    err = DiagonalError(np.full(N_OBS, 0.8)) if error_kind == "diagonal" else AR1Error(0.8, t, 2.0)
    R = err.dense()
    d = G @ X_TRUE + err.sample(rng, 1)[0]
    C_post = np.linalg.inv(np.linalg.inv(C0) + G.T @ np.linalg.solve(R, G))
    mu_post = C_post @ (np.linalg.solve(C0, MU0) + G.T @ np.linalg.solve(R, d))
    return G, C0, err, d, mu_post, C_post


def _assert_matches_posterior(X, mu_post, C_post):
    mean_err = np.abs(X.mean(axis=0) - mu_post) / np.abs(mu_post)
    cov_err = np.linalg.norm(np.cov(X.T) - C_post) / np.linalg.norm(C_post)
    diag_err = np.abs(np.var(X, axis=0, ddof=1) / np.diag(C_post) - 1.0)
    assert mean_err.max() < 0.03, mean_err
    assert cov_err < 0.10, cov_err
    assert diag_err.max() < 0.10, diag_err


@pytest.mark.parametrize("error_kind", ["diagonal", "ar1"])
def test_one_es_update_with_5000_members_gives_the_exact_kalman_posterior(error_kind):
    G, C0, err, d, mu_post, C_post = _problem(error_kind)
    rng = np.random.default_rng(100)
    X = rng.multivariate_normal(MU0, C0, size=5000)
    res = esmda_update(X, X @ G.T, d, err, alpha=1.0, rng=rng, truncation=1.0)
    _assert_matches_posterior(res.params, mu_post, C_post)
    # the paper's EnKF without inflation is the same single update
    res2 = enkf_update(X, X @ G.T, d, err, rng=101, inflation=None)
    _assert_matches_posterior(res2.params, mu_post, C_post)


@pytest.mark.parametrize("error_kind", ["diagonal", "ar1"])
@pytest.mark.parametrize("truncation", [1.0, 0.99])
def test_esmda_over_three_steps_gives_the_exact_kalman_posterior(error_kind, truncation):
    G, C0, err, d, mu_post, C_post = _problem(error_kind)
    rng = np.random.default_rng(200)
    X = rng.multivariate_normal(MU0, C0, size=5000)
    alphas = esmda_alphas(3)
    for alpha in alphas:
        X = esmda_update(X, X @ G.T, d, err, alpha=alpha, rng=rng, truncation=truncation).params
    _assert_matches_posterior(X, mu_post, C_post)


def test_esmda_default_weights_are_4_2_1_rescaled_to_unit_sum_of_inverses():
    a = esmda_alphas()
    assert np.allclose(a, [7.0, 3.5, 1.75])
    assert np.sum(1.0 / a) == pytest.approx(1.0, abs=1e-15)
    assert np.sum(1.0 / esmda_alphas(5)) == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(esmda_alphas(base=[9.0, 1.0]), [10.0, 10.0 / 9.0])
    assert np.allclose(esmda_alphas(1), [1.0])


def test_augmented_state_update_of_the_curve_matches_the_dense_kalman_formula():
    G, C0, err, d, _, _ = _problem("ar1")
    rng = np.random.default_rng(5)
    X = rng.multivariate_normal(MU0, C0, size=40)
    Y = X @ G.T + 0.05 * rng.normal(size=(40, N_OBS))  # not exactly linear: Y anomalies have full rank
    res = esmda_update(X, Y, d, err, alpha=2.0, rng=np.random.default_rng(9), truncation=1.0)
    # Reference: dense eqs. (3)-(4) on the augmented state [x; y] with the same perturbations.
    E = err.color(np.random.default_rng(9).standard_normal((40, N_OBS)).T).T
    D = d + np.sqrt(2.0) * E
    A = np.hstack([X, Y])
    Af = A - A.mean(axis=0)
    P = Af.T @ Af / 39
    K = P[:, N_PARAMS:] @ np.linalg.inv(P[N_PARAMS:, N_PARAMS:] + 2.0 * err.dense())
    A_a = A + (D - Y) @ K.T
    assert np.allclose(res.params, A_a[:, :N_PARAMS], rtol=1e-9, atol=1e-9)
    assert np.allclose(res.responses, A_a[:, N_PARAMS:], rtol=1e-9, atol=1e-9)


def test_localization_mask_zeroes_declared_cross_covariances_exactly_as_the_dense_formula():
    G, C0, err, d, _, _ = _problem("ar1")
    rng = np.random.default_rng(6)
    X = rng.multivariate_normal(MU0, C0, size=30)
    Y = X @ G.T + 0.05 * rng.normal(size=(30, N_OBS))
    mask = localization_mask(N_PARAMS, N_OBS, {0: slice(6, None), 2: np.arange(N_OBS) < 4})
    assert mask.sum() == N_PARAMS * N_OBS - 6 - 4
    res = enkf_update(X, Y, d, err, rng=np.random.default_rng(3), localization=mask, inflation=None)
    E = err.color(np.random.default_rng(3).standard_normal((30, N_OBS)).T).T
    Xf, Yf = X - X.mean(axis=0), Y - Y.mean(axis=0)
    C_xy, C_yy = Xf.T @ Yf / 29, Yf.T @ Yf / 29
    K = (mask * C_xy) @ np.linalg.inv(C_yy + err.dense())
    expected = X + (d + E - Y) @ K.T
    assert np.allclose(res.params, expected, rtol=1e-9, atol=1e-9)
    # a uniform taper of 0.5 halves the unmasked parameter increment, whatever the truncation
    for trunc in (1.0, 0.9):
        full = enkf_update(X, Y, d, err, rng=1, inflation=None, truncation=trunc)
        half = enkf_update(X, Y, d, err, rng=1, localization=np.full((N_PARAMS, N_OBS), 0.5), inflation=None,
                           truncation=trunc)
        assert np.allclose(half.params - X, 0.5 * (full.params - X), rtol=1e-9, atol=1e-12)
        assert full.rank == half.rank


def test_a_parameter_masked_from_every_observation_is_not_updated():
    G, C0, err, d, _, _ = _problem("diagonal")
    X = np.random.default_rng(7).multivariate_normal(MU0, C0, size=30)
    mask = localization_mask(N_PARAMS, N_OBS, {1: slice(None)})
    res = enkf_update(X, X @ G.T, d, err, rng=2, localization=mask, inflation=None)
    assert np.array_equal(res.params[:, 1], X[:, 1])
    assert np.abs(res.params[:, 0] - X[:, 0]).max() > 1e-3


def test_truncation_keeps_the_leading_singular_values_holding_the_requested_fraction_of_their_sum():
    s = np.array([50.0, 30.0, 15.0, 4.0, 1.0, 0.0])
    assert truncation_rank(s, 1.0) == 5
    assert truncation_rank(s, 0.995) == 5
    assert truncation_rank(s, 0.985) == 4
    assert truncation_rank(s, 0.94) == 3
    assert truncation_rank(s, 0.5) == 1
    assert truncation_rank(np.zeros(3), 0.99) == 0


def test_an_ensemble_whose_responses_do_not_vary_is_left_unchanged():
    P = np.random.default_rng(0).normal(size=(6, 2))
    res = esmda_update(P, np.ones((6, 10)), np.zeros(10), AR1Error(1.0, np.arange(10.0), 2.0), alpha=1.0, rng=0,
                       localization=localization_mask(2, 10, {0: slice(0, 3)}))
    assert res.rank == 0
    assert np.array_equal(res.params, P)
