"""Sleeping bodies against the all-awake engine, and against the engine's own sensitivity to rounding.

For each member (the fast disc at the three check points of the Table 2 box; fast cylinders driven by
four marble and two sandstone records, the records the benchmarks and the default run use), three runs
of the same model on one core: sleeping (the engine's default), all awake (`fdem.run(..., sleep=False)`),
all awake with the specimen's nodes moved by 1e-17 m at random, and all awake with the incident bar's
nodes given velocities of 1e-17 m/s at random (rounding-level perturbations: how far the engine's answer
moves when its last bits do). Per member: when each body woke against the
wave's nominal arrival, the solver times, and the largest difference of the transmitted stress up to
the all-awake run's peak and over the whole window, each over that peak.

Prints one JSON object (studies/results/sleep_check.json). Usage:
  python studies/sleep_check.py
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fdem.solver import run  # noqa: E402
from shpb.fracture import CHECK_POINTS  # noqa: E402
from shpb.paths import freiburg_raw_files  # noqa: E402
from shpb.simulate import build  # noqa: E402

RECORDS = ["CaMa_SHPB_003", "CaMa_SHPB_004", "CaMa_SHPB_005", "CaMa_SHPB_006", "SeeSst_SHPB_023", "SeeSst_SHPB_024"]


def _record(stem: str) -> str:
    return str(next(p for p in freiburg_raw_files(("CaMa", "SeeSst")) if p.name.startswith(stem + "_")))


def _cases():
    for name, point in CHECK_POINTS.items():
        yield f"disc_{name}", "brazilian_disc", dict(zip(("sigma_t", "E_t"), point)), None
    for stem in RECORDS:
        params = {"sigma_t": 20e6, "E_t": 3e3} if "SeeSst" in stem else {"sigma_t": 35e6, "E_t": 2.75e4}
        yield f"cylinder_{stem}", "cylinder", params, _record(stem)


def _member(geometry, params, record) -> dict:
    s = build(geometry, "fast", params, record=record)
    m = s["model"]
    t_end = s["arrival_s"] + s["window_s"]
    kw = dict(traction_bcs=s["traction_bcs"], sample_dt=5e-7)
    tb = m.body_index(s["geometry"].transmission_bar)
    x0 = m.x0.copy()
    on = m.body_nodes(s["geometry"].specimen)
    x0[on] += 1e-17 * np.random.default_rng(17).standard_normal((on.size, 2))
    v0 = np.zeros_like(m.x0)
    bar = m.body_nodes(s["geometry"].incident_bar)
    v0[bar] = 1e-17 * np.random.default_rng(18).standard_normal((bar.size, 2))
    runs = {"sleeping": run(m, t_end, **kw), "awake": run(m, t_end, sleep=False, **kw),
            "awake_rounded": run(m, t_end, sleep=False, x_init=x0, **kw),
            "awake_bar_rounded": run(m, t_end, sleep=False, v_init=v0, **kw)}
    ref = runs["awake"].body_force[:, tb, 0]
    peak = float(np.abs(ref).max())
    i = int(np.argmax(np.abs(ref)))
    out = {"arrival_s": s["arrival_s"], "t_end_s": t_end, "wake_s": runs["sleeping"].body_wake_t,
           "solver_s": {k: r.wall_s for k, r in runs.items()}, "status": {k: r.status for k, r in runs.items()}}
    for k in ("sleeping", "awake_rounded", "awake_bar_rounded"):
        d = np.abs(runs[k].body_force[:, tb, 0] - ref)
        out[f"{k}_vs_awake"] = {"to_peak_over_peak": float(d[:i + 1].max() / peak),
                                "window_over_peak": float(d.max() / peak)}
    return out


def main() -> dict:
    build("brazilian_disc", "fast")  # meshes and imports before any timing
    run(build("brazilian_disc", "fast")["model"], 2e-6)  # and the compiled loop
    members = {name: _member(g, p, r) for name, g, p, r in _cases()}
    cyl = [v for k, v in members.items() if k.startswith("cylinder")]
    disc = [v for k, v in members.items() if k.startswith("disc")]

    def share(vs):
        return [float(1 - v["solver_s"]["sleeping"] / v["solver_s"]["awake"]) for v in vs]

    return {"study": "sleep_check", "cores_on_machine": os.cpu_count(), "threads_used": 1,
            "preset": "fast", "perturbation_m": 1e-17, "members": members,
            "summary": {"cylinder_solver_saved": share(cyl), "disc_solver_saved": share(disc),
                        "to_peak_sleeping_max": max(v["sleeping_vs_awake"]["to_peak_over_peak"]
                                                    for v in members.values()),
                        "to_peak_rounded_max": max(max(v[f"{k}_vs_awake"]["to_peak_over_peak"]
                                                       for k in ("awake_rounded", "awake_bar_rounded"))
                                                   for v in members.values())}}


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
