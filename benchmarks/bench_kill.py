"""SIGKILL of Snakemake at random points of a small run, resumed each time (calibration.heal).

    python benchmarks/bench_kill.py [--kills 20] [--seed 1] [--out benchmarks/results/bench_kill.json]

A small twin (the stand-in simulator of tests/test_workflow.py, an analytic pulse through the
simulator's command line that sleeps ``--sleep`` s per run, so that most kills land while simulations
run; N = 6 members, two ES-MDA analyses, target ``iter_1/analysis.json``). First one uninterrupted run
(the reference). Then, in a second folder: start Snakemake, SIGKILL its process alone (not its process
group: its jobs must die by themselves) after a random wait, and check

* no process of the run alive 2 s after the kill (job scripts, simulators),
* no file under ``results/`` written after the kill (mtimes against the kill time, looked at 3 s later,
  once an orphan would have finished its 1 s simulation),
* the temporaries found after a kill are gone once a later run has started (a kill before the next
  start has read the Snakefile leaves them to the one after; none may be left after the final run),

then ``snakemake --unlock`` and the next start resumes. A run that finishes before its kill is compared
with the reference by tools/compare_runs.py (one that fails by itself, not killed, is resumed and
counted apart) (identical but for timings; a manifest may differ in its
``run.json`` entry, which holds the wall time, never in ``curve.csv``'s), and the folder starts afresh.
Writes JSON with the cores, the wall times and every kill's record.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

from shpb.atomic import emit_json  # noqa: E402
from test_workflow import STAND_IN, twin_config, write_config  # noqa: E402
from tools.compare_runs import compare  # noqa: E402

TARGET = "results/twin/iter_1/analysis.json"


def snakemake_argv(workdir: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(workdir),
            "--configfile", str(workdir / "config.yaml"), "--workflow-profile", "none", *args]


def setup(workdir: Path, simulator: str) -> None:
    cfg = twin_config(ensemble_size=6, esmda={"steps": 2})
    cfg["experiments"]["twin"]["observations"]["model_error"] = {"simulator_replicates": 0}
    cfg["simulator"] = simulator
    write_config(workdir, cfg)


def processes_of(marks: list[str]) -> dict[int, str]:
    """Live processes (pid: command line) whose command line names one of ``marks`` (a zombie is dead)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z" and any(m in cmd for m in marks):
            found[int(entry.name)] = cmd[-160:]
    return found


def temporaries(results: Path) -> list[Path]:
    if not results.is_dir():
        return []
    return sorted([p for p in results.rglob(".sim-*") if p.is_dir()] + list(results.rglob(".*.tmp")))


def same_as_reference(ref: Path, run: Path) -> dict:
    rep = compare(ref, run)
    differ = {}
    for rel, detail in rep["differ"].items():
        if Path(rel).name == "manifest.json":
            a, b = (json.loads((root / rel).read_text())["files"] for root in (ref, run))
            if a.get("curve.csv") == b.get("curve.csv") and set(a) == set(b):
                continue  # run.json's hash differs by its wall time only
        differ[rel] = detail
    return {"identical": not differ and not rep["only_before"] and not rep["only_after"], "differ": differ,
            "only_reference": rep["only_before"], "only_resumed": rep["only_after"], "counts": rep["counts"]}


