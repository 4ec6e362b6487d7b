"""Python front end of a simulation: loads, probes, the compiled step loop, and the result."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .integrator import ENERGY_NAMES, STATUS_ENERGY, STATUS_NONFINITE, STATUS_OK, STATUS_RUNAWAY, run_loop
from .model import DEFAULT_SAFETY, WAKE_TRACTION, Model, stable_time_step
from .state import (Loads, Outputs, Probes, Settings, bodies_of, joint_state, joints_of, nodes_of, surfaces_of,
                    triangles_of)


@dataclass
class VelocityBC:
    """Prescribed velocity [m/s] of `nodes` in `direction` (0 = x, 1 = y), piecewise linear in time."""

    nodes: np.ndarray
    direction: int
    times: np.ndarray
    values: np.ndarray


@dataclass
class TractionBC:
    """Nodal force in `direction`: F = area * (traction(t) - impedance * v) [N].

    area: tributary area per node [m^2]; traction [Pa] piecewise linear in time; impedance [Pa s/m]
    turns the boundary into a dashpot. For a bar end that injects an incident wave sigma_I and
    absorbs everything returning, use traction = 2 sigma_I and impedance = rho c (1D wave theory:
    sigma = sigma_I + sigma_R, v = (sigma_I - sigma_R) / (rho c)).
    """

    nodes: np.ndarray
    direction: int
    area: np.ndarray
    times: np.ndarray
    traction: np.ndarray
    impedance: float | np.ndarray = 0.0


@dataclass
class Snapshot:
    """State of the model at one time: deformed coordinates x (n_nodes, 2) [m] and each joint's
    damage D (n_joints,) in [0, 1] (1 = broken)."""

    time: float
    x: np.ndarray
    D: np.ndarray


@dataclass
class Result:
    """Sampled histories of a run. Stresses [Pa] are area-weighted means of Cauchy stress
    (sxx, syy, sxy) over element sets; node probes are mean (ux, uy, vx, vy); body forces are the
    contact forces acting on each body [N] (per unit thickness already integrated)."""

    time: np.ndarray
    energy: dict
    body_force: np.ndarray
    stress: dict
    nodes: dict
    broken: np.ndarray
    penetration: np.ndarray
    status: str
    message: str
    dt: float
    steps: int
    wall_s: float
    updates_per_s: float
    contact_rebuilds: int
    x: np.ndarray
    v: np.ndarray
    Dmax: np.ndarray
    joint_broken: np.ndarray
    body_names: list = field(default_factory=list)
    joint_onset_t: np.ndarray | None = None
    joint_break_t: np.ndarray | None = None
    body_wake_t: dict = field(default_factory=dict)  # when each body woke [s] (0: awake from the start, -1: never)
    snapshots: list = field(default_factory=list)
    peak: Snapshot | None = None

    def energy_balance_error(self) -> np.ndarray:
        """(sum of stored + dissipated energies - initial energy - external work), per sample [J]."""
        e = self.energy
        stored = sum(e[k] for k in ENERGY_NAMES if k != "external_work")
        return stored - stored[0] - e["external_work"] + e["external_work"][0]

    def body_force_of(self, name: str) -> np.ndarray:
        return self.body_force[:, self.body_names.index(name), :]


def _pack_histories(velocity_bcs, traction_bcs):
    ptr, ts, vs = [0], [], []
    for bc in list(velocity_bcs) + list(traction_bcs):
        t = np.asarray(bc.times, float)
        val = np.asarray(bc.values if isinstance(bc, VelocityBC) else bc.traction, float)
        if t.ndim != 1 or t.shape != val.shape or t.size < 1:
            raise ValueError("a load history needs 1D times and values of equal length")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            raise ValueError("load history times must increase strictly")
        if not np.all(np.isfinite(val)):
            raise ValueError("load history values must be finite")
        if t.size == 1:
            t = np.array([t[0], t[0] + 1.0])
            val = np.array([val[0], val[0]])
        ts.append(t)
        vs.append(val)
        ptr.append(ptr[-1] + t.size)
    if not ts:
        return np.zeros(1, np.int64), np.zeros(0), np.zeros(0)
    return np.array(ptr, np.int64), np.concatenate(ts), np.concatenate(vs)


def _csr(groups):
    ptr = [0]
    idx = []
    for g in groups:
        g = np.asarray(g, np.int64)
        if g.size == 0:
            raise ValueError("a probe set is empty")
        idx.append(g)
        ptr.append(ptr[-1] + g.size)
    return np.array(ptr, np.int64), (np.concatenate(idx) if idx else np.zeros(0, np.int64))


def _resolve(sets, probes, kind):
    out = {}
    for p in probes or []:
        if isinstance(p, str):
            if p not in sets:
                raise KeyError(f"unknown {kind} set {p!r}; known: {sorted(sets)}")
            out[p] = sets[p]
        else:
            name, idx = p
            out[name] = np.asarray(idx, np.int64)
    return out


def run(model: Model, t_end: float, *, dt: float | None = None, safety: float = DEFAULT_SAFETY,
        sample_dt: float | None = None, velocity_bcs=(), traction_bcs=(), stress_probes=(),
        node_probes=(), x_init=None, v_init=None, energy_guard: float = 10.0,
        snapshot_times=(), track_peak=None, peak_drop: float = 0.0, peak_floor: float = 0.0,
        sleep: bool = True) -> Result:
    """Run an explicit dynamic simulation from t = 0 to t_end [s].

    dt: time step (default: stable_time_step(model, safety)); sample_dt: output interval
    (default: about 500 samples); stress_probes / node_probes: element / node set names of the
    model, or (name, indices) pairs. energy_guard: the run stops with status 'failed' when the
    energy balance error exceeds this multiple of (external work + initial energy), the signature
    of a numerical instability. The model itself is not modified.
    snapshot_times: times [s] at which the deformed mesh and the joint damage are kept (each taken at
    the first step at or after it; Result.snapshots). track_peak = (body name, direction, sign): keep
    the sampled state at which sign * (contact force on that body along direction) is largest
    (Result.peak), e.g. the peak of the transmitted force; peak_drop > 0 keeps the first peak: the
    search stops once the force has fallen by that fraction below its running maximum, once that
    maximum exceeds peak_floor [N] (a specimen that splits and then carries load again has its
    failure peak first). Result.joint_onset_t / joint_break_t give,
    per joint, when it first reached its strength and when it broke (-1: never).
    sleep: a body at rest in its reference state sleeps, its triangles and joints not evaluated, until a
    nodal force above WAKE_TRACTION reaches it (fdem.integrator._wake); False evaluates every body at
    every step.
    """
    if not (np.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be > 0 s, got {t_end}")
    if dt is None:
        dt = stable_time_step(model, safety)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"time step must be > 0 s, got {dt}")
    n_steps = int(np.ceil(t_end / dt))
    if sample_dt is None:
        sample_dt = t_end / 500.0
    sample_every = max(1, int(round(sample_dt / dt)))
    # whole sample intervals, so the last sample lies at or after t_end: callers compare the curve with
    # data up to t_end, and a window ending up to one interval short would leave its last point uncovered
    n_steps = -(-n_steps // sample_every) * sample_every
    n_samples = n_steps // sample_every + 1

    x = np.array(model.x0 if x_init is None else x_init, dtype=np.float64, order="C")
    v = np.zeros_like(x) if v_init is None else np.array(v_init, dtype=np.float64, order="C")
    hist_ptr, hist_t, hist_v = _pack_histories(velocity_bcs, traction_bcs)
    nv = len(velocity_bcs)
    vel_nodes, vel_dir, vel_hist = [], [], []
    for h, bc in enumerate(velocity_bcs):
        nodes = np.asarray(bc.nodes, np.int64)
        vel_nodes.append(nodes)
        vel_dir.append(np.full(nodes.size, int(bc.direction)))
        vel_hist.append(np.full(nodes.size, h))
    tr_nodes, tr_dir, tr_area, tr_imp, tr_hist = [], [], [], [], []
    for h, bc in enumerate(traction_bcs):
        nodes = np.asarray(bc.nodes, np.int64)
        tr_nodes.append(nodes)
        tr_dir.append(np.full(nodes.size, int(bc.direction)))
        tr_area.append(np.broadcast_to(np.asarray(bc.area, float), nodes.shape))
        tr_imp.append(np.broadcast_to(np.asarray(bc.impedance, float), nodes.shape))
        tr_hist.append(np.full(nodes.size, nv + h))

    def cat(lst, dtype):
        return np.ascontiguousarray(np.concatenate(lst).astype(dtype)) if lst else np.zeros(0, dtype)

    stress_sets = _resolve(model.element_sets, stress_probes, "element")
    node_sets = _resolve(model.node_sets, node_probes, "node")
    eg_ptr, eg_el = _csr(stress_sets.values())
    ng_ptr, ng_nodes = _csr(node_sets.values())
    nb = len(model.body_names)

    out_t = np.zeros(n_samples)
    out_energy = np.zeros((n_samples, 8))
    out_bforce = np.zeros((n_samples, nb, 2))
    out_stress = np.zeros((n_samples, max(len(stress_sets), 1), 3))
    out_nodes = np.zeros((n_samples, max(len(node_sets), 1), 4))
    out_broken = np.zeros(n_samples, np.int64)
    out_pen = np.zeros(n_samples)
    edge_active = model.edge_active0.copy()
    c = model.contact
    use_contact = c is not None
    buffer = 0.0
    if use_contact:
        buffer = c.buffer if c.buffer is not None else 0.3 * float(
            np.min(model.edge_dlim[model.edge_active0]) * 2.0)
    snap_t = np.sort(np.asarray(snapshot_times, float).reshape(-1))
    if snap_t.size and not (np.all(np.isfinite(snap_t)) and snap_t[0] >= 0.0):
        raise ValueError(f"snapshot times must be finite and >= 0 s, got {snapshot_times!r}")
    snap_steps = np.minimum(np.ceil(snap_t / dt - 1e-9), n_steps).astype(np.int64)
    snap_x = np.zeros((snap_steps.size, model.n_nodes, 2))
    snap_D = np.zeros((snap_steps.size, model.n_joints))
    track = np.array([-1, 0, 1], np.int64)
    if track_peak is not None:
        name, direction, sign = track_peak
        track[:] = (model.body_index(name), int(direction), 1 if sign >= 0 else -1)
    peak_x = np.zeros((model.n_nodes, 2))
    peak_D = np.zeros(model.n_joints)
    if not (0.0 <= peak_drop < 1.0):
        raise ValueError(f"peak_drop must be in [0, 1), got {peak_drop}")
    peak_info = np.array([0.0, 0.0, -1.0, float(peak_drop), 0.0, float(peak_floor)])
    j_onset = -np.ones(model.n_joints)
    j_break = -np.ones(model.n_joints)

    nodes = nodes_of(model, x, v)
    js = joint_state(model.n_joints)
    surf = surfaces_of(model, edge_active, c.table(model.body_names) if use_contact else np.zeros((nb, nb)),
                       c.friction_table(model.body_names) if use_contact else np.zeros((nb, nb)))
    loads = Loads(cat(vel_nodes, np.int64), cat(vel_dir, np.int64), cat(vel_hist, np.int64),
                  cat(tr_nodes, np.int64), cat(tr_dir, np.int64), cat(tr_area, float), cat(tr_imp, float),
                  cat(tr_hist, np.int64), hist_ptr, hist_t, hist_v)
    out = Outputs(out_t, out_energy, out_bforce, out_stress, out_nodes, out_broken, out_pen, j_onset, j_break,
                  snap_steps, snap_x, snap_D, track, peak_x, peak_D, peak_info)
    settings = Settings(float(dt), n_steps, sample_every, float(model.alpha_mass), float(energy_guard),
                        float(buffer), use_contact, nb)
    t0 = time.perf_counter()
    bodies = bodies_of(model, x, v, loads.vel_nodes, loads.tr_nodes, WAKE_TRACTION, sleep)
    status, ns, steps, E, rebuilds = run_loop(nodes, triangles_of(model), joints_of(model), js, surf, loads,
                                              Probes(eg_ptr, eg_el, ng_ptr, ng_nodes), out, settings, bodies)
    wall = time.perf_counter() - t0
    msg = {STATUS_OK: "completed",
           STATUS_NONFINITE: f"non-finite state at t = {out_t[max(ns - 1, 0)]:.3e} s (numerical instability)",
           STATUS_ENERGY: f"energy balance diverged at t = {out_t[max(ns - 1, 0)]:.3e} s (numerical instability)",
           STATUS_RUNAWAY: f"a node crossed the contact buffer in one step after t = {out_t[max(ns - 1, 0)]:.3e} s "
                           "(numerical instability)"}[status]
    updates = (model.n_triangles + model.n_joints) * steps
    return Result(
        time=out_t[:ns], energy={k: out_energy[:ns, i] for i, k in enumerate(ENERGY_NAMES)},
        body_force=out_bforce[:ns], stress={k: out_stress[:ns, i] for i, k in enumerate(stress_sets)},
        nodes={k: out_nodes[:ns, i] for i, k in enumerate(node_sets)}, broken=out_broken[:ns],
        penetration=out_pen[:ns], status="ok" if status == STATUS_OK else "failed", message=msg,
        dt=float(dt), steps=int(steps), wall_s=wall, updates_per_s=updates / wall if wall > 0 else 0.0,
        contact_rebuilds=int(rebuilds), x=x, v=v, Dmax=js.Dmax, joint_broken=js.broken,
        body_names=list(model.body_names), joint_onset_t=j_onset, joint_break_t=j_break,
        body_wake_t=dict(zip(model.body_names, bodies.t_wake.tolist())),
        snapshots=[Snapshot(float(min(k, steps) * dt), snap_x[i], snap_D[i])
                   for i, k in enumerate(snap_steps) if k <= steps],
        peak=(Snapshot(float(peak_info[0]), peak_x, peak_D) if peak_info[2] >= 0 else None))
