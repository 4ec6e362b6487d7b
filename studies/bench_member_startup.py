"""What a member costs beyond its simulation: ``python -m shpb simulate`` in a fresh process, as every
member job runs it, timed from outside and set against the simulator's own ``wall_s`` and
``solver_wall_s`` (``run.json``). The difference is the process's start-up (interpreter, imports); the
first call's ``solver_wall_s`` also holds Numba loading the cached engine.

    python studies/bench_member_startup.py [--repeats 5] [--other-tree <checkout of another commit>]

With ``--other-tree`` the same runs of that checkout are interleaved with this one's (old and new in one
run, on the same machine state). One core; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from calibration.runner import simulate_argv, simulator_command

ROOT = Path(__file__).resolve().parents[1]
RECORD = "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
CASES = {  # as a member job runs them: the geometry, preset, parameters, record and window of the default run
    "disc_fast": dict(geometry="brazilian_disc", preset="fast", params={"sigma_t": 4.5e7, "E_t": 500.0},
                      t_end=1.6e-4, sample_dt=5e-7),
    "cylinder_fast_CaMa_SHPB_004": dict(geometry="cylinder", preset="fast", params={"sigma_t": 4e7, "E_t": 2e4},
                                        record=RECORD, t_end=3.6e-4, sample_dt=5e-7),
}


def one_run(tree: Path, case: dict) -> dict:
    with tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, PYTHONPATH=str(tree))
        argv = simulate_argv(simulator_command(), out_dir=out, **case)  # the member runner's command line
        t0 = time.perf_counter()
        subprocess.run(argv, cwd=tree, env=env, check=True, capture_output=True)
        total = time.perf_counter() - t0
        run = json.loads((Path(out) / "run.json").read_text())
    return {"process_s": total, "wall_s": run["wall_s"], "solver_wall_s": run["solver_wall_s"]}


def summary(rows: list[dict]) -> dict:
    med = lambda k: round(statistics.median(r[k] for r in rows), 3)  # noqa: E731
    return {"runs": len(rows), "process_s_median": med("process_s"), "wall_s_median": med("wall_s"),
            "solver_wall_s_median": med("solver_wall_s"),
            "outside_wall_s_median": round(statistics.median(r["process_s"] - r["wall_s"] for r in rows), 3)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--other-tree", default=None)
    a = ap.parse_args(argv)
    trees = {"this": ROOT} | ({"other": Path(a.other_tree).resolve()} if a.other_tree else {})
    for tree in trees.values():  # warm each tree's Numba cache: the job times below are warm-cache ones
        for case in CASES.values():
            one_run(tree, case)
    rows = {(t, c): [] for t in trees for c in CASES}
    for _ in range(a.repeats):
        for c, case in CASES.items():
            for t, tree in trees.items():
                rows[(t, c)].append(one_run(tree, case))
    print(json.dumps({"benchmark": "bench_member_startup", "cores_on_machine": os.cpu_count(), "threads_used": 1,
                      "trees": {t: str(p) for t, p in trees.items()},
                      "cases": {f"{t}:{c}": summary(v) for (t, c), v in rows.items()}}, indent=1))


if __name__ == "__main__":
    main()
