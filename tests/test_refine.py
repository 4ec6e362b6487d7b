"""The refinement batch's design (enkf.refine) and its place in the reported posterior (calibration.posterior)."""
from __future__ import annotations

import numpy as np
import pytest

from enkf.refine import refinement_design


def test_the_batch_spreads_over_the_sample_in_proportion_to_its_mass_and_is_reproducible():
    """Two clusters holding 80 % and 20 % of a sample: the centroids sit in both, the smaller one getting
    more than its mass share, as k-means does (centroid density ~ mass density^(d/(d+2)), Gersho 1979: in
    2D 0.8^0.5 : 0.2^0.5, 16.7 of 25 in the larger; 13-19 over 40 seeds, asserted 12-21), inside the
    box, and the same seed gives the same batch."""
    rng = np.random.default_rng(0)
    lo, hi = np.array([0.0, 100.0]), np.array([1.0, 300.0])
    a = np.column_stack([rng.normal(0.3, 0.03, 8000), rng.normal(150.0, 6.0, 8000)])
    b = np.column_stack([rng.normal(0.8, 0.03, 2000), rng.normal(250.0, 6.0, 2000)])
    S = np.vstack([a, b])
    P = refinement_design(S, lo, hi, 25, 11)
    assert P.shape == (25, 2) and np.all((P >= lo) & (P <= hi))
    near_a = np.sum(P[:, 0] < 0.55)
    assert 12 <= near_a <= 21
    # not the sample's mode 25 times: the batch spans each cluster (its sd about the cluster's own)
    assert P[P[:, 0] < 0.55, 1].std() > 0.5 * 6.0
    assert np.array_equal(P, refinement_design(S, lo, hi, 25, 11))


def test_bad_input_is_named():
    S = np.random.default_rng(1).uniform(size=(100, 2))
    with pytest.raises(ValueError, match=r"samples must be \(S, 3\)"):
        refinement_design(S, [0, 0, 0], [1, 1, 1], 5, 0)
    with pytest.raises(ValueError, match="cannot place 200 refinement runs on 100 samples"):
        refinement_design(S, [0, 0], [1, 1], 200, 0)
