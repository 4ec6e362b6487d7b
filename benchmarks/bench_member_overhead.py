"""What a member job costs beyond its solver: the shipped simulator run by ``calibration.runner.run_member``
in a second interpreter (``python -m shpb simulate`` as a subprocess, the old path) against a forked child
of the job process (the new path), for the same member.

    python benchmarks/bench_member_overhead.py [--repeats 5] [--case disc_fast]
        [--out benchmarks/results/bench_member_overhead.json]

Each run is a fresh job process, as Snakemake starts one per member: ``python -c`` importing what the
rule adapter scripts/simulate.py imports and calling ``run_member`` once (without Snakemake's own
preamble, which both paths pay alike; its import is timed apart, ``snakemake_script_import_s``, and so is
what importing ``calibration.workflow_io`` instead of ``calibration.runner`` adds, ``workflow_io_extra_s``,
the adapter's import before it took the runner's module). The job
is timed from outside; ``run.json`` gives the simulator's ``wall_s`` (from its set-up to its end) and
``solver_wall_s`` (the time loop, holding Numba's load of the cached engine). ``overhead_s`` = job wall
minus ``solver_wall_s``. Old and new alternate, after one warm-up run each (warm Numba cache, warm file
cache). ``numba_first_call``: the member run twice in one process, the first call's ``solver_wall_s``
minus the second's (Numba's set-up and the cached engine's load, paid once per process on either path).
``fork_without_gc_freeze``: the fork without ``gc.freeze()`` before it, the choice that measure made.
Threads pinned to one, as in a member job. Writes JSON with the cores, Python and load average.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO)]

from calibration.job_log import THREAD_VARIABLES  # noqa: E402 (what rules/common.smk pins)
from shpb.atomic import emit_json  # noqa: E402

RECORD = "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
CASES = {  # as the default run's member jobs run them (studies/bench_member_startup.py's cases)
    "disc_fast": dict(geometry="brazilian_disc", preset="fast", params={"sigma_t": 4.5e7, "E_t": 500.0},
                      t_end=1.6e-4, sample_dt=5e-7),
    "cylinder_fast_CaMa_SHPB_004": dict(geometry="cylinder", preset="fast", params={"sigma_t": 4e7, "E_t": 2e4},
                                        record=RECORD, t_end=3.6e-4, sample_dt=5e-7),
}
MODES = ("subprocess", "fork", "fork_without_gc_freeze")
THREADS = dict.fromkeys(THREAD_VARIABLES, "1")

# one member job; "subprocess" turns the fork off, which leaves run_member's old path unchanged;
# "fork_without_gc_freeze" forks without moving the inherited objects out of the child's collections
JOB = """
import json, sys
from calibration.ensemble_files import simulation_params  # noqa: F401 (scripts/simulate.py's imports)
from calibration import runner
from calibration.runner import failure_card, run_member, simulator_command
mode, folder, case = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
if mode == "subprocess":
    runner._forkable = lambda command: False
elif mode == "fork_without_gc_freeze":
    runner.gc.freeze = lambda: None
run_member(command=simulator_command(None), curve_path=folder + "/curve.csv", run_path=folder + "/run.json",
           log_path=folder + "/simulate.log", **case)
"""


def one_job(mode: str, case: dict) -> dict:
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", JOB, mode, out, json.dumps(case)], cwd=REPO, check=True,
                       env={**os.environ, **THREADS}, capture_output=True)
        job = time.perf_counter() - t0
        run = json.loads((Path(out) / "run.json").read_text())
    assert run["status"] == "ok", run
    return {"job_s": job, "wall_s": run["wall_s"], "solver_wall_s": run["solver_wall_s"],
            "overhead_s": job - run["solver_wall_s"], "outside_simulator_s": job - run["wall_s"]}


# the same member twice in one process: the first call's solver_wall_s holds Numba's one-off work (its CPU
# target's set-up, the cached engine's load), the second's is the time loop alone
TWICE = """
import json, sys, tempfile
from shpb.simulate import simulate
case, walls = json.loads(sys.argv[1]), []
for _ in range(2):
    with tempfile.TemporaryDirectory() as out:
        walls.append(simulate(case["geometry"], case["preset"], params=case["params"], record=case.get("record"),
                              out_dir=out, t_end=case["t_end"], sample_dt=case["sample_dt"]).run["solver_wall_s"])
