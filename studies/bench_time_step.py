"""How conservative the stable time step is: the Gershgorin bound the engine uses (fdem.model.
stable_time_step) against the largest eigenvalue of M^-1 K of the intact disc, found by power
iteration on the assembled operator (the triangles' and joints' forces, linearised by a finite
difference at the reference configuration; no contact, no damping).

Prints one JSON object per preset: the critical step from the power iteration, the Gershgorin
bound with and without the contact budget (both at safety 1), their ratios, and the step the runs
use (safety 0.6 on the bound with contact).
Usage: python studies/bench_time_step.py [--presets fast,standard]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os

import numpy as np


def critical_step(model, iterations: int = 400, tol: float = 1e-6) -> float:
    """2 / sqrt(lambda_max(M^-1 K)) by power iteration, K u from forces at x0 + eps u."""
    from fdem.kernels import joint_forces
    from fdem.state import joint_state, joints_of
    from fdem.triangles import triangle_forces_scalar
    m = model
    n, nj = m.n_nodes, m.n_joints

    def force(x):
        f = np.zeros((n, 2))
        v = np.zeros((n, 2))
        triangle_forces_scalar(x, v, m.tri, m.dminv, m.vol0, m.lam, m.mu, np.zeros_like(m.eta), f)
        # strengths raised far above any stress: the elastic branch, linear in the gap
        joint_forces(x, v, joints_of(m, ft=m.ft * 1e9, fs=m.fs * 1e9), joint_state(nj), f)
        return f

    x0 = m.x0.copy()
    f0 = force(x0)
    u = np.random.default_rng(0).standard_normal((n, 2))
    u /= np.linalg.norm(u)
    eps = 1e-9 * float(np.ptp(x0[:, 0]))
    lam = 0.0
    for _ in range(iterations):
        w = -(force(x0 + eps * u) - f0) / eps / m.mass[:, None]
        lam_new = float(np.linalg.norm(w))
        u = w / lam_new
        if abs(lam_new - lam) < tol * lam_new:
            break
        lam = lam_new
    return 2.0 / np.sqrt(lam_new)


def main():
    from fdem.model import stable_time_step
    from shpb.fracture import CHECK_POINTS
    from shpb.simulate import build
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="fast,standard")
    rows = {}
    for preset in ap.parse_args().presets.split(","):
        m = build("brazilian_disc", preset, dict(zip(("sigma_t", "E_t"), CHECK_POINTS["reference"])))["model"]
        dt_power = critical_step(m)
        g_contact = stable_time_step(m, 1.0)
        g_bulk = stable_time_step(dataclasses.replace(m, contact=None), 1.0)
        rows[preset] = {"dt_power_iteration_no_contact_s": dt_power, "dt_gershgorin_no_contact_s": g_bulk,
                        "dt_gershgorin_with_contact_s": g_contact,
                        "power_over_gershgorin_no_contact": dt_power / g_bulk,
                        "contact_budget_factor": g_bulk / g_contact, "dt_used_s": stable_time_step(m)}
    print(json.dumps({"benchmark": "time_step_bound", "cores_on_machine": os.cpu_count(), "presets": rows}, indent=1))


if __name__ == "__main__":
    main()
