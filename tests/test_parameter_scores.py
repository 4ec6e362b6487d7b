"""The score a posterior expects over the prior's (enkf.scores), against closed forms.

The uniform prior on a box of width w, scored on truths drawn from the box (WIS of its 50 % and 90 %
central intervals and median, Bracher et al. 2021): E|y - m| / 2 = w / 8, the 50 % interval's
0.25 (w / 2 + 4 x 2 x (w / 4)^2 / (2 w)) = 0.1875 w, the 90 % interval's 0.05 (0.9 w + 20 x 2 x (w / 20)^2 /
(2 w)) = 0.0475 w, over K + 1/2 = 2.5: 0.144 w.

A Gaussian posterior with sd s scored on its own draws: E|y - m| / 2 = s sqrt(2 / pi) / 2 = 0.3989 s; the
central interval at z = z_{1 - a/2} scores 2 z s + (2 / a) 2 s (phi(z) - z a / 2), that is 2.5422 s at
a = 0.5 (weight 0.25) and 4.1254 s at a = 0.1 (weight 0.05): 1.2408 s / 2.5 = 0.4963 s, so 3.447 s / w of
the prior's.
"""
import math

import numpy as np
import pytest
from scipy import stats

from enkf.ces import interval_summary
from enkf.diagnostics import prediction_interval_dict
from enkf.scores import expected_score_over_prior, expected_wis, prior_expected_wis, weighted_interval_score
from enkf.transforms import BoxTransform


def _gaussian_expected_wis(s: float) -> float:
    total = 0.5 * s * math.sqrt(2.0 / math.pi)
    for a in (0.5, 0.1):
        z = stats.norm.ppf(1.0 - a / 2.0)
        total += 0.5 * a * (2.0 * z * s + (2.0 / a) * 2.0 * s * (stats.norm.pdf(z) - z * a / 2.0))
    return total / 2.5


def test_the_uniform_prior_scores_0144_of_its_box_on_its_own_truths():
    assert prior_expected_wis(0.0, 1.0) == pytest.approx(0.144, abs=1e-6)
    assert prior_expected_wis(4e6, 60e6) == pytest.approx(0.144 * 56e6, rel=1e-6)


def test_the_prior_reported_as_a_posterior_expects_the_prior_s_score():
    draws = np.random.default_rng(3).uniform(200.0, 2400.0, 100_000)
    assert expected_score_over_prior(draws, 200.0, 2400.0) == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("s", [0.02, 0.05, 0.1])
def test_a_gaussian_posterior_expects_its_closed_form(s):
    draws = stats.norm.ppf((np.arange(200_000) + 0.5) / 200_000, 0.5, s)
    assert _gaussian_expected_wis(1.0) == pytest.approx(0.4963, abs=1e-4)
    assert expected_wis(draws) == pytest.approx(_gaussian_expected_wis(s), rel=1e-3)
    assert expected_score_over_prior(draws, 0.0, 1.0) == pytest.approx(3.447 * s, rel=2e-3)


def test_the_expected_score_is_the_mean_score_over_truths_the_posterior_draws():
    """For a calibrated posterior the expectation equals what truths drawn from it score on average: the
    quantity a coverage benchmark's wis_over_prior pools over twins."""
    rng = np.random.default_rng(5)
    draws = rng.gamma(4.0, 1.0, 50_000)
    q = {k: float(np.quantile(draws, f)) for k, f in (("q05", .05), ("q25", .25), ("q50", .5), ("q75", .75),
                                                      ("q95", .95))}
    truths = rng.gamma(4.0, 1.0, 50_000)
    assert weighted_interval_score(q, truths).mean() == pytest.approx(expected_wis(draws), rel=0.02)


def test_both_reported_forms_carry_the_score_and_agree_on_one_gaussian():
    """The MCMC sample's summary and the ensemble's t prediction intervals report the same expected score for
    a large ensemble of a Gaussian (in the unbounded space, far from the box's ends)."""
    tr = BoxTransform(np.array([4e6]), np.array([60e6]))
    z = np.random.default_rng(7).normal(0.0, 0.3, (4000, 1))
    P = tr.to_bounded(z)
    ens = prediction_interval_dict(P, ["sigma_t"], transform=tr)["sigma_t"]["score_over_prior"]
    mcmc = interval_summary(P, ["sigma_t"], tr.lower, tr.upper)["sigma_t"]["score_over_prior"]
    assert ens == pytest.approx(mcmc, rel=0.03)
    assert 0.2 < mcmc < 0.35
