"""Does the numbering of the specimen's mesh limit the engine's speed? (issue 54, the paper disc's bar)

The force passes walk the triangles and joints in index order and gather and scatter node rows; at the
paper resolution the node arrays outgrow the core's cache. The same paper-disc member (the reference
point, one core, warm JIT) is run with the specimen's vertices and triangles numbered three ways, a
relabelling that moves no node: the mesher's (the engine's), along a Z-curve of their positions
(Morton order), and shuffled at random. Runs alternate between the numberings; each keeps its fastest.
The curves differ by rounding only (the sums of a node's forces formed in another order), grown by the
fracture's chaos; the largest difference to the peak is reported.

    python studies/mesh_numbering.py [--repeat 2]

Writes ``studies/results/mesh_numbering.json``.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

import shpb.simulate as sim  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

OUT = ROOT / "studies" / "results" / "mesh_numbering.json"
POINT = {"sigma_t": 45e6, "E_t": 500.0}


def morton(points: np.ndarray) -> np.ndarray:
    """Indices sorting (n, 2) points along the Z-curve of their bounding box (16 bits per axis)."""
    lo = points.min(axis=0)
    q = ((points - lo) / np.maximum(points.max(axis=0) - lo, 1e-300) * 65535).astype(np.uint64)
    code = np.zeros(len(points), np.uint64)
    for b in range(16):
        code |= ((q[:, 0] >> np.uint64(b)) & np.uint64(1)) << np.uint64(2 * b)
        code |= ((q[:, 1] >> np.uint64(b)) & np.uint64(1)) << np.uint64(2 * b + 1)
    return np.argsort(code, kind="stable")


def renumbered(body, how: str):
    """The body with its vertices and triangles in another order, its sets naming the same entities."""
    if how == "mesher":
        return body
    n, m = len(body.nodes), len(body.triangles)
    if how == "z_curve":
        pv, pt = morton(body.nodes), morton(body.nodes[body.triangles].mean(axis=1))
    else:
        rng = np.random.default_rng(0)
        pv, pt = rng.permutation(n), rng.permutation(m)
    nv, nt = np.empty(n, np.int64), np.empty(m, np.int64)
    nv[pv], nt[pt] = np.arange(n), np.arange(m)
    return dataclasses.replace(body, nodes=body.nodes[pv], triangles=nv[body.triangles[pt]],
                               node_sets={k: nv[v] for k, v in body.node_sets.items()},
                               element_sets={k: nt[v] for k, v in body.element_sets.items()})


def member(how: str) -> dict:
    real = sim.build_model
    sim.build_model = lambda bodies, **kw: real([renumbered(b, how) if b.fracturable else b for b in bodies], **kw)
    try:
        out = sim.simulate("brazilian_disc", "paper", POINT)
    finally:
        sim.build_model = real
    return {"solver_wall_s": out.run["solver_wall_s"], "element_updates_per_s": out.run["element_updates_per_s"],
            "curve": out.columns["stress_Pa"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    load_before = os.getloadavg()
    sim.warm_up()
    ways = ("mesher", "z_curve", "shuffled")
    runs = {w: [] for w in ways}
    for _ in range(a.repeat):
        for w in ways:
            runs[w].append(member(w))
    ref = runs["mesher"][0]["curve"]
    out = {"what": __doc__.split("\n\n")[0], "case": "paper disc, reference point", "point": POINT,
           "cores_on_machine": os.cpu_count(), "threads_used": 1, "python": platform.python_version(),
           "load_average_before": load_before, "load_average_after": os.getloadavg(), "repeat": a.repeat}
    for w in ways:
        best = min(runs[w], key=lambda r: r["solver_wall_s"])
        out[w] = {"solver_wall_s_all": [r["solver_wall_s"] for r in runs[w]],
                  "solver_wall_s": best["solver_wall_s"], "element_updates_per_s": best["element_updates_per_s"],
                  "speedup_over_mesher": None,
                  "max_diff_to_peak_over_peak": float(np.max(np.abs(best["curve"] - ref)) / np.max(ref))}
    for w in ways:
        out[w]["speedup_over_mesher"] = out["mesher"]["solver_wall_s"] / out[w]["solver_wall_s"]
    emit_json(out, OUT)


if __name__ == "__main__":
    main()
