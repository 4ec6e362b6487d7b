"""The engine before and after, side by side in one run: member wall time and the same-answers check.

A baseline revision of the repository (default: the last commit before the engine's speed work) is
checked out into a temporary folder with `git worktree`; every member is run once with that tree's
packages and once with this checkout's, one process at a time on one core (each tree with its own
warm JIT cache), so both see the same machine in the same state.

Cases: the Brazilian disc at the three check points of the Table 2 box (shpb.fracture.CHECK_POINTS)
at `fast` and `standard`, and the marble cylinder (CaMa_SHPB_004, its measured incident wave) at
`fast`; the paper-resolution disc at the reference point for the speed figure.

Per member: wall and solver time of each engine, the speed-up, element updates per second, and the
agreement of the two curves: the largest difference of the transmitted stress up to the failure
peak relative to the peak, the peaks' relative difference, whether the curves are bit-identical,
and whether the fracture checks (shpb.fracture) agree. Targets (issue "4x faster engine"): paper
member <= 30 s and >= 4x; >= 3e7 updates/s at paper; curves within 0.5 % of the peak up to the
failure peak, peaks within 1 %.

--repeat N runs every member N times per engine, alternating the engines, and keeps each engine's
fastest run (a shared machine's load only ever adds time). --first-call also times, per engine, a
fresh process's first short simulation with an empty Numba cache: the compile time every new
process pays when the cache is cold (wall and CPU seconds; CPU is the steadier figure under load).

Prints one JSON object. Usage:
  python benchmarks/bench_engine.py [--baseline REV] [--cases disc_fast,disc_standard,marble_fast,disc_paper]
                                    [--repeat N] [--first-call]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "571e177"  # main before the engine's speed work (issue 33)
MEMBER = r"""
import json, sys, time
from shpb.simulate import simulate
from shpb.fracture import CHECK_POINTS
geometry, preset, point, out = sys.argv[1:5]
record = sys.argv[5] if len(sys.argv) > 5 else None
simulate("brazilian_disc", "fast", t_end=5e-6)  # warm this tree's JIT cache
if geometry == "cylinder":
    params = {"sigma_t": 35e6, "E_t": 2.75e4}
else:
    params = dict(zip(("sigma_t", "E_t"), CHECK_POINTS[point]))
t0 = time.perf_counter()
o = simulate(geometry, preset, params=params, record=record)
wall = time.perf_counter() - t0
o.curve.to_csv(out, index=False)
r = o.run
f = r.get("fracture", {})
print(json.dumps({"wall_s": wall, "solver_wall_s": r["solver_wall_s"], "steps": r["steps"], "dt_s": r["dt_s"],
                  "element_updates_per_s": r["element_updates_per_s"], "status": r["status"],
                  "energy_balance_rel": r["energy_balance_rel"], "contact_rebuilds": r["contact_rebuilds"],
                  "checks": f.get("checks"), "peak_stress_Pa": f.get("peak_stress_Pa")}))
"""


FIRST_CALL = r"""
import resource, time
t0 = time.perf_counter()
from shpb.simulate import simulate
simulate("brazilian_disc", "fast", t_end=5e-6)
ru = resource.getrusage(resource.RUSAGE_SELF)
print(time.perf_counter() - t0, ru.ru_utime + ru.ru_stime)
"""


def _first_call(tree: Path, cache: Path) -> dict:
    """Wall and CPU seconds of a fresh process's first short run with an empty Numba cache."""
    cache.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1",
               NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, cwd=tree, capture_output=True, text=True,
                         check=False)
    if out.returncode != 0:
        raise RuntimeError(f"first call with the engine of {tree} failed:\n{out.stderr[-2000:]}")
    wall, cpu = map(float, out.stdout.split()[-2:])
    return {"wall_s": wall, "cpu_s": cpu}


def _fastest(runs: list[dict]) -> dict:
    best = min(runs, key=lambda r: r["solver_wall_s"])
    return dict(best, solver_wall_s_all=[r["solver_wall_s"] for r in runs])


