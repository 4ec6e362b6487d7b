"""The re-anchored design of studies/reanchored_refit.py: the anchor, then each moved parameter on both
sides of it, inside the box, the others left at the anchor."""
import numpy as np

from studies.reanchored_refit import local_design


def test_each_moved_parameter_is_run_on_both_sides_of_the_anchor_and_clipped_to_the_box():
    anchor = np.array([25.0, 12.0, 0.0, 80.0])
    steps = np.array([2.0, 3.0, 5.0, 20.0])
    moved = np.array([True, True, False, True])
    X, axis = local_design(anchor, steps, moved, lower=np.zeros(4), upper=np.array([40.0, 13.0, 100.0, 400.0]))
    assert axis.tolist() == [-1, 0, 0, 1, 1, 3, 3]
    assert X[0].tolist() == anchor.tolist()
    assert X[1:3, 0].tolist() == [23.0, 27.0] and X[3:5, 1].tolist() == [9.0, 13.0] and X[5:, 3].tolist() == [60.0, 100.0]
    # every row moves its own parameter only
    for x, j in zip(X[1:], axis[1:]):
        assert np.flatnonzero(x != anchor).tolist() == [j]


def test_a_parameter_at_its_bound_is_run_on_one_side_only():
    X, axis = local_design(np.array([0.0, 5.0]), np.array([1.0, 1.0]), np.array([True, False]),
                           lower=np.zeros(2), upper=np.full(2, 10.0))
    assert axis.tolist() == [-1, 0] and X[1].tolist() == [1.0, 5.0]
