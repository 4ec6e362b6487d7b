"""How long `snakemake -n` of the default config takes (issue 54: <= 2 s warm), old code against new in
one run on one machine.

Each code version is a `git worktree` of its commit (nothing of the working checkout is touched),
with its own `.snakemake/`; every command runs in the worktree with `PYTHONPATH` set to it, so the
Snakefile imports that version's packages. Per version: one cold dry run (its first: for the new code the
record check reduces every record and stores its summary), one warm-up, then `--repeats` warm runs,
the two versions alternated run by run so that the machine's other load falls on both alike. Also
timed the same way: Snakemake's own floor, the dry run of a one-rule Snakefile (its imports, plugin
registry and DAG machinery, which no workflow can go below); the import of the modules the Snakefile
and rules/*.smk import at parse time, in the new code; and per version, from one more warm dry run under
``python -X importtime``, the modules of SciPy, Numba, matplotlib, enkf and fdem it imports (none is
needed before a job runs: tests/test_dry_run_imports.py).

    python benchmarks/bench_dry_run.py [--old REV] [--new REV] [--repeats 5]
        [--out benchmarks/results/bench_dry_run.json]

--old defaults to the parent of the commit that added calibration/record_check.py (the record
check's cache), --new to HEAD. About 2 x (repeats + 2) dry runs of 2-10 s.
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
DRY_RUN = ["-m", "snakemake", "-n", "--cores", "2", "--quiet"]


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=REPO, check=True, capture_output=True, text=True).stdout.strip()


def _default_old() -> str:
    added = _git("log", "--diff-filter=A", "--format=%H", "--", "calibration/record_check.py").splitlines()
    if not added:
        raise SystemExit("no commit adds calibration/record_check.py: give --old")
    return _git("rev-parse", f"{added[-1]}^")


def _timed(workdir: Path, args=DRY_RUN) -> float:
    """Wall time of ``python <args>`` in ``workdir`` with that version's packages first on the path."""
    env = {**os.environ, "PYTHONPATH": str(workdir)}
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, *args], cwd=workdir, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{args} in {workdir} failed:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    return wall


def _import_time(workdir: Path, module: str) -> float:
    """Wall time of importing ``module`` in a fresh Python that has already imported what Snakemake's
    own start imports (pandas, snakemake.api): its share of a dry run's parse time."""
    code = (f"import time, pandas, snakemake.api; t = time.perf_counter(); import {module}; "
            "print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], cwd=workdir, env={**os.environ, "PYTHONPATH": str(workdir)},
                         capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


HEAVY = ("scipy", "numba", "matplotlib", "enkf", "fdem")
#: What the Snakefile and rules/*.smk import at parse time (tests/test_dry_run_imports.py's PARSE_MODULES).
PARSE_MODULES = ("calibration.config_files", "calibration.observations", "calibration.workflow_io",
                 "calibration.heal", "calibration.approximation", "calibration.model_error",
                 "calibration.diagnosis_config", "calibration.sensitivity")


def _heavy_imports(workdir: Path) -> list[str]:
    """The modules of :data:`HEAVY` a warm dry run in ``workdir`` imports (``python -X importtime``)."""
    env = {**os.environ, "PYTHONPATH": str(workdir)}
    out = subprocess.run([sys.executable, "-X", "importtime", *DRY_RUN], cwd=workdir, env=env, capture_output=True,
                         text=True, check=True)
    names = {line.rsplit("|", 1)[1].strip() for line in out.stderr.splitlines()
             if line.startswith("import time:") and "|" in line}
    return sorted(n for n in names if n.split(".")[0] in HEAVY)


def _stats(times: list[float]) -> dict:
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times), "runs_s": times}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default=None)
    ap.add_argument("--new", default="HEAD")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(REPO / "benchmarks/results/bench_dry_run.json"))
    args = ap.parse_args(argv)
    load_before = list(os.getloadavg())
    revs = {"old": _git("rev-parse", args.old or _default_old()), "new": _git("rev-parse", args.new)}
    with tempfile.TemporaryDirectory(prefix="bench_dry_run_") as tmp:
        dirs = {}
        for name, rev in revs.items():
            dirs[name] = Path(tmp) / name
            _git("worktree", "add", "--detach", str(dirs[name]), rev)
        floor = Path(tmp) / "floor"
        floor.mkdir()
        (floor / "Snakefile").write_text('rule all:\n    output: "x"\n    shell: "touch x"\n')
        dirs["snakemake_floor"] = floor
        try:
            cold = {name: _timed(d) for name, d in dirs.items()}
            for d in dirs.values():
                _timed(d)  # warm-up: the OS file cache, Python's bytecode caches
            warm = {name: [] for name in dirs}
            for _ in range(args.repeats):
                for name, d in dirs.items():
                    warm[name].append(_timed(d))
            # all the parse's modules in one import statement, and enkf for scale (what they no longer import)
            imports = {key: statistics.median(_import_time(dirs["new"], m) for _ in range(args.repeats))
                       for key, m in (("parse_modules", ", ".join(PARSE_MODULES)), ("enkf", "enkf"))}
            heavy = {name: _heavy_imports(dirs[name]) for name in revs}
        finally:
            for name in revs:
                subprocess.run(["git", "worktree", "remove", "--force", str(dirs[name])], cwd=REPO,
                               capture_output=True)
    result = {
        "what": "wall time of `python -m snakemake -n --cores 2 --quiet` of config/config.yaml (default run)",
        "commits": revs, "repeats": args.repeats, "cores": os.cpu_count(),
        "load_average_before": load_before, "load_average_after": list(os.getloadavg()),
        "python": platform.python_version(),
        "PYTHONDONTWRITEBYTECODE": os.environ.get("PYTHONDONTWRITEBYTECODE"),
        "cold_s": cold, "warm": {name: _stats(t) for name, t in warm.items()},
        "new_import_median_s": imports, "parse_modules": list(PARSE_MODULES),
        "heavy_modules_imported": {name: {"count": len(h), "top_level": sorted({n.split(".")[0] for n in h})}
                                   for name, h in heavy.items()},
    }
    w = result["warm"]
    result["speedup_warm_old_over_new"] = w["old"]["median_s"] / w["new"]["median_s"]
    result["new_above_snakemake_floor_s"] = w["new"]["median_s"] - w["snakemake_floor"]["median_s"]
    result["old_above_snakemake_floor_s"] = w["old"]["median_s"] - w["snakemake_floor"]["median_s"]
    result["goal_s"] = 2.0
    result["goal_met"] = w["new"]["median_s"] <= 2.0
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: result[k] for k in ("cold_s", "speedup_warm_old_over_new", "goal_met")}, indent=1))
    print({name: round(s["median_s"], 3) for name, s in w.items()})
    return result


if __name__ == "__main__":
    main()
