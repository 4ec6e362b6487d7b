"""No member may leave its prior box, however large the innovation."""

import numpy as np
import pytest

from enkf import BoxTransform, DiagonalError, enkf_update, esmda_update, latin_hypercube

LOWER, UPPER = np.array([1.0, -5.0, 100.0]), np.array([2.0, 5.0, 1e4])
G = np.random.default_rng(0).normal(size=(20, 3))


def _forward(P):
    u = (P - LOWER) / (UPPER - LOWER)
    return u @ G.T


@pytest.mark.parametrize("kind", ["logit", "probit"])
@pytest.mark.parametrize("method", ["enkf", "esmda"])
def test_no_member_leaves_its_box_through_ten_updates_with_large_innovations(kind, method):
    tf = BoxTransform(LOWER, UPPER, kind=kind)
    rng = np.random.default_rng(3)
    P = latin_hypercube(LOWER, UPPER, 25, rng)
    obs = 1e4 * np.sign(G.sum(axis=1))  # unreachable: responses are O(1)
    err = DiagonalError(0.01, m=20)
    for _ in range(10):
        if method == "enkf":
            res = enkf_update(P, _forward(P), obs, err, rng=rng, transform=tf, inflation=1.5)
        else:
            res = esmda_update(P, _forward(P), obs, err, alpha=1.0, rng=rng, transform=tf)
        P = res.params
        assert np.all(np.isfinite(P))
        assert np.all(P >= LOWER) and np.all(P <= UPPER)
    # the innovations were large: the members are pushed against the bounds
    assert np.abs(P.mean(axis=0) - (LOWER + UPPER) / 2).max() > 0.25 * (UPPER - LOWER).min()


def test_without_the_transform_the_same_update_would_leave_the_box():
    rng = np.random.default_rng(3)
    P = latin_hypercube(LOWER, UPPER, 25, rng)
    obs = 1e4 * np.sign(G.sum(axis=1))
    res = esmda_update(P, _forward(P), obs, DiagonalError(0.01, m=20), alpha=1.0, rng=rng)
    assert np.any(res.params < LOWER) or np.any(res.params > UPPER)
