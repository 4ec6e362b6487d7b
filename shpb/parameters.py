"""Model parameters of the SHPB simulations: names (docs/workflow.md, "What goes where"), defaults and validation.

Names follow the paper: sigma_n, sigma_t [Pa] tensile and shear strength; E_n, E_t [J/m^2] mode I
and mode II specific fracture energies; a, b, c the softening-curve shape; E [Pa], nu, rho [kg/m^3]
the specimen's elastic constants. Extra model settings: phi_deg (Mohr-Coulomb friction angle on the
joint shear strength), mu_crack (Coulomb friction of the specimen's crack faces once joints have
broken; the bar-specimen faces have their own, interface_friction.mu), penalty_factor (joint penalty p = f E), contact_penalty_factor (bar-specimen
contact penalty in units of the specimen's E), damping.beta (element viscous damping fraction),
interface_friction.mu (Coulomb friction at the bar-specimen faces), seating.compliance_m_per_Pa
(an extra face closure C sigma at the loaded faces, in series with the contact penalty),
rate_strength.k (DIF = max(1, 1 + k log10(rate / 1 s^-1)) on both joint strengths, rate = the
joint's relative face velocity over its element size; fdem.model.JointParams.rate_k), face_gap.gap_m
(an initial gap [m] between the incident bar and the specimen's front face, which the bar's face must
close before the specimen takes load; shpb.geometry), closure.range_m (a non-parallel front end: the gap
grows across the face from face_gap.gap_m to face_gap.gap_m + range, so the face closes progressively;
shpb.geometry).
"""
from __future__ import annotations

import math

# Brazilian disc, granite (Godinez & Rougier 2021): E, nu, rho from Table 1; sigma_t and E_t are
# the twin experiment's reference values (Table 2). The paper gives none of the others; ours, with
# their sources:
# - sigma_n = 15 MPa: the quasi-static tensile (Brazilian) strength of Kuru granite, between the two
#   laboratories' values for it: about 13 MPa (Saksala et al. 2013, section 2.2) and 16.9 MPa
#   (Wessling & Kajberg 2022, Table 5), both as read via a secondary summary. The joints carry the
#   material's strength; the dynamic apparent strength comes out of the model (inertia and the
#   crack's run time): its peak Brazilian stress at its loading rate, 31-33 MPa at about 400 GPa/s,
#   lies within 20 % of the Kuru SHPB law sigma_td = 21 MPa + 0.017 x rate [GPa/s] (28 MPa there).
#   A tensile strength this far below the shear capacity also makes the disc's centre, not an
#   inclined joint off it, the first place to fail at every point of the Table 2 box
#   (shpb.disc_theory; 25 MPa put the weakest joint in shear at 0.55 R on the standard mesh).
# - E_n = 100 J/m^2: granite's mode I fracture energy K_Ic^2 / E with K_Ic = 1.5-2 MPa m^0.5
#   (65-115 J/m^2).
# - phi_deg = 54: Mohr-Coulomb friction angle of intact granite, the Hoek, Carranza-Torres & Corkum
#   (2002) fit of the Hoek-Brown envelope with m_i = 32 (granite; Marinos & Hoek 2000) over
#   0 <= sigma_3 <= sigma_ci / 4: sin(phi) = 6 a m (s + m/4)^(a-1) / (2 (1+a)(2+a) + 6 a m (s + m/4)^(a-1)),
#   a = 0.5, s = 1, m = 32, gives 54.1 degrees. Without it the disc crushes under the loading flats
#   (shear under compression at the cohesion alone) before the centre splits.
# - mu_crack = 0.85: Coulomb friction of crack faces once joints have broken, Byerlee's (1978) rule for
#   rock surfaces at normal stresses below 200 MPa.
BRAZILIAN_DEFAULTS = {
    "sigma_n": 15e6, "sigma_t": 45e6, "E_n": 100.0, "E_t": 500.0,
    "a": 0.63, "b": 1.8, "c": 6.0,
    "E": 35e9, "nu": 0.16, "rho": 2550.0,
    "phi_deg": 54.0, "mu_crack": 0.85, "penalty_factor": 10.0, "contact_penalty_factor": 2.0,
    "damping.beta": 0.0, "interface_friction.mu": 0.0, "seating.compliance_m_per_Pa": 0.0,
    "rate_strength.k": 0.0, "face_gap.gap_m": 0.0, "closure.range_m": 0.0,
}

