"""Where the default run's time goes (issue 54: the 5-minute goal): the FDEM solver seconds per
experiment and stage, the job time per rule, and the bound the solver alone sets on 2 cores.

    git clone <repo> run && cd run && snakemake --cores 2 > ../run.log 2>&1
    python benchmarks/default_run_costs.py run run.log --wall <s> [--out benchmarks/results/default_run_costs.json]

Per experiment and stage (the stage names of :mod:`benchmarks.bench_loro`): runs and summed
``solver_wall_s``; per rule (:func:`tools.job_times.job_times` on the console log): jobs and job seconds.
``solver_bound_s`` = the summed solver seconds over the cores: no scheduling of these runs ends sooner.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO)]

from benchmarks.bench_loro import run_stage  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from tools.job_times import job_times  # noqa: E402


def costs(clone: Path, log: str, wall_s: float, cores: int = 2) -> dict:
    per_exp = {exp: fdem_runs_of(clone, exp) for exp in sorted(
        p.name for p in (clone / "results").iterdir() if p.is_dir() and not p.name.startswith("."))}
    solver = sum(row["solver_s"] for stages in per_exp.values() for row in stages.values())
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True, text=True,
                         check=True).stdout.strip()
    return {"benchmark": "default_run_costs", "commit": rev, "cores": cores, "machine_cores": os.cpu_count(),
            "wall_s": round(float(wall_s), 1), "solver_s": round(solver, 1),
            "solver_bound_s": round(solver / cores, 1), "fdem_runs": per_exp, "job_times": job_times(log.splitlines())}


def fdem_runs_of(clone: Path, exp: str) -> dict:
    """Per stage of one experiment (:func:`benchmarks.bench_loro.run_stage`'s names): runs and solver seconds."""
    results = clone / "results"
    out: dict[str, dict] = {}
    for run_json in sorted((results / exp).glob("**/run.json")):
        row = out.setdefault(run_stage(run_json, results), {"runs": 0, "solver_s": 0.0})
        row["runs"] += 1
        row["solver_s"] += float(json.loads(run_json.read_text()).get("solver_wall_s") or 0.0)
    return {k: {**v, "solver_s": round(v["solver_s"], 1)} for k, v in sorted(out.items())}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("clone", help="the folder the default run ran in")
    ap.add_argument("log", help="its console log")
    ap.add_argument("--wall", type=float, required=True, help="its wall time [s]")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    return emit_json(costs(Path(a.clone), Path(a.log).read_text(), a.wall, a.cores), a.out)


if __name__ == "__main__":
    main()
