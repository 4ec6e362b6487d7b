"""The levelled pair terms of ``tensor_points.py`` reproduce the runs they are built from and vanish on the
anchor's own strength."""
import numpy as np

from studies.tensor_points import levelled
from enkf.emulator import AnchoredEmulator

T = np.linspace(0.0, 1.0, 7)


def f(s, e, m):
    # a response whose effect (m) grows non-linearly with the strength (s): no one-level term holds it
    return s * T + 0.1 * e * T ** 2 + m * s ** 2 * np.sin(3 * T)


def test_levelled_terms_reproduce_their_runs_and_vanish_at_the_anchor():
    anchor = np.array([2.0, 1.0, 0.0])
    names = ["sigma_t", "E_t", "interface_friction.mu"]
    axes = {0: ([1.5, 2.5], [f(1.5, 1, 0), f(2.5, 1, 0)]), 1: ([0.5], [f(2, 0.5, 0)]),
            2: ([0.1, 0.2], [f(2, 1, 0.1), f(2, 1, 0.2)])}
    em = AnchoredEmulator(anchor, f(2, 1, 0), axes, [0.5, 0.1, 0.0], [3.0, 2.0, 0.3], names=names)
    low = (1.0, f(1.0, 1, 0))
    sweeps = {2: [(1.5, [0.1, 0.2], [f(1.5, 1, 0.1), f(1.5, 1, 0.2)]),
                  (1.0, [0.1, 0.2], [f(1.0, 1, 0.1), f(1.0, 1, 0.2)])]}
    L = levelled(em, low, sweeps)
    for s in (1.0, 1.5, 2.0):
        for m in (0.1, 0.2):
            np.testing.assert_allclose(L(np.array([[s, 1.0, m]]))[0], f(s, 1, m), atol=1e-12)
    # between the levels the term is interpolated linearly in the strength
    mid = L(np.array([[1.25, 1.0, 0.2]]))[0] - L(np.array([[1.25, 1.0, 0.0]]))[0]
    np.testing.assert_allclose(mid, 0.2 * (1.0 + 1.5 ** 2) / 2 * np.sin(3 * T), atol=1e-12)
    # the one-level form (the term at 1.5 scaled linearly in the strength) misses the lowest level by
    # 0.5 m max|sin(3t)| (the term's curvature in s), which the levelled form holds exactly
    one = AnchoredEmulator(anchor, f(2, 1, 0), axes, [0.5, 0.1, 0.0], [3.0, 2.0, 0.3], names=names,
                           pairs={(0, 2): sweeps[2][0]})
    miss = np.abs(one(np.array([[1.0, 1.0, 0.2]]))[0] - f(1.0, 1, 0.2)).max()
    np.testing.assert_allclose(miss, 0.1 * np.abs(np.sin(3 * T)).max(), rtol=1e-9)
