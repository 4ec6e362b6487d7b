#!/usr/bin/env python3
"""The workflow on a (test) Slurm cluster versus the same workflow run locally.

Runs inside a cluster that ``tools/slurm/slurm_local_cluster.sh`` started (``SLURM_CONF`` must point at its
``slurm.conf``); ``tools/slurm/slurm_local_cluster.sh run-compare`` does both in one command and tears the
cluster down afterwards. Scenarios (all by default):

``compare``
    The same config and seed once with ``profiles/default`` and once with ``profiles/slurm``, each in
    its own working directory; every ``results/*/iter_*/params.csv``, ``posterior.csv`` and every
    number in ``summary.json`` (wall times excepted) must be identical.
``fail``
    Two faults through the workflow's ``simulator`` config hook (a wrapper around the simulator), the
    same in a local and a Slurm run. Member 1 of iteration 0 crashes (exit 1) on every attempt: the
    rule's ``retries`` re-run it (inside the same Slurm job: the rule-level ``retries`` also apply in
    the job's own Snakemake), the last attempt records it as failed, the analysis drops it. Member 2 of
    iteration 0 hangs on every attempt: the simulator is stopped at ``member_time_limit_s`` (set to
    40 s here), before the job's Slurm time limit (the limit plus 5 minutes), and the member is
    dropped with the reason ``time limit``; no Slurm job may end in TIMEOUT, member 2 is submitted
    once, and the run goes on. The results must equal the local run's.
``resume``
    The head process is SIGKILLed while member jobs are queued and running; the old run's jobs are
    cancelled (``scancel --name <run id>``), the directory unlocked, the workflow re-run: members that
    had finished are not run again (their files are untouched) and the results equal the local run's.

Prints one JSON report on stdout (wall times in seconds) and exits non-zero if any check fails.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[2]
#: The comparison's experiment: the paper's twin (Brazilian disc, sigma_t and E_t) on the `fast` mesh,
#: small enough for a test (6 members, 2 ES-MDA steps: 18 member simulations + truth + forecast), on the
#: shipped reported posterior with 4 refinement runs instead of 25.
FAST_TWIN = {
    "run": ["slurm_twin"],
    "experiments": {
        "slurm_twin": {
            "description": "Cluster test: the paper's twin on the fast mesh, 6 members, 2 ES-MDA steps.",
            "kind": "twin",
            "geometry": "brazilian_disc",
            "preset": "fast",
            "seed": 7,
            "ensemble_size": 6,
            "method": "esmda",
            "esmda": {"steps": 2},
            "emulated": {"refine_runs": 4},
            "parameters": {"sigma_t": [4.0e6, 6.0e7], "E_t": [200.0, 2400.0]},
            "simulation": {"t_end": 1.5e-4, "sample_dt": 5.0e-7},
            "observations": {"t_start": 0.0, "t_end": 1.5e-4, "dt": 1.0e-6,
                             "truth": {"sigma_t": 4.5e7, "E_t": 500.0}, "preset": "fast",
                             "noise": {"relative_sigma": 0.01}},
        }
    },
}
#: Keys of summary.json (at any depth) that measure time, not results.
TIMING_KEY = re.compile(r"wall|elapsed|duration|timestamp|date|updates_per_s", re.I)
#: What the working directory of a run needs from the repository (read relative to the cwd).
LINKED = ("config", "data")


def log(msg: str) -> None:
    print(f"[slurm-compare {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


class CheckFailed(AssertionError):
    pass


# --------------------------------------------------------------------------------------------------
# Running the workflow
# --------------------------------------------------------------------------------------------------
def prepare(workdir: Path) -> Path:
    workdir.mkdir(parents=True, exist_ok=True)
    for name in LINKED:
        link = workdir / name
        if (REPO / name).exists() and not link.exists():
            link.symlink_to(REPO / name)
    return workdir


def snakemake_argv(profile: str, configfile: Path, extra=()) -> list[str]:
    return [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"),
            "--profile", str(REPO / "profiles" / profile), "--configfile", str(configfile), *extra]


def start(workdir: Path, argv: list[str], logname: str) -> tuple[subprocess.Popen, Path]:
    logfile = workdir / logname
    fh = open(logfile, "w")
    log(f"{workdir.name}: {' '.join(argv[2:])} (log {logfile})")
    # Own session: a kill of the head takes its local jobs with it, as a closed login shell would.
    proc = subprocess.Popen(argv, cwd=workdir, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
    fh.close()
    return proc, logfile


def run(workdir: Path, argv: list[str], logname: str, timeout: float) -> dict:
    t0 = time.perf_counter()
    proc, logfile = start(workdir, argv, logname)
    try:
        rc = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait()
        raise CheckFailed(f"{workdir}: snakemake did not finish in {timeout:.0f} s (log {logfile})")
    wall = time.perf_counter() - t0
    if rc != 0:
        tail = "".join(logfile.read_text().splitlines(keepends=True)[-40:])
        raise CheckFailed(f"{workdir}: snakemake exited {rc} after {wall:.0f} s; log tail:\n{tail}")
    log(f"{workdir.name}: finished in {wall:.1f} s")
    return {"wall_s": round(wall, 1), "log": str(logfile)}


def member_folder(member: int) -> str:
    """The member's folder name in results/<exp>/iter_<k>/members/ (calibration.workflow_io.member_ids)."""
    return f"{member:03d}"


