"""Pictures of a fracture: the deformed mesh with joint damage as VTK (ParaView) and a PNG damage map.

Written by ``python -m shpb simulate ... --snapshots`` and by the workflow's forecast run. Each VTK file
(``.vtu``, written with meshio) holds every triangle of the model at the snapshot's coordinates, with
cell data ``body`` (index into the model's bodies) and ``damage`` (a triangle's largest joint damage),
and every joint as a line cell between its first pair of nodes with ``damage`` in [0, 1] and
``broken`` (0/1); point data ``displacement`` [m]. Files are written to a temporary name and renamed
(:func:`shpb.atomic.create_temp`: the mode of a normally created file, 0644 under umask 022).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .atomic import create_temp


def _replace_into(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = create_temp(path.parent, prefix=f".{path.stem}-", suffix=path.suffix)  # mode 0666 & ~umask
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def triangle_damage(model, D: np.ndarray) -> np.ndarray:
    """Largest damage of the joints on each triangle's edges (0 for triangles without joints)."""
    out = np.zeros(model.n_triangles)
    if model.n_joints:
        tA = model.edge_tri[model.jedges[:, 0]]
        tB = model.edge_tri[model.jedges[:, 1]]
        np.maximum.at(out, tA, D)
        np.maximum.at(out, tB, D)
    return out


def write_vtk(path, model, snapshot) -> Path:
    """The model at one snapshot as an unstructured VTK file (see module docstring)."""
    import meshio

    path = Path(path)
    x = np.asarray(snapshot.x)
    pts = np.column_stack([x, np.zeros(len(x))])
    disp = np.column_stack([x - model.x0, np.zeros(len(x))])
    D = np.clip(np.asarray(snapshot.D, float), 0.0, 1.0)
    cells = [("triangle", model.tri)]
    cell_data = {"body": [model.tri_body.astype(np.int32)], "damage": [triangle_damage(model, D)],
                 "broken": [np.zeros(model.n_triangles, np.int32)]}
    if model.n_joints:
        cells.append(("line", model.jn[:, :2]))
        cell_data["body"].append(model.j_body.astype(np.int32))
        cell_data["damage"].append(D)
        cell_data["broken"].append((D >= 1.0).astype(np.int32))
    mesh = meshio.Mesh(pts, cells, point_data={"displacement": disp}, cell_data=cell_data)
    _replace_into(path, lambda tmp: mesh.write(tmp, file_format="vtu"))
    return path


def _draw_damage(fig, ax, model, geometry, snapshot, title: str = "") -> None:
    """Deformed triangles, the specimen's damaged joints coloured by damage, broken ones black."""
    from matplotlib.collections import LineCollection

    x = np.asarray(snapshot.x) * 1e3
    D = np.clip(np.asarray(snapshot.D, float), 0.0, 1.0)
    spec = model.body_index(geometry.specimen)
    for b, colour in ((model.body_index(geometry.incident_bar), "0.55"),
                      (model.body_index(geometry.transmission_bar), "0.55"), (spec, "0.85")):
        tris = model.tri[model.tri_body == b]
        ax.triplot(x[:, 0], x[:, 1], tris, color=colour, lw=0.25)
    sel = np.flatnonzero((model.j_body == spec) & (D > 0.0))
    if sel.size:
        segs = np.stack([x[model.jn[sel, 0]], x[model.jn[sel, 1]]], axis=1)
        broken = D[sel] >= 1.0
        lc = LineCollection(segs[~broken], array=D[sel][~broken], cmap="YlOrRd", linewidths=1.2)
        lc.set_clim(0.0, 1.0)
        ax.add_collection(lc)
        ax.add_collection(LineCollection(segs[broken], colors="k", linewidths=1.8))
        fig.colorbar(lc, ax=ax, label="joint damage D (black: broken)", shrink=0.8)
    R = 0.5e3 * geometry.specimen_dims["diameter_m"]
    half = 1.15 * max(R, 0.5e3 * geometry.specimen_dims.get("length_m", 0.0))
    ax.set_xlim(-half, half)
    ax.set_ylim(-1.15 * R, 1.15 * R)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm] (load axis)")
    ax.set_ylabel("y [mm]")
    ax.set_title(title, fontsize=9)


def damage_map(path, model, geometry, snapshot, title: str = "") -> Path:
    """PNG of the specimen at one snapshot: deformed triangles, joints coloured by damage, broken joints
    black, the bars' end faces for reference. Axes in mm, the specimen's frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    fig = Figure(figsize=(6.4, 5.6))
    FigureCanvasAgg(fig)
    _draw_damage(fig, fig.add_subplot(1, 1, 1), model, geometry, snapshot, title)
    fig.tight_layout()
    _replace_into(path, lambda tmp: fig.savefig(tmp, dpi=130, format="png"))
    return path


def fracture_overview(path, model, geometry, curve, frames) -> Path:
    """PNG of a run's curve next to its fracture: the specimen stress and the two faces' stresses
    against time with the snapshot times marked, and one damage map per frame.

    curve: the run's curve (``time_s``, ``stress_Pa``, ``stress_front_Pa``, ``stress_back_Pa``);
    frames: [(label, snapshot, time on the curve's axis [s])], e.g. the failure peak and the end."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    fig = Figure(figsize=(5.2 * (1 + len(frames)), 4.6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1 + len(frames), 1)
    t_us = np.asarray(curve["time_s"]) * 1e6
    ax.plot(t_us, np.asarray(curve["stress_Pa"]) / 1e6, "k", lw=1.5, label="specimen (back face)")
    ax.plot(t_us, np.asarray(curve["stress_front_Pa"]) / 1e6, "C0--", lw=1.0, label="front face")
    ax.plot(t_us, np.asarray(curve["stress_back_Pa"]) / 1e6, "C3:", lw=1.0, label="back face")
    for label, _, t in frames:
        ax.axvline(t * 1e6, color="0.5", lw=0.8)
        ax.text(t * 1e6, ax.get_ylim()[1], f" {label}", fontsize=8, va="top", rotation=90)
    ax.set_xlabel("time after the incident wave's arrival [us]")
    ax.set_ylabel("stress [MPa]")
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(f"{geometry.kind}, {geometry.preset}", fontsize=9)
    for k, (label, snap, t) in enumerate(frames):
        _draw_damage(fig, fig.add_subplot(1, 1 + len(frames), k + 2), model, geometry, snap,
                     f"{label}: t = {t * 1e6:.1f} us, {int(np.sum(np.asarray(snap.D) >= 1.0))} joints broken")
    fig.tight_layout()
    _replace_into(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return path


def failure_card(path, text: str) -> Path:
    """PNG that says a run left no picture and why (a failed forecast has no fracture to show)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    fig = Figure(figsize=(6.4, 2.0))
    FigureCanvasAgg(fig)
    fig.text(0.02, 0.5, text, fontsize=9, va="center", wrap=True)
    _replace_into(path, lambda tmp: fig.savefig(tmp, dpi=100, format="png"))
    return path
