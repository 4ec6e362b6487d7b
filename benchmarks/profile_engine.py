"""Where the FDEM step's time goes: each part of the step timed alone on a captured mid-run state.

The member is run to a point of interest (the disc: 70 % of its failure-peak time, where contact and
joints are both busy; the same for the marble cylinder), its state taken, and each part of one step
called many times on that state: triangle forces, joint forces, contact forces, the node update
(two half kicks and the drift), the contact broad phase (one rebuild; its per-step share is rebuilds /
steps from the full run) and sampling (one sample; its share is 1 / sample_every). The sum of the
parts is compared with the measured solver time per step of the full run, so a part the profile
misses shows up as a gap.

Prints one JSON object (one core, warm JIT cache).
Usage: python benchmarks/profile_engine.py [--cases disc_paper,marble_fast] [--calls 200]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # benchmarks._step_parts


def _case(name):
    from shpb.simulate import build
    from shpb.fracture import CHECK_POINTS
    if name.startswith("disc_"):
        sigma_t, E_t = CHECK_POINTS["reference"]
        return build("brazilian_disc", name.split("_", 1)[1], {"sigma_t": sigma_t, "E_t": E_t})
    if name.startswith("marble_"):
        from pathlib import Path
        rec = next(Path("data/freiburg-rae-rock-shpb").rglob("CaMa_SHPB_004*"))
        return build("cylinder", name.split("_", 1)[1], {"sigma_t": 35e6, "E_t": 2.75e4}, record=rec)
    raise ValueError(f"unknown case {name!r}: expected disc_<preset> or marble_<preset>")


def _best_of(fn, calls):
    """Median time of one call [s] over `calls` calls (after one warm call)."""
    fn()
    ts = []
    for _ in range(calls):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _state(m, s, t_end):
    """Run to t_end [s]; the state, the active edges as the integrator would have them, the run."""
    from fdem.solver import run
    r = run(m, t_end, sample_dt=0.5e-6, traction_bcs=s["traction_bcs"], stress_probes=s["stress_probes"])
    edge_active = m.edge_active0.copy()
    for j in np.nonzero(r.Dmax[:, 0] > 0)[0]:
        for side in range(2):
            edge_active[m.tri_edges[m.edge_tri[m.jedges[j, side]]]] = True
    return r, edge_active


def _parts(m, s, r, edge_active, calls):
    """Time of each part of one step [s] at the run's final state (see the module docstring)."""
    from fdem.kernels import triangle_forces, joint_forces, contact_forces
    from fdem.contact import build_pairs, surface_nodes
    from benchmarks._step_parts import node_update, sample_stress
    x, v, Dm, br = r.x, r.v, r.Dmax.copy(), r.joint_broken.copy()
    n, nj, dt = m.n_nodes, m.n_joints, r.dt
    f = np.zeros((n, 2))
    c = m.contact
    p_c, mu_tab = c.table(m.body_names), c.friction_table(m.body_names)
    buffer = c.buffer if c.buffer is not None else 0.3 * float(np.min(m.edge_dlim[m.edge_active0]) * 2.0)
    snodes = surface_nodes(m.edges, edge_active, n)
    args_bp = (x, m.edges, edge_active, m.edge_tri, snodes, m.node_vertex, m.node_body, m.node_tri, m.tri,
               m.body_fracturable, buffer)
    pn, pe, nrm = build_pairs(*args_bp)
    sa, sb, sc = m.softening
    newly, newly_dam = np.empty(nj, np.int64), np.empty(nj, np.int64)
    jdif, slip, kappa = np.ones((nj, 2)), np.zeros((nj, 2)), np.zeros((nj, 2))
    zeta = np.ones(nj)
    ce, cd, se, su = -np.ones(n, np.int64), np.zeros(n), -np.ones(n, np.int64), np.zeros((n, 2))
    bforce = np.zeros((len(m.body_names), 2))
    eg = [m.element_sets[k] for k in s["stress_probes"]]
    eg_ptr = np.concatenate([[0], np.cumsum([len(g) for g in eg])]).astype(np.int64)
    eg_el = np.concatenate(eg).astype(np.int64)
    xc, vc, inv_m, g = x.copy(), v.copy(), 1.0 / m.mass, np.zeros_like(f)
    t = {
        "triangles": _best_of(lambda: triangle_forces(x, v, m.tri, m.dminv, m.vol0, m.lam, m.mu, m.eta, f), calls),
        "joints": _best_of(lambda: joint_forces(
            x, v, m.jn, m.jarea, m.kn, m.kt, m.ft, m.fs, m.dn, m.dt, m.tanphi, sa, sb, sc, Dm, br, f,
            newly, newly_dam, m.jrate, jdif, slip, kappa, zeta), calls),
        "contact_forces": _best_of(lambda: contact_forces(
            x, v, pn, pe, pn.shape[0], nrm, m.edges, m.edge_tri, m.edge_joint, br, Dm, m.edge_dlim,
            m.edge_thick, m.node_thick, m.node_body, m.node_tri, m.tri, m.node_vertex, m.body_fracturable,
            p_c, mu_tab, dt, f, bforce, ce, cd, se, su), calls),
        "node_update": _best_of(lambda: node_update(xc, vc, f, inv_m, dt, snodes, x, g), calls),
        "one_contact_rebuild": _best_of(lambda: build_pairs(*args_bp), max(5, calls // 10)),
        "one_sample": _best_of(lambda: sample_stress(x, m.tri, m.dminv, m.lam, m.mu, m.vol0, eg_ptr, eg_el),
                               calls),
    }
    counts = {"contact_pairs": int(pn.shape[0]), "surface_nodes": int(snodes.shape[0]),
              "damaged_joints": int(np.sum(r.Dmax[:, 0] > 0)), "broken_joints": int(np.sum(r.joint_broken))}
    return t, counts


def _phase(t_parts, rebuilds, steps, sample_every, measured_step):
    """Per-step cost of each part over one phase of the run, and how much of the measured step
    time the parts account for."""
    per = {k: t_parts[k] for k in ("triangles", "joints", "contact_forces", "node_update")}
    per["contact_rebuild"] = t_parts["one_contact_rebuild"] * rebuilds / max(steps, 1)
    per["sampling"] = t_parts["one_sample"] / sample_every
    total = sum(per.values())
    return {"measured_step_us": round(1e6 * measured_step, 2), "steps": int(steps), "contact_rebuilds": int(rebuilds),
            "parts_us": {k: round(1e6 * v, 2) for k, v in per.items()},
            "share_of_parts": {k: round(v / total, 3) for k, v in per.items()},
            "parts_over_measured": round(total / measured_step, 3)}


def profile(name: str, calls: int) -> dict:
    """Pre-peak (up to 70 % of the transmitted-force peak) and post-peak (the rest of the window)
    phases of one member: measured step time of each and the parts at each phase's final state."""
    s = _case(name)
    m = s["model"]
    t_total = s["arrival_s"] + s["window_s"]
    full, act_end = _state(m, s, t_total)
    F = full.body_force_of(s["geometry"].transmission_bar)[:, 0]
    t_pre = 0.7 * float(full.time[int(np.argmax(F))])
    pre, act_pre = _state(m, s, t_pre)
    sample_every = max(1, int(round(0.5e-6 / full.dt)))
    parts_pre, counts_pre = _parts(m, s, pre, act_pre, calls)
    parts_end, counts_end = _parts(m, s, full, act_end, calls)
    post_steps = full.steps - pre.steps
    return {
        "case": name, "n_nodes": int(m.n_nodes), "triangles": int(m.n_triangles), "joints": int(m.n_joints),
        "steps": int(full.steps), "dt_s": float(full.dt), "solver_wall_s": round(full.wall_s, 3),
        "element_updates_per_s": round(full.updates_per_s), "pre_peak_end_s": t_pre,
        "pre_peak": dict(_phase(parts_pre, pre.contact_rebuilds, pre.steps, sample_every, pre.wall_s / pre.steps),
                         state=counts_pre, wall_s=round(pre.wall_s, 3)),
        "post_peak": dict(_phase(parts_end, full.contact_rebuilds - pre.contact_rebuilds, post_steps, sample_every,
                                 (full.wall_s - pre.wall_s) / post_steps),
                          state=counts_end, wall_s=round(full.wall_s - pre.wall_s, 3)),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="disc_paper,marble_fast")
    ap.add_argument("--calls", type=int, default=200)
    a = ap.parse_args()
    from shpb.simulate import simulate
    simulate("brazilian_disc", "fast", t_end=5e-6)  # warm the JIT cache
    rows = [profile(c, a.calls) for c in a.cases.split(",")]
    print(json.dumps({"benchmark": "profile_engine", "cores_on_machine": os.cpu_count(), "threads_used": 1,
                      "cases": rows}, indent=1))


if __name__ == "__main__":
    main()
