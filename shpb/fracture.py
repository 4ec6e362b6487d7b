"""How a simulated specimen broke: where fracture started, where the broken joints are, force balance.

A Brazilian test measures tensile strength only when the crack starts at the centre and runs along the
loaded diameter while the two loaded faces carry the same force (Li & Wong 2013, review; Dai et al.
2010 for the dynamic case). These numbers say whether a simulated disc did that; ``run.json`` carries
them (``fracture``) and the tests and ``benchmarks/bench_shpb.py`` assert them.

Coordinates are those of the reference (undeformed) mesh, in units of the specimen radius R, with the
load along x and the specimen centre at the origin. A joint's position is its midpoint.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The central region where the first joint must reach its strength: |x| < 0.5 R, |y| < 0.1 R.
CENTRAL_X, CENTRAL_Y = 0.5, 0.1
#: The band around the loaded diameter that must hold the broken joints at the peak: |y| < 0.15 R.
BAND_Y = 0.15
#: The failure peak: the running maximum of the specimen stress until the curve first falls this
#: fraction below it. Flattened Brazilian disc: 1 %, i.e. the first load maximum, the crack-initiation
#: load P_max from which Wang et al. (2004) compute the tensile strength; after the central split the
#: two halves can carry load again on the flats (their local minimum and second rise), and cracks
#: from the rim and the flats' corners that form then are not the Brazilian failure. The intact
#: disc's stress rises monotonically under the ramp (measured at every preset and check point), so
#: a 1 % dip is a failure, not ringing. Cylinder: 15 %, the compressive strength is the global
#: maximum, and the compacting specimen's curve wobbles by a few per cent before it.
PEAK_DROP = {"brazilian_disc": 0.01, "cylinder": 0.15}
#: Specimen stress [Pa] below which a dip is noise before the load arrives, not a failure.
PEAK_FLOOR_PA = 2e6
#: A valid test: at least this share of the broken joints in the band at the peak, and the two loaded
#: faces within this fraction of each other's force there.
BAND_SHARE, BALANCE = 0.7, 0.10
#: The Table 2 reference and two more points of the box (sigma_t [Pa], E_t [J/m^2]) at which the disc
#: must fail as a Brazilian disc: weak and brittle, strong and tough.
CHECK_POINTS = {"reference": (45e6, 500.0), "weak_brittle": (30e6, 300.0), "strong_tough": (50e6, 700.0)}


@dataclass(frozen=True)
class FractureSummary:
    """Failure pattern of one run (positions in units of R, times on the curve's time axis [s]).

    first_joint_xy / first_joint_t_s: the joint that reached its strength first.
    peak_t_s, peak_stress_Pa: the failure peak of the specimen stress (first peak, PEAK_DROP by geometry).
    broken_at_peak, broken_in_band_at_peak: joints broken by then, and those with |y| < BAND_Y.
    damaged_at_peak: joints with damage > 0 by then.
    force_ratio_at_peak: F_front / F_back at the peak.
    broken_at_end: joints broken at the window's end.
    overlap_at_peak_m, overlap_at_end_m: deepest node of the specimen inside another of its triangles
    (pieces passing through each other; overlap_depth).
    """

    first_joint_xy: tuple[float, float] | None
    first_joint_t_s: float | None
    peak_t_s: float
    peak_stress_Pa: float
    broken_at_peak: int
    broken_in_band_at_peak: int
    damaged_at_peak: int
    force_ratio_at_peak: float
    broken_at_end: int
    overlap_at_peak_m: float = 0.0
    overlap_at_end_m: float = 0.0

    @property
    def band_fraction_at_peak(self) -> float:
        return self.broken_in_band_at_peak / self.broken_at_peak if self.broken_at_peak else float("nan")

    @property
    def starts_central(self) -> bool:
        return (self.first_joint_xy is not None and abs(self.first_joint_xy[0]) < CENTRAL_X
                and abs(self.first_joint_xy[1]) < CENTRAL_Y)

    def checks(self) -> dict:
        """The three Brazilian-test conditions (module docstring), each True or False."""
        return {"starts_central": bool(self.starts_central),
                "broken_along_diameter": bool(self.broken_at_peak > 0 and self.band_fraction_at_peak >= BAND_SHARE),
                "faces_balanced": bool(abs(self.force_ratio_at_peak - 1.0) <= BALANCE)}

    def to_dict(self) -> dict:
        return {"checks": self.checks(), **self._fields()}

    def _fields(self) -> dict:
        return {
            "first_joint_xy_over_R": None if self.first_joint_xy is None else [float(v) for v in self.first_joint_xy],
            "first_joint_t_s": self.first_joint_t_s, "starts_central": bool(self.starts_central),
            "peak_t_s": float(self.peak_t_s), "peak_stress_Pa": float(self.peak_stress_Pa),
            "broken_at_peak": int(self.broken_at_peak),
            "broken_in_band_at_peak": int(self.broken_in_band_at_peak),
            "band_fraction_at_peak": (None if not self.broken_at_peak else float(self.band_fraction_at_peak)),
            "damaged_at_peak": int(self.damaged_at_peak),
            "force_ratio_at_peak": float(self.force_ratio_at_peak),
            "broken_at_end": int(self.broken_at_end),
            "overlap_at_peak_m": float(self.overlap_at_peak_m),
            "overlap_at_end_m": float(self.overlap_at_end_m),
        }


def overlap_depth(model, x: np.ndarray, body: str) -> tuple[float, int]:
    """How far the body's nodes sit inside its own triangles that are not theirs, at coordinates x:
    (largest depth [m], number of nodes inside some other triangle). A node of a triangle that
    shares its mesh vertex is not counted (that is the same point of the intact body); anything else
    is one piece of the body passing through another. Found on a cell grid, independent of the
    contact search, so it also sees what contact let through."""
    b = model.body_index(body)
    tris = model.tri[model.tri_body == b]
    nodes = np.unique(tris)
    if tris.shape[0] == 0:
        return 0.0, 0
    P = x[tris]                                   # (m, 3, 2)
    lo, hi = P.min(axis=1), P.max(axis=1)
    h = float(np.sqrt(np.median(np.abs(0.5 * ((P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
                                             - (P[:, 1, 1] - P[:, 0, 1]) * (P[:, 2, 0] - P[:, 0, 0]))))))
    origin = lo.min(axis=0)
    i0 = np.floor((lo - origin) / h).astype(np.int64)
    i1 = np.floor((hi - origin) / h).astype(np.int64)
    # (triangle, cell) entries: every cell a triangle's bounding box touches, sorted by cell key
    nx, ny = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
    t_of = np.repeat(np.arange(tris.shape[0]), nx * ny)
    k = np.arange(t_of.size) - np.repeat(np.cumsum(nx * ny) - nx * ny, nx * ny)
    cx = i0[t_of, 0] + k % nx[t_of]
    cy = i0[t_of, 1] + k // nx[t_of]
    span = int(max(i1[:, 1].max(), 0)) + 2
    key = cx * span + cy
    order = np.argsort(key, kind="stable")
    key, t_of = key[order], t_of[order]
    # (node, candidate triangle) pairs: the triangles of the node's own cell
    cell_of = np.floor((x[nodes] - origin) / h).astype(np.int64)
    nkey = cell_of[:, 0] * span + cell_of[:, 1]
    first, last = np.searchsorted(key, nkey, "left"), np.searchsorted(key, nkey, "right")
    cnt = last - first
    node_k = np.repeat(np.arange(nodes.size), cnt)
    cand = t_of[np.repeat(first, cnt) + np.arange(node_k.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    vert = model.node_vertex
    keep = ~np.any(vert[tris[cand]] == vert[nodes[node_k]][:, None], axis=1)
    node_k, cand = node_k[keep], cand[keep]
    p = x[nodes[node_k]]
    depth = np.full(cand.size, np.inf)
    inside = np.ones(cand.size, bool)
    for u, w in ((P[cand, 0], P[cand, 1]), (P[cand, 1], P[cand, 2]), (P[cand, 2], P[cand, 0])):
        e = w - u
        L = np.hypot(e[:, 0], e[:, 1])
        # signed distance to the edge line, positive on the triangle's (counter-clockwise) inside
        dist = (e[:, 0] * (p[:, 1] - u[:, 1]) - e[:, 1] * (p[:, 0] - u[:, 0])) / L
        inside &= dist > 0.0
        depth = np.minimum(depth, dist)
    if not np.any(inside):
        return 0.0, 0
    return float(depth[inside].max()), int(np.unique(node_k[inside]).size)


def joint_midpoints(model, specimen: str, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the specimen's joints, their reference midpoints / R (n, 2))."""
    idx = np.flatnonzero(model.j_body == model.body_index(specimen))
    mid = 0.5 * (model.x0[model.jn[idx, 0]] + model.x0[model.jn[idx, 1]]) / radius_m
    return idx, mid


def first_peak(stress: np.ndarray, drop: float, floor: float = PEAK_FLOOR_PA) -> int:
    """Index of the failure peak: the running maximum until the curve first falls by ``drop`` below it
    (the global maximum if it never does). Drops while the running maximum is below ``floor`` [Pa]
    are noise before the load, not a failure. The engine keeps its peak snapshot by the same rule
    (fdem.run's peak_drop / peak_floor), so the two agree sample for sample."""
    stress = np.asarray(stress, float)
    best = 0
    for i in range(1, len(stress)):
        if stress[i] > stress[best]:
            best = i
        elif stress[best] > floor and stress[i] < (1.0 - drop) * stress[best]:
            break
    return best


def summarize(model, geometry, result, curve, arrival_s: float) -> FractureSummary:
    """Failure pattern of a run of ``shpb.simulate`` (curve time axis: 0 at the wave's arrival)."""
    R = 0.5 * geometry.specimen_dims["diameter_m"]
    idx, mid = joint_midpoints(model, geometry.specimen, R)
    t = np.asarray(curve["time_s"])
    sigma = np.asarray(curve["stress_Pa"])
    ip = first_peak(sigma, PEAK_DROP[geometry.kind])
    t_peak = float(t[ip])
    onset = result.joint_onset_t[idx] - arrival_s
    brk = result.joint_break_t[idx] - arrival_s
    started = result.joint_onset_t[idx] >= 0.0
    first = None
    t_first = None
    if np.any(started):
        k = int(np.argmin(np.where(started, onset, np.inf)))
        first = (float(mid[k, 0]), float(mid[k, 1]))
        t_first = float(onset[k])
    broken_peak = (result.joint_break_t[idx] >= 0.0) & (brk <= t_peak + 1e-12)
    damaged_peak = started & (onset <= t_peak + 1e-12)
    front = np.asarray(curve["stress_front_Pa"])[ip]
    back = np.asarray(curve["stress_back_Pa"])[ip]
    return FractureSummary(
        first_joint_xy=first, first_joint_t_s=t_first, peak_t_s=t_peak, peak_stress_Pa=float(sigma[ip]),
        broken_at_peak=int(broken_peak.sum()),
        broken_in_band_at_peak=int((broken_peak & (np.abs(mid[:, 1]) < BAND_Y)).sum()),
        damaged_at_peak=int(damaged_peak.sum()),
        force_ratio_at_peak=float(front / back) if back > 0 else float("nan"),
        broken_at_end=int((result.joint_break_t[idx] >= 0.0).sum()),
        overlap_at_peak_m=(overlap_depth(model, result.peak.x, geometry.specimen)[0]
                           if result.peak is not None else float("nan")),
        overlap_at_end_m=overlap_depth(model, result.x, geometry.specimen)[0])
