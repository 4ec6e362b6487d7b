"""The engine's state and inputs as named structures the compiled step loop takes apart by name.

Named tuples of arrays (and a few scalars) compile in Numba's nopython mode as plain structs, so
grouping the step loop's arrays costs nothing at run time; a field read in a loop is the array it
names. The split follows who owns what: constants of the mesh and the laws (Nodes' masses,
Triangles, Joints, Surfaces, Loads, Probes, Settings) and what the step changes (the positions and
velocities in Nodes, JointState, ContactState, Outputs). Everything is allocated here, in Python,
so the compiled loop never decides a shape.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

# x, v [m, m/s] change every step; the rest is the mesh: mass [kg], its inverse per coordinate
# (n, 2: the kick runs over x, v and f as flat arrays), reference coordinates x0 [m],
# each node's body, vertex of the unsplit mesh, triangle (fracturable bodies) and thickness [m].
Nodes = namedtuple("Nodes", "x v mass inv_mass x0 body vertex tri thick")
# Constant-strain triangles: node indices, inverse reference edge matrix, volume [m^3], Lame
# constants [Pa], viscosity [Pa s], and each triangle's three edge indices (-1: none).
Triangles = namedtuple("Triangles", "tri dminv vol0 lam mu eta edges")
# Cohesive joints (fdem.kernels.joint_forces): 4 nodes, area [m^2], penalties [Pa/m], strengths
# [Pa], critical opening and sliding delta_n, delta_t [m] (paper eqs. A8-A9), tan(friction angle),
# the two edges, rate columns (h, k, rate0), softening shape a, b, c (eq. A3).
Joints = namedtuple("Joints", "nodes area kn kt ft fs delta_n delta_t tanphi edges rate a b c")
# History of each joint (one value per joint: the law acts on the mean gap) and the buffers
# joint_forces lists newly broken / newly damaged joints in.
JointState = namedtuple("JointState", "Dmax broken dif slip_p kappa zeta newly_broken newly_damaged")
# Work buffers of fdem.kernels.joint_forces_into (made by fdem.kernels.joint_work): G the gathered
# rows (midline, end gaps, DIF) x joints, H the force terms (Mx, My, Bx, By) x joints, slow the joints
# its vectorised trial cannot finish, any_rate whether a joint's strength depends on the rate.
JointWork = namedtuple("JointWork", "G H slow any_rate")
# Contact surfaces: edges (node pairs, counter-clockwise), owning triangle, penetration limit [m],
# thickness [m], joint (-1: body boundary), active flag (changes as joints damage), per-body
# fracturable flag, per-body-pair penalty [Pa] and Coulomb coefficient.
Surfaces = namedtuple("Surfaces", "edges tri dlim thick joint active body_fracturable penalty friction")
# Per node: the edge it pushes on and how deep (-1, 0 when free), its friction spring's edge and
# (extension [m], stiffness [N/m]).
ContactState = namedtuple("ContactState", "edge d stick_edge stick_u")
# Prescribed velocities and tractions: per loaded node its node, direction and history; tractions
# also area [m^2] and impedance [Pa s/m]; the histories as CSR (hist_ptr) of times and values.
Loads = namedtuple("Loads", "vel_nodes vel_dir vel_hist tr_nodes tr_dir tr_area tr_imp tr_hist "
                            "hist_ptr hist_t hist_v")
# Stress probes (element sets, CSR) and node probes (node sets, CSR).
Probes = namedtuple("Probes", "eg_ptr eg_el ng_ptr ng_nodes")
# What the loop records: samples, the fracture record, snapshots and the tracked peak
# (fdem.integrator.run_loop).
Outputs = namedtuple("Outputs", "t energy bforce stress nodes broken pen j_onset j_break "
                                "snap_steps snap_x snap_D track peak_x peak_D peak_info")
# The bodies, for skipping those at rest (fdem.integrator._wake): seg the maximal runs of one body in
# triangle order (lo, hi, body; unsigned: fdem.triangles.triangle_forces_into), node_ptr / node_idx each
# body's exposed nodes (CSR: those a contact or a traction can reach), has_joints whether a body owns
# joints, f_wake [N] the nodal force that wakes a sleeping body, awake whether a body moves or carries
# load and t_wake [s] when it woke (0: awake from the start, -1: asleep; both change as the run wakes
# bodies).
Bodies = namedtuple("Bodies", "seg node_ptr node_idx has_joints f_wake awake t_wake")
# dt [s] is the time step; buffer [m] the contact search buffer; alpha_mass [1/s] mass damping.
Settings = namedtuple("Settings", "dt n_steps sample_every alpha_mass energy_guard buffer use_contact "
                                  "n_bodies")


def nodes_of(model, x, v) -> Nodes:
    inv_mass = np.repeat((1.0 / model.mass)[:, None], 2, axis=1)
    return Nodes(x, v, model.mass, inv_mass, model.x0, model.node_body, model.node_vertex,
                 model.node_tri, model.node_thick)


def triangles_of(model) -> Triangles:
    return Triangles(model.tri, model.dminv, model.vol0, model.lam, model.mu, model.eta, model.tri_edges)


def joints_of(model, **override) -> Joints:
    """The model's joints; override replaces fields (e.g. ft=model.ft * 1e9 for the elastic branch)."""
    a, b, c = model.softening
    j = Joints(model.jn, model.jarea, model.kn, model.kt, model.ft, model.fs, model.delta_n,
               model.delta_t, model.tanphi, model.jedges, model.jrate, float(a), float(b), float(c))
    return j._replace(**override)