# Cylinder (uniaxial compression, Carrara marble records): E, nu, rho are overwritten by the
# record's spreadsheet / PetrophysicalProperties.xlsx. Strengths: marble's tensile strength is of
# the order of 7-10 MPa and its cohesion about 30-40 MPa with a friction angle near 30 degrees, which
# puts the uniaxial compressive strength 2 c cos(phi) / (1 - sin(phi)) near 100-140 MPa. Crack faces:
# Byerlee's (1978) mu = 0.85, as for the granite.
CYLINDER_DEFAULTS = {
    "sigma_n": 10e6, "sigma_t": 35e6, "E_n": 50.0, "E_t": 500.0,
    "a": 0.63, "b": 1.8, "c": 6.0,
    "E": 50e9, "nu": 0.27, "rho": 2700.0,
    "phi_deg": 30.0, "mu_crack": 0.85, "penalty_factor": 10.0, "contact_penalty_factor": 2.0,
    "damping.beta": 0.0, "interface_friction.mu": 0.0, "seating.compliance_m_per_Pa": 0.0,
    "rate_strength.k": 0.0, "face_gap.gap_m": 0.0, "closure.range_m": 0.0,
}

_BOUNDS = {
    "sigma_n": (0.0, math.inf, False), "sigma_t": (0.0, math.inf, False),
    "E_n": (0.0, math.inf, False), "E_t": (0.0, math.inf, False),
    "a": (0.0, math.inf, False), "b": (0.0, math.inf, False), "c": (0.0, math.inf, False),
    "E": (0.0, math.inf, False), "nu": (-1.0, 0.5, False), "rho": (0.0, math.inf, False),
    "phi_deg": (0.0, 89.0, True), "mu_crack": (0.0, 5.0, True), "penalty_factor": (3.0, math.inf, False),
    "contact_penalty_factor": (0.0, math.inf, False), "damping.beta": (0.0, 1.0, True),
    "interface_friction.mu": (0.0, 5.0, True),
    "seating.compliance_m_per_Pa": (0.0, 1e-9, True),
    "rate_strength.k": (0.0, 2.0, True),
    "face_gap.gap_m": (0.0, 2e-3, True),
    "closure.range_m": (0.0, 2e-3, True),
}


def bounds(name: str) -> tuple[float, float, bool]:
    """``(lo, hi, closed_lo)``: the range :func:`resolve` accepts for ``name`` (``lo <= v`` if
    ``closed_lo`` else ``lo < v``, and ``v < hi``). Raises KeyError for an unknown name."""
    return _BOUNDS[name]


def defaults(geometry: str) -> dict:
    if geometry == "brazilian_disc":
        return dict(BRAZILIAN_DEFAULTS)
    if geometry == "cylinder":
        return dict(CYLINDER_DEFAULTS)
    raise ValueError(f"unknown geometry {geometry!r}: expected 'brazilian_disc' or 'cylinder'")


def resolve(geometry: str, given: dict | None) -> dict:
    """Defaults overridden by `given`; raises ValueError naming any unknown or out-of-range value."""
    p = defaults(geometry)
    for name, value in (given or {}).items():
        if name not in p:
            raise ValueError(f"unknown parameter {name!r}; known parameters: {sorted(p)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"parameter {name} must be a number, got {value!r}") from None
        lo, hi, closed_lo = _BOUNDS[name]
        ok = math.isfinite(v) and (v >= lo if closed_lo else v > lo) and v < hi
        if not ok:
            raise ValueError(f"parameter {name}={v!r} out of range: expected "
                             f"{'>=' if closed_lo else '>'} {lo} and < {hi}")
        p[name] = v
    return p
