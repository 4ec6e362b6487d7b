"""FDEM engine performance: element updates per second and warm-start latency.

Prints one JSON object. Element updates = (triangles + joints) x steps. The jointed disc has the
paper's specimen resolution (about 17,500 triangles of 0.5 mm); it is loaded dynamically between
two rigid-ish steel platens so that contact is active, and run on one core.
element_updates_per_cpu_s divides by the process's CPU time, which stays meaningful when other jobs
share the cores (wall-clock figures then drop). Usage: python studies/bench_fdem.py [--steps N]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np


def disc_model(h=0.00064):
    from fdem import Body, ContactParams, JointParams, Material, build_model
    from fdem import meshing
    granite = Material(35e9, 0.16, 2550.0)
    steel = Material(200e9, 0.29, 7850.0)
    R, t = 0.025, 0.025
    nodes, tris = meshing.disc(R, h)
    pn, pt = meshing.rectangle(-0.01, R, 0.02, 0.005, 8, 2)
    bn, bt = meshing.rectangle(-0.01, -R - 0.005, 0.02, 0.005, 8, 2)
    jp = JointParams(sigma_n=10e6, sigma_t=45e6, E_n=100.0, E_t=500.0)
    return build_model([Body("disc", nodes, tris, granite, t, fracturable=True),
                        Body("top", pn, pt, steel, t), Body("bot", bn, bt, steel, t)],
                       joints={"disc": jp}, contact=ContactParams(penalty=granite.E))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=4000)
    args = ap.parse_args()
    from fdem import VelocityBC, run, stable_time_step
    t0 = time.perf_counter()
    model = disc_model()
    t_build = time.perf_counter() - t0
    R = 0.025
    tn = model.body_nodes("top")
    bn = model.body_nodes("bot")
    tn = tn[np.isclose(model.x0[tn, 1], R + 0.005)]
    bn = bn[np.isclose(model.x0[bn, 1], -R - 0.005)]
    th = np.array([0.0, 20e-6, 1.0])
    vh = np.array([0.0, 5.0, 5.0])
    bcs = [VelocityBC(tn, 1, th, -vh), VelocityBC(bn, 1, th, vh)]
    dt = stable_time_step(model)
    run(model, 5 * dt, dt=dt, velocity_bcs=bcs)  # compile or load the cache
    cpu0 = time.process_time()
    res = run(model, args.steps * dt, dt=dt, velocity_bcs=bcs, sample_dt=args.steps * dt / 50)
    cpu_s = time.process_time() - cpu0
    disc_tris = int(np.sum(model.tri_body == 0))
    # Warm-start latency: a fresh interpreter importing the engine and taking one step.
    code = ("import time; t0 = time.perf_counter(); import sys; sys.path.insert(0, %r); "
            "from studies.bench_fdem import disc_model; from fdem import run, stable_time_step; "
            "m = disc_model(0.002); run(m, 2 * stable_time_step(m)); "
            "print(time.perf_counter() - t0)") % os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    t_start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    warm_ready = float(out.stdout.strip().splitlines()[-1])
    wall_process = time.perf_counter() - t_start
    print(json.dumps({
        "benchmark": "fdem_element_updates",
        "cores_on_machine": os.cpu_count(),
        "threads_used": 1,
        "specimen_triangles": disc_tris,
        "triangles_total": model.n_triangles,
        "joints": model.n_joints,
        "steps": res.steps,
        "dt_s": res.dt,
        "broken_joints": int(res.broken[-1]),
        "contact_rebuilds": res.contact_rebuilds,
        "wall_s": round(res.wall_s, 3),
        "element_updates_per_s": res.updates_per_s,
        "cpu_s": round(cpu_s, 3),
        "element_updates_per_cpu_s": (model.n_triangles + model.n_joints) * res.steps / cpu_s,
        "target_updates_per_s": 2e7,
        "model_build_s": round(t_build, 3),
        "warm_process_ready_and_first_step_s": round(warm_ready, 3),
        "warm_process_total_incl_interpreter_s": round(wall_process, 3),
        "target_warm_ready_s": 2.0,
    }, indent=1))


if __name__ == "__main__":
    main()
