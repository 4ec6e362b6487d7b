"""The default run, old and new code, from fresh clones in one sitting: wall time and whether the result
files are the same (issue 54: the default run's time; the same answers where the arithmetic is unchanged).

    python benchmarks/bench_default_run.py [--old REV] [--new REV] [--out benchmarks/results/bench_default_run.json]
        [--keep-results DIR]

Each commit is cloned into an empty temporary folder and runs ``snakemake --cores 2`` there as a user
starts it (the clone's packages first on the path, its own Numba cache compiled by the run, as in a
fresh clone); old first, then new, on an otherwise idle machine. ``tools/compare_runs.py`` then compares
every file under the two ``results/`` folders (identical, identical but for wall times, differing), and
the differing files are listed. Writes JSON with the cores, the load average, both walls and job counts.
"""
from __future__ import annotations

import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO)]

from benchmarks.bench_batch import clone_at, old_and_new  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402


def default_run(clone: Path, log_to: Path | None = None) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2"], cwd=clone, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(clone)})
    wall = time.perf_counter() - t0
    log = proc.stdout + proc.stderr
    if log_to is not None:  # the console log, for benchmarks/default_run_costs.py's job times
        log_to.write_text(log)
    done = re.findall(r"Finished jobid: \d+ \(Rule: (\w+)\)", log)
    return {"wall_s": round(wall, 1), "exit_code": proc.returncode, "jobs": len(done),
            "jobs_per_rule": {r: done.count(r) for r in sorted(set(done))},
            "fdem_runs": len(list((clone / "results").rglob("run.json"))),
            "log_tail": log[-1500:] if proc.returncode else ""}


def main(argv=None) -> dict:
    a, new = old_and_new(argv, "bench_default_run.json", keep_results=None)
    load0, t0 = list(os.getloadavg()), time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        old_clone, new_clone = clone_at(a.old, tmp / "old"), clone_at(new, tmp / "new")
        keep = Path(a.keep_results) if a.keep_results else None
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
        runs = {"old": default_run(old_clone),
                "new": default_run(new_clone, None if keep is None else keep / "snakemake.log")}
        if keep is not None:  # the new run's results/ and log, for benchmarks/results/default_run (its README)
            shutil.copytree(new_clone / "results", keep / "results", dirs_exist_ok=True)
        cmp = subprocess.run([sys.executable, str(REPO / "tools" / "compare_runs.py"), str(old_clone / "results"),
                              str(new_clone / "results"), "--out", str(tmp / "compare.json")],
                             capture_output=True, text=True)
        compare = json.loads((tmp / "compare.json").read_text()) if (tmp / "compare.json").is_file() else {
            "error": cmp.stderr[-2000:]}
    result = {"benchmark": "bench_default_run", "cores": os.cpu_count(), "python": platform.python_version(),
              "old": a.old, "new": new, "command": "snakemake --cores 2 (fresh clone)",
              "load_average_before": load0, "load_average_after": list(os.getloadavg()),
              "bench_wall_s": round(time.perf_counter() - t0, 1), "runs": runs,
              "wall_ratio_old_over_new": round(runs["old"]["wall_s"] / runs["new"]["wall_s"], 2),
              "compare": compare}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
