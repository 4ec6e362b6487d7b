"""The five-record leave-one-record-out series (``config/validation.yaml``), old and new code, from fresh
clones: wall time, what each stage costs, the FDEM runs made and copied, and the series' answers
(issue 54: the series' time and item 5; issue 52: the held-out predictive bands' coverage).

    python benchmarks/bench_loro.py [--old REV] [--new REV] [--out benchmarks/results/bench_loro.json]
    python benchmarks/bench_loro.py --from OLD_CLONE OLD_LOG OLD_WALL_S NEW_CLONE NEW_LOG NEW_WALL_S [--out ...]
    python benchmarks/bench_loro.py --add NAME CLONE LOG WALL_S [--out ...]

The first form clones each commit into an empty temporary folder and runs ``snakemake --cores 2
--configfile config/validation.yaml`` there (the clone's packages first on the path, its own Numba cache
compiled by the run), old then new. The second assembles the same JSON from two such runs made by hand
(a clone, its console log, its wall time). The third adds one such run under ``runs[NAME]`` to the JSON
already at ``--out``, keeping its other runs (each run's own ``commit`` and the note say when and how
each was made; only runs of one sitting are compared in ``wall_ratio_old_over_new``). Per run: :func:`tools.job_times.job_times` on the console log
(the simulating rule split by stage, the job time per fold), the FDEM runs per stage with the solver
seconds of those simulated in this run (a copied run's run.json carries its source's time, so it is
counted apart), and the series' ``loro/summary.json`` totals with each fold's held-out band coverage.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO)]

from benchmarks.bench_batch import clone_at  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from tools.job_times import job_times  # noqa: E402

SERIES = "sandstone_unseen"
COMMAND = ["snakemake", "--cores", "2", "--configfile", "config/validation.yaml"]
_COPIED = re.compile(r"^(\S+): copied from ")


def run_stage(run_json: Path, results: Path) -> str:
    """``member iter_0``, ``replicate iter_2``, ``design``, ``check``, ``refit``, ``forecast`` of a run's folder."""
    parts = run_json.relative_to(results).parts
    if parts[1].startswith("iter_"):
        return f"{parts[2].rstrip('s')} {parts[1]}"
    if parts[1] == "diagnosis":
        return parts[2] if parts[2] in ("design", "refit") else "check"
    return parts[1]


def fdem_runs(clone: Path) -> dict:
    """Per stage: runs, runs copied from another fold's (the batch logs' ``copied from`` lines) and the
    solver seconds of the runs simulated here."""
    results = clone / "results"
    copied = set()
    for log in results.glob("*/simulate/*/*/batch_*.log"):
        for line in log.read_text().splitlines():
            if m := _COPIED.match(line):
                copied.add(str((clone / m.group(1)).resolve()))  # the log names folders from the clone
    out: dict[str, dict] = defaultdict(lambda: {"runs": 0, "copied": 0, "solver_s": 0.0})
    for run_json in results.glob("*/**/run.json"):
        if run_json.relative_to(results).parts[0].startswith("."):
            continue
        row = out[run_stage(run_json, results)]
        row["runs"] += 1
        if str(run_json.parent.resolve()) in copied:
            row["copied"] += 1
        else:
            row["solver_s"] += float(json.loads(run_json.read_text()).get("solver_wall_s") or 0.0)
    return {k: {**v, "solver_s": round(v["solver_s"], 1)} for k, v in sorted(out.items())}


def emulator_against_noise(clone: Path) -> dict:
    """Per fold and record, the rms over the observation times [Pa] of the selection emulator's
    leave-one-out error (:func:`calibration.protocol.emulator_errors`), the record's noise and the
    simulator's own variability: a design point is worth cutting only where the first is already below
    the others (issue 54, item 5)."""
    import pickle

    import numpy as np

    from calibration.protocol import emulator_errors

    def rms(err) -> float:
        return float(np.sqrt(np.mean(np.asarray(err.std) ** 2)))  # std: per observation time

    out = {}
    for path in sorted((clone / "results").glob(f"{SERIES}__*/diagnosis/selection.pkl")):
        with path.open("rb") as fh:
            sel = pickle.load(fh)
        emulated = emulator_errors(sel["model"], list(sel["noise"]))
        out[path.parts[-3]] = {r: {"emulator_rms_Pa": rms(emulated[r]), "noise_rms_Pa": rms(sel["noise"][r]),
                                   "simulator_rms_Pa": rms(sel["simulator"][r]) if r in (sel["simulator"] or {}) else None}
                               for r in sel["noise"]}
    return out


def answers(clone: Path) -> dict:
    s = json.loads((clone / "results" / SERIES / "loro" / "summary.json").read_text())
    t = s["totals"]
    keep = ("mean_rmse_before", "mean_rmse_after", "folds_worse", "effects_kept",
            "mean_predictive_coverage_90_before", "mean_predictive_coverage_90_after")
    return {"totals": {k: t.get(k) for k in keep},
            "folds": [{k: r.get(k) for k in ("heldout", "effects", "rmse_before", "rmse_after",
                                              "predictive_coverage_90_before", "predictive_coverage_90_after")}
                      for r in s["rows"]]}


def summarize(clone: Path, log: str, wall_s: float, exit_code: int = 0) -> dict:
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True, text=True,
                         check=True).stdout.strip()
    times = job_times(log.splitlines())
    return {"commit": rev, "wall_s": round(float(wall_s), 1), "exit_code": exit_code,
            "job_times": times, "fdem_runs": fdem_runs(clone), "answers": answers(clone) if exit_code == 0 else None,
            "emulator_against_noise": emulator_against_noise(clone) if exit_code == 0 else None}


def run_series(clone: Path) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", *COMMAND], cwd=clone, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(clone)})
    return summarize(clone, proc.stdout + proc.stderr, time.perf_counter() - t0, proc.returncode)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", default="4b72e5d", help="the commit before runs were shared between folds")
    ap.add_argument("--new", default="HEAD")
    ap.add_argument("--from", dest="made", nargs=6, metavar=("OLD_CLONE", "OLD_LOG", "OLD_WALL_S", "NEW_CLONE",
                                                             "NEW_LOG", "NEW_WALL_S"))
    ap.add_argument("--add", nargs=4, metavar=("NAME", "CLONE", "LOG", "WALL_S"))
    ap.add_argument("--note", default="")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "bench_loro.json"))
    a = ap.parse_args(argv)
    load0 = list(os.getloadavg())
    if a.add:
        doc = json.loads(Path(a.out).read_text())
        name, clone, log, wall = a.add
        doc["runs"][name] = {**summarize(Path(clone), Path(log).read_text(), float(wall)), "note": a.note,
                             "load_average_at_assembly": load0}
        return emit_json(doc, a.out)
    if a.made:
        runs = {side: summarize(Path(a.made[i]), Path(a.made[i + 1]).read_text(), float(a.made[i + 2]))
                for side, i in (("old", 0), ("new", 3))}
    else:
        with tempfile.TemporaryDirectory() as tmp:
            runs = {side: run_series(clone_at(rev, Path(tmp) / side)) for side, rev in (("old", a.old), ("new", a.new))}
    result = {"benchmark": "bench_loro", "cores": os.cpu_count(), "python": platform.python_version(),
              "command": " ".join(COMMAND) + " (fresh clone)", "series": SERIES,
              "load_average_at_assembly": load0, "note": a.note, "runs": runs,
              "wall_ratio_old_over_new": round(runs["old"]["wall_s"] / runs["new"]["wall_s"], 2)}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