def kill_once(work: Path, marks: list[str], wait_s: float, env: dict) -> dict:
    """One start of Snakemake killed after ``wait_s`` (or finished before it)."""
    t0 = time.time()
    log = work.parent / "snakemake.log"
    with open(log, "w") as fh:
        proc = subprocess.Popen(snakemake_argv(work, "--cores", "2", "--rerun-incomplete", TARGET), env=env,
                                stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        proc.wait(timeout=wait_s)
        return {"wait_s": wait_s, "finished_before_kill": True, "returncode": proc.returncode,
                "run_wall_s": time.time() - t0, "log_tail": log.read_text()[-400:] if proc.returncode else ""}
    except subprocess.TimeoutExpired:
        pass
    os.kill(proc.pid, signal.SIGKILL)  # Snakemake alone: its jobs must die with it by themselves
    t_kill = time.time()
    proc.wait()
    time.sleep(2.0)
    alive = processes_of(marks)
    for pid in alive:  # ours: end them so that the next trial starts clean (and report them)
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    time.sleep(1.0)
    files = [p for p in (work / "results").rglob("*") if p.is_file()] if (work / "results").is_dir() else []
    late = sorted(str(p.relative_to(work)) for p in files if p.stat().st_mtime > t_kill)
    return {"wait_s": wait_s, "finished_before_kill": False, "alive_after_2s": len(alive),
            "alive_commands": sorted(alive.values()),
            "files_written_after_kill": late, "temporaries_after_kill": [str(p.relative_to(work)) for p in temporaries(work / "results")]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sleep", type=float, default=1.0, help="seconds per stand-in simulation")
    ap.add_argument("--max-wait", type=float, default=20.0, help="a kill comes 0.5 s to this after a start")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--keep", type=Path, help="work here (kept) instead of a temporary folder")
    a = ap.parse_args(argv)
    rng = random.Random(a.seed)
    root = Path(a.keep or tempfile.mkdtemp(prefix="bench_kill_"))
    root.mkdir(parents=True, exist_ok=True)
    (root / "stand_in_simulator.py").write_text(STAND_IN)
    simulator = f"{sys.executable} {root / 'stand_in_simulator.py'}"
    env = {**os.environ, "STAND_IN_SLEEP": repr(a.sleep)}
    ref, work = root / "reference", root / "killed"
    setup(ref, simulator)
    t0 = time.time()
    out = subprocess.run(snakemake_argv(ref, "--cores", "2", TARGET), env=env, capture_output=True, text=True)
    ref_wall = time.time() - t0
    if out.returncode:
        raise SystemExit(f"the reference run failed:\n{out.stderr[-3000:]}")
    setup(work, simulator)
    marks = [str(work), str(root / "stand_in_simulator.py")]
    trials, finished, t_all = [], [], time.time()
    pending: set[Path] = set()  # temporaries of earlier kills not yet removed
    while len([t for t in trials if not t["finished_before_kill"]]) < a.kills:
        trial = kill_once(work, marks, rng.uniform(0.5, a.max_wait), env)
        pending = {p for p in pending if p.exists()}
        trial["earlier_temporaries_left"] = len(pending)
        pending |= {work / p for p in trial.get("temporaries_after_kill", [])}
        if trial["finished_before_kill"] and trial["returncode"] != 0:
            # a run that failed by itself (its log tail is kept): the next start resumes it
            if sum(t["finished_before_kill"] and t["returncode"] != 0 for t in trials) >= a.kills:
                raise SystemExit(f"the run keeps failing by itself:\n{trial['log_tail']}")
        elif trial["finished_before_kill"]:
            trial["vs_reference"] = same_as_reference(ref / "results", work / "results")
            trial["temporaries_left_after_the_run"] = sorted(str(p) for p in pending if p.exists())
            finished.append(trial["vs_reference"]["identical"] and not trial["temporaries_left_after_the_run"])
            shutil.rmtree(work / "results")
            shutil.rmtree(work / ".snakemake", ignore_errors=True)
            pending = set()
        if not trial["finished_before_kill"] or trial["returncode"] != 0:
            subprocess.run(snakemake_argv(work, "--unlock"), capture_output=True, env=env)
        trials.append(trial)
        print(json.dumps({k: v for k, v in trial.items() if k != "vs_reference"})[:300], flush=True)
    last = kill_once(work, marks, 1e9, env)  # the last resume, to its end
    last["vs_reference"] = same_as_reference(ref / "results", work / "results")
    last["temporaries_left_after_the_run"] = sorted(str(p) for p in pending if p.exists())
    trials.append(last)
    finished.append(last["vs_reference"]["identical"] and not last["temporaries_left_after_the_run"])
    killed = [t for t in trials if not t["finished_before_kill"]]
    result = {
        "benchmark": "bench_kill", "cores": 2, "cpu_count": os.cpu_count(), "seed": a.seed, "kills": len(killed),
        "stand_in_sleep_s": a.sleep, "target": TARGET, "members": 6, "analyses": 2,
        "reference_wall_s": ref_wall, "total_wall_s": time.time() - t_all,
        "kills_with_live_processes": sum(t["alive_after_2s"] > 0 for t in killed),
        "kills_with_files_written_after": sum(bool(t["files_written_after_kill"]) for t in killed),
        "kills_with_temporaries_left": sum(bool(t["temporaries_after_kill"]) for t in killed),
        "temporaries_left_after_a_completed_run": sum(len(t.get("temporaries_left_after_the_run", []))
                                                      for t in trials),
        "runs_failed_by_themselves": sum(t["finished_before_kill"] and t["returncode"] != 0 for t in trials),
        "completed_runs": len(finished), "completed_runs_identical_to_reference_and_clean": sum(finished),
        "trials": trials,
    }
    if not a.keep:
        shutil.rmtree(root, ignore_errors=True)
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