def joint_state(n_joints: int, **given) -> JointState:
    """Undamaged history for n_joints joints; given replaces fields with the caller's arrays (kept
    by reference, so the caller sees what joint_forces writes)."""
    n = int(n_joints)
    s = JointState(Dmax=np.zeros(n), broken=np.zeros(n, np.bool_), dif=np.ones(n),
                   slip_p=np.zeros(n), kappa=np.zeros(n), zeta=np.ones(n),
                   newly_broken=np.empty(max(n, 1), np.int64), newly_damaged=np.empty(max(n, 1), np.int64))
    unknown = set(given) - set(JointState._fields)
    if unknown:
        raise KeyError(f"joint_state: unknown fields {sorted(unknown)}; fields are {JointState._fields}")
    for name, arr in given.items():
        ref = getattr(s, name)
        if not (isinstance(arr, np.ndarray) and arr.shape[0] == ref.shape[0] and arr.ndim == ref.ndim
                and arr.dtype == ref.dtype):
            raise ValueError(f"joint_state: {name} must be a {ref.dtype} array of shape {ref.shape}, got "
                             f"{getattr(arr, 'dtype', type(arr).__name__)} {getattr(arr, 'shape', '')}")
    return s._replace(**given)


def surfaces_of(model, edge_active, penalty, friction) -> Surfaces:
    return Surfaces(model.edges, model.edge_tri, model.edge_dlim, model.edge_thick, model.edge_joint,
                    edge_active, model.body_fracturable, penalty, friction)


def bodies_of(model, x, v, velocity_nodes, traction_nodes, wake_traction, sleep: bool = True) -> Bodies:
    """The bodies of model at positions x and velocities v. A body is awake from the start when a velocity
    is prescribed on one of its nodes (an impulse, not a force) or one of them is away from its reference
    position or moving; every other body sleeps until a nodal force above wake_traction [Pa] times its
    mean triangle's edge and thickness reaches one of its exposed nodes: the nodes of its surface edges
    (contact) and traction_nodes. Nothing else can push a body whose triangles and joints are at rest.
    sleep=False: every body awake from the start."""
    nb = len(model.body_names)
    tb = np.asarray(model.tri_body, np.int64)
    starts = np.flatnonzero(np.r_[True, tb[1:] != tb[:-1]]) if tb.size else np.zeros(0, np.int64)
    ends = np.r_[starts[1:], tb.size].astype(np.int64)
    seg = np.ascontiguousarray(np.stack([starts, ends, tb[starts]], axis=1).astype(np.uint64).reshape(-1, 3))
    node_body = np.asarray(model.node_body, np.int64)
    exposed = np.union1d(np.asarray(model.edges, np.int64)[np.asarray(model.edge_active0, bool)].ravel(),
                         np.asarray(traction_nodes, np.int64))
    node_idx = exposed[np.argsort(node_body[exposed], kind="stable")].astype(np.int64)
    node_ptr = np.searchsorted(node_body[node_idx], np.arange(nb + 1)).astype(np.int64)
    has_joints = np.zeros(nb, np.bool_)
    has_joints[node_body[np.asarray(model.jn, np.int64)[:, 0]]] = True
    f_wake = np.zeros(nb)
    for b in range(nb):
        on = tb == b
        if on.any():  # a traction on one edge of the body's mean triangle (edge ~ sqrt(2 area))
            w = float(model.body_thickness[b])
            f_wake[b] = wake_traction * np.sqrt(2.0 * np.mean(model.vol0[on]) / w) * w
    awake = np.zeros(nb, np.bool_)
    awake[node_body[np.asarray(velocity_nodes, np.int64)]] = True
    moved = np.any(x != model.x0, axis=1) | np.any(v != 0.0, axis=1)
    awake[node_body[moved]] = True
    awake |= not sleep
    return Bodies(seg, node_ptr, node_idx, has_joints, f_wake, awake, np.where(awake, 0.0, -1.0))


def contact_state(n_nodes: int) -> ContactState:
    """Every node free of contact."""
    return ContactState(-np.ones(n_nodes, np.int64), np.zeros(n_nodes), -np.ones(n_nodes, np.int64),
                        np.zeros((n_nodes, 2)))
