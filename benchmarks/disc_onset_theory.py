"""Where along the loaded diameter should the first joint reach its strength? Theory, no simulation.

The elastic field of a disc loaded by a uniform pressure over two arcs of half-angle alpha (Hondros
1959) gives, on the loaded diameter at x = rho R, the stress along the load sigma_r and across it
sigma_theta, in units of the Brazilian stress 2F / (pi D t). A joint at angle theta to the diameter
carries sigma_n = sigma_theta cos^2 + sigma_r sin^2 and tau = (sigma_theta - sigma_r) sin cos, and the
joint law (fdem.kernels.joint_forces) starts to damage it when sigma_n reaches the tensile strength
sigma_n_max, or tau reaches sigma_t + tan(phi) max(-sigma_n, 0). For each position this prints the
lowest Brazilian stress at which some joint angle starts to damage, the angle and the mode.

Prints one JSON object. Usage: python benchmarks/disc_onset_theory.py [--sigma-n 25e6]
[--sigma-t 45e6,30e6,50e6] [--phi 54] [--half-angle 10]
"""
from __future__ import annotations

import argparse
import json

import numpy as np


def hondros_on_diameter(rho, alpha):
    """(sigma_r, sigma_theta) on the loaded diameter in units of 2F/(pi D t) (compression < 0)."""
    A = (1 - rho**2) * np.sin(2 * alpha) / (1 - 2 * rho**2 * np.cos(2 * alpha) + rho**4)
    B = np.arctan((1 + rho**2) / (1 - rho**2) * np.tan(alpha))
    return -(A + B) / alpha, (A - B) / alpha


def onset(rho, alpha, sigma_n_max, sigma_t, phi):
    """Lowest Brazilian stress [Pa] at which a joint at x = rho R starts to damage, its angle [deg]
    to the diameter and its mode, over joint angles 0-45 degrees."""
    s_r, s_th = hondros_on_diameter(rho, alpha)
    best = (np.inf, None, None)
    for th in np.radians(np.arange(0.0, 45.5, 0.5)):
        sn = s_th * np.cos(th) ** 2 + s_r * np.sin(th) ** 2
        tau = abs((s_th - s_r) * np.sin(th) * np.cos(th))
        p_tension = sigma_n_max / sn if sn > 0 else np.inf
        resist = tau - (np.tan(phi) * -sn if sn < 0 else 0.0)
        p_shear = sigma_t / resist if resist > 0 else np.inf
        p = min(p_tension, p_shear)
        if p < best[0]:
            best = (float(p), float(np.degrees(th)), "tension" if p_tension <= p_shear else "shear")
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sigma-n", type=float, default=25e6)
    ap.add_argument("--sigma-t", default="45e6,30e6,50e6")
    ap.add_argument("--phi", type=float, default=54.0)
    ap.add_argument("--half-angle", type=float, default=10.0)
    args = ap.parse_args()
    alpha, phi = np.radians(args.half_angle), np.radians(args.phi)
    out = {"benchmark": "disc_onset_theory", "sigma_n_Pa": args.sigma_n, "phi_deg": args.phi,
           "flat_half_angle_deg": args.half_angle, "cases": []}
    for st in (float(v) for v in args.sigma_t.split(",")):
        rows = []
        for rho in np.arange(0.0, 0.75, 0.05):
            p, th, mode = onset(rho, alpha, args.sigma_n, st, phi)
            rows.append({"x_over_R": round(float(rho), 2), "onset_brazilian_stress_Pa": p,
                         "joint_angle_deg": th, "mode": mode})
        weakest = min(rows, key=lambda r: r["onset_brazilian_stress_Pa"])
        centre = rows[0]["onset_brazilian_stress_Pa"]
        out["cases"].append({"sigma_t_Pa": st, "centre_onset_Pa": centre, "weakest": weakest,
                             "weakest_over_centre": weakest["onset_brazilian_stress_Pa"] / centre,
                             "along_diameter": rows})
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