print(json.dumps(walls))
"""


def numba_first_call_s(case: dict, repeats: int) -> dict:
    rows = []
    for _ in range(repeats):
        proc = subprocess.run([sys.executable, "-c", TWICE, json.dumps(case)], cwd=REPO, check=True,
                              env={**os.environ, **THREADS}, capture_output=True, text=True)
        rows.append(json.loads(proc.stdout))
    return {"first_solver_wall_s": [round(a, 3) for a, _ in rows],
            "second_solver_wall_s": [round(b, 3) for _, b in rows],
            "first_minus_second_s_median": round(statistics.median(a - b for a, b in rows), 3)}


def summary(rows: list[dict]) -> dict:
    out = {"runs": len(rows)}
    for key in ("job_s", "wall_s", "solver_wall_s", "overhead_s", "outside_simulator_s"):
        values = [r[key] for r in rows]
        out[f"{key}_median"] = round(statistics.median(values), 3)
        out[f"{key}_min"] = round(min(values), 3)
    return out


def import_time(modules: str, repeats: int, base: str = "") -> float:
    """Median wall of ``python -c 'import base, modules'`` minus that of ``import base`` (a bare
    ``python -c pass`` without ``base``); the two alternate."""
    def wall(code):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True, env={**os.environ, **THREADS})
        return time.perf_counter() - t0
    with_, without = [], []
    for _ in range(repeats):
        without.append(wall(f"import {base}" if base else "pass"))
        with_.append(wall(f"import {base + ', ' if base else ''}{modules}"))
    return round(statistics.median(with_) - statistics.median(without), 3)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--case", choices=sorted(CASES), action="append")
    ap.add_argument("--out", default=str(REPO / "benchmarks/results/bench_member_overhead.json"))
    a = ap.parse_args(argv)
    cases = a.case or ["disc_fast"]
    load0 = list(os.getloadavg())
    t0 = time.perf_counter()
    rows = {(m, c): [] for c in cases for m in MODES}
    for c in cases:
        for m in MODES:
            one_job(m, CASES[c])  # warm-up, not counted
    for _ in range(a.repeats):
        for c in cases:
            for m in MODES:
                rows[(m, c)].append(one_job(m, CASES[c]))
    result = {"benchmark": "bench_member_overhead", "cores": os.cpu_count(), "threads_per_job": 1,
              "python": platform.python_version(), "repeats": a.repeats,
              "load_average_before": load0, "load_average_after": list(os.getloadavg()),
              "bench_wall_s": round(time.perf_counter() - t0, 1),
              "snakemake_script_import_s": import_time("snakemake.script", 7),
              "workflow_io_extra_s": import_time("calibration.workflow_io", 7,
                                                 base="calibration.ensemble_files, calibration.runner"),
              "cases": {}}
    for c in cases:
        old, new = summary(rows[("subprocess", c)]), summary(rows[("fork", c)])
        result["cases"][c] = {"subprocess": old, "fork": new,
                              "fork_without_gc_freeze": summary(rows[("fork_without_gc_freeze", c)]),
                              "overhead_saved_s_median": round(old["overhead_s_median"] - new["overhead_s_median"], 3),
                              "job_saved_s_median": round(old["job_s_median"] - new["job_s_median"], 3),
                              "numba_first_call": numba_first_call_s(CASES[c], 3),
                              "runs": {m: rows[(m, c)] for m in MODES}}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
