"""Where the FDEM step's time goes, measured inside the real step loop.

A copy of `fdem.integrator.run_loop` is made from its source with a timer (Numba's objmode calling
time.perf_counter) around one part of the step: the half kick and drift (node update), the contact
list check and refresh, the triangle forces, the joint forces, the newly damaged joints' bookkeeping,
the contact forces, and the rest (tractions, damping, second half kick). The member is run once per
part with that copy (one timer pair per step, the same in every run), and once with a copy timing an
empty section to measure the timer's own cost, which is subtracted. Timing each part in isolation on
a frozen state misses what only the dynamics do (joints whose damage grows, crack faces appearing),
which in a fragmenting disc is most of the post-peak cost.

Prints one JSON object (one core). Usage:
  python studies/profile_engine.py [--cases disc_paper,marble_fast]
"""
from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import os
import sys
import tempfile
from pathlib import Path

# Each part as (first line of the part, first line after it) in fdem/integrator.py's run_loop.
PARTS = {
    "node_update": ("            # half kick, with mass damping", "            # contact neighbour list\n"),
    "contact_refresh": ("            # contact neighbour list\n", "            bforce[:, :] = 0.0\n"),
    "triangles": ("            bforce[:, :] = 0.0\n", "            Psi, dis, nnew, ndam = 0.0, 0.0, 0, 0\n"),
    "joints": ("            Psi, dis, nnew, ndam = 0.0, 0.0, 0, 0\n", "            E[4] += dis\n"),
    "damage_bookkeeping": ("            E[4] += dis\n", "            Uc, Pf, pen = contact_forces("),
    "contact_forces": ("            Uc, Pf, pen = contact_forces(", "            if pen > max_pen:\n"),
    "rest_of_step": ("            if pen > max_pen:\n", "        while isnap"),
}
START = "            with objmode(t_a='float64'):\n                t_a = time.perf_counter()\n"
STOP = ("            with objmode(t_b='float64'):\n                t_b = time.perf_counter()\n"
        "            timer_s[0] += t_b - t_a\n")


def timed_source(part: str | None) -> str:
    """run_loop's module source with a timer around `part` (None: an empty timed section)."""
    import fdem.integrator as integ
    src = inspect.getsource(integ)
    src = src.replace("from .", "from fdem.").replace("from numba import njit", "from numba import njit, objmode\nimport time")
    src = src.replace("@njit(cache=True)\ndef run_loop(", "@njit(cache=False)\ndef run_loop(")
    src = src.replace("    E = np.zeros(8)\n", "    E = np.zeros(8)\n    timer_s = np.zeros(1)\n    t_a = 0.0\n", 1)
    src = src.replace("    return status, ns, step, E, rebuilds",
                      "    t_total = timer_s[0]\n    with objmode(rec_ok='int64'):\n        rec_ok = _record(t_total)\n    status += rec_ok\n"
                      "    return status, ns, step, E, rebuilds")
    src = src.replace("STATUS_OK = 0\n", "STATUS_OK = 0\nTIMES = []\n\n\ndef _record(t):\n    TIMES.append(t)\n    return 0\n\n\n", 1)
    first, after = PARTS[part] if part else PARTS["contact_refresh"][:1] * 2
    for anchor in (first, after):
        if src.count(anchor) != 1:
            raise RuntimeError(f"studies/profile_engine.py: anchor {anchor.strip()!r} is not unique in "
                               "fdem/integrator.py any more; update PARTS")
    i = src.index(first)
    if part is None:
        return src[:i] + START + STOP + src[i:]
    src = src[:i] + START + src[i:]
    j = src.index(after, i + len(START))
    return src[:j] + STOP + src[j:]


def _load(part, folder: Path):
    path = folder / f"timed_{part or 'empty'}.py"
    path.write_text(timed_source(part))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = mod  # Numba's objmode finds the module's globals by its name
    spec.loader.exec_module(mod)
    return mod


def _member(case: str):
    """(geometry, preset, params, record) of a case name: disc_<preset> (Table 2 reference point) or
    marble_<preset> (CaMa_SHPB_004 driven by its measured incident wave)."""
    from shpb.fracture import CHECK_POINTS
    kind, preset = case.split("_", 1)
    if kind == "disc":
        return "brazilian_disc", preset, dict(zip(("sigma_t", "E_t"), CHECK_POINTS["reference"])), None
    if kind == "marble":
        root = Path(__file__).resolve().parents[1] / "data" / "freiburg-rae-rock-shpb"
        return "cylinder", preset, {"sigma_t": 35e6, "E_t": 2.75e4}, next(root.rglob("CaMa_SHPB_004*"))
    raise ValueError(f"unknown case {case!r}: expected disc_<preset> or marble_<preset>")


def profile(case: str, folder: Path) -> dict:
    import fdem.solver as solver
    from shpb.simulate import simulate
    geometry, preset, params, record = _member(case)
    plain = solver.run_loop
    out, info = {}, {}
    try:
        for part in [None, *PARTS]:
            mod = _load(part, folder)
            solver.run_loop = mod.run_loop
            simulate(geometry, preset, params=params, record=record, t_end=2e-6)  # compile this copy
            r = simulate(geometry, preset, params=params, record=record).run
            out[part or "timer_overhead"] = float(mod.TIMES[-1])
        solver.run_loop = plain
        r = simulate(geometry, preset, params=params, record=record).run
    finally:
        solver.run_loop = plain
    overhead = out.pop("timer_overhead")
    parts = {k: max(v - overhead, 0.0) for k, v in out.items()}
    total = sum(parts.values())
    info = {"case": case, "steps": r["steps"], "triangles": r["n_triangles"], "joints": r["n_joints"],
            "solver_wall_s": round(r["solver_wall_s"], 3), "element_updates_per_s": round(r["element_updates_per_s"]),
            "contact_rebuilds": r["contact_rebuilds"], "timer_overhead_s": round(overhead, 3),
            "parts_s": {k: round(v, 3) for k, v in parts.items()},
            "parts_share": {k: round(v / total, 3) for k, v in parts.items()},
            "parts_sum_over_solver": round(total / r["solver_wall_s"], 3)}
    return info


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="disc_paper,marble_fast")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sys.path.insert(0, tmp)
        rows = [profile(c, Path(tmp)) for c in a.cases.split(",")]
    print(json.dumps({"benchmark": "profile_engine", "cores_on_machine": os.cpu_count(), "threads_used": 1,
                      "cases": rows}, indent=1))


if __name__ == "__main__":
    main()
