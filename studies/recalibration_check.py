"""The product's location recalibration (``emulated.recalibrate: location``, enkf.selfcal) against the
study that proposed it (``studies/pit_recalibration.py``'s ``location``), on the same development twins,
before the planned benchmark scores it (``benchmarks/coverage_plan_location.json``).

The product reads each pseudo-run's posterior on a quasi-random grid of 2^14 points and moves the MCMC
sample; the study reads it on a 121 x 121 grid and moves the grid posterior's quantiles. Both take the
same pseudo-runs (the self-calibration's, one noise draw each). Inputs: a ``bench_coverage.py
--recalibrate location --score-only --keep-runs`` JSON per development seed and the study's JSON of the
same seed.

    python studies/recalibration_check.py --bench 70=/tmp/cov70_location.json \\
        --bench 72=/tmp/cov72_location.json --out studies/results/recalibration_check_dev.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("sigma_t", "E_t")


def compare(bench: dict, study: dict) -> dict:
    """Per twin the two ``mu`` and ``lambda``; per parameter the largest difference of ``mu`` and each
    one's scores (the product's from the harness, the study's from its grid)."""
    twins = bench["well_specified"]["twins"]
    rows = study["sets"]["well_specified"]["rows"]
    if [t["seed"] for t in twins] != [r["seed"] for r in rows]:
        raise SystemExit("the benchmark's twins and the study's rows are not the same twins")
    per_twin = [{"seed": t["seed"], "lambda": t["emulator_mcmc"]["self_calibration_lambda"],
                 "lambda_study": r["lambda"],
                 "effective_points_min": t["emulator_mcmc"]["recalibration"]["effective_points_min"],
                 **{p: {"mu": t["emulator_mcmc"]["recalibration"]["mu"][p], "mu_study": r["forms"]["location"][p]["mu"]}
                    for p in NAMES}} for t, r in zip(twins, rows)]
    prod = bench["well_specified"]["summary_emulator_mcmc"]["params"]
    summ = study["sets"]["well_specified"]["summary"]
    out = {}
    for p in NAMES:
        d = np.array([abs(x[p]["mu"] - x[p]["mu_study"]) for x in per_twin])
        out[p] = {"mu_abs_difference_max": float(d.max()), "mu_abs_difference_median": float(np.median(d)),
                  "product": {"coverage_90": prod[p]["coverage_90"]["fraction"],
                              "coverage_50": prod[p]["coverage_50"]["fraction"],
                              "wis_over_prior": prod[p]["wis_over_prior"], "sbc_ks_p": prod[p]["sbc"]["ks_p"]},
                  "study_location": {k: summ["location"][p][k] for k in ("coverage_90", "coverage_50",
                                                                         "wis_over_prior", "pit_ks_p")},
                  "study_power": {k: summ["power"][p][k] for k in ("coverage_90", "coverage_50",
                                                                   "wis_over_prior", "pit_ks_p")}}
    return {"summary": out, "twins": per_twin}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bench", action="append", required=True, help="SEED=bench_coverage JSON")
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    result = {"study": "recalibration_check", "what": __doc__.split("\n\n")[0].replace("\n", " "), "seeds": {}}
    for item in args.bench:
        seed, path = item.split("=", 1)
        study = json.loads((ROOT / "studies" / "results" / f"pit_recalibration_dev{seed}.json").read_text())
        result["seeds"][seed] = compare(json.loads(Path(path).read_text()), study)
    text = json.dumps(result, indent=1) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    json.dump({s: v["summary"] for s, v in result["seeds"].items()}, sys.stdout, indent=1)
    return result


if __name__ == "__main__":
    main()
