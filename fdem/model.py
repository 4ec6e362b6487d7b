"""Assemble bodies into the engine's structure-of-arrays model.

Fracturable bodies are split so that every triangle owns its three nodes, and a 4-node cohesive
joint is inserted on every interior edge. Every triangle edge that is (or may become) a free surface
is listed for contact: body boundaries are active from the start, joint faces become active when
their joint breaks.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .body import Body
from .softening import A0, DEFAULT_A, DEFAULT_B, DEFAULT_C


# Time-step safety factor on the Gershgorin critical step. Fracture runs with crushing close their
# energy balance within about 1.3% at 0.6 and drift to about 3% at 0.8 (tests/test_fdem_fracture.py).
DEFAULT_SAFETY = 0.6
# The traction [Pa] that wakes a body at rest (fdem.integrator._wake). On the fast marble cylinder the
# explicit step's precursor and rounding woke the specimen 190 us before the wave at 1e-4 Pa, not at
# 1e-3; 1e-2 keeps a decade above that, and moves the curve up to the peak by 1e-10 of the peak
# (studies/sleep_check.py measures it against the engine's own rounding sensitivity).
WAKE_TRACTION = 1e-2

# Apparent-compliance factor of intrinsic joints in an isotropic 2D mesh: E_app = E / (1 + K/f).
JOINT_COMPLIANCE_2D = 1.5


@dataclass(frozen=True)
class JointParams:
    """Cohesive joint parameters of a fracturable body (paper Appendix A names).

    sigma_n, sigma_t: tensile and shear strengths [Pa]; E_n, E_t: specific fracture energies in
    modes I and II [J/m^2]; a, b, c: softening-curve shape (eq. A3).
    penalty_factor f: joint normal penalty p = f E [Pa]; the stiffness per unit area is p / h with h
    the mean altitude of the two triangles onto the joint. tangential_penalty_factor: the same for
    sliding (default = f). Joints add compliance: for an isotropic 2D mesh with equal normal and
    tangential penalties, the crack-density argument (joint length per area 2 sqrt(3)/a times
    h = sqrt(3) a/2, orientation average <n1^2> = 1/2) gives E_app = E / (1 + 3/(2 f)) (-13% at
    f = 10), not the 1D series rule E / (1 + 1/f) (-9%); the tests measure it.
    compensate_compliance: scale the triangles' modulus by 1 / (1 - 3/(2 f)) so that the jointed
    body has the apparent modulus E (tested to 1%).
    friction_angle_deg: Mohr-Coulomb term on the shear strength, fs = sigma_t + tan(phi) * compression.
    rate_k, rate0: strain-rate-dependent strength, DIF = max(1, 1 + rate_k log10(rate / rate0)) on
    both strengths, rate = relative face velocity / element size (fdem.kernels.joint_forces).
    """

    sigma_n: float
    sigma_t: float
    E_n: float
    E_t: float
    a: float = DEFAULT_A
    b: float = DEFAULT_B
    c: float = DEFAULT_C
    penalty_factor: float = 10.0
    tangential_penalty_factor: float | None = None
    compensate_compliance: bool = False
    friction_angle_deg: float = 0.0
    unbreakable: bool = False
    rate_k: float = 0.0
    rate0: float = 1.0

    def __post_init__(self):
        for name in ("sigma_n", "sigma_t", "E_n", "E_t", "a", "b", "c", "penalty_factor"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise ValueError(f"joint parameter {name} must be finite and > 0, got {val!r}")
        if not (np.isfinite(self.rate_k) and self.rate_k >= 0 and self.rate0 > 0):
            raise ValueError(f"rate_k must be >= 0 and rate0 > 0 1/s, got {self.rate_k}, {self.rate0}")
        if self.compensate_compliance and self.penalty_factor <= 3.0:
            raise ValueError("compensate_compliance needs penalty_factor > 3 (compensation 1/(1 - 3/(2f)))")
        if not (0.0 <= self.friction_angle_deg < 90.0):
            raise ValueError(f"friction_angle_deg must be in [0, 90), got {self.friction_angle_deg}")

    @property
    def A0(self) -> float:
        return A0(self.a, self.b, self.c)

    @property
    def delta_n_max(self) -> float:
        return self.E_n / (self.sigma_n * self.A0)

    @property
    def delta_t_max(self) -> float:
        return self.E_t / (self.sigma_t * self.A0)


@dataclass(frozen=True)
class ContactParams:
    """Penalty contact: penalty [Pa] (force = penalty * contact width * penetration), Coulomb
    friction coefficient, and the neighbour-search buffer [m] (None: 0.3 x the smallest surface
    triangle altitude). pair_penalty overrides the penalty for given body pairs,
    {(body_a, body_b): penalty}, e.g. a compliant seating layer between a bar and the specimen.
    pair_friction overrides the friction coefficient the same way; (body, body) is the friction of
    that body's own crack faces once its joints have broken, which is a property of the fractured
    rock, not of the bar-specimen interface."""

    penalty: float
    friction: float = 0.0
    buffer: float | None = None
    pair_penalty: dict = field(default_factory=dict)
    pair_friction: dict = field(default_factory=dict)

    def __post_init__(self):
        if not (np.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"contact friction must be finite and >= 0, got {self.friction!r}")

    def table(self, body_names) -> np.ndarray:
        """Symmetric per-body-pair penalty table [Pa]."""
        return _pair_table(body_names, self.penalty, self.pair_penalty, "pair penalty", positive=True)

    def friction_table(self, body_names) -> np.ndarray:
        """Symmetric per-body-pair Coulomb friction coefficients [-]."""
        return _pair_table(body_names, self.friction, self.pair_friction, "pair friction", positive=False)


def _pair_table(body_names, default, pairs, what, positive) -> np.ndarray:
    t = np.full((len(body_names), len(body_names)), float(default))
    for (a, b), val in pairs.items():
        if a not in body_names or b not in body_names:
            raise KeyError(f"{what} names unknown bodies {(a, b)}; bodies are {body_names}")
        ok = np.isfinite(val) and (val > 0 if positive else val >= 0)
        if not ok:
            raise ValueError(f"{what} for {(a, b)} must be {'> 0' if positive else '>= 0'}, got {val}")
        i, j = body_names.index(a), body_names.index(b)
        t[i, j] = t[j, i] = float(val)
    return t


@dataclass
class Model:
    """Structure-of-arrays state of an assembled FDEM model (SI units).

    Per joint, delta_n and delta_t are the critical opening and sliding [m] at which a joint has
    softened completely (paper eqs. A8-A9); the time step is not part of the model
    (stable_time_step, fdem.solver.run)."""

    x0: np.ndarray
    mass: np.ndarray
    node_body: np.ndarray
    node_vertex: np.ndarray
    node_tri: np.ndarray
    node_thick: np.ndarray
    tri: np.ndarray
    dminv: np.ndarray
    area0: np.ndarray
    vol0: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    eta: np.ndarray
    tri_body: np.ndarray
    tri_h: np.ndarray
    jn: np.ndarray
    jarea: np.ndarray
    jrate: np.ndarray
    jlen0: np.ndarray
    kn: np.ndarray
    kt: np.ndarray
    ft: np.ndarray
    fs: np.ndarray
    delta_n: np.ndarray
    delta_t: np.ndarray
    tanphi: np.ndarray
    jedges: np.ndarray
    j_body: np.ndarray
    softening: tuple
    edges: np.ndarray
    edge_tri: np.ndarray
    edge_dlim: np.ndarray
    edge_thick: np.ndarray
    edge_active0: np.ndarray
    tri_edges: np.ndarray
    edge_joint: np.ndarray
    body_names: list
    body_fracturable: np.ndarray
    body_thickness: np.ndarray
    body_materials: list
    node_sets: dict = field(default_factory=dict)
    element_sets: dict = field(default_factory=dict)
    contact: ContactParams | None = None
    alpha_mass: float = 0.0
    damping_beta: float = 0.0
    joint_params: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return self.x0.shape[0]

    @property
    def n_triangles(self) -> int:
        return self.tri.shape[0]

    @property
    def n_joints(self) -> int:
        return self.jn.shape[0]

    def body_index(self, name: str) -> int:
        try:
            return self.body_names.index(name)
        except ValueError:
            raise KeyError(f"no body named {name!r}; bodies are {self.body_names}") from None

    def body_nodes(self, name: str) -> np.ndarray:
        return np.nonzero(self.node_body == self.body_index(name))[0]

    def body_triangles(self, name: str) -> np.ndarray:
        return np.nonzero(self.tri_body == self.body_index(name))[0]


def _dminv_and_area(p):
    """Inverse reference edge matrix Dm^-1 and signed area of triangles p (m, 3, 2)."""
    Dm = np.empty((p.shape[0], 2, 2))
    Dm[:, :, 0] = p[:, 1] - p[:, 0]
    Dm[:, :, 1] = p[:, 2] - p[:, 0]
    det = Dm[:, 0, 0] * Dm[:, 1, 1] - Dm[:, 0, 1] * Dm[:, 1, 0]
    inv = np.empty_like(Dm)
    inv[:, 0, 0] = Dm[:, 1, 1] / det
    inv[:, 1, 1] = Dm[:, 0, 0] / det
    inv[:, 0, 1] = -Dm[:, 0, 1] / det
    inv[:, 1, 0] = -Dm[:, 1, 0] / det
    return inv, 0.5 * det


def build_model(bodies: list[Body], joints: dict[str, JointParams] | None = None,
                contact: ContactParams | None = None, damping_beta: float = 0.0,
                alpha_mass: float = 0.0) -> Model:
    """Assemble bodies into a Model.

    joints: JointParams per fracturable body name (required for each fracturable body).
    contact: penalty contact parameters (None: no contact).
    damping_beta: element viscous damping as a fraction of critical at the element scale,
      eta = 2 h beta sqrt(E rho) (Y-lineage form, h = sqrt(2 * area)).
    alpha_mass: mass-proportional damping [1/s] (force -alpha m v), for quasi-static relaxation.
    """
    joints = dict(joints or {})
    names = [b.name for b in bodies]
    if len(set(names)) != len(names):
        raise ValueError(f"body names must be unique, got {names}")
    for b in bodies:
        if b.fracturable and b.name not in joints:
            raise ValueError(f"fracturable body {b.name!r} needs JointParams in `joints`")
    unknown = set(joints) - {b.name for b in bodies if b.fracturable}
    if unknown:
        raise ValueError(f"joint parameters given for non-fracturable or unknown bodies: {sorted(unknown)}")

    X, tris, tbody, nbody, nvert, edges, edge_tri, edge_act = [], [], [], [], [], [], [], []
    edge_loc = []
    jn_l, jedge_l, jbody_l = [], [], []
    node_sets, elem_sets = {}, {}
    n_off = 0
    t_off = 0
    v_off = 0
    e_off = 0
    for bi, b in enumerate(bodies):
        T = b.triangles
        m = T.shape[0]
        # Edge table: (tri, local k) -> vertices (T[k], T[k+1]) in CCW order.
        ev = np.stack([T, np.roll(T, -1, axis=1)], axis=2).reshape(-1, 2)
        key = np.sort(ev, axis=1)
        order = np.lexsort((key[:, 1], key[:, 0]))
        ks = key[order]
        same = np.all(ks[1:] == ks[:-1], axis=1)
        first = order[:-1][same]
        second = order[1:][same]
        interior = np.zeros(3 * m, bool)
        interior[first] = True
        interior[second] = True
        if b.fracturable:
            nodes_local = np.arange(3 * m).reshape(m, 3)
            X.append(b.nodes[T.reshape(-1)])
            nvert.append(T.reshape(-1) + v_off)
            tri_nodes = nodes_local + n_off
            # Joint: side A = `first` edge, side B = its twin.
            tA, kA = first // 3, first % 3
            tB, kB = second // 3, second % 3
            vA1 = T[tA, kA]
            a1 = nodes_local[tA, kA]
            a2 = nodes_local[tA, (kA + 1) % 3]
            # Twin edge runs the other way: its start vertex is A's end vertex.
            b_start = nodes_local[tB, kB]
            b_end = nodes_local[tB, (kB + 1) % 3]
            vB_start = T[tB, kB]
            b1 = np.where(vB_start == vA1, b_start, b_end)
            b2 = np.where(vB_start == vA1, b_end, b_start)
            jn_l.append(np.stack([a1, a2, b1, b2], axis=1) + n_off)
            jedge_l.append(np.stack([first, second], axis=1) + e_off)
            jbody_l.append(np.full(first.shape[0], bi))
            edge_nodes = np.stack([nodes_local, np.roll(nodes_local, -1, axis=1)], axis=2).reshape(-1, 2)
            vert_to_nodes = {}
            flatT = T.reshape(-1)
            order_v = np.argsort(flatT, kind="stable")
            splits = np.split(order_v, np.nonzero(np.diff(flatT[order_v]))[0] + 1)
            for grp in splits:
                vert_to_nodes[int(flatT[grp[0]])] = grp
            for sname, idx in b.node_sets.items():
                sel = [vert_to_nodes[int(v)] for v in np.asarray(idx) if int(v) in vert_to_nodes]
                node_sets[f"{b.name}.{sname}"] = (np.sort(np.concatenate(sel)) + n_off if sel
                                                   else np.zeros(0, np.int64))
            n_b = 3 * m
        else:
            X.append(b.nodes)
            nvert.append(np.arange(b.nodes.shape[0]) + v_off)
            tri_nodes = T + n_off
            edge_nodes = ev
            for sname, idx in b.node_sets.items():
                node_sets[f"{b.name}.{sname}"] = np.asarray(idx, np.int64) + n_off
            n_b = b.nodes.shape[0]
        # Contact surfaces: boundary edges always; interior edges only where joints can break.
        keep = np.ones(3 * m, bool) if b.fracturable else ~interior
        kept = np.nonzero(keep)[0]
        remap = -np.ones(3 * m, np.int64)
        remap[kept] = np.arange(kept.shape[0]) + e_off
        if b.fracturable:
            jedge_l[-1] = remap[jedge_l[-1] - e_off]
        edges.append(edge_nodes[kept] + n_off)
        edge_tri.append(kept // 3 + t_off)
        edge_loc.append(kept % 3)
        edge_act.append(~interior[kept])
        tris.append(tri_nodes)
        tbody.append(np.full(m, bi))
        nbody.append(np.full(n_b, bi))
        for sname, idx in b.element_sets.items():
            elem_sets[f"{b.name}.{sname}"] = np.asarray(idx, np.int64) + t_off
        n_off += n_b
        t_off += m
        v_off += b.nodes.shape[0]
        e_off += kept.shape[0]

    x0 = np.ascontiguousarray(np.concatenate(X))
    tri = np.ascontiguousarray(np.concatenate(tris)).astype(np.int64)
    tri_body = np.concatenate(tbody).astype(np.int64)
    node_body = np.concatenate(nbody).astype(np.int64)
    node_vertex = np.concatenate(nvert).astype(np.int64)
    edges_a = np.ascontiguousarray(np.concatenate(edges)).astype(np.int64)
    edge_tri_a = np.concatenate(edge_tri).astype(np.int64)
    edge_active0 = np.concatenate(edge_act).astype(np.bool_)
    edge_local = np.concatenate(edge_loc).astype(np.int64)
    # Triangle -> its contact edges (-1 where an interior edge of a non-fracturable body was dropped).
    tri_edges = -np.ones((sum(t.shape[0] for t in tris), 3), np.int64)
    tri_edges.reshape(-1)[edge_tri_a * 3 + edge_local] = np.arange(edge_tri_a.shape[0])

    dminv, area = _dminv_and_area(x0[tri])
    if np.any(area <= 0):
        raise ValueError("inverted or degenerate triangle after assembly")
    thick_b = np.array([b.thickness for b in bodies])
    E_b = np.array([b.material.E for b in bodies])
    nu_b = np.array([b.material.nu for b in bodies])
    rho_b = np.array([b.material.rho for b in bodies])
    E_tri = E_b[tri_body].copy()
    for bi, b in enumerate(bodies):
        if b.fracturable and joints[b.name].compensate_compliance:
            E_tri[tri_body == bi] /= 1.0 - JOINT_COMPLIANCE_2D / joints[b.name].penalty_factor
    nu_tri = nu_b[tri_body]
    thick = thick_b[tri_body]
    vol0 = area * thick
    lam = E_tri * nu_tri / (1.0 - nu_tri**2)
    mu = E_tri / (2.0 * (1.0 + nu_tri))
    tri_h = np.sqrt(2.0 * area)
    eta = 2.0 * tri_h * damping_beta * np.sqrt(E_tri * rho_b[tri_body])

    mass = np.zeros(x0.shape[0])
    np.add.at(mass, tri.reshape(-1), np.repeat(rho_b[tri_body] * vol0 / 3.0, 3))
    node_tri = np.empty(x0.shape[0], np.int64)
    node_tri[tri.reshape(-1)] = np.repeat(np.arange(tri.shape[0]), 3)
    # For nodes shared by several triangles (non-fracturable bodies) node_tri is one of them; the
    # contact exclusion on shared mesh vertices covers the others.
    node_thick = thick_b[node_body]

    # Contact geometry per edge: penetration limit = 0.3 x the owner triangle's altitude on it (a node
    # deeper than that is no contact with this edge: it came from elsewhere).
    ep = x0[edges_a]
    elen = np.linalg.norm(ep[:, 1] - ep[:, 0], axis=1)
    edge_dlim = 0.3 * (2.0 * area[edge_tri_a] / elen)
    edge_thick = thick[edge_tri_a]

    if jn_l:
        jn = np.ascontiguousarray(np.concatenate(jn_l)).astype(np.int64)
        jedges = np.concatenate(jedge_l).astype(np.int64)
        j_body = np.concatenate(jbody_l).astype(np.int64)
    else:
        jn = np.zeros((0, 4), np.int64)
        jedges = np.zeros((0, 2), np.int64)
        j_body = np.zeros(0, np.int64)
    nj = jn.shape[0]
    edge_joint = -np.ones(edges_a.shape[0], np.int64)
    if nj:
        edge_joint[jedges[:, 0]] = np.arange(nj)
        edge_joint[jedges[:, 1]] = np.arange(nj)
    L0 = np.linalg.norm(x0[jn[:, 1]] - x0[jn[:, 0]], axis=1) if nj else np.zeros(0)
    triA = edge_tri_a[jedges[:, 0]] if nj else np.zeros(0, np.int64)
    triB = edge_tri_a[jedges[:, 1]] if nj else np.zeros(0, np.int64)
    h_j = (area[triA] + area[triB]) / L0 if nj else np.zeros(0)
    jarea = L0 * thick_b[j_body] if nj else np.zeros(0)
    kn = np.empty(nj)
    kt = np.empty(nj)
    ft = np.empty(nj)
    fs = np.empty(nj)
    dn = np.empty(nj)
    dtm = np.empty(nj)
    tanphi = np.empty(nj)
    jrate = np.zeros((nj, 3))
    softening = (DEFAULT_A, DEFAULT_B, DEFAULT_C)
    for bi, b in enumerate(bodies):
        if not b.fracturable:
            continue
        jp = joints[b.name]
        sel = j_body == bi
        fpen = jp.penalty_factor
        ftan = jp.tangential_penalty_factor or fpen
        kn[sel] = fpen * b.material.E / h_j[sel]
        kt[sel] = ftan * b.material.E / h_j[sel]
        big = 1e30 if jp.unbreakable else 1.0
        ft[sel] = jp.sigma_n * big
        fs[sel] = jp.sigma_t * big
        dn[sel] = jp.delta_n_max
        dtm[sel] = jp.delta_t_max
        tanphi[sel] = np.tan(np.radians(jp.friction_angle_deg))
        jrate[sel, 0] = h_j[sel]
        jrate[sel, 1] = jp.rate_k
        jrate[sel, 2] = jp.rate0
        softening = (jp.a, jp.b, jp.c)
    fr = [b for b in bodies if b.fracturable]
    if len({(joints[b.name].a, joints[b.name].b, joints[b.name].c) for b in fr}) > 1:
        raise ValueError("all fracturable bodies must share the softening parameters a, b, c")

    return Model(
        x0=x0, mass=mass, node_body=node_body, node_vertex=node_vertex, node_tri=node_tri,
        node_thick=node_thick, tri=tri, dminv=np.ascontiguousarray(dminv), area0=area, vol0=vol0,
        lam=lam, mu=mu, eta=eta, tri_body=tri_body, tri_h=tri_h, jn=jn, jarea=jarea, jrate=jrate, jlen0=L0, kn=kn, kt=kt,
        ft=ft, fs=fs, delta_n=dn, delta_t=dtm, tanphi=tanphi, jedges=jedges, j_body=j_body,
        softening=softening, edges=edges_a, edge_tri=edge_tri_a, edge_dlim=edge_dlim,
        edge_thick=edge_thick, edge_active0=edge_active0, tri_edges=tri_edges, edge_joint=edge_joint, body_names=names,
        body_fracturable=np.array([b.fracturable for b in bodies], np.bool_),
        body_thickness=thick_b, body_materials=[b.material for b in bodies],
        node_sets=node_sets, element_sets=elem_sets, contact=contact, alpha_mass=alpha_mass,
        joint_params=joints, damping_beta=damping_beta,
    )


def stable_time_step(model: Model, safety: float = DEFAULT_SAFETY) -> float:
    """Critical explicit time step from a Gershgorin bound on the largest eigenvalue of M^-1 K.

    Rows of the linearised stiffness of triangles (exact CST matrices), joint springs (normal and
    tangential penalties through the Gauss-point shape functions) and the contact penalty of
    surface nodes are summed in absolute value per degree of freedom; lambda_max <= max row sum / m,
    dt_crit = 2 / sqrt(lambda_max). Element damping beta shortens it by sqrt(1 + beta^2) - beta.
    Returns safety * dt_crit [s].
    """
    if not (0.0 < safety <= 1.0):
        raise ValueError(f"time-step safety factor must be in (0, 1], got {safety}")
    n = model.n_nodes
    rows = np.zeros((n, 2))
    # CST stiffness K = V B^T C B with plane-stress C.
    m = model.dminv
    gx = np.stack([-(m[:, 0, 0] + m[:, 1, 0]), m[:, 0, 0], m[:, 1, 0]], axis=1)
    gy = np.stack([-(m[:, 0, 1] + m[:, 1, 1]), m[:, 0, 1], m[:, 1, 1]], axis=1)
    lam, mu, V = model.lam, model.mu, model.vol0
    c11 = lam + 2 * mu
    for a in range(3):
        for d in range(2):
            s = np.zeros(model.n_triangles)
            for b in range(3):
                # K[(a,d),(b,e)] for e = x, y
                if d == 0:
                    kx = c11 * gx[:, a] * gx[:, b] + mu * gy[:, a] * gy[:, b]
                    ky = lam * gx[:, a] * gy[:, b] + mu * gy[:, a] * gx[:, b]
                else:
                    kx = lam * gy[:, a] * gx[:, b] + mu * gx[:, a] * gy[:, b]
                    ky = c11 * gy[:, a] * gy[:, b] + mu * gx[:, a] * gx[:, b]
                s += np.abs(kx) + np.abs(ky)
            np.add.at(rows[:, d], model.tri[:, a], V * s)
    if model.n_joints:
        # Row sum of k_n n n^T + k_t t t^T is at most max(k) + |k_n - k_t| / 2.
        kmax = (np.maximum(model.kn, model.kt) + 0.5 * np.abs(model.kn - model.kt)) * model.jarea
        g0, g1 = 0.5 - 0.5 / np.sqrt(3), 0.5 + 0.5 / np.sqrt(3)
        # Spring through shape functions N = (1-xi, xi) on each side: row sum of node with weight
        # w_a at a Gauss point is k w_a * sum|N| = 2 k w_a (two sides, each sum 1).
        wa1 = 0.5 * ((1 - g0) + (1 - g1))
        wa2 = 0.5 * (g0 + g1)
        for col, wgt in ((0, wa1), (1, wa2), (2, wa1), (3, wa2)):
            np.add.at(rows[:, 0], model.jn[:, col], 2.0 * kmax * wgt)
            np.add.at(rows[:, 1], model.jn[:, col], 2.0 * kmax * wgt)
    if model.contact is not None:
        surf = np.unique(model.edges.reshape(-1))
        kc = model.contact.table(model.body_names).max(axis=1)[model.node_body[surf]] * model.node_thick[surf]
        # As a slave (row sum 2k) plus as the end of master edges pressed by the facing nodes: two
        # aligned faces make each node pair a double spring, so budget 8k (measured: 4k is unstable).
        rows[surf] += 8.0 * kc[:, None]
    lam_max = np.max(rows.max(axis=1) / model.mass)
    lam_max += model.alpha_mass**2  # conservative allowance for mass damping
    dt = 2.0 / np.sqrt(lam_max)
    if model.damping_beta > 0:
        beta = model.damping_beta
        dt *= np.sqrt(1.0 + beta**2) - beta
    return float(safety * dt)

