"""Wall time of one Brazilian-disc member per preset (one core, warm JIT cache) and mesh convergence
of the peak stress at the paper's reference values (sigma_t 45 MPa, E_t 500 J/m^2).

Prints one JSON object. Targets (issue): fast <= 5 s, standard <= 30 s, paper <= 120 s.
Usage: python benchmarks/bench_shpb.py [--presets fast,standard,paper]
"""
from __future__ import annotations

import argparse
import json
import os


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="fast,standard,paper")
    args = ap.parse_args()
    from shpb.simulate import simulate
    simulate("brazilian_disc", "fast", t_end=5e-6)  # warm the JIT cache
    targets = {"fast": 5.0, "standard": 30.0, "paper": 120.0}
    rows = {}
    for preset in args.presets.split(","):
        out = simulate("brazilian_disc", preset, params={"sigma_t": 45e6, "E_t": 500.0})
        c, r = out.curve, out.run
        i = int(c.stress_Pa.idxmax())
        rows[preset] = {
            "status": r["status"], "wall_s": round(r["wall_s"], 2), "target_wall_s": targets.get(preset),
            "specimen_triangles": r["specimen_triangles"], "triangles_total": r["n_triangles"],
            "joints": r["n_joints"], "steps": r["steps"], "dt_s": r["dt_s"],
            "element_updates_per_s": round(r["element_updates_per_s"]),
            "peak_stress_Pa": float(c.stress_Pa[i]), "time_to_peak_s": float(c.time_s[i]),
            "energy_balance_rel": r["energy_balance_rel"], "broken_joints": r["broken_joints"],
        }
    ref = rows.get("paper") or rows[list(rows)[-1]]
    for row in rows.values():
        row["peak_rel_diff_to_finest"] = round(row["peak_stress_Pa"] / ref["peak_stress_Pa"] - 1.0, 4)
    print(json.dumps({"benchmark": "shpb_brazilian_disc_member", "cores_on_machine": os.cpu_count(),
                      "threads_used": 1, "presets": rows}, indent=1))


if __name__ == "__main__":
    main()
