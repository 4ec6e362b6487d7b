"""Meshing of the SHPB geometries with Shewchuk's Triangle: the disc (round or flattened), the
cylinder's rectangle, the graded bars, and the gauge sets (:mod:`shpb.geometry` builds on these)."""

from __future__ import annotations

import numpy as np
import triangle
from numba import njit

from fdem.body import Body, Material
from shpb.presets import MIN_ANGLE_DEG, Preset

#: The specimen's ``centre`` set: at least this many triangles.
CENTRE_MIN_TRIANGLES = 6


def bar_thickness(diameter_m: float) -> float:
    """Plane-stress thickness of a round bar of diameter D [m]: ``pi D / 4``, so that ``D t = pi D^2 / 4``."""
    return float(np.pi * diameter_m / 4.0)



def _sizes(p: Preset) -> dict[str, float]:
    return {"specimen": p.specimen_h_m, "bar": p.bar_h_m, "bar_near": p.bar_near_h_m}


def _area_opt(a: float) -> str:
    # Triangle's option parser does not read exponents: write the area in positional notation.
    return np.format_float_positional(a, trim="-")


def _triangulate(vertices: np.ndarray, segments: np.ndarray, max_area: float) -> tuple[np.ndarray, np.ndarray]:
    """Quality mesh of a polygon (no Steiner points on its boundary); returns CCW (nodes, triangles)."""
    out = triangle.triangulate({"vertices": vertices, "segments": segments},
                               f"pq{MIN_ANGLE_DEG:g}Ya{_area_opt(max_area)}Q")
    return _ccw(out["vertices"], out["triangles"])


