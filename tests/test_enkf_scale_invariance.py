"""Changing the units of the data (observations, simulated responses and their errors) must not change
the parameter update: the analysis only sees whitened responses."""

import numpy as np
import pytest

from enkf import (AR1Error, BoxTransform, DenseError, DiagonalError, SquaredExponentialError, enkf_update,
                  esmda_update, latin_hypercube)

LOWER, UPPER = np.array([5e6, 10.0, 0.2]), np.array([40e6, 200.0, 0.8])
T = np.arange(300) * 0.8e-6


def _curves(P):
    amp, tau, shape = P[:, :1], P[:, 1:2] * 1e-6, P[:, 2:3]
    return amp * (T / tau) ** shape * np.exp(-T / tau)


def _error(kind, scale):
    sigma = scale * 0.5e6 * (1.0 + 0.5 * np.sin(T / 40e-6))
    if kind == "diagonal":
        return DiagonalError(sigma)
    if kind == "ar1":
        return AR1Error(sigma, T, 4e-6)
    if kind == "sqexp":
        return SquaredExponentialError(sigma, T, 3e-6, nugget=1e-4)
    return DenseError(AR1Error(sigma, T, 2e-6).dense())


@pytest.mark.parametrize("kind", ["diagonal", "ar1", "sqexp", "dense"])
@pytest.mark.parametrize("method", ["enkf", "esmda"])
@pytest.mark.parametrize("factor", [1e-6, 7.3e3])
def test_scaling_observations_and_their_errors_leaves_the_parameter_update_unchanged(kind, method, factor):
    tf = BoxTransform(LOWER, UPPER)
    P = latin_hypercube(LOWER, UPPER, 30, rng=1)
    Y = _curves(P)
    d = _curves(np.array([[22e6, 60.0, 0.5]]))[0] + _error("diagonal", 1.0).sample(2, 1)[0]

    def update(c):
        kw = dict(rng=np.random.default_rng(77), transform=tf)
        if method == "enkf":
            return enkf_update(P, c * Y, c * d, _error(kind, c), **kw)
        return esmda_update(P, c * Y, c * d, _error(kind, c), alpha=3.5, **kw)

    base, scaled = update(1.0), update(factor)
    rel = np.abs(scaled.params - base.params) / np.abs(base.params)
    assert rel.max() < 1e-10
    assert np.abs(base.params - P).max(axis=0).min() > 0  # there was an update to compare
    assert base.rank == scaled.rank
    chi_b, chi_s = base.diagnostics["misfit_mean"]["chi2_per_obs"], scaled.diagnostics["misfit_mean"]["chi2_per_obs"]
    assert chi_s == pytest.approx(chi_b, rel=1e-10)
