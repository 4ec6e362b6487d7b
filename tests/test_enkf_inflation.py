"""Parameter inflation, paper eq. (5), in the unbounded space."""

import numpy as np
import pytest

from enkf import (BoxTransform, DiagonalError, Multiplicative, SpreadFloor, as_inflation, enkf_update, inflate,
                  latin_hypercube)

LOWER, UPPER = np.array([10e6, 50.0]), np.array([40e6, 500.0])
TF = BoxTransform(LOWER, UPPER)
T = np.linspace(0.0, 1.0, 50)


def _forward(P):
    u = (P - LOWER) / (UPPER - LOWER)
    return u[:, :1] * np.sin(np.pi * T) + u[:, 1:] * T**2


def test_eq5_keeps_the_mean_and_multiplies_the_spread_by_lambda():
    z = np.random.default_rng(0).normal(size=(30, 3)) + [1.0, -2.0, 5.0]
    lam = np.array([1.0, 1.5, 0.5])
    zi = inflate(z, lam)
    assert np.allclose(zi.mean(axis=0), z.mean(axis=0), atol=1e-13)
    assert np.allclose(zi.std(axis=0, ddof=1), lam * z.std(axis=0, ddof=1), rtol=1e-13)


def test_multiplicative_factor_scales_the_analysis_spread_in_the_unbounded_space():
    P = latin_hypercube(LOWER, UPPER, 25, rng=1)
    d = _forward(np.array([[20e6, 200.0]]))[0]
    err = DiagonalError(0.02, m=T.size)
    plain = enkf_update(P, _forward(P), d, err, rng=5, transform=TF, inflation=None)
    inflated = enkf_update(P, _forward(P), d, err, rng=5, transform=TF, inflation=1.2)
    zp, zi = plain.params_unbounded, inflated.params_unbounded
    assert np.allclose(zi.std(axis=0, ddof=1), 1.2 * zp.std(axis=0, ddof=1), rtol=1e-12)
    assert np.allclose(zi.mean(axis=0), zp.mean(axis=0), rtol=1e-12, atol=1e-12)
    assert np.allclose(inflated.inflation, [1.2, 1.2])
    assert np.all((inflated.params >= LOWER) & (inflated.params <= UPPER))


def test_paper_reading_floors_each_parameter_spread_at_45_percent_of_its_initial_spread():
    P0 = latin_hypercube(LOWER, UPPER, 25, rng=2)
    sd0 = TF.to_unbounded(P0).std(axis=0, ddof=1)
    d = _forward(np.array([[20e6, 200.0]]))[0]
    err = DiagonalError(1e-4, m=T.size)  # precise data: the plain analysis shrinks the spread
    plain = enkf_update(P0, _forward(P0), d, err, rng=5, transform=TF, inflation=None)
    sd_plain = plain.params_unbounded.std(axis=0, ddof=1)
    assert np.all(sd_plain < 0.4 * sd0)  # the floor is active for both parameters
    paper = enkf_update(P0, _forward(P0), d, err, rng=5, transform=TF, inflation="paper", prior_std=sd0)
    sd_paper = paper.params_unbounded.std(axis=0, ddof=1)
    assert np.allclose(sd_paper, 0.45 * sd0, rtol=1e-12)
    assert np.allclose(paper.inflation, 0.45 * sd0 / sd_plain, rtol=1e-10)
    assert np.allclose(paper.params_unbounded.mean(axis=0), plain.params_unbounded.mean(axis=0), atol=1e-12)
    # default reference spread: the analytic uniform-prior spread pi/sqrt(3) in logit space
    default = enkf_update(P0, _forward(P0), d, err, rng=5, transform=TF)
    assert np.allclose(default.params_unbounded.std(axis=0, ddof=1), 0.45 * np.pi / np.sqrt(3.0), rtol=1e-12)


def test_spread_floor_never_deflates_a_wide_ensemble():
    z = np.random.default_rng(3).normal(0.0, 2.0, size=(40, 2))
    lam = SpreadFloor(0.45).factors(z, prior_std=np.array([1.0, 10.0]))
    assert lam[0] == 1.0
    assert lam[1] == pytest.approx(4.5 / z[:, 1].std(ddof=1), rel=1e-12)


def test_inflation_specs():
    assert as_inflation(None) is None
    assert as_inflation("paper") == SpreadFloor(0.45)
    assert as_inflation(1.05) == Multiplicative(1.05)
    with pytest.raises(ValueError):
        as_inflation("huge")
    with pytest.raises(ValueError):
        Multiplicative(0.0)
