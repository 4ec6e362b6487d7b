"""Which joints break, in which mode, in which time window: the trace of a cylinder run's failure.

    python tools/trace_fracture.py <record> '<params as JSON>' [--preset fast] [--bin-us 10]

Runs the cylinder model on a measured record at the given parameters (``shpb.simulate``, snapshots
every 4 us over the window) and prints JSON: the specimen stress curve's peak, the times from the peak
to 50 % and 10 % of it, and per time bin the joints that broke then, with the share whose separation
just after the break is mostly opening (mode I) rather than slip (mode II), their median angle to the
load axis (0 = axial, splitting; about 30 = a Mohr-Coulomb shear band) and how many lie near the loaded
faces. Used for docs/closing-the-loop.md ("The post-peak residual").
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from shpb.simulate import simulate

SNAPSHOT_US = 4.0


def joint_separation(x, jn, j) -> tuple[float, float]:
    """Mean opening and slip [m] of joint j's two faces in the deformed configuration x."""
    a1, a2, b1, b2 = jn[j]
    t = 0.5 * (x[a2] + x[b2]) - 0.5 * (x[a1] + x[b1])
    t = t / np.linalg.norm(t)
    n = np.array([t[1], -t[0]])
    g = 0.5 * ((x[b1] - x[a1]) + (x[b2] - x[a2]))
    return float(g @ n), float(g @ t)


def trace(record: str, params: dict, preset: str = "fast", t_end: float = 2.8e-4, bin_us: float = 10.0) -> dict:
    snaps = list(np.arange(SNAPSHOT_US, t_end * 1e6 + 1e-9, SNAPSHOT_US) * 1e-6)
    out = simulate("cylinder", preset, params=params, record=record, t_end=t_end, sample_dt=5e-7, snapshots=snaps)
    res, setup = out.extra["result"], out.extra["setup"]
    model, arrival = setup["model"], setup["arrival_s"]
    x0, jn = model.x0, model.jn
    snap_t = np.array([s.time for s in res.snapshots])
    half_length = 0.5 * np.ptp(x0[model.node_body == model.body_index(setup["geometry"].specimen), 0])
    joints = []
    for j in np.nonzero(res.joint_break_t >= 0)[0]:
        k = min(int(np.searchsorted(snap_t, res.joint_break_t[j] + 1e-6)), len(snap_t) - 1)
        opening, slip = joint_separation(res.snapshots[k].x, jn, j)
        a1, a2, b1, b2 = jn[j]
        d = 0.5 * (x0[a2] + x0[b2]) - 0.5 * (x0[a1] + x0[b1])
        mid = 0.25 * (x0[a1] + x0[a2] + x0[b1] + x0[b2])
        joints.append((float((res.joint_break_t[j] - arrival) * 1e6), abs(opening) > abs(slip),
                       float(np.degrees(np.arctan2(abs(d[1]), abs(d[0])))), abs(mid[0]) > 0.8 * half_length))
    t = out.columns["time_s"] * 1e6
    s = out.columns["stress_Pa"]
    ip = int(np.argmax(s))
    after = np.nonzero(t > t[ip])[0]

    def time_to(frac):
        below = after[s[after] < frac * s[ip]]
        return float(t[below[0]] - t[ip]) if below.size else None

    bins = []
    for lo in np.arange(0.0, t_end * 1e6, bin_us):
        sel = [r for r in joints if lo <= r[0] < lo + bin_us]
        if sel:
            bins.append({"window_us": [float(lo), float(lo + bin_us)], "broken": len(sel),
                         "opening_dominated": float(np.mean([r[1] for r in sel])),
                         "median_angle_to_load_axis_deg": float(np.median([r[2] for r in sel])),
                         "near_loaded_faces": float(np.mean([r[3] for r in sel]))})
    return {"record": record, "params": params, "preset": preset, "status": out.run["status"],
            "peak_us": float(t[ip]), "peak_Pa": float(s[ip]), "peak_to_50_percent_us": time_to(0.5),
            "peak_to_10_percent_us": time_to(0.1), "broken_joints": len(joints), "n_joints": int(model.n_joints),
            "bins": bins}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("record")
    ap.add_argument("params", help="JSON, e.g. '{\"sigma_t\": 5.3e7, \"face_gap.gap_m\": 2.3e-4}'")
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--t-end", type=float, default=2.8e-4)
    ap.add_argument("--bin-us", type=float, default=10.0)
    a = ap.parse_args(argv)
    print(json.dumps(trace(a.record, json.loads(a.params), a.preset, a.t_end, a.bin_us), indent=1))


if __name__ == "__main__":
    main()
