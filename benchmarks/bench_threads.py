"""Results do not depend on the caller's thread settings (rules/common.smk pins one BLAS/OpenMP/Numba
thread per job): a config run twice, once with
OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=2 in the environment and once with 1, and every result file
compared (tools/compare_runs.py: CSV and JSON as data without wall-time columns and keys, logs apart,
everything else byte for byte; a run's manifest.json differs where the checksum of a run.json with
another wall time does, and is listed apart when that is its only difference). While each run goes, its job processes are sampled from /proc: the
thread variables they see and their OS thread count (a BLAS with more than one thread starts its
worker threads when numpy loads).

    python benchmarks/bench_threads.py [--config ci|default] [--out ...]

--config ci (default; out benchmarks/results/bench_threads.json): the CI config (.test/config) copied
into two work folders beside this checkout's Snakefile. --config default (out
benchmarks/results/bench_threads_default.json): two fresh clones of the committed HEAD, each run as a
user runs it, `snakemake --cores 2` in the clone (config/config.yaml, the default run). Two runs: about
2 x the config's run time. Not a test: the suite's budget has no room for two workflow runs.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from calibration.job_log import THREAD_VARIABLES as VARIABLES  # noqa: E402 (what rules/common.smk pins)
from tools.compare_runs import compare  # noqa: E402


def _job_processes(workdir: Path) -> list[dict]:
    """The Python processes working in `workdir` (jobs and their simulators), each with its thread
    variables and OS thread count."""
    seen = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if Path(os.readlink(proc / "cwd")) != workdir:
                continue
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
            if b"snakemake" in b" ".join(cmd[:3]) and b"-m" in cmd[:3]:
                continue  # Snakemake itself, not a job
            env = dict(kv.split("=", 1) for kv in (proc / "environ").read_bytes().decode(errors="replace").split("\0")
                       if "=" in kv)
            threads = int(next(ln.split()[1] for ln in (proc / "status").read_text().splitlines()
                               if ln.startswith("Threads:")))
        except (OSError, StopIteration, ValueError):
            continue  # gone meanwhile
        seen.append({"cmd": " ".join(c.decode(errors="replace") for c in cmd if c)[:160],
                     "env": {v: env.get(v) for v in VARIABLES}, "threads": threads})
    return seen


def run(workdir: Path, threads: str, clone: bool = False) -> dict:
    """One run in `workdir` with `threads` in the caller's environment: the CI config beside this
    checkout's Snakefile, or (`clone`) the clone's own default run as a user starts it."""
    env = {**os.environ, "OMP_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": threads,
           "PYTHONPATH": str(workdir if clone else REPO)}
    cmd = ([sys.executable, "-m", "snakemake", "--cores", "2"] if clone else
           [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(workdir),
            "--cores", "2", "--workflow-profile", "none"])
    samples, stop = [], threading.Event()

    def sample():
        while not stop.is_set():
            samples.extend(_job_processes(workdir.resolve()))
            time.sleep(0.5)

    sampler = threading.Thread(target=sample, daemon=True)
    t0 = time.time()
    sampler.start()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3 * 3600, cwd=workdir)
    stop.set()
    sampler.join()
    if out.returncode != 0:
        raise SystemExit(f"the run with {threads} thread(s) failed:\n{out.stderr[-4000:]}")
    envs = {json.dumps(s["env"], sort_keys=True) for s in samples}
    return {"caller_threads": threads, "wall_s": round(time.time() - t0, 1), "job_processes_sampled": len(samples),
            "max_os_threads_of_a_job": max((s["threads"] for s in samples), default=None),
            "thread_variables_seen_by_jobs": [json.loads(e) for e in sorted(envs)]}


def timing_derived(rep: dict, before: Path, after: Path) -> dict:
    """The differing manifest.json files (calibration's per-run checksums of curve.csv and run.json)
    whose only differences are the entries of files identical but for their wall times: a run.json
    with another wall_s has another checksum. {path: why}; the rest stay in rep["differ"]."""
    same_but_timings = set(rep["identical_but_timings"])
    out = {}
    for rel in [r for r in rep["differ"] if Path(r).name == "manifest.json"]:
        a, b = (json.loads((root / rel).read_text()).get("files", {}) for root in (before, after))
        differing = sorted(n for n in set(a) | set(b) if a.get(n) != b.get(n))
        if differing and all(str(Path(rel).parent / n) in same_but_timings for n in differing):
            out[rel] = f"checksums of {', '.join(differing)} (identical but for timings)"
    for rel in out:
        del rep["differ"][rel]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", choices=("ci", "default"), default="ci")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    out_name = "bench_threads.json" if a.config == "ci" else "bench_threads_default.json"
    a.out = a.out or REPO / "benchmarks" / "results" / out_name
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                            check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {}
        for threads in ("2", "1"):
            d = Path(tmp) / f"threads_{threads}"
            if a.config == "ci":
                shutil.copytree(REPO / ".test" / "config", d / "config")
            else:
                # both runs on the commit read at the start, whatever is committed meanwhile
                subprocess.run(["git", "clone", "--quiet", str(REPO), str(d)], check=True)
                subprocess.run(["git", "checkout", "--quiet", commit], cwd=d, check=True)
            dirs[threads] = (d, run(d, threads, clone=a.config == "default"))
        rep = compare(dirs["2"][0] / "results", dirs["1"][0] / "results")
        derived = timing_derived(rep, dirs["2"][0] / "results", dirs["1"][0] / "results")
    rep["counts"]["differ"] = len(rep["differ"])
    rep["counts"]["manifests_differing_by_timings_only"] = len(derived)
    result = {"config": a.config, "commit": commit, "cores": os.cpu_count(),
              "load_average_after": list(os.getloadavg()), "runs": [r for _, r in dirs.values()], "counts": rep["counts"], "differ": rep["differ"],
              "manifests_differing_by_timings_only": derived,
              "one_sided_keys": rep["one_sided_keys"], "only_with_2_threads": rep["only_before"],
              "only_with_1_thread": rep["only_after"], "identical_but_timings": rep["identical_but_timings"]}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({"counts": rep["counts"], "runs": result["runs"]}, indent=1))
    return 0 if not (rep["differ"] or rep["only_before"] or rep["only_after"]) else 1


if __name__ == "__main__":
    sys.exit(main())
