"""Loading histories of the SHPB models.

The incident bar is modelled as semi-infinite: its loaded section injects the incident wave and
absorbs whatever returns (1D wave theory: sigma = 2 sigma_I - rho c v at the section), so the model
needs only the bar length between that section and the specimen.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrapezoidPulse:
    """Particle-velocity pulse of the incident wave [m/s]: linear rise, plateau, linear fall [s].

    Defaults: the 5 m/s striker case of SHPB Brazilian tests on Kuru granite (Saksala 2013, read
    off the figures of Saksala et al. 2013): incident stress 115 MPa with rise 120 us,
    plateau 45 us, fall 115 us; in the paper's steel bars (rho c = 7850 x 5048) 115 MPa is a particle
    velocity of 2.9 m/s. The paper's Figure 2 velocity boundary condition has the same trapezoid
    shape. (The 10 m/s case, 225 MPa, crushes the disc at the loaded flats within the window.)
    """

    amplitude_m_s: float = 2.9
    rise_s: float = 120e-6
    plateau_s: float = 45e-6
    fall_s: float = 115e-6

    def __post_init__(self):
        for k in ("amplitude_m_s", "rise_s", "fall_s"):
            if not getattr(self, k) > 0:
                raise ValueError(f"pulse {k} must be > 0, got {getattr(self, k)}")
        if self.plateau_s < 0:
            raise ValueError(f"pulse plateau_s must be >= 0, got {self.plateau_s}")

    def history(self):
        """(times [s], velocities [m/s]) of the piecewise-linear pulse."""
        t1 = self.rise_s
        t2 = t1 + self.plateau_s
        t3 = t2 + self.fall_s
        return (np.array([0.0, t1, t2, t3, t3 + 1.0]),
                np.array([0.0, self.amplitude_m_s, self.amplitude_m_s, 0.0, 0.0]))

    @property
    def duration_s(self) -> float:
        return self.rise_s + self.plateau_s + self.fall_s


def face_tributary_areas(nodes: np.ndarray, face_nodes: np.ndarray, thickness: float) -> np.ndarray:
    """Tributary area [m^2] of each node of a straight end face (x = const): half the distance to
    each neighbour along the face times the plane-stress thickness; they sum to height x thickness."""
    y = nodes[face_nodes, 1]
    order = np.argsort(y)
    ys = y[order]
    half = np.zeros_like(ys)
    gaps = np.diff(ys)
    half[:-1] += 0.5 * gaps
    half[1:] += 0.5 * gaps
    out = np.empty_like(half)
    out[order] = half * thickness
    return out
