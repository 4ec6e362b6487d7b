"""The bars and measurement chain of an SHPB: bar material and geometry, gauge positions, bridge factor
(the Freiburg set-up of Rae et al. as :data:`FREIBURG_BAR`). Read by the record readers and the reduction."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["BarSetup", "FREIBURG_BAR", "freiburg_bar", "bridge_strain_per_volt"]


def bridge_strain_per_volt(excitation_V: float, gain: float, gauge_factor: float, active_arms: int = 1) -> float:
    r"""Strain per volt of amplified Wheatstone-bridge output.

    For :math:`n` active arms carrying the same axial strain, :math:`U = G\,U_0\,n\,k\,\varepsilon/4`, so

    .. math:: \varepsilon = \frac{4}{n\,U_0\,G\,k}\,U

    Freiburg (quarter bridge per gauge, :math:`U_0=5` V, :math:`G=400`, :math:`k=1.99`):
    1.005e-3 /V. LANL HopPyBar (two active arms): :math:`2/(k\,G\,U_0)`.
    """
    if excitation_V <= 0 or gain <= 0 or gauge_factor <= 0 or active_arms < 1:
        raise ValueError("excitation, gain, gauge factor and active arms must be positive")
    return 4.0 / (active_arms * excitation_V * gain * gauge_factor)


@dataclass(frozen=True)
class BarSetup:
    """Bars and measurement chain of an SHPB (incident and transmission bar of the same material).

    Attributes
    ----------
    E : float
        Bar Young's modulus [Pa].
    rho : float
        Bar density [kg/m^3].
    diameter : float
        Bar diameter [m] (equivalent diameter for a square bar).
    gauge_distance_incident : float
        Distance from the incident-bar gauges to the specimen front face [m].
    gauge_distance_transmitted : float
        Distance from the transmission-bar gauges to the specimen back face [m].
    strain_per_volt_incident, strain_per_volt_transmitted : float
        Volts-to-strain factors [1/V] (magnitude; 1.0 for records already in strain).
    compression_sign : int
        Sign of a compressive strain in the recorded signal (+1: compression reads positive, as in the
        Freiburg and LANL standard records; -1: compression reads negative, as in the Yao records).
    name : str
        Free label.
    """

    E: float
    rho: float
    diameter: float
    gauge_distance_incident: float
    gauge_distance_transmitted: float
    strain_per_volt_incident: float
    strain_per_volt_transmitted: float
    compression_sign: int = 1
    name: str = ""

    def __post_init__(self) -> None:
        for f in ("E", "rho", "diameter", "gauge_distance_incident", "gauge_distance_transmitted",
                  "strain_per_volt_incident", "strain_per_volt_transmitted"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"BarSetup.{f} must be a positive finite number, got {v!r}")
        if self.compression_sign not in (1, -1):
            raise ValueError(f"BarSetup.compression_sign must be +1 or -1, got {self.compression_sign!r}")

    @property
    def c0(self) -> float:
        """One-dimensional bar wave speed :math:`c_0 = \\sqrt{E/\\rho}` [m/s]."""
        return math.sqrt(self.E / self.rho)

    @property
    def area(self) -> float:
        """Bar cross-section :math:`A_b = \\pi D_b^2/4` [m^2]."""
        return math.pi * self.diameter ** 2 / 4.0


#: Freiburg (Rae et al.) titanium bars: E 110 GPa, 4430 kg/m^3, 50 mm, gauges 1.25 m (incident) and
#: 1.00 m (transmission) from the specimen, bridge U0 = 5 V, gain 400, k = 1.99 -> 1.005e-3 strain/V,
#: compression positive (from the authors' script SHPB_v4.0.py, see the folder's PROVENANCE.md).
FREIBURG_BAR = BarSetup(
    E=110.0e9,
    rho=4430.0,
    diameter=0.050,
    gauge_distance_incident=1.25,
    gauge_distance_transmitted=1.00,
    strain_per_volt_incident=bridge_strain_per_volt(5.0, 400.0, 1.99, active_arms=1),
    strain_per_volt_transmitted=bridge_strain_per_volt(5.0, 400.0, 1.99, active_arms=1),
    compression_sign=1,
    name="Freiburg Ti bars",
)


def freiburg_bar() -> BarSetup:
    """The Freiburg bar set-up (:data:`FREIBURG_BAR`)."""
    return FREIBURG_BAR