def fault_wrapper(workdir: Path, crash: int | None = None, hang: int | None = None, iteration: int = 0) -> str:
    """A `simulator` command for fault injection: crash (exit 1) for member `crash` of `iteration` and
    hang (sleep 15 min) for member `hang` of `iteration`, both on every attempt; else simulate."""
    script = workdir / "faulty_simulator.sh"
    lines = ["#!/bin/sh", "# Fault injection for the failed-member checks (tools/slurm/slurm_compare.py)."]
    if crash is not None:
        lines.append(f'case "$*" in *"/iter_{iteration}/members/{member_folder(crash)}/"*) '
                     'echo "injected crash" >&2; exit 1;; esac')
    if hang is not None:
        lines.append(f'case "$*" in *"/iter_{iteration}/members/{member_folder(hang)}/"*) '
                     'echo "injected hang" >&2; exec sleep 900;; esac')
    lines.append(f'exec {sys.executable} -m shpb simulate "$@"')
    script.write_text("\n".join(lines) + "\n")
    script.chmod(0o755)
    return f"sh {script}"


# --------------------------------------------------------------------------------------------------
# Comparing results
# --------------------------------------------------------------------------------------------------
def _frames(root: Path, pattern: str) -> dict[str, pd.DataFrame]:
    return {str(p.relative_to(root)): pd.read_csv(p) for p in sorted(root.glob(pattern))}


def compare_tables(a: Path, b: Path, pattern: str) -> int:
    fa, fb = _frames(a, pattern), _frames(b, pattern)
    if not fa:
        raise CheckFailed(f"no {pattern} under {a}")
    if set(fa) != set(fb):
        raise CheckFailed(f"{pattern}: different files: {sorted(set(fa) ^ set(fb))}")
    for name in fa:
        x, y = fa[name], fb[name]
        if list(x.columns) != list(y.columns) or x.shape != y.shape:
            raise CheckFailed(f"{name}: columns/shape differ: {list(x.columns)} {x.shape} vs {list(y.columns)} {y.shape}")
        for col in x.columns:
            if TIMING_KEY.search(str(col)):  # e.g. responses.csv's wall_s of each member
                continue
            u, v = x[col].to_numpy(), y[col].to_numpy()
            if u.dtype.kind in "fiu" and v.dtype.kind in "fiu":
                if not np.array_equal(u.astype(float), v.astype(float), equal_nan=True):
                    d = np.nanmax(np.abs(u.astype(float) - v.astype(float)))
                    raise CheckFailed(f"{name}: column {col} differs (max |diff| {d:.3g})")
            elif x[col].fillna("<missing>").astype(str).tolist() != y[col].fillna("<missing>").astype(str).tolist():
                raise CheckFailed(f"{name}: column {col} differs")
    return len(fa)