def _run(tree: Path, args: list[str]) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", MEMBER, *args], env=env, cwd=tree, capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"member {args} with the engine of {tree} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _agreement(old_csv: Path, new_csv: Path) -> dict:
    a, b = pd.read_csv(old_csv), pd.read_csv(new_csv)
    sa, sb = a["stress_Pa"].to_numpy(), b["stress_Pa"].to_numpy()
    n = min(len(sa), len(sb))
    k = int(np.argmax(sa[:n]))  # the baseline's failure peak
    peak = abs(sa[k])
    return {"bit_identical": bool(a.equals(b)),
            "max_diff_to_peak_over_peak": float(np.max(np.abs(sa[:k + 1] - sb[:k + 1])) / peak),
            "peak_rel_diff": float(np.max(sb[:n]) / np.max(sa[:n]) - 1.0)}


def _cases(names: list[str]) -> list[tuple[str, list[str]]]:
    from shpb.fracture import CHECK_POINTS
    rec = str(next((ROOT / "data/freiburg-rae-rock-shpb").rglob("CaMa_SHPB_004*")))
    out = []
    for name in names:
        kind, preset = name.split("_", 1)
        if kind == "disc" and preset == "paper":
            out.append((f"{name}_reference", ["brazilian_disc", preset, "reference"]))
        elif kind == "disc":
            out += [(f"{name}_{p}", ["brazilian_disc", preset, p]) for p in CHECK_POINTS]
        elif kind == "marble":
            out.append((name, ["cylinder", preset, "-", "RECORD", rec]))
        else:
            raise ValueError(f"unknown case {name!r}: expected disc_<preset> or marble_<preset>")
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default=BASELINE)
    ap.add_argument("--cases", default="disc_fast,disc_standard,marble_fast,disc_paper")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--first-call", action="store_true")
    a = ap.parse_args()
    if a.repeat < 1:
        raise SystemExit(f"--repeat must be >= 1, got {a.repeat}")
    first_call = {}
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "baseline"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(base), a.baseline],
                       check=True, capture_output=True)
        try:
            if a.first_call:
                first_call = {engine: _first_call(tree, Path(tmp) / f"numba_cache_{engine}")
                              for engine, tree in (("baseline", base), ("new", ROOT))}
                print("first_call", json.dumps(first_call), file=sys.stderr)
            for label, args in _cases(a.cases.split(",")) if a.cases else []:
                runs = {"baseline": [], "new": []}
                for _ in range(a.repeat):
                    for engine, tree in (("baseline", base), ("new", ROOT)):
                        csv = Path(tmp) / f"{label}_{engine}.csv"
                        call = args[:3] + [str(csv)] + args[4:]
                        runs[engine].append(_run(tree, call))
                res = {engine: _fastest(r) for engine, r in runs.items()}
                res["speedup_solver"] = res["baseline"]["solver_wall_s"] / res["new"]["solver_wall_s"]
                res["speedup_wall"] = res["baseline"]["wall_s"] / res["new"]["wall_s"]
                res["agreement"] = _agreement(Path(tmp) / f"{label}_baseline.csv", Path(tmp) / f"{label}_new.csv")
                res["fracture_checks_agree"] = res["baseline"]["checks"] == res["new"]["checks"]
                rows[label] = res
                print(label, json.dumps({k: res[k] for k in ("speedup_solver", "agreement")}), file=sys.stderr)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], check=False,
                           capture_output=True)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "fdem", "shpb"],
                                capture_output=True, text=True).stdout.strip())
    print(json.dumps({"benchmark": "engine_before_after", "baseline": a.baseline, "new": head,
                      "new_has_uncommitted_engine_changes": dirty,
                      "cores_on_machine": os.cpu_count(), "threads_used": 1, "repeat": a.repeat,
                      "first_call": first_call, "cases": rows}, indent=1))


if __name__ == "__main__":
    main()
