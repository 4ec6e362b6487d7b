"""What the approximation error (``observations.model_error.approximation_error``) adds to a record's run.

The term runs, per record, ``pairs`` design points of the prior box once at ``standard`` and
``coarse_realizations`` times at the model's preset (24 and 2 by default: 24 ``standard`` and 48 ``fast``
runs). This times the first ``--points`` of those design points (the experiment's own design, from its
seed) at both presets on one core, for the default twin's disc (``twin_ref``) and the default run's
marble cylinder (``marble_loop``'s first record), and extrapolates to a record's pairs: solver and process
time per run, the pairs' run time on one core and, split evenly, on ``--cores``. Prints one JSON object
(and writes it with ``--out``).

    python benchmarks/bench_approximation_cost.py --points 3 --out benchmarks/results/bench_approximation_cost.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import shipped_experiment  # noqa: E402
from calibration.approximation import (approximation_design, approximation_run, approximation_run_ids,  # noqa: E402
                                       approximation_settings)
from calibration.experiment import ExperimentSpec  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from shpb.lab.init_config_yaml import APPROXIMATION_ERROR  # noqa: E402

CASES = {"disc": "twin_ref", "cylinder": "marble_loop"}


def _experiment(name: str) -> dict:
    """The shipped experiment with the block init-config writes (schema defaults filled in)."""
    def edit(exp):
        me = exp["observations"].get("model_error") or {}
        exp["observations"]["model_error"] = {**me, "approximation_error": dict(APPROXIMATION_ERROR)}
    return shipped_experiment(name, edit)


def _time_run(geometry: str, preset: str, params: dict, record, t_end: float) -> dict:
    from shpb.simulate import simulate

    t0 = time.perf_counter()
    out = simulate(geometry, preset, params=params, record=record, t_end=t_end)
    return {"wall_s": time.perf_counter() - t0, "solver_s": float(out.run["solver_wall_s"]),
            "status": out.run["status"]}


def case(kind: str, points: int, cores: int) -> dict:
    name = CASES[kind]
    exp = _experiment(name)
    spec = ExperimentSpec.from_config(name, exp)
    design = approximation_design(name, exp)[:points]
    records = (exp["observations"].get("records") or [None])[:1]
    record = str(ROOT / records[0]) if records[0] else None
    t_end = float(exp["simulation"]["t_end"])
    fine = approximation_settings(exp)["preset"]
    runs = {fine: [], exp["preset"]: []}
    for row in design:
        params = dict(zip(spec.names, map(float, row)))
        for preset in runs:
            runs[preset].append({"params": params, **_time_run(exp["geometry"], preset, params, record, t_end)})
    mean = {p: sum(r["wall_s"] for r in rs) / len(rs) for p, rs in runs.items()}
    # a record's runs as the workflow names them (fine_<i>, coarse_<i>_<r>)
    levels = [approximation_run(r)[0] for r in approximation_run_ids(exp)]
    count = {fine: levels.count("fine"), exp["preset"]: levels.count("coarse")}
    one_core = sum(count[p] * mean[p] for p in count)
    return {"experiment": name, "geometry": exp["geometry"], "record": records[0], "model_preset": exp["preset"],
            "points_timed": points, "runs": runs, "mean_run_wall_s": mean,
            "standard_over_model_preset": mean[fine] / mean[exp["preset"]],
            "pairs_per_record": count,
            "pairs_one_core_s": one_core, "pairs_on_cores_s": one_core / cores}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=3, help="design points timed per case (of the 24)")
    ap.add_argument("--cores", type=int, default=2, help="cores the pairs' time is split over")
    ap.add_argument("--cases", default="disc,cylinder")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    from shpb.simulate import warm_up

    warm_up()
    started = time.time()
    out = {"benchmark": "bench_approximation_cost", "cores": a.cores, "machine_cores": os.cpu_count(),
           "threads_used": 1, "python": platform.python_version(),
           "note": "each run timed on one core, one after another; the pairs' time extrapolated from the points "
                   "timed (the 24 design points of a record span the prior box as these do)",
           "cases": {k: case(k, a.points, a.cores) for k in a.cases.split(",")}}
    out["wall_s"] = time.time() - started
    return emit_json(out, a.out)


if __name__ == "__main__":
    main()