def numbers_equal(x, y, path="") -> list[str]:
    """Differences between two JSON documents, timing keys skipped."""
    if isinstance(x, dict) and isinstance(y, dict):
        out = []
        for k in sorted(set(x) | set(y)):
            if TIMING_KEY.search(str(k)):
                continue
            if k not in x or k not in y:
                out.append(f"{path}/{k}: only in one")
            else:
                out += numbers_equal(x[k], y[k], f"{path}/{k}")
        return out
    if isinstance(x, list) and isinstance(y, list):
        if len(x) != len(y):
            return [f"{path}: lengths {len(x)} vs {len(y)}"]
        return [d for i, (u, v) in enumerate(zip(x, y)) for d in numbers_equal(u, v, f"{path}[{i}]")]
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return []
    return [] if x == y else [f"{path}: {x!r} vs {y!r}"]


def compare_results(a: Path, b: Path) -> dict:
    n_params = compare_tables(a, b, "results/*/iter_*/params.csv")
    n_resp = compare_tables(a, b, "results/*/iter_*/responses.csv")  # the simulated curves
    n_post = compare_tables(a, b, "results/*/posterior.csv")
    sa, sb = sorted(a.glob("results/*/summary.json")), sorted(b.glob("results/*/summary.json"))
    if not sa or [p.relative_to(a) for p in sa] != [p.relative_to(b) for p in sb]:
        raise CheckFailed(f"summary.json files differ: {sa} vs {sb}")
    summaries = {}
    for pa, pb in zip(sa, sb):
        ja, jb = json.loads(pa.read_text()), json.loads(pb.read_text())
        diffs = numbers_equal(ja, jb)
        if diffs:
            raise CheckFailed(f"{pa.relative_to(a)} differs: " + "; ".join(diffs[:10]))
        summaries[pa.parent.name] = {k: ja.get(k) for k in ("iterations", "converged", "stop_reason", "n_simulations")}
    return {"params_files": n_params, "responses_files": n_resp, "posterior_files": n_post, "summaries": summaries, "identical": True}


def member_runs(root: Path) -> dict[str, dict]:
    return {str(p.relative_to(root)): json.loads(p.read_text())
            for p in sorted(root.glob("results/*/iter_*/members/*/*/run.json"))}


# --------------------------------------------------------------------------------------------------
# Slurm helpers
# --------------------------------------------------------------------------------------------------
def run_id(logfile: Path) -> str | None:
    m = re.search(r"SLURM run ID: (\S+)", logfile.read_text())
    return m.group(1) if m else None


def squeue(name: str, states: str = "PENDING,RUNNING,COMPLETING,CONFIGURING") -> list[str]:
    out = subprocess.run(["squeue", "-h", "--name", name, "-t", states, "-o", "%i %T"],
                         capture_output=True, text=True, check=True).stdout
    return out.split("\n")[:-1] if out else []


def jobs_in_log(logfile: Path, rule: str) -> list[dict]:
    """Jobs of `rule` the head process started, with their wildcards (from its log)."""
    jobs, current = [], None
    for line in logfile.read_text().splitlines():
        s = line.strip()
        if re.fullmatch(rf"(local)?rule {re.escape(rule)}:", s):
            current = {}
            jobs.append(current)
        elif current is not None and s.startswith("wildcards:"):
            current.update(dict(kv.split("=", 1) for kv in s[len("wildcards:"):].strip().split(", ")))
            current = None
    return jobs


def failed_slurm_jobs(logfile: Path) -> list[str]:
    return re.findall(r"SLURM-job '(\d+)' failed, SLURM status is: '(\w+)'", logfile.read_text())


# --------------------------------------------------------------------------------------------------
# Scenarios
# --------------------------------------------------------------------------------------------------
def scenario_compare(out: Path, cfg: Path, timeout: float) -> dict:
    local = run(prepare(out / "local"), snakemake_argv("default", cfg, ["--cores", "2"]), "snakemake.log", timeout)
    slurm = run(prepare(out / "slurm"), snakemake_argv("slurm", cfg), "snakemake.log", timeout)
    res = compare_results(out / "local", out / "slurm")
    # the member simulations' batch jobs (rule simulate, stage member)
    n_jobs = len([w for w in jobs_in_log(Path(slurm["log"]), "simulate") if w.get("stage") == "member"])
    return {"local_wall_s": local["wall_s"], "slurm_wall_s": slurm["wall_s"], "slurm_member_batches": n_jobs, **res}


FAIL_TIME_LIMIT_S = 40  # the fail scenario's member_time_limit_s (fast members take a few seconds)


