"""Where along the loaded diameter a flattened Brazilian disc's joints should first reach their
strength: elasticity plus the joint law's onset criterion, no simulation.

The elastic field of a disc loaded by a uniform pressure over two arcs of half-angle alpha (Hondros
1959) gives, on the loaded diameter at x = rho R, the stress along the load sigma_r and across it
sigma_theta, in units of the Brazilian stress 2F / (pi D t). A joint at angle theta to the diameter
carries sigma_n = sigma_theta cos^2 + sigma_r sin^2 and tau = (sigma_theta - sigma_r) sin cos; the
joint law (fdem.kernels.joint_forces) starts to damage it when sigma_n reaches the tensile strength,
or tau reaches sigma_t + tan(phi) max(-sigma_n, 0) (friction only under compression).
"""
from __future__ import annotations

import numpy as np

#: Joint angles to the diameter searched [deg]: an unstructured mesh has edges at any angle.
JOINT_ANGLES_DEG = np.arange(0.0, 45.5, 0.5)


def hondros_on_diameter(rho, alpha_rad):
    """(sigma_r, sigma_theta) on the loaded diameter at x = rho R (0 <= rho < 1), in units of the
    Brazilian stress 2F/(pi D t); compression negative. alpha_rad: half-angle of the loaded arcs."""
    rho = np.asarray(rho, float)
    A = (1 - rho**2) * np.sin(2 * alpha_rad) / (1 - 2 * rho**2 * np.cos(2 * alpha_rad) + rho**4)
    B = np.arctan((1 + rho**2) / (1 - rho**2) * np.tan(alpha_rad))
    return -(A + B) / alpha_rad, (A - B) / alpha_rad


def joint_onset(rho, alpha_rad, sigma_n, sigma_t, phi_rad):
    """Lowest Brazilian stress [Pa] at which a joint at x = rho R starts to damage, over the joint
    angles of JOINT_ANGLES_DEG: (stress [Pa], joint angle [deg], 'tension' or 'shear')."""
    s_r, s_th = hondros_on_diameter(rho, alpha_rad)
    th = np.radians(JOINT_ANGLES_DEG)
    sn = s_th * np.cos(th) ** 2 + s_r * np.sin(th) ** 2
    tau = np.abs((s_th - s_r) * np.sin(th) * np.cos(th))
    with np.errstate(divide="ignore"):
        p_tension = np.where(sn > 0, sigma_n / np.where(sn > 0, sn, 1.0), np.inf)
        resist = tau - np.tan(phi_rad) * np.maximum(-sn, 0.0)
        p_shear = np.where(resist > 0, sigma_t / np.where(resist > 0, resist, 1.0), np.inf)
    p = np.minimum(p_tension, p_shear)
    k = int(np.argmin(p))
    return float(p[k]), float(JOINT_ANGLES_DEG[k]), "tension" if p_tension[k] <= p_shear[k] else "shear"


def onset_along_diameter(alpha_rad, sigma_n, sigma_t, phi_rad, rhos=np.arange(0.0, 0.75, 0.05)):
    """joint_onset at each rho: a list of {x_over_R, onset_brazilian_stress_Pa, joint_angle_deg, mode}."""
    rows = []
    for rho in rhos:
        p, th, mode = joint_onset(rho, alpha_rad, sigma_n, sigma_t, phi_rad)
        rows.append({"x_over_R": round(float(rho), 2), "onset_brazilian_stress_Pa": p,
                     "joint_angle_deg": th, "mode": mode})
    return rows
