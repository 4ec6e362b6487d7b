"""What a workflow job spends before it computes: each rule script's imports, old code against new in one
run on one machine, and the stand-in workflow of tests/test_calibration_verdict.py's box-limited test end
to end (issue 54: the workflow around the engine).

Each code version is a `git worktree` of its commit; every command runs there with `PYTHONPATH` set to it.
Per script of scripts/ (both versions' own copy): a fresh Python runs the script's top-level import
statements (what the job's process pays before its first line of work; Snakemake's script preamble is
the same for both), `--repeats` times, the versions alternated run by run so that the machine's other
load falls on both alike. The replicate job's parameters (calibration.ensemble_files.simulation_params
with ``{"ensemble_mean": ...}``, which imported the experiment module before) are timed the same way on a
small params.csv. `--workflow N`: the box-limited end-to-end test (two twins, 70 stand-in simulations,
about 100 jobs) run N times per version, alternated, as `pytest -n 0` in the worktree.

    python benchmarks/bench_job_start.py --old REV [--new HEAD] [--repeats 3] [--workflow 2]
        [--out benchmarks/results/bench_job_start.json]
"""
from __future__ import annotations

import argparse
import ast
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.bench_dry_run import _git, _stats, _timed  # noqa: E402

WORKFLOW_TEST = ("tests/test_calibration_verdict.py::"
                 "test_a_box_cutting_the_posterior_ends_box_limited_end_to_end")
REPLICATE = textwrap.dedent("""
    import sys
    from calibration.ensemble_files import simulation_params
    p = simulation_params({"ensemble_mean": "x"}, {}, sys.argv[1], {"x": {
        "parameters": {"sigma_t": [4.0e6, 60.0e6], "E_t": [200.0, 2400.0]}, "ensemble_size": 4, "seed": 1,
        "method": "esmda", "kind": "twin", "posterior": "ensemble"}})
    print(p)
""")


def script_imports(path: Path) -> str:
    """The top-level import statements of a rule script, as one line of code."""
    tree = ast.parse(path.read_text())
    return "; ".join(ast.unparse(n) for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom)))


def _alternated(dirs: dict, repeats: int, args_of) -> dict:
    times = {name: [] for name in dirs}
    for _ in range(repeats):
        for name, d in dirs.items():
            times[name].append(_timed(d, args_of(d)))
    return times


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True)
    ap.add_argument("--new", default="HEAD")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workflow", type=int, default=0, help="end-to-end runs of the stand-in workflow per version")
    ap.add_argument("--out", default=str(REPO / "benchmarks/results/bench_job_start.json"))
    args = ap.parse_args(argv)
    load_before = list(os.getloadavg())
    revs = {"old": _git("rev-parse", args.old), "new": _git("rev-parse", args.new)}
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_job_start_") as tmp:
        dirs = {name: Path(tmp) / name for name in revs}
        for name, rev in revs.items():
            _git("worktree", "add", "--detach", str(dirs[name]), rev)
        params = Path(tmp) / "params.csv"
        params.write_text("member,sigma_t,E_t\n0,2.0e7,500.0\n1,3.0e7,900.0\n2,4.0e7,1500.0\n3,2.5e7,700.0\n")
        try:
            scripts = sorted(p.name for p in (dirs["new"] / "scripts").glob("*.py")
                             if (dirs["old"] / "scripts" / p.name).is_file())
            for d in dirs.values():  # warm-up: the OS file cache, bytecode where it is written
                _timed(d, ("-c", script_imports(d / "scripts" / "analysis.py")))
            imports = {s: _alternated(dirs, args.repeats, lambda d, s=s: ("-c", script_imports(d / "scripts" / s)))
                       for s in scripts}
            replicate = _alternated(dirs, args.repeats, lambda d: ("-c", REPLICATE, str(params)))
            workflow = (_alternated(dirs, args.workflow, lambda d: (
                "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", "-o", "addopts=", WORKFLOW_TEST))
                if args.workflow else None)
        finally:
            for d in dirs.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(d)], cwd=REPO, capture_output=True)
    med = {s: {name: statistics.median(t) for name, t in v.items()} for s, v in imports.items()}
    result = {
        "what": "process wall time of each rule script's top-level imports (python -c), of the replicate "
                "job's parameter read, and of the stand-in box-limited workflow test",
        "commits": revs, "repeats": args.repeats, "cores": os.cpu_count(), "python": platform.python_version(),
        "PYTHONDONTWRITEBYTECODE": os.environ.get("PYTHONDONTWRITEBYTECODE"),
        "load_average_before": load_before, "load_average_after": list(os.getloadavg()),
        "bench_wall_s": round(time.perf_counter() - t_start, 1),
        "script_imports": {s: {name: _stats(t) for name, t in v.items()} for s, v in imports.items()},
        "script_imports_median_s": med,
        "script_imports_sum_of_medians_s": {name: sum(m[name] for m in med.values()) for name in revs},
        "replicate_parameters": {name: _stats(t) for name, t in replicate.items()},
        "workflow_test": None if workflow is None else {"test": WORKFLOW_TEST, **{name: _stats(t) for name, t in
                                                                                  workflow.items()}},
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({"sum_of_medians_s": result["script_imports_sum_of_medians_s"],
                      "replicate_median_s": {n: s["median_s"] for n, s in result["replicate_parameters"].items()},
                      "workflow_median_s": None if workflow is None else
                      {n: statistics.median(t) for n, t in workflow.items()}}, indent=1))
    return result


if __name__ == "__main__":
    main()