def _ccw(nodes: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nodes = np.ascontiguousarray(nodes, dtype=np.float64)
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    flip = _signed_areas(nodes, tris) < 0
    tris[flip] = tris[flip][:, [0, 2, 1]]
    return nodes, tris


def _signed_areas(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = nodes[tris]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


def _triangle_areas(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    return np.abs(_signed_areas(nodes, tris))


def _loop_segments(n: int) -> np.ndarray:
    i = np.arange(n)
    return np.column_stack([i, (i + 1) % n])


def _mesh_disc(R: float, h: float, p: Preset, flat_half_angle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Disc of radius R centred at the origin: an inscribed polygon of n = 4k vertices, chord ~ h.

    Vertices at angles 0, pi/2, pi, 3pi/2 are placed exactly, so (-R, 0) and (R, 0) are nodes (the
    contact points with the bars). With flat_half_angle = alpha > 0 the disc has two flat loaded
    faces, the chords x = +-R cos(alpha), |y| <= R sin(alpha) (a flattened Brazilian disc), split into
    segments of about h.
    """
    if flat_half_angle > 0.0:
        return _mesh_flattened_disc(R, h, p, flat_half_angle)
    n = 4 * max(2, int(round(2.0 * np.pi * R / (4.0 * h))))
    theta = 2.0 * np.pi * np.arange(n) / n
    v = np.column_stack([R * np.cos(theta), R * np.sin(theta)])
    q = n // 4
    v[0] = (R, 0.0)
    v[q] = (0.0, R)
    v[2 * q] = (-R, 0.0)
    v[3 * q] = (0.0, -R)
    return _triangulate(v, _loop_segments(n), p.max_area(h))


def _mesh_flattened_disc(R: float, h: float, p: Preset, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Disc with two flats of half-angle alpha facing the bars (see _mesh_disc)."""
    xf = R * np.cos(alpha)
    yf = R * np.sin(alpha)
    n_flat = max(2, int(round(2.0 * yf / h)))
    n_arc = max(2, int(round(R * (np.pi - 2.0 * alpha) / h)))
    pts = []
    # right flat, bottom to top (x = +xf), then the upper arc, left flat top to bottom, lower arc
    pts += [(xf, y) for y in np.linspace(-yf, yf, n_flat + 1)[:-1]]
    pts += [(R * np.cos(t), R * np.sin(t)) for t in np.linspace(alpha, np.pi - alpha, n_arc + 1)[:-1]]
    pts += [(-xf, y) for y in np.linspace(yf, -yf, n_flat + 1)[:-1]]
    pts += [(R * np.cos(t), R * np.sin(t)) for t in np.linspace(np.pi + alpha, 2 * np.pi - alpha, n_arc + 1)[:-1]]
    v = np.array(pts)
    v[np.isclose(v[:, 0], xf), 0] = xf
    v[np.isclose(v[:, 0], -xf), 0] = -xf
    return _triangulate(v, _loop_segments(len(v)), p.max_area(h))


def _mesh_rectangle(x0: float, x1: float, height: float, h: float, p: Preset) -> tuple[np.ndarray, np.ndarray]:
    """Rectangle [x0, x1] x [-height/2, height/2] with a uniform boundary split of length ~ h."""
    nx = max(1, int(round((x1 - x0) / h)))
    ny = max(1, int(round(height / h)))
    y0, y1 = -0.5 * height, 0.5 * height
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y0, y1, ny + 1)
    xs[0], xs[-1], ys[0], ys[-1] = x0, x1, y0, y1
    v = np.concatenate([
        np.column_stack([xs[:-1], np.full(nx, y0)]),          # bottom, left to right
        np.column_stack([np.full(ny, x1), ys[:-1]]),          # right face, upwards
        np.column_stack([xs[::-1][:-1], np.full(nx, y1)]),    # top, right to left
        np.column_stack([np.full(ny, x0), ys[::-1][:-1]]),    # left face, downwards
    ])
    return _triangulate(v, _loop_segments(len(v)), p.max_area(h))


def _bar_size(s: np.ndarray, p: Preset) -> np.ndarray:
    """Element size [m] in a bar at distance s [m] from its specimen face."""
    return np.minimum(p.bar_h_m, p.bar_near_h_m + p.bar_grading * np.maximum(0.0, s - p.bar_near_length_m))


def _graded_stations(length: float, p: Preset) -> np.ndarray:
    """Stations 0 = s_0 < ... < s_n = length along a bar with local spacing ~ _bar_size(s)."""
    s = np.linspace(0.0, length, 20001)
    inv_h = 1.0 / _bar_size(s, p)
    count = np.concatenate([[0.0], np.cumsum(0.5 * (inv_h[1:] + inv_h[:-1]) * np.diff(s))])
    n = max(1, int(round(count[-1])))
    st = np.interp(np.arange(n + 1) * count[-1] / n, count, s)
    st[0], st[-1] = 0.0, length
    return st


def _split(height: float, h: float, odd: bool) -> np.ndarray:
    n = max(1, int(round(height / h)))
    if odd and n % 2 == 0:
        n += 1
    y = np.linspace(-0.5 * height, 0.5 * height, n + 1)
    y[0], y[-1] = -0.5 * height, 0.5 * height
    return y


def _split_face(height: float, h_coarse: float, h_fine: float, y_fine: float) -> np.ndarray:
    """Face stations: segments of about h_fine on |y| <= y_fine (an odd number, so that y = 0 falls
    inside a segment), about h_coarse beyond."""
    y_fine = min(y_fine, 0.5 * height)
    n = max(1, int(round(2.0 * y_fine / h_fine)))
    n += 1 - n % 2
    mid = np.linspace(-y_fine, y_fine, n + 1)
    rest = 0.5 * height - y_fine
    if rest <= 0.25 * h_fine:
        mid[0], mid[-1] = -0.5 * height, 0.5 * height
        return mid
    m = max(1, int(round(rest / h_coarse)))
    out = np.linspace(y_fine, 0.5 * height, m + 1)[1:]
    y = np.concatenate([-out[::-1], mid, out])
    y[0], y[-1] = -0.5 * height, 0.5 * height
    return y


def _mesh_bar(length: float, height: float, p: Preset, odd_face: bool,
              face_h: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar strip in local coordinates (s, y): s in [0, length] is the distance from the specimen face.

    Refined to ``bar_near_h_m`` near s = 0 and graded to ``bar_h_m`` (``_bar_size``). With ``odd_face`` the
    face s = 0 is split into an odd number of segments so that y = 0 (a disc's contact point) falls
    inside an edge, not on a node. ``face_h = (h, y_f)``: segments of about h on |y| <= y_f of the face
    (default: ``bar_near_h_m`` everywhere); the mesh grades from them.
    Returns (nodes, triangles, indices of the face nodes).
    """
    st = _graded_stations(length, p)
    y0, y1 = -0.5 * height, 0.5 * height
    if face_h is None:
        y_face = _split(height, p.bar_near_h_m, odd_face)
    else:
        y_face = _split_face(height, p.bar_near_h_m, min(face_h[0], p.bar_near_h_m), face_h[1])
    y_end = _split(height, float(_bar_size(np.array([length]), p)[0]), False)
    v = np.concatenate([
        np.column_stack([st[:-1], np.full(len(st) - 1, y0)]),               # bottom, s increasing
        np.column_stack([np.full(len(y_end) - 1, length), y_end[:-1]]),      # far end, upwards
        np.column_stack([st[::-1][:-1], np.full(len(st) - 1, y1)]),         # top, s decreasing
        np.column_stack([np.zeros(len(y_face) - 1), y_face[::-1][:-1]]),    # face s = 0, downwards
    ])
    seg = _loop_segments(len(v))
    out = triangle.triangulate({"vertices": v, "segments": seg},
                               f"pq{MIN_ANGLE_DEG:g}Ya{_area_opt(p.max_area(p.bar_h_m))}Q")
    # Refine to the graded size: the area cap of a triangle is set by the smallest size at its vertices.
    for _ in range(6):
        nodes, tris = out["vertices"], out["triangles"]
        target = p.max_area(_bar_size(nodes[tris][:, :, 0], p).min(axis=1))
        if face_h is not None:
            target = np.minimum(target, p.max_area(_face_size(nodes[tris], p, face_h[0], face_h[1])))
        if np.all(_triangle_areas(nodes, tris) <= target):
            break
        out = triangle.triangulate({"vertices": nodes, "segments": out["segments"], "triangles": tris,
                                    "triangle_max_area": target}, f"rpq{MIN_ANGLE_DEG:g}YaQ")
    nodes, tris = _ccw(out["vertices"], out["triangles"])
    return nodes, tris, np.flatnonzero(nodes[:, 0] == 0.0)


def _face_size(tri_nodes: np.ndarray, p: Preset, h_face: float, y_fine: float) -> np.ndarray:
    """Element size near a finely split face: the face's segment length on it (|y| <= y_fine),
    growing with the distance from that stretch (twice as fast) so that it does not force the whole
    bar end to its size."""
    s_min = np.maximum(tri_nodes[:, :, 0].min(axis=1), 0.0)
    y_out = np.maximum(np.abs(tri_nodes[:, :, 1]).min(axis=1) - y_fine, 0.0)
    return h_face + 2.0 * np.maximum(s_min, y_out)


def _bars(p: Preset, bar: Material, D: float, x_front: float, x_back: float, L_i: float, L_t: float,
          d_i: float, d_t: float, odd_face: bool,
          face_h: tuple[float, float] | None = None) -> tuple[Body, Body, tuple[float, float]]:
    """Incident bar on [x_front - L_i, x_front] and transmission bar on [x_back, x_back + L_t]."""
    t = bar_thickness(D)
    # Incident bar: x = x_front - s (a mirror image, so reverse the triangles to keep them CCW).
    s_nodes, tris, face = _mesh_bar(L_i, D, p, odd_face, face_h)
    x_load = x_front - L_i
    nodes = np.column_stack([x_front - s_nodes[:, 0], s_nodes[:, 1]])
    nodes[s_nodes[:, 0] == L_i, 0] = x_load
    nodes[face, 0] = x_front
    tris = tris[:, [0, 2, 1]].copy()
    xg_i = x_front - d_i
    incident = Body("incident_bar", nodes, tris, bar, thickness=t,
                    node_sets={"load_end": np.flatnonzero(nodes[:, 0] == x_load),
                               "specimen_face": face},
                    element_sets={"gauge": _gauge_set(nodes, tris, xg_i, float(_bar_size(np.array([d_i]), p)[0]))})
    # Transmission bar: x = x_back + s.
    s_nodes, tris, face = _mesh_bar(L_t, D, p, odd_face, face_h)
    x_end = x_back + L_t
    nodes = np.column_stack([x_back + s_nodes[:, 0], s_nodes[:, 1]])
    nodes[s_nodes[:, 0] == L_t, 0] = x_end
    nodes[face, 0] = x_back
    xg_t = x_back + d_t
    transmission = Body("transmission_bar", nodes, tris, bar, thickness=t,
                        node_sets={"specimen_face": face,
                                   "free_end": np.flatnonzero(nodes[:, 0] == x_end)},
                        element_sets={"gauge": _gauge_set(nodes, tris, xg_t,
                                                          float(_bar_size(np.array([d_t]), p)[0]))})
    return incident, transmission, (float(xg_i), float(xg_t))


def _gauge_set(nodes: np.ndarray, tris: np.ndarray, x_gauge: float, half_width: float) -> np.ndarray:
    xc = nodes[tris][:, :, 0].mean(axis=1)
    return np.flatnonzero(np.abs(xc - x_gauge) <= half_width)


def _centre_set(nodes: np.ndarray, tris: np.ndarray, centre: tuple[float, float],
                radius: float) -> tuple[np.ndarray, float]:
    """Triangles with centroid within ``radius`` of ``centre``, grown to at least CENTRE_MIN_TRIANGLES."""
    c = nodes[tris].mean(axis=1)
    r = np.hypot(c[:, 0] - centre[0], c[:, 1] - centre[1])
    if np.count_nonzero(r <= radius) < CENTRE_MIN_TRIANGLES:
        radius = float(np.sort(r)[CENTRE_MIN_TRIANGLES - 1])
    return np.flatnonzero(r <= radius), float(radius)


# --------------------------------------------------------------------------------------------------
# Mesh realizations (issue 30): random perturbation of the specimen's interior nodes
# --------------------------------------------------------------------------------------------------

#: Default radius of an interior node's random move, as a fraction of the shortest edge at the node.
MESH_JITTER = 0.25
#: A perturbed triangle may not be sharper than this fraction of the unperturbed mesh's minimum angle.
MIN_ANGLE_KEEP = 0.5
#: A move that breaks that is halved up to this many times, then dropped (the node stays).
MAX_HALVINGS = 4


def perturb_interior_nodes(nodes: np.ndarray, tris: np.ndarray, keep: np.ndarray, mesh_seed: int | None,
                           jitter: float = MESH_JITTER) -> np.ndarray:
    """One mesh realization: every node off the boundary and not in ``keep`` moves by a random vector,
    uniform in a disc of radius ``jitter`` x the shortest edge at that node, drawn from
    ``numpy.random.default_rng(mesh_seed)``; the topology does not change.

    The boundary stays (the specimen's shape and area, its contact faces), and so do the ``keep``
    nodes (node and element sets: the probes keep their triangles). Nodes move one after the other in
    index order; a move that would invert a triangle or make one sharper than MIN_ANGLE_KEEP x the
    mesh's minimum angle is halved, up to MAX_HALVINGS times, then dropped. ``mesh_seed=None``
    returns ``nodes`` itself (today's mesh, bit for bit).
    """
    if mesh_seed is None:
        return nodes
    _check_mesh_seed(mesh_seed, jitter)
    fixed = _boundary_nodes(tris, len(nodes))
    fixed[np.asarray(keep, dtype=np.int64)] = True
    # One draw per node, fixed or not, so that node i's draw depends on the seed and i only.
    move = _draws_in_unit_disc(np.random.default_rng(mesh_seed), len(nodes))
    move *= (jitter * _shortest_edge_at_nodes(nodes, tris))[:, None]
    floor = MIN_ANGLE_KEEP * float(_min_angles(nodes, tris).min())
    order = np.argsort(tris.ravel(), kind="stable")  # each node's star: the triangles that use it
    ptr = np.concatenate([[0], np.cumsum(np.bincount(tris.ravel(), minlength=len(nodes)))])
    out = np.array(nodes, dtype=np.float64, copy=True)
    _move_nodes(out, np.ascontiguousarray(tris, dtype=np.int64), ptr.astype(np.int64), (order // 3).astype(np.int64),
                np.flatnonzero(~fixed).astype(np.int64), move, floor, MAX_HALVINGS)
    return out


def _check_mesh_seed(mesh_seed, jitter: float) -> None:
    if isinstance(mesh_seed, bool) or not isinstance(mesh_seed, (int, np.integer)) or mesh_seed < 0:
        raise ValueError(f"mesh_seed must be None or an integer >= 0, got {mesh_seed!r}")
    # Half an edge would let two neighbours meet; a quarter keeps the mesh's quality (MIN_ANGLE_KEEP).
    if not (np.isfinite(jitter) and 0.0 <= jitter < 0.5):
        raise ValueError(f"mesh jitter must be in [0, 0.5) (a fraction of the shortest edge), got {jitter!r}")


def _edges(tris: np.ndarray) -> np.ndarray:
    """Every triangle's three edges as sorted node pairs, triangle by triangle (3 m rows)."""
    return np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)


def _boundary_nodes(tris: np.ndarray, n_nodes: int) -> np.ndarray:
    """Mask of the nodes on the mesh's boundary: the ends of edges that belong to one triangle only
    (read from the topology, so it holds for the disc, the flattened disc and the rectangle alike)."""
    e, count = np.unique(_edges(tris), axis=0, return_counts=True)
    mask = np.zeros(n_nodes, dtype=bool)
    mask[e[count == 1].ravel()] = True
    return mask


def _shortest_edge_at_nodes(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    e = _edges(tris)
    length = np.linalg.norm(nodes[e[:, 0]] - nodes[e[:, 1]], axis=1)
    h = np.full(len(nodes), np.inf)
    np.minimum.at(h, e[:, 0], length)
    np.minimum.at(h, e[:, 1], length)
    return h


def _draws_in_unit_disc(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points uniform in the unit disc (radius sqrt(U): uniform per area, not per radius)."""
    u = rng.random((n, 2))
    r, phi = np.sqrt(u[:, 0]), 2.0 * np.pi * u[:, 1]
    return np.column_stack([r * np.cos(phi), r * np.sin(phi)])


def _min_angles(nodes: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Smallest interior angle of each triangle [rad]; 0 for an inverted (clockwise) one."""
    p = nodes[tris]
    ang = []
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        w = p[:, (i + 2) % 3] - p[:, i]
        cross = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
        ang.append(np.arctan2(cross, np.sum(u * w, axis=1)))  # signed: negative when inverted
    return np.maximum(np.min(ang, axis=0), 0.0)


@njit(cache=True)
def _min_angle(p: np.ndarray, tri: np.ndarray) -> float:
    """:func:`_min_angles` of one triangle, operation for operation (the same roundings, libm's atan2)."""
    best = np.inf
    for i in range(3):
        a, b, c = tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]
        u0, u1 = p[b, 0] - p[a, 0], p[b, 1] - p[a, 1]
        w0, w1 = p[c, 0] - p[a, 0], p[c, 1] - p[a, 1]
        best = min(best, np.arctan2(u0 * w1 - u1 * w0, u0 * w0 + u1 * w1))
    return max(best, 0.0)


@njit(cache=True)
def _move_nodes(nodes, tris, ptr, star, free, move, floor, max_halvings) -> None:
    """Move each ``free`` node in turn (in place): the largest of move, move/2, ... (``max_halvings``
    times) that keeps every triangle of its star (``star[ptr[i]:ptr[i + 1]]``) counter-clockwise and no
    sharper than ``floor`` [rad]; the old position if none does. Compiled: the loop ran in Python at
    about 50 ms a mesh, a quarter of a `fast` member's time outside its solver."""
    for i in free:
        old0, old1 = nodes[i, 0], nodes[i, 1]
        kept = False
        for k in range(max_halvings + 1):
            f = 0.5 ** k
            nodes[i, 0] = old0 + move[i, 0] * f
            nodes[i, 1] = old1 + move[i, 1] * f
            worst = np.inf
            for s in range(ptr[i], ptr[i + 1]):
                worst = min(worst, _min_angle(nodes, tris[star[s]]))
            if worst >= floor:
                kept = True
                break
        if not kept:
            nodes[i, 0] = old0
            nodes[i, 1] = old1
