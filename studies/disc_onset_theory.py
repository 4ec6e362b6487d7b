"""Where along the loaded diameter should the first joint reach its strength? Theory, no simulation
(shpb.disc_theory: Hondros' elastic field of the flattened disc and the joint law's onset criterion).
For each position, the lowest Brazilian stress at which some joint angle starts to damage, the angle
and the mode; per sigma_t, the weakest place and its onset relative to the centre's.

Prints one JSON object. Usage: python studies/disc_onset_theory.py [--sigma-n 15e6] (default: the model's)
[--sigma-t 45e6,30e6,50e6] [--phi 54] [--half-angle 10]
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from shpb.disc_theory import onset_along_diameter


def main():
    ap = argparse.ArgumentParser()
    from shpb.parameters import BRAZILIAN_DEFAULTS
    ap.add_argument("--sigma-n", type=float, default=BRAZILIAN_DEFAULTS["sigma_n"])
    ap.add_argument("--sigma-t", default="45e6,30e6,50e6")
    ap.add_argument("--phi", type=float, default=54.0)
    ap.add_argument("--half-angle", type=float, default=10.0)
    args = ap.parse_args()
    alpha, phi = np.radians(args.half_angle), np.radians(args.phi)
    out = {"benchmark": "disc_onset_theory", "sigma_n_Pa": args.sigma_n, "phi_deg": args.phi,
           "flat_half_angle_deg": args.half_angle, "cases": []}
    for st in (float(v) for v in args.sigma_t.split(",")):
        rows = onset_along_diameter(alpha, args.sigma_n, st, phi)
        weakest = min(rows, key=lambda r: r["onset_brazilian_stress_Pa"])
        centre = rows[0]["onset_brazilian_stress_Pa"]
        out["cases"].append({"sigma_t_Pa": st, "centre_onset_Pa": centre, "weakest": weakest,
                             "weakest_over_centre": weakest["onset_brazilian_stress_Pa"] / centre,
                             "along_diameter": rows})
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
