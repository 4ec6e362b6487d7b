"""Observation error models: products with the Cholesky factor, draws, and the noise estimate."""

import numpy as np
import pytest
from scipy import linalg

from enkf import (AR1Error, DenseError, DiagonalError, SquaredExponentialError, estimate_noise,
                  observation_error)

RNG = np.random.default_rng(20)
T = np.sort(RNG.uniform(0.0, 100e-6, 60))  # non-uniform grid, s
GROUPS = (T > 50e-6).astype(int)  # two independent records
SIGMA = RNG.uniform(1e6, 3e6, 60)  # Pa


def _models():
    return [
        DiagonalError(SIGMA),
        AR1Error(SIGMA, T, 7e-6, groups=GROUPS),
        SquaredExponentialError(SIGMA, T, 5e-6, groups=GROUPS, nugget=1e-4),
        DenseError(AR1Error(SIGMA, T, 3e-6).dense()),
    ]


@pytest.mark.parametrize("model", _models(), ids=lambda e: e.kind)
def test_whiten_and_color_are_the_products_with_the_cholesky_factor(model):
    C = model.dense()
    L = linalg.cholesky(C, lower=True)
    z = RNG.standard_normal((60, 4))
    assert np.allclose(model.color(z), L @ z, rtol=1e-10, atol=1e-10 * np.abs(L @ z).max())
    assert np.allclose(model.whiten(z), linalg.solve_triangular(L, z, lower=True), rtol=1e-8, atol=1e-22)
    assert np.allclose(model.whiten_T(z), linalg.solve_triangular(L, z, lower=True, trans="T"),
                       rtol=1e-8, atol=1e-22)
    assert np.allclose(model.std, np.sqrt(np.diag(C)), rtol=1e-12)
    r = RNG.standard_normal(60) * SIGMA
    assert model.chi2(r) == pytest.approx(r @ np.linalg.solve(C, r), rel=1e-8)


def test_ar1_dense_matrix_is_exponential_in_time_and_zero_across_records():
    e = AR1Error(2.0, T, 7e-6, groups=GROUPS)
    C = e.dense()
    i, j = 3, 5
    assert C[i, j] == pytest.approx(4.0 * np.exp(-(T[j] - T[i]) / 7e-6), rel=1e-12)
    assert np.all(C[np.ix_(GROUPS == 0, GROUPS == 1)] == 0.0)


@pytest.mark.parametrize("kind", ["ar1", "sqexp"])
def test_draws_have_the_model_covariance(kind):
    t = np.arange(40) * 1e-6
    e = observation_error(kind, 3.0, times=t, corr_time=4e-6)
    draws = e.sample(np.random.default_rng(1), 40000)
    emp = np.cov(draws.T)
    assert np.abs(emp - e.dense()).max() < 0.05 * 9.0


def test_observation_error_factory_and_diagonal_size():
    assert observation_error("diagonal", 2.0, m=7).m == 7
    assert observation_error("diagonal", 2.0, times=np.arange(9.0)).m == 9
    with pytest.raises(ValueError):
        observation_error("ar1", 1.0)
    with pytest.raises(ValueError):
        observation_error("pink", 1.0, times=np.arange(3.0))


def _ar1_series(n, sigma, tau, dt, rng):
    phi = np.exp(-dt / tau)
    x = np.empty(n)
    x[0] = rng.standard_normal() * sigma
    z = rng.standard_normal(n) * sigma * np.sqrt(1 - phi**2)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + z[k]
    return x


def test_estimate_noise_recovers_ar1_sigma_and_correlation_time_from_a_pre_trigger_record():
    dt = 0.8e-6  # 1.25 MHz sampling
    x = 4e-3 + _ar1_series(20000, 6e-3, 3 * dt, dt, np.random.default_rng(8))  # volts, with offset
    est = estimate_noise(x, dt)
    assert est.sigma == pytest.approx(6e-3, rel=0.03)
    assert est.corr_time == pytest.approx(3 * dt, rel=0.10)
    assert est.rho1 == pytest.approx(np.exp(-1 / 3), abs=0.02)
    model = est.error_model(np.arange(100) * dt)
    assert model.kind == "ar1" and model.corr_time == est.corr_time


def test_estimate_noise_recovers_squared_exponential_length_and_white_noise():
    dt = 1.0
    t = np.arange(4000) * dt
    se = SquaredExponentialError(2.0, t[:400], 3.0, nugget=1e-8)
    x = se.sample(np.random.default_rng(3), 10)  # ten independent pre-trigger segments
    est = estimate_noise(x, dt, model="sqexp")
    assert est.sigma == pytest.approx(2.0, rel=0.05)
    assert est.corr_time == pytest.approx(3.0, rel=0.10)
    white = estimate_noise(np.random.default_rng(4).normal(0, 5.0, 50000), dt)
    assert white.sigma == pytest.approx(5.0, rel=0.02)
    assert white.corr_time < 0.5 * dt  # essentially uncorrelated
    assert white.error_model(np.arange(10.0)).kind in ("diagonal", "ar1")


def test_estimate_noise_linear_detrend_removes_a_drifting_baseline():
    dt = 1.0
    rng = np.random.default_rng(9)
    x = rng.normal(0.0, 1.0, 5000) + 1e-3 * np.arange(5000)
    assert estimate_noise(x, dt, detrend="linear").sigma == pytest.approx(1.0, rel=0.03)
    assert estimate_noise(x, dt, detrend="constant").sigma > 1.3
