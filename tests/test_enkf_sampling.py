"""Latin hypercube initial ensemble and the box transforms."""

import numpy as np
import pytest

from enkf import BoxTransform, latin_hypercube, stratum_index

LOWER = np.array([5e6, 10.0, 0.1, -3.0, 1e-3])
UPPER = np.array([40e6, 200.0, 0.9, 3.0, 2e-3])


@pytest.mark.parametrize("n_members", [1, 7, 25, 100])
def test_lhs_puts_exactly_one_sample_in_each_stratum_of_each_parameter(n_members):
    p = latin_hypercube(LOWER, UPPER, n_members, rng=11)
    assert p.shape == (n_members, LOWER.size)
    strata = stratum_index(p, LOWER, UPPER, n_members)
    for j in range(LOWER.size):
        assert np.array_equal(np.sort(strata[:, j]), np.arange(n_members))


def test_lhs_stays_inside_the_prior_box_and_centered_option_hits_stratum_centres():
    p = latin_hypercube(LOWER, UPPER, 50, rng=3)
    assert np.all(p >= LOWER) and np.all(p <= UPPER)
    c = latin_hypercube(LOWER, UPPER, 10, rng=3, centered=True)
    u = (c - LOWER) / (UPPER - LOWER)
    assert np.allclose(np.sort(u, axis=0), ((np.arange(10) + 0.5) / 10)[:, None], atol=1e-12)


def test_lhs_is_seeded_and_refuses_an_unseeded_call():
    a = latin_hypercube(LOWER, UPPER, 25, rng=np.random.default_rng(5))
    b = latin_hypercube(LOWER, UPPER, 25, rng=np.random.default_rng(5))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, latin_hypercube(LOWER, UPPER, 25, rng=6))
    with pytest.raises(TypeError):
        latin_hypercube(LOWER, UPPER, 25, rng=None)


def test_lhs_rejects_an_empty_box():
    with pytest.raises(ValueError):
        latin_hypercube([1.0, 2.0], [1.0, 3.0], 5, rng=0)


@pytest.mark.parametrize("kind", ["logit", "probit"])
def test_box_transform_round_trips_and_maps_any_real_number_inside_the_box(kind):
    tf = BoxTransform(LOWER, UPPER, kind=kind)
    p = latin_hypercube(LOWER, UPPER, 40, rng=2)
    assert np.allclose(tf.to_bounded(tf.to_unbounded(p)), p, rtol=1e-12, atol=0.0)
    z = np.array([[-1e300, 1e300, -50.0, 50.0, 0.0]])
    q = tf.to_bounded(z)
    assert np.all(q >= LOWER) and np.all(q <= UPPER)
    # a member saturated on a bound maps back to a finite unbounded value
    assert np.all(np.isfinite(tf.to_unbounded(q)))
    assert tf.to_bounded(np.zeros((1, 5)))[0] == pytest.approx((LOWER + UPPER) / 2, rel=1e-12)


@pytest.mark.parametrize("kind, expected", [("logit", np.pi / np.sqrt(3.0)), ("probit", 1.0)])
def test_prior_std_is_the_unbounded_std_of_a_uniform_box_prior(kind, expected):
    tf = BoxTransform(LOWER, UPPER, kind=kind)
    p = latin_hypercube(LOWER, UPPER, 20000, rng=4)
    sd = tf.to_unbounded(p).std(axis=0, ddof=1)
    assert np.allclose(tf.prior_std(), expected)
    assert np.allclose(sd, expected, rtol=0.01)
