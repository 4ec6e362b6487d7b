"""What a longer time step would cost in answers: the engine's remaining speed lever, measured.

The engine steps at 0.6 of the Gershgorin bound with the contact budget (fdem.model.stable_time_step),
about 0.41 of the intact disc's critical step from the assembled operator (studies/results/
bench_time_step.json). The solver's time is proportional to the number of steps, so a step k times
longer makes every member about k times faster; it also changes the discretisation, so every curve
moves. This study measures by how much, against the scale the calibration already carries: the
simulator's own scatter over mesh realizations (the replicates' `S`).

Per case (a `fast` disc at the Table 2 reference point and at the weak-brittle check point, the `fast`
Carrara-marble cylinder driven by CaMa_SHPB_004's incident wave at E_t 27.5 kJ/m^2 and at a brittle
1 kJ/m^2, two Seeberger-sandstone cylinders (SeeSst_SHPB_023 at 85 1/s, SeeSst_SHPB_028 at 280 1/s;
sigma_t 20 MPa, E_t 3 kJ/m^2, the points studies/sleep_check.py uses), the `standard` disc, the paper
disc), one run at today's step, runs at k = 1.25, 1.5, 2 and 2.5 times it (the Gershgorin safety 0.75,
0.9, 1.2, 1.5), and runs at today's step on three mesh realizations (`mesh_seed` 1-3; the paper disc:
k = 1.5 and 2 only, no realizations).
Each is compared with today's run: the peak of the specimen stress (relative), its time [us], the rms
difference of the curve up to today's peak and over the whole window (relative to the peak), the
energy balance error, the solver time and the fracture checks (discs). One run's peak can move by a
mesh's worth through the fracture's path alone, so the marble and the faster sandstone are also run on
eight meshes at today's step and at 1.5 and 2 times it (``paired``): the mean shift of the peak over
the pairs against its own scatter. One core, one run at a time.

Prints one JSON object; with --out writes it. Usage:
  python studies/time_step_answers.py [--cases disc_fast,marble_fast,...] [--out F]
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from shpb.atomic import emit_json

ROOT = Path(__file__).resolve().parents[1]
FACTORS = (1.25, 1.5, 2.0, 2.5)
PAPER_FACTORS = (1.5, 2.0)
MESH_SEEDS = (1, 2, 3)
# The paired check: every mesh of PAIRED_SEEDS (None: Triangle's own) at today's step and at each of
# PAIRED_FACTORS, so that a shift of the peak is read against the meshes' own scatter, not one run's.
CASES = ("disc_fast", "discweak_fast", "marble_fast", "brittlemarble_fast", "sandstone_fast", "sandstone028_fast",
         "disc_standard", "disc_paper")
PAIRED_CASES = ("marble_fast", "sandstone028_fast")
PAIRED_FACTORS = (1.5, 2.0)
PAIRED_SEEDS = (None, 1, 2, 3, 4, 5, 6, 7)


def _member(case: str):
    """(geometry, preset, params, record) of a case name: disc_<preset> or marble_<preset>."""
    from shpb.fracture import CHECK_POINTS
    kind, preset = case.split("_", 1)
    if kind in ("disc", "discweak"):
        point = CHECK_POINTS["reference" if kind == "disc" else "weak_brittle"]
        return "brazilian_disc", preset, dict(zip(("sigma_t", "E_t"), point)), None
    root = ROOT / "data" / "freiburg-rae-rock-shpb"
    if kind == "marble":
        return "cylinder", preset, {"sigma_t": 35e6, "E_t": 2.75e4}, next(root.rglob("CaMa_SHPB_004*"))
    if kind == "brittlemarble":
        return "cylinder", preset, {"sigma_t": 35e6, "E_t": 1.0e3}, next(root.rglob("CaMa_SHPB_004*"))
    if kind.startswith("sandstone"):
        stem = {"sandstone": "SeeSst_SHPB_023", "sandstone028": "SeeSst_SHPB_028"}[kind]
        return "cylinder", preset, {"sigma_t": 20e6, "E_t": 3e3}, next(root.rglob(stem + "*"))
    raise ValueError(f"unknown case {case!r}: expected disc_, discweak_, marble_, brittlemarble_ or "
                     "sandstone[028]_<preset>")


def _run(case: str, **kw) -> dict:
    from shpb.simulate import simulate
    geometry, preset, params, record = _member(case)
    o = simulate(geometry, preset, params=params, record=record, **kw)
    r = o.run
    return {"t": np.asarray(o.columns["time_s"]), "s": np.asarray(o.columns["stress_Pa"]), "status": r["status"],
            "dt_s": r["dt_s"], "steps": r["steps"], "solver_wall_s": r["solver_wall_s"],
            "energy_balance_rel": r["energy_balance_rel"],
            "checks": (r.get("fracture") or {}).get("checks")}


def compare(ref: dict, run: dict) -> dict:
    """run against ref on ref's time axis: relative peak change, time-to-peak change [us], rms differences
    up to ref's peak and over the window, both over ref's peak."""
    out = {k: run[k] for k in ("status", "dt_s", "steps", "solver_wall_s", "energy_balance_rel", "checks")}
    if run["status"] != "ok" or not np.all(np.isfinite(run["s"])):
        return out
    s = np.interp(ref["t"], run["t"], run["s"])
    ip = int(np.argmax(ref["s"]))
    peak = float(ref["s"][ip])
    d = s - ref["s"]
    out.update({"peak_rel": float(np.max(run["s"]) / peak - 1.0),
                "time_to_peak_us": 1e6 * float(run["t"][int(np.argmax(run["s"]))] - ref["t"][ip]),
                "rms_to_peak_rel": float(np.sqrt(np.mean(d[:ip + 1] ** 2)) / peak),
                "rms_window_rel": float(np.sqrt(np.mean(d ** 2)) / peak),
                "speedup": ref["solver_wall_s"] / run["solver_wall_s"],
                "checks_agree": run["checks"] == ref["checks"]})
    return out


def study(case: str) -> dict:
    from shpb.simulate import simulate
    geometry, preset, params, record = _member(case)
    simulate(geometry, "fast", params=params, record=record, t_end=2e-6)  # compile before timing
    ref = _run(case)
    factors = PAPER_FACTORS if case.endswith("paper") else FACTORS
    seeds = () if case.endswith("paper") else MESH_SEEDS
    row = {"case": case, "dt_today_s": ref["dt_s"], "steps_today": ref["steps"],
           "solver_wall_today_s": ref["solver_wall_s"], "energy_balance_today": ref["energy_balance_rel"],
           "peak_today_Pa": float(np.max(ref["s"])), "checks_today": ref["checks"],
           "longer_step": {f"{k:g}": compare(ref, _run(case, dt=k * ref["dt_s"])) for k in factors},
           "mesh_realizations": {str(s): compare(ref, _run(case, mesh_seed=s)) for s in seeds}}
    return row


def paired(case: str) -> dict:
    """Peaks over PAIRED_SEEDS' meshes at today's step and k times it: per k the mean and sd of the peak
    [Pa], the paired peak change's mean, sd and t (mean over its standard error), the largest energy
    balance error."""
    base = {s: _run(case, mesh_seed=s) for s in PAIRED_SEEDS}
    p0 = np.array([np.max(r["s"]) for r in base.values()])
    today = {"peak_mean_Pa": float(p0.mean()), "peak_sd_Pa": float(p0.std(ddof=1)),
             "energy_max": max(r["energy_balance_rel"] for r in base.values())}
    out = {"seeds": list(PAIRED_SEEDS), "today": today}
    for k in PAIRED_FACTORS:
        runs = [_run(case, mesh_seed=s, dt=k * base[s]["dt_s"]) for s in PAIRED_SEEDS]
        p = np.array([np.max(r["s"]) for r in runs])
        d = (p - p0) / p0.mean()
        out[f"{k:g}"] = {"peak_mean_Pa": float(p.mean()), "peak_sd_Pa": float(p.std(ddof=1)),
                         "paired_change_rel_mean": float(d.mean()), "paired_change_rel_sd": float(d.std(ddof=1)),
                         "paired_t": float(d.mean() / (d.std(ddof=1) / np.sqrt(d.size))),
                         "energy_max": max(r["energy_balance_rel"] for r in runs),
                         "statuses": sorted({r["status"] for r in runs})}
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out")
    a = ap.parse_args()
    cases = a.cases.split(",")
    rows = [study(c) for c in cases]
    doc = {"study": "time_step_answers", "cores_on_machine": os.cpu_count(), "threads_used": 1,
           "factors": list(FACTORS), "paper_factors": list(PAPER_FACTORS), "mesh_seeds": list(MESH_SEEDS),
           "cases": rows, "paired": {c: paired(c) for c in PAIRED_CASES if c in cases}}
    emit_json(doc, a.out)


if __name__ == "__main__":
    main()
