"""Small mesh generators for tests and simple bodies (the SHPB geometries live in shpb.geometry).

Unstructured meshes come from Shewchuk's Triangle (the `triangle` package).
"""
from __future__ import annotations

import numpy as np
import triangle as tr


def rectangle(x0: float, y0: float, lx: float, ly: float, nx: int, ny: int, pattern: str = "cross"):
    """Structured triangulation of a rectangle with nx x ny cells.

    pattern 'right': each cell split along one diagonal; 'alternate': diagonals alternate (no
    preferred direction). Returns (nodes (n, 2), triangles (m, 3)).
    """
    if nx < 1 or ny < 1 or lx <= 0 or ly <= 0:
        raise ValueError("rectangle needs lx, ly > 0 and nx, ny >= 1")
    xs = np.linspace(x0, x0 + lx, nx + 1)
    ys = np.linspace(y0, y0 + ly, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    nodes = np.column_stack([X.ravel(), Y.ravel()])
    tris = []
    for j in range(ny):
        for i in range(nx):
            n00 = j * (nx + 1) + i
            n10 = n00 + 1
            n01 = n00 + nx + 1
            n11 = n01 + 1
            if pattern == "alternate" and (i + j) % 2:
                tris += [(n00, n10, n01), (n10, n11, n01)]
            else:
                tris += [(n00, n10, n11), (n00, n11, n01)]
    return nodes, np.array(tris, np.int64)


def disc(radius: float, h: float, center=(0.0, 0.0), quality: float = 30.0, extra_points=None):
    """Quality triangulation of a disc with boundary segments and target edge length about h.

    extra_points: optional (k, 2) points forced into the mesh (e.g. the load points).
    Returns (nodes, triangles).
    """
    if radius <= 0 or h <= 0:
        raise ValueError("disc needs radius > 0 and h > 0")
    nseg = max(12, int(np.ceil(2 * np.pi * radius / h)))
    th = 2 * np.pi * np.arange(nseg) / nseg
    pts = np.column_stack([center[0] + radius * np.cos(th), center[1] + radius * np.sin(th)])
    seg = np.column_stack([np.arange(nseg), (np.arange(nseg) + 1) % nseg])
    if extra_points is not None:
        pts = np.vstack([pts, np.asarray(extra_points, float)])
    max_area = np.sqrt(3) / 4 * h**2
    out = tr.triangulate({"vertices": pts, "segments": seg}, f"pq{quality:g}a{max_area:.15f}Q")
    return np.asarray(out["vertices"]), np.asarray(out["triangles"], np.int64)
