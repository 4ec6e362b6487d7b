"""What a simulation costs beyond its solver inside the workflow: one job per simulation (the old code)
against batches of simulations per job (rule simulate, calibration.batch), old and new timed in one run.

    python benchmarks/bench_batch.py [--old REV] [--new REV] [--members 16] [--repeats 2]
        [--out benchmarks/results/bench_batch.json]

Each code version is cloned at its commit into a temporary folder (its own Numba cache, compiled by a
warm-up run that is not counted). The workload: a `fast` Brazilian-disc twin (the default run's
`twin_ref` settings, `--members` members, no replicates), and the timed command is what Snakemake does
for one ensemble iteration's simulations: ``snakemake --cores 1 <iter_0's responses.csv> --omit-from
aggregate`` (every job upstream of the aggregation; targeting each member's run.json instead would add
a job per member that runs nothing, which the workflow no longer has)
after the member folders (and, new, their batch files) are removed, so that only the simulations run,
one after another on one core. ``overhead_per_member_s`` = (the command's wall minus Snakemake's own
floor, the same command with nothing to do measured beside each repeat, minus the members' summed
``solver_wall_s``) / members: what
each simulation costs beyond its time loop (Snakemake's job, the interpreter, the imports, the engine's
load, the mesh, the files). Writes JSON with the cores, the load average and every repeat.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO)]

from shpb.atomic import emit_json  # noqa: E402

EXP = "bench"


def config(members: int) -> dict:
    return {"run": [EXP], "experiments": {EXP: {
        "kind": "twin", "geometry": "brazilian_disc", "preset": "fast", "seed": 2021, "ensemble_size": members,
        "method": "esmda", "esmda": {"steps": 1}, "posterior": "ensemble",
        "parameters": {"sigma_t": [4.0e6, 60.0e6], "E_t": [200.0, 2400.0]},
        "simulation": {"t_end": 1.6e-4, "sample_dt": 5.0e-7},
        "observations": {"t_end": 1.6e-4, "dt": 1.0e-6, "truth": {"sigma_t": 45.0e6, "E_t": 500.0},
                         "noise": {"relative_sigma": 0.01}, "model_error": {"simulator_replicates": 0}}}}}


def snakemake(clone: Path, work: Path, *args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(clone / "Snakefile"), "--directory",
                    str(work), "--configfile", str(work / "config.yaml"), "--workflow-profile", "none",
                    "--quiet", "all", *args], check=True, capture_output=True, cwd=clone,
                   env={**os.environ, "PYTHONPATH": str(clone)})  # the clone's packages, not the installed ones
    return time.perf_counter() - t0


def clone_at(rev: str, where: Path) -> Path:
    subprocess.run(["git", "clone", "--quiet", str(REPO), str(where)], check=True)
    subprocess.run(["git", "checkout", "--quiet", rev], cwd=where, check=True)
    return where


def old_and_new(argv, out: str, **extra) -> tuple[argparse.Namespace, str]:
    """The command line of an old-against-new benchmark (--old, --new, --out and ``extra`` options) and
    the new commit's short hash, fixed before anything runs."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", default="7b72408", help="the commit before batches")
    ap.add_argument("--new", default="HEAD")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / out))
    for name, default in extra.items():
        ap.add_argument(f"--{name.replace('_', '-')}", type=str if default is None else type(default), default=default)
    a = ap.parse_args(argv)
    return a, subprocess.run(["git", "rev-parse", "--short", a.new], cwd=REPO, check=True, capture_output=True,
                             text=True).stdout.strip()


def measure(clone: Path, work: Path, members: int, repeats: int) -> dict:
    work.mkdir(parents=True)
    (work / "config.yaml").write_text(yaml.safe_dump(config(members), sort_keys=False))
    # what the workflow runs for one iteration's simulations: the jobs upstream of its aggregation (the
    # batch jobs and, before the aggregation took the batch files, a job per member that ran nothing)
    targets = [f"results/{EXP}/iter_0/responses.csv", "--omit-from", "aggregate"]
    runs = [work / f"results/{EXP}/iter_0/members/{m:03d}/synthetic/run.json" for m in range(members)]
    snakemake(clone, work, "--cores", "2", *targets)  # warm-up: the engine compiled, the inputs made
    floor, rows = [], []
    for _ in range(repeats):
        # Snakemake's own floor (the same command with nothing to do) scatters by 0.5 s between calls, 0.03 s
        # a member: measured beside each repeat, the median of those three calls taken off that repeat
        before = snakemake(clone, work, "--cores", "1", *targets)
        shutil.rmtree(work / "results" / EXP / "iter_0" / "members")
        shutil.rmtree(work / "results" / EXP / "simulate" / "member", ignore_errors=True)
        shutil.rmtree(work / "results" / ".runs", ignore_errors=True)  # no copies from an earlier repeat
        wall = snakemake(clone, work, "--cores", "1", *targets)
        after = [snakemake(clone, work, "--cores", "1", *targets) for _ in range(2)]
        here = statistics.median([before, *after])
        floor.append(round(here, 3))
        solver = sum(json.loads(r.read_text())["solver_wall_s"] for r in runs)
        rows.append({"wall_s": round(wall, 3), "solver_sum_s": round(solver, 3), "snakemake_floor_s": round(here, 3),
                     "overhead_per_member_s": round((wall - here - solver) / members, 3)})
    return {"snakemake_floor_s": floor, "repeats": rows,
            "overhead_per_member_s_median": statistics.median(r["overhead_per_member_s"] for r in rows),
            "wall_s_median": statistics.median(r["wall_s"] for r in rows)}


def main(argv=None) -> dict:
    a, new = old_and_new(argv, "bench_batch.json", members=16, repeats=2)
    load0, t0 = list(os.getloadavg()), time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        res = {"old": measure(clone_at(a.old, tmp / "old"), tmp / "work_old", a.members, a.repeats),
               "new": measure(clone_at(new, tmp / "new"), tmp / "work_new", a.members, a.repeats)}
    result = {"benchmark": "bench_batch", "cores": os.cpu_count(), "timed_with_cores": 1,
              "python": platform.python_version(), "old": a.old, "new": new, "members": a.members,
              "case": "fast Brazilian disc twin, t_end 160 us (twin_ref's)",
              "load_average_before": load0, "load_average_after": list(os.getloadavg()),
              "bench_wall_s": round(time.perf_counter() - t0, 1), **res,
              "wall_ratio_old_over_new": round(res["old"]["wall_s_median"] / res["new"]["wall_s_median"], 2)}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
