"""tools/trace_fracture.py's mode split: a joint's separation resolved into opening and slip in the
joint's own frame, with the engine's sign convention (fdem.kernels: the normal n = (t_y, -t_x) of the
face direction t, opening > 0 in tension)."""
import numpy as np
import pytest

from tools import trace_fracture


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 90.0, 137.0])
def test_pure_opening_and_pure_slip_are_resolved_in_the_joint_frame(angle_deg):
    """Face A from a1 to a2 along t at any angle; face B displaced by 12 um along n (opening) and
    then by 7 um along t (slip): the split returns exactly those, whatever the joint's orientation."""
    th = np.radians(angle_deg)
    t = np.array([np.cos(th), np.sin(th)])
    n = np.array([t[1], -t[0]])
    a1, a2 = np.array([0.01, 0.02]), np.array([0.01, 0.02]) + 2e-3 * t
    jn = np.array([[0, 1, 2, 3]])
    for shift, expected in [(12e-6 * n, (12e-6, 0.0)), (7e-6 * t, (0.0, 7e-6)),
                            (12e-6 * n - 7e-6 * t, (12e-6, -7e-6))]:
        x = np.array([a1, a2, a1 + shift, a2 + shift])
        opening, slip = trace_fracture.joint_separation(x, jn, 0)
        assert opening == pytest.approx(expected[0], abs=1e-12) and slip == pytest.approx(expected[1], abs=1e-12)