def fault_config(cfg: Path, workdir: Path, crash: int, hang: int) -> Path:
    """The run's config plus the fault-injecting simulator and a short member time limit."""
    conf = yaml.safe_load(cfg.read_text())
    conf["simulator"] = fault_wrapper(workdir, crash=crash, hang=hang)
    conf["member_time_limit_s"] = {"fast": FAIL_TIME_LIMIT_S}
    # one member per batch and per Slurm job, as the checks below count them (batch k = member k of the
    # twin's one record): in a batch or group job a crash re-runs the job, whose finished runs are kept
    # (calibration.batch), tested by tests/test_batch.py and tests/test_slurm_grouping.py
    conf["simulations_per_job"] = {"fast": 1}
    conf["simulations_per_cluster_job"] = {"fast": 1}
    path = workdir / "fault_config.yaml"
    path.write_text(json.dumps(conf, indent=2) + "\n")  # JSON is YAML (and keeps 4e6 a number)
    return path


def scenario_fail(out: Path, cfg: Path, timeout: float, crash: int = 1, hang: int = 2) -> dict:
    loc, slu = prepare(out / "fail-local"), prepare(out / "fail-slurm")
    r_loc = run(loc, snakemake_argv("default", fault_config(cfg, loc, crash, hang), ["--cores", "2"]),
                "snakemake.log", timeout)
    r_slu = run(slu, snakemake_argv("slurm", fault_config(cfg, slu, crash, hang)), "snakemake.log", timeout)
    slurm_log = Path(r_slu["log"])
    failed = failed_slurm_jobs(slurm_log)
    if any(state == "TIMEOUT" for _, state in failed):
        raise CheckFailed(f"a Slurm job ended in TIMEOUT although the simulator stops itself first: {failed}")
    submissions = {m: [j for j in jobs_in_log(slurm_log, "simulate")
                       if j.get("stage") == "member" and j.get("key") == "iter_0" and j.get("batch") == str(m)]
                   for m in (crash, hang)}
    if len(submissions[hang]) != 1:
        raise CheckFailed(f"the hanging member {hang} was submitted {len(submissions[hang])} times, not once")
    runs = member_runs(slu)
    crashed = {k: v for k, v in runs.items() if f"/iter_0/members/{member_folder(crash)}/" in k}
    hung = {k: v for k, v in runs.items() if f"/iter_0/members/{member_folder(hang)}/" in k}
    if not crashed or any(r.get("status") != "failed" for r in crashed.values()):
        raise CheckFailed(f"member {crash} of iteration 0 not recorded as failed: {crashed}")
    if not hung or any(r.get("status") != "failed" or not str(r.get("reason", "")).startswith("time limit")
                       for r in hung.values()):
        raise CheckFailed(f"member {hang} of iteration 0 not recorded as failed for its time limit: {hung}")
    analyses = [json.loads(p.read_text()) for p in sorted(slu.glob("results/*/iter_0/analysis.json"))]
    dropped = sorted(f["member"] for d in analyses for f in d.get("failed_members", []))
    if dropped != sorted([crash, hang]):
        raise CheckFailed(f"iteration 0 dropped members {dropped}, expected {sorted([crash, hang])}")
    res = compare_results(loc, slu)
    return {"local_wall_s": r_loc["wall_s"], "slurm_wall_s": r_slu["wall_s"],
            "slurm_failed_jobs": [f"{j} {s}" for j, s in failed],
            "crashed_member": crash, "crashed_member_slurm_jobs": len(submissions[crash]),
            "crashed_member_record": {k: f"{v.get('status')} (attempt {v.get('attempt')}): {v.get('reason', '')[:120]}"
                                      for k, v in crashed.items()},
            "hung_member": hang, "hung_member_slurm_jobs": len(submissions[hang]),
            "hung_member_record": {k: f"{v.get('status')}: {v.get('reason', '')[:120]}" for k, v in hung.items()},
            "iteration0_dropped": dropped, "iteration0_alive": [d.get("n_alive") for d in analyses], **res}


