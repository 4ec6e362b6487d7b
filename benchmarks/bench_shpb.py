"""The Brazilian disc per preset (one core, warm JIT cache): wall time of one member, whether it fails
as a Brazilian disc at the three check points of the Table 2 box (shpb.fracture: crack starts in the
centre, broken joints along the loaded diameter, faces in balance at the failure peak), how far its
pieces pass into each other, and the mesh convergence of the failure peak against the paper preset.

Prints one JSON object. Targets (issues): member wall time fast <= 5 s, standard <= 30 s, paper <= 120 s
(reference point); failure peak at standard and paper within 10 % of each other.
Usage: python benchmarks/bench_shpb.py [--presets fast,standard,paper] [--points reference,...]
"""
from __future__ import annotations

import argparse
import json
import os


def main():
    from shpb.fracture import CHECK_POINTS
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="fast,standard,paper")
    ap.add_argument("--points", default=",".join(CHECK_POINTS))
    args = ap.parse_args()
    from shpb.simulate import simulate
    simulate("brazilian_disc", "fast", t_end=5e-6)  # warm the JIT cache
    targets = {"fast": 5.0, "standard": 30.0, "paper": 120.0}
    rows = {}
    for preset in args.presets.split(","):
        rows[preset] = {}
        for point in args.points.split(","):
            sigma_t, E_t = CHECK_POINTS[point]
            out = simulate("brazilian_disc", preset, params={"sigma_t": sigma_t, "E_t": E_t})
            r = out.run
            f = r["fracture"]
            h = out.extra["setup"]["geometry"].element_size_m["specimen"]
            rows[preset][point] = {
                "sigma_t": sigma_t, "E_t": E_t, "status": r["status"],
                "wall_s": round(r["wall_s"], 2), "solver_wall_s": round(r["solver_wall_s"], 2),
                "target_wall_s": targets.get(preset), "specimen_triangles": r["specimen_triangles"],
                "triangles_total": r["n_triangles"], "joints": r["n_joints"], "steps": r["steps"],
                "dt_s": r["dt_s"], "element_updates_per_s": round(r["element_updates_per_s"]),
                "energy_balance_rel": r["energy_balance_rel"],
                "peak_stress_Pa": f["peak_stress_Pa"], "peak_t_s": f["peak_t_s"],
                "checks": f["checks"], "first_joint_xy_over_R": f["first_joint_xy_over_R"],
                "first_joint_t_s": f["first_joint_t_s"], "band_fraction_at_peak": f["band_fraction_at_peak"],
                "broken_at_peak": f["broken_at_peak"], "force_ratio_at_peak": f["force_ratio_at_peak"],
                "max_contact_penetration_over_h": r["max_penetration_over_h"],
                "overlap_at_peak_over_h": f["overlap_at_peak_m"] / h, "overlap_at_end_over_h": f["overlap_at_end_m"] / h,
            }
    finest = "paper" if "paper" in rows else list(rows)[-1]
    for preset, points in rows.items():
        for point, row in points.items():
            ref = rows[finest].get(point)
            if ref is not None:
                row["peak_rel_diff_to_" + finest] = round(row["peak_stress_Pa"] / ref["peak_stress_Pa"] - 1.0, 4)
    print(json.dumps({"benchmark": "shpb_brazilian_disc", "cores_on_machine": os.cpu_count(),
                      "threads_used": 1, "presets": rows}, indent=1))


if __name__ == "__main__":
    main()
