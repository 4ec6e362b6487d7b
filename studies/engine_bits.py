"""How far the reported interval moves when the engine's last bits change: the same twins (same seeds,
same truths, same code) simulated on two x86 machines whose compiled engine differs in its vector unit
(AVX-512 on one, AVX2 on the other: the same arithmetic, other rounding), the reported posterior
(``emulator_mcmc``) of each compared.

Fracture is chaotic, so a difference in the last bit of one run grows into another crack path; the
runs of the two machines are then two draws of the simulator's own scatter, not the same draw twice.
The spread of the two reported intervals is the part of the interval set by which draws the loop got:
an error of the quoted interval that no single run shows. Inputs: the location benchmark's part-1
records (``benchmarks/results/coverage_location_records/machine-a/``) and the same twins re-run under its
amendment 1 (the well-specified twins of ``benchmarks/results/coverage_location.json``, the scored JSON that
holds their records); only twins present in both are compared. No twin is scored
against its truth here beyond whether the two intervals agree on holding it.

    python studies/engine_bits.py --out studies/results/engine_bits.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "benchmarks" / "results" / "coverage_location_records"
SCORED = ROOT / "benchmarks" / "results" / "coverage_location.json"
NAMES = ("sigma_t", "E_t")


def pair_rows(a: dict, b: dict) -> dict:
    """One twin's two reported intervals compared, per parameter, in units of machine A's 90 % width."""
    if a["seed"] != b["seed"] or a["truth"] != b["truth"]:
        raise ValueError(f"records of twin {a['seed']} and {b['seed']} are not the same twin")
    out = {"seed": a["seed"], "stop_chi2_per_obs": [a["stop_chi2_per_obs"], b["stop_chi2_per_obs"]]}
    for p in NAMES:
        x, y = a["emulator_mcmc"]["params"][p], b["emulator_mcmc"]["params"][p]
        w = x["q95"] - x["q05"]
        t = a["truth"][p]
        out[p] = {"median_shift_over_width": (y["q50"] - x["q50"]) / w,
                  "q05_shift_over_width": (y["q05"] - x["q05"]) / w,
                  "q95_shift_over_width": (y["q95"] - x["q95"]) / w,
                  "width_ratio": (y["q95"] - y["q05"]) / w,
                  "last_ensemble_mean_ratio": b["params"][p]["mean"] / a["params"][p]["mean"],
                  "holds_truth": [bool(x["q05"] <= t <= x["q95"]), bool(y["q05"] <= t <= y["q95"])]}
    return out


def summarise(rows: list) -> dict:
    out = {"twins": len(rows)}
    for p in NAMES:
        col = {k: np.array([r[p][k] for r in rows]) for k in
               ("median_shift_over_width", "q05_shift_over_width", "q95_shift_over_width", "width_ratio",
                "last_ensemble_mean_ratio")}
        ends = np.abs(np.concatenate([col["q05_shift_over_width"], col["q95_shift_over_width"]]))
        out[p] = {"median_shift_over_width_abs": {"median": float(np.median(np.abs(col["median_shift_over_width"]))),
                                                  "p90": float(np.quantile(np.abs(col["median_shift_over_width"]), 0.9))},
                  "end_shift_over_width_abs": {"median": float(np.median(ends)), "p90": float(np.quantile(ends, 0.9))},
                  "width_ratio": {"median": float(np.median(col["width_ratio"])),
                                  "p10": float(np.quantile(col["width_ratio"], 0.1)),
                                  "p90": float(np.quantile(col["width_ratio"], 0.9))},
                  "last_ensemble_mean_rel_abs_median": float(np.median(np.abs(col["last_ensemble_mean_ratio"] - 1))),
                  "truth_held_by_one_only": int(sum(r[p]["holds_truth"][0] != r[p]["holds_truth"][1] for r in rows))}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", default=str(RECORDS / "machine-a"))
    ap.add_argument("--b", default=str(SCORED), help="a bench_coverage JSON whose well-specified twins are machine B's")
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    b = {t["seed"]: t for t in json.loads(Path(args.b).read_text())["well_specified"]["twins"]}
    rows = []
    for fa in sorted(Path(args.a).glob("well_specified_*.json")):
        a = json.loads(fa.read_text())
        if a["seed"] in b:
            rows.append(pair_rows(a, b[a["seed"]]))
    if not rows:
        raise SystemExit(f"no twin is in both {args.a} and {args.b}")
    result = {"study": "engine_bits", "what": __doc__.split("\n\n")[0].replace("\n", " "),
              "summary": summarise(rows), "rows": rows}
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    json.dump(result["summary"], sys.stdout, indent=1)
    return result


if __name__ == "__main__":
    main()