def scenario_resume(out: Path, cfg: Path, timeout: float, reference: Path) -> dict:
    wd = prepare(out / "resume")
    argv = snakemake_argv("slurm", cfg)
    t0 = time.perf_counter()
    proc, log1 = start(wd, argv, "snakemake-killed.log")
    # Kill the head once some members have finished and others are still queued or running.
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            raise CheckFailed(f"the run ended (exit {proc.returncode}) before it could be interrupted; log {log1}")
        rid = run_id(log1)
        done = [p for p in wd.glob("results/*/iter_0/members/*/*/run.json")]
        # (3: a member whose job is cancelled between writing its files and finishing loses them)
        if rid and len(done) >= 3 and squeue(rid):
            break
        if time.monotonic() > deadline:
            raise CheckFailed("no member finished in time")
        time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    killed_after = time.perf_counter() - t0
    left = squeue(rid)
    log(f"head SIGKILLed after {killed_after:.0f} s; {len(left)} job(s) of run {rid} still on the cluster")
    subprocess.run(["scancel", "--name", rid], check=True)
    for _ in range(300):
        if not squeue(rid):
            break
        time.sleep(0.2)
    else:
        raise CheckFailed(f"jobs of run {rid} still there 60 s after scancel")
    finished = {str(p.relative_to(wd)): p.stat().st_mtime_ns for p in wd.glob("results/*/iter_*/members/*/*/run.json")}
    subprocess.run(snakemake_argv("slurm", cfg, ["--unlock"]), cwd=wd, check=True, capture_output=True)
    second = run(wd, argv, "snakemake-resumed.log", timeout)
    rerun = jobs_in_log(Path(second["log"]), "member")
    again = [j for j in rerun if f"results/{j.get('exp')}/iter_{j.get('it')}/members/{j.get('member')}/{j.get('record')}/run.json" in finished]
    touched = [f for f, t in finished.items() if (wd / f).stat().st_mtime_ns != t]
    if again or touched:
        raise CheckFailed(f"finished members ran again after the restart: jobs {again}, rewritten {touched}")
    res = compare_results(reference, wd)
    return {"killed_after_s": round(killed_after, 1), "jobs_cancelled": len(left),
            "members_finished_before_kill": len(finished), "member_jobs_after_restart": len(rerun),
            "resumed_wall_s": second["wall_s"], **res}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configfile", type=Path,
                    help="workflow config for every run (default: FAST_TWIN above, written to the workdir)")
    ap.add_argument("--out", type=Path, help="working directory (default: a temporary one, removed on success)")
    ap.add_argument("--scenarios", default="compare,fail,resume")
    ap.add_argument("--timeout", type=float, default=1800, help="per snakemake run [s]")
    args = ap.parse_args(argv)
    if not os.environ.get("SLURM_CONF"):
        ap.error("SLURM_CONF is not set: run inside `tools/slurm/slurm_local_cluster.sh with-cluster -- ...`")
    out = (args.out or Path(tempfile.mkdtemp(prefix="slurm-compare-"))).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if args.configfile:
        cfg = args.configfile.resolve()
    else:
        cfg = out / "slurm_fast_twin.yaml"
        cfg.write_text(json.dumps(FAST_TWIN, indent=2) + "\n")  # JSON is YAML (and keeps 4e6 a number)
    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    report = {"configfile": str(cfg), "workdir": str(out)}
    t0 = time.perf_counter()
    ok = True
    try:
        for s in scenarios:
            t1 = time.perf_counter()
            if s == "compare":
                report[s] = scenario_compare(out, cfg, args.timeout)
            elif s == "fail":
                report[s] = scenario_fail(out, cfg, args.timeout)
            elif s == "resume":
                if not (out / "local" / "results").is_dir():
                    run(prepare(out / "local"), snakemake_argv("default", cfg, ["--cores", "2"]), "snakemake.log",
                        args.timeout)
                report[s] = scenario_resume(out, cfg, args.timeout, out / "local")
            else:
                raise SystemExit(f"unknown scenario {s!r}")
            report[s]["scenario_wall_s"] = round(time.perf_counter() - t1, 1)
    except CheckFailed as exc:
        ok = False
        report["error"] = str(exc)
        log(f"FAILED: {exc}")
    report["total_wall_s"] = round(time.perf_counter() - t0, 1)
    report["ok"] = ok
    print(json.dumps(report, indent=2))
    if ok and args.out is None:
        shutil.rmtree(out, ignore_errors=True)
    elif not ok:
        log(f"kept {out} for inspection")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
