"""The approximate Bayesian computation of studies/bank_ceiling.py against exact posteriors: a conjugate
Gaussian stand-in (its adjusted quantiles), weighted quantiles, and the box's logit map."""
import numpy as np
from scipy import stats

from studies.bank_ceiling import abc_posterior, to_theta, to_u, weighted_quantiles


def test_weighted_quantiles_of_equal_weights_are_the_midpoint_rule_quantiles():
    x = np.arange(1.0, 11.0)
    w = np.full(10, 0.1)
    # the i-th of n sorted values sits at cumulative weight (i - 1/2)/n
    assert np.allclose(weighted_quantiles(x, w, [0.05, 0.5, 0.95]), [1.0, 5.5, 10.0])


def test_the_logit_map_of_the_box_round_trips():
    lo, hi = np.array([4e6, 200.0]), np.array([6e7, 2400.0])
    theta = np.array([[5e6, 250.0], [3e7, 1300.0], [5.9e7, 2390.0]])
    assert np.allclose(to_theta(to_u(theta, lo, hi), lo, hi), theta, rtol=1e-12)


def test_adjusted_abc_gives_the_conjugate_gaussian_posterior():
    # u ~ N(0, 1), the summary s = u + N(0, 0.5^2): u | s ~ N(s / 1.25, 0.2)
    rng = np.random.default_rng(5)
    n, sigma = 40000, 0.5
    u = rng.standard_normal((n, 1))
    s = u + sigma * rng.standard_normal((n, 1))
    exact = stats.norm(0.8 / (1 + sigma**2), np.sqrt(sigma**2 / (1 + sigma**2)))
    # a wide acceptance window (0.4 of the reference): the neighbours alone are a blurred posterior, their
    # regression on the summary takes the blur out
    adjusted = weighted_quantiles(*_abc(s, u, 16000, True), [0.05, 0.5, 0.95])
    plain = weighted_quantiles(*_abc(s, u, 16000, False), [0.05, 0.5, 0.95])
    assert np.allclose(adjusted, exact.ppf([0.05, 0.5, 0.95]), atol=0.02)
    assert (plain[2] - plain[0]) / (exact.ppf(0.95) - exact.ppf(0.05)) > 1.1


def _abc(s, u, k, adjust):
    post_u, w = abc_posterior(s, u, np.array([0.8]), k, np.array([1.0]), adjust)
    assert abs(np.sum(w) - 1.0) < 1e-12
    return post_u[:, 0], w
