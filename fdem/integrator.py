"""The explicit central-difference step loop, entirely in compiled code.

Velocity-Verlet form of the central-difference scheme: half kick, drift, force evaluation, half
kick. Prescribed velocities are imposed as impulses whose work is booked exactly
(impulse x mean velocity). Output is sampled every ``sample_every`` steps.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .contact import refresh_pairs, surface_nodes
from .kernels import contact_forces, joint_forces_into, joint_work
from .softening import z
from .state import ContactState
from .triangles import soa_dminv, triangle_cauchy, triangle_forces_into, triangle_forces_scalar_range, viscous

# Columns of the energy record.
ENERGY_NAMES = ("kinetic", "strain", "joint_elastic", "contact", "joint_dissipated",
                "damping_dissipated", "friction_dissipated", "external_work")

STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_ENERGY = 2
STATUS_RUNAWAY = 3

# The contact candidates' extra reach, in contact buffers (fdem.contact.refresh_pairs): larger means
# fewer searches for candidates and more candidates to filter at each refresh of the list.
CANDIDATE_MARGIN = 2.0


@njit(cache=True)
def _hist_eval(hist_ptr, hist_t, hist_v, cursor, t, out):
    """Linear interpolation of every load history at time t (clamped at both ends)."""
    for h in range(hist_ptr.shape[0] - 1):
        lo = hist_ptr[h]
        hi = hist_ptr[h + 1] - 1
        if t <= hist_t[lo]:
            out[h] = hist_v[lo]
            continue
        if t >= hist_t[hi]:
            out[h] = hist_v[hi]
            continue
        i = cursor[h]
        if i < lo or i >= hi:
            i = lo
        while hist_t[i] > t:
            i -= 1
        while hist_t[i + 1] < t:
            i += 1
        cursor[h] = i
        w = (t - hist_t[i]) / (hist_t[i + 1] - hist_t[i])
        out[h] = (1.0 - w) * hist_v[i] + w * hist_v[i + 1]


@njit(cache=True)
def _apply_velocity_bc(v, mass, vel_nodes, vel_dir, vel_hist, hv):
    """Impose prescribed velocities; returns the work of the impulses that did it [J].

    The impulse J = m (v_target - v) acts on a node that then moves at v_target, so its work in the
    discrete energy balance is J v_target (booking J times the mean velocity would count the
    kick the node just received from the internal forces as external work).
    """
    W = 0.0
    for k in range(vel_nodes.shape[0]):
        n = vel_nodes[k]
        d = vel_dir[k]
        vt = hv[vel_hist[k]]
        W += mass[n] * (vt - v[n, d]) * vt
        v[n, d] = vt
    return W


@njit(cache=True)
def _snapshot(x, Dmax, broken, out_x, out_D):
    """Copy the coordinates and each joint's damage (1 if broken)."""
    for i in range(x.shape[0]):
        out_x[i, 0] = x[i, 0]
        out_x[i, 1] = x[i, 1]
    for j in range(Dmax.shape[0]):
        d = Dmax[j]
        out_D[j] = 1.0 if (broken[j] or d > 1.0) else d


@njit(cache=True, inline="always")
def _init_zeta(joints, js):
    """z(Dmax) of every damaged joint (a model handed in with damage starts from it)."""
    for j in range(js.Dmax.shape[0]):
        if js.Dmax[j] > 0.0:
            js.zeta[j] = z(js.Dmax[j], joints.a, joints.b, joints.c)


@njit(cache=True, inline="always")
def _kinetic(nodes):
    KE = 0.0
    for i in range(nodes.x.shape[0]):
        KE += 0.5 * nodes.mass[i] * (nodes.v[i, 0] ** 2 + nodes.v[i, 1] ** 2)
    return KE


@njit(cache=True, inline="always")
def _flat(a):
    """A C-contiguous (n, 2) array as its 2n values (a view): the node loops below then run over one
    stream of doubles, which LLVM vectorises."""
    return a.reshape(a.size)


@njit(cache=True, inline="always")
def _kick(nodes, f, dt):
    """Half kick: v += dt/2 f/m."""
    v = _flat(nodes.v)
    f1 = _flat(f)
    inv_mass = _flat(nodes.inv_mass)
    for k in range(v.shape[0]):
        v[k] += 0.5 * dt * f1[k] * inv_mass[k]


@njit(cache=True)
def _largest_speed2(v):
    """The largest squared nodal speed (its own loop: a reduction in the node loop kept that loop from
    vectorising)."""
    vmax2 = 0.0
    for i in range(v.shape[0]):
        vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
        if vv > vmax2:
            vmax2 = vv
    return vmax2


@njit(cache=True, inline="always")
def _drift(nodes, dt):
    """x += dt v; returns the largest squared speed."""
    x = _flat(nodes.x)
    v = _flat(nodes.v)
    for k in range(x.shape[0]):
        x[k] += dt * v[k]
    return _largest_speed2(nodes.v)


@njit(cache=True, inline="always")
def _kick_drift(nodes, f, dt):
    """Half kick and drift in one pass over the nodes (nothing to impose between them), which also
    clears the force buffer for this step's forces (the arithmetic of _kick then _drift)."""
    x = _flat(nodes.x)
    v = _flat(nodes.v)
    f1 = _flat(f)
    inv_mass = _flat(nodes.inv_mass)
    for k in range(x.shape[0]):
        v[k] += 0.5 * dt * f1[k] * inv_mass[k]
        f1[k] = 0.0
        x[k] += dt * v[k]
    return _largest_speed2(nodes.v)


@njit(cache=True, inline="always")
def _largest_move2(x, x_ref, snodes):
    """Largest squared displacement of the surface nodes since the last neighbour search."""
    dmax2 = 0.0
    for k in range(snodes.shape[0]):
        s_ = snodes[k]
        ddx = x[s_, 0] - x_ref[s_, 0]
        ddy = x[s_, 1] - x_ref[s_, 1]
        dd = ddx * ddx + ddy * ddy
        if dd > dmax2:
            dmax2 = dd
    return dmax2


@njit(cache=True, inline="always")
def _internal_forces(nodes, tris, is_viscous, M_soa, D_tri, H_tri, W_tri, f, energy, bodies):
    """Triangle forces of the awake bodies into f, each run of consecutive awake triangles in one call
    (all awake: one call over every triangle); returns (strain energy [J], viscous dissipation rate [W]).
    Triangles without viscous stress go through the vectorised kernel, on buffers allocated once."""
    seg = bodies.seg
    awake = bodies.awake
    Us = 0.0
    Pd = 0.0
    k = 0
    while k < seg.shape[0]:
        if not awake[seg[k, 2]]:
            k += 1
            continue
        lo = seg[k, 0]
        while k + 1 < seg.shape[0] and awake[seg[k + 1, 2]]:
            k += 1
        hi = seg[k, 1]
        k += 1
        if is_viscous:
            u, p = triangle_forces_scalar_range(nodes.x, nodes.v, tris.tri, tris.dminv, tris.vol0, tris.lam,
                                                tris.mu, tris.eta, f, energy, lo, hi)
            Us += u
            Pd += p
        else:
            Us += triangle_forces_into(nodes.x, tris.tri, M_soa, tris.lam, tris.mu, tris.vol0, f, energy, D_tri,
                                       H_tri, W_tri, lo, hi)
    return Us, Pd


@njit(cache=True, inline="always")
def _joints_awake(bodies):
    """Whether a body that owns joints is awake (the joints of a body at rest have no gap: no force)."""
    for b in range(bodies.awake.shape[0]):
        if bodies.has_joints[b] and bodies.awake[b]:
            return True
    return False


@njit(cache=True)
def _wake(bodies, f, t):
    """Wake every sleeping body on one of whose exposed nodes a force above its f_wake acts, and drop the
    smaller forces on the bodies that sleep on; returns whether any body still sleeps.

    Why bodies sleep: a body in its reference state at rest carries no internal force, so its triangles
    and joints need no evaluation until a force reaches it (in an SHPB run the wave takes 30 us to reach
    a disc from the injection and 250 us to reach a cylinder from its record's gauge, and the specimen
    is most of the mesh). Why a threshold and not any force: the explicit step carries a disturbance one
    element per step, far ahead of the wave, so a few 1e-16 m of rounding reach the specimen from the
    first steps; they and the rounding self-stress of the triangles' F = Ds Dm^-1 at the reference
    state (strains of 1e-16) are forces no physical body feels. Dropped, they leave a sleeping body
    exactly in its reference state, where its skipped triangles and joints would give no force."""
    sleeping = False
    for b in range(bodies.awake.shape[0]):
        if bodies.awake[b]:
            continue
        lo = bodies.node_ptr[b]
        hi = bodies.node_ptr[b + 1]
        for k in range(lo, hi):
            n = bodies.node_idx[k]
            if abs(f[n, 0]) > bodies.f_wake[b] or abs(f[n, 1]) > bodies.f_wake[b]:
                bodies.awake[b] = True
                bodies.t_wake[b] = t
                break
        if not bodies.awake[b]:
            sleeping = True
            for k in range(lo, hi):
                f[bodies.node_idx[k], 0] = 0.0
                f[bodies.node_idx[k], 1] = 0.0
    return sleeping


@njit(cache=True, inline="always")
def _book_damage(t, nnew, ndam, js, joints, tris, surf, out):
    """Record when joints first damaged / broke, and expose their faces to contact: a joint that
    starts to soften exposes all edges of its two triangles while they still fit together, so no
    overlap can build up unseen before the faces part. Returns whether an edge became active."""
    exposed = False
    for k in range(ndam):
        out.j_onset[js.newly_damaged[k]] = t
    for k in range(nnew):
        out.j_break[js.newly_broken[k]] = t
    for k in range(ndam):
        for side in range(2):
            t_ = surf.tri[joints.edges[js.newly_damaged[k], side]]
            for le in range(3):
                ed = tris.edges[t_, le]
                if ed >= 0 and not surf.active[ed]:
                    surf.active[ed] = True
                    exposed = True
    for k in range(nnew):
        for side in range(2):
            ed = joints.edges[js.newly_broken[k], side]
            if not surf.active[ed]:
                surf.active[ed] = True
                exposed = True
    return exposed


@njit(cache=True, inline="always")
def _tractions(loads, v, hv, f, tr_F, dt):
    """Boundary tractions into f; returns their work over the drift: trapezoidal in force, times the
    half-step velocity that moved the node (second order, like the integrator)."""
    W_tr = 0.0
    for k in range(loads.tr_nodes.shape[0]):
        nn = loads.tr_nodes[k]
        d = loads.tr_dir[k]
        F = loads.tr_area[k] * (hv[loads.tr_hist[k]] - loads.tr_imp[k] * v[nn, d])
        f[nn, d] += F
        W_tr += 0.5 * (F + tr_F[k]) * v[nn, d] * dt
        tr_F[k] = F
    return W_tr


@njit(cache=True, inline="always")
def _mass_damping(nodes, alpha_mass, f):
    """Mass-proportional damping forces into f; returns their dissipation rate [W]."""
    P_mass = 0.0
    mass = nodes.mass
    v = nodes.v
    for i in range(v.shape[0]):
        fx = -alpha_mass * mass[i] * v[i, 0]
        fy = -alpha_mass * mass[i] * v[i, 1]
        f[i, 0] += fx
        f[i, 1] += fy
        P_mass -= fx * v[i, 0] + fy * v[i, 1]
    return P_mass


@njit(cache=True, inline="always")
def _track_peak(out, step, t, bforce, x, js):
    """Keep the sampled state where the tracked body force is largest (run_loop's peak_info)."""
    track = out.track
    info = out.peak_info
    fpk = track[2] * bforce[track[0], track[1]]
    if info[2] < 0.0 or fpk > info[1]:
        info[0] = t
        info[1] = fpk
        info[2] = step
        _snapshot(x, js.Dmax, js.broken, out.peak_x, out.peak_D)
    elif info[3] > 0.0 and info[1] > info[5] and fpk < (1.0 - info[3]) * info[1]:
        info[4] = 1.0


@njit(cache=True, inline="always")
def _probe_stress(out, ns, nodes, tris, probes):
    """Area-weighted mean Cauchy stress of each element set."""
    eg_ptr = probes.eg_ptr
    for g in range(eg_ptr.shape[0] - 1):
        sxx = 0.0
        syy = 0.0
        sxy = 0.0
        A = 0.0
        for m in range(eg_ptr[g], eg_ptr[g + 1]):
            e = probes.eg_el[m]
            a_, b_, c_ = triangle_cauchy(nodes.x, tris.tri, tris.dminv, tris.lam, tris.mu, e)
            w = tris.vol0[e]
            sxx += w * a_
            syy += w * b_
            sxy += w * c_
            A += w
        out.stress[ns, g, 0] = sxx / A
        out.stress[ns, g, 1] = syy / A
        out.stress[ns, g, 2] = sxy / A


@njit(cache=True, inline="always")
def _probe_nodes(out, ns, nodes, probes):
    """Mean displacement and velocity of each node set."""
    ng_ptr = probes.ng_ptr
    x = nodes.x
    v = nodes.v
    for g in range(ng_ptr.shape[0] - 1):
        ux = 0.0
        uy = 0.0
        vx = 0.0
        vy = 0.0
        cnt = ng_ptr[g + 1] - ng_ptr[g]
        for m in range(ng_ptr[g], ng_ptr[g + 1]):
            nn = probes.ng_nodes[m]
            ux += x[nn, 0] - nodes.x0[nn, 0]
            uy += x[nn, 1] - nodes.x0[nn, 1]
            vx += v[nn, 0]
            vy += v[nn, 1]
        out.nodes[ns, g, 0] = ux / cnt
        out.nodes[ns, g, 1] = uy / cnt
        out.nodes[ns, g, 2] = vx / cnt
        out.nodes[ns, g, 3] = vy / cnt


@njit(cache=True, inline="always")
def _write_sample(out, ns, t, E, bforce, max_pen, nodes, tris, probes, js):
    """Write sample ns: time, energies E, body forces, probes, broken joints, largest penetration."""
    out.t[ns] = t
    for q in range(8):
        out.energy[ns, q] = E[q]
    for b in range(bforce.shape[0]):
        out.bforce[ns, b, 0] = bforce[b, 0]
        out.bforce[ns, b, 1] = bforce[b, 1]
    _probe_stress(out, ns, nodes, tris, probes)
    _probe_nodes(out, ns, nodes, probes)
    nb = 0
    for jj in range(js.broken.shape[0]):
        if js.broken[jj]:
            nb += 1
    out.broken[ns] = nb
    out.pen[ns] = max_pen


@njit(cache=True, inline="always")
def _edge_rigid(surf, nodes):
    """Whether each edge belongs to a body that cannot fracture."""
    edges = surf.edges
    rigid = np.zeros(edges.shape[0], np.bool_)
    for e in range(edges.shape[0]):
        rigid[e] = not surf.body_fracturable[nodes.body[edges[e, 0]]]
    return rigid


@njit(cache=True)
def run_loop(nodes, tris, joints, js, surf, loads, probes, out, settings, bodies):
    """Advance the model settings.n_steps steps of size settings.dt from t = 0 and record samples.

    The arguments are the named structures of fdem.state; nodes.x, nodes.v, js, surf.active and out
    are updated in place. Fracture record: out.j_onset[j] / out.j_break[j] receive the time [s] at
    which joint j first reached its strength (damage > 0) and broke (-1 if never). Snapshots: at the
    steps listed (ascending) in out.snap_steps the deformed coordinates go to out.snap_x[k] and each
    joint's damage max(D) (1 once broken) to out.snap_D[k]. out.track = (body, direction, sign) with
    body >= 0 keeps a snapshot of the sampled state where sign * (contact force on that body) is
    largest (the peak of a force curve) in out.peak_x / out.peak_D, with out.peak_info = (time,
    force, step, drop, frozen, floor): with drop > 0 the search stops once the force has fallen
    below (1 - drop) x its running maximum, that maximum being above floor [N] (the first peak, not
    a later one; the floor keeps noise before the load arrives out).

    bodies (fdem.state.Bodies): a body sleeps, its triangles and joints not evaluated, until a force
    acts on one of its nodes (_wake); bodies.awake is updated in place.

    Returns (status, samples written, steps done, energy state (8,), contact rebuilds).
    """
    x = nodes.x
    v = nodes.v
    n = x.shape[0]
    dt = settings.dt
    buffer = settings.buffer
    use_contact = settings.use_contact
    f = np.zeros((n, 2))
    nh = loads.hist_ptr.shape[0] - 1
    cursor = np.zeros(max(nh, 1), np.int64)
    hv = np.zeros(max(nh, 1))
    _init_zeta(joints, js)
    bforce = np.zeros((settings.n_bodies, 2))
    cs = ContactState(-np.ones(n, np.int64), np.zeros(n), -np.ones(n, np.int64), np.zeros((n, 2)))
    E = np.zeros(8)
    # Contact state: candidate pairs within buffer + margin, from which the contact list is filtered
    # (refresh_pairs)
    snodes = surface_nodes(surf.edges, surf.active, n)
    margin = CANDIDATE_MARGIN * buffer
    all_edges = np.arange(surf.edges.shape[0])
    edge_nodes = surface_nodes(surf.edges, np.ones(surf.edges.shape[0], np.bool_), n)
    edge_rigid = _edge_rigid(surf, nodes)
    x_cand = x.copy()
    cand_node = np.zeros(0, np.int64)
    cand_edge = np.zeros(0, np.int64)
    if use_contact:
        pair_node, pair_edge, node_normal, snodes, cand_node, cand_edge = refresh_pairs(
            x, surf.edges, surf.active, surf.tri, nodes.vertex, nodes.body, nodes.tri, tris.tri,
            surf.body_fracturable, buffer, margin, cand_node, cand_edge, x_cand, all_edges, edge_nodes, edge_rigid)
    else:
        pair_node = np.zeros(0, np.int64)
        pair_edge = np.zeros(0, np.int64)
        node_normal = np.zeros((n, 2))
    x_ref = x.copy()
    rebuilds = 0
    pending_faces = False
    steps_since = 0
    max_pen = 0.0
    t = 0.0

    # Forces at t = 0
    if nh > 0:
        _hist_eval(loads.hist_ptr, loads.hist_t, loads.hist_v, cursor, 0.0, hv)
        E[7] += _apply_velocity_bc(v, nodes.mass, loads.vel_nodes, loads.vel_dir, loads.vel_hist, hv)
    is_viscous = viscous(tris.eta)
    M_soa = soa_dminv(tris.dminv)
    D_tri = np.empty((4, tris.tri.shape[0]))
    H_tri = np.empty((4, tris.tri.shape[0]))
    W_tri = np.empty(tris.tri.shape[0])
    Us, Pd = _internal_forces(nodes, tris, is_viscous, M_soa, D_tri, H_tri, W_tri, f, True, bodies)
    jw = joint_work(joints)
    Psi, dis, nnew, ndam = 0.0, 0.0, 0, 0
    if _joints_awake(bodies):
        Psi, dis, nnew, ndam = joint_forces_into(x, v, joints, js, f, True, jw)
    Uc, Pf, pen = contact_forces(x, v, pair_node, pair_edge, node_normal, nodes, tris.tri, surf, js, dt, f,
                                 bforce, cs)
    tr_F = np.zeros(loads.tr_nodes.shape[0])
    _tractions(loads, v, hv, f, tr_F, dt)
    sleeping = _wake(bodies, f, 0.0)
    scale_max = 0.0
    isnap = 0
    ns = 0
    status = STATUS_OK
    step = 0
    E0 = _kinetic(nodes)
    E0 += Us + Psi + Uc
    for step in range(settings.n_steps + 1):
        if step > 0:
            # half kick, with mass damping and external tractions booked at the half-step velocity
            if loads.vel_nodes.shape[0] == 0:
                vmax2 = _kick_drift(nodes, f, dt)
                if nh > 0:
                    _hist_eval(loads.hist_ptr, loads.hist_t, loads.hist_v, cursor, t + 0.5 * dt, hv)
            else:
                _kick(nodes, f, dt)
                if nh > 0:
                    _hist_eval(loads.hist_ptr, loads.hist_t, loads.hist_v, cursor, t + 0.5 * dt, hv)
                    E[7] += _apply_velocity_bc(v, nodes.mass, loads.vel_nodes, loads.vel_dir, loads.vel_hist, hv)
                vmax2 = _drift(nodes, dt)
                f[:, :] = 0.0
            t += dt
            # A node that crosses the contact buffer in one step moves faster than any wave the stable
            # step resolves: the state is already garbage, and each contact rebuild over an exploding
            # mesh would cost more than the whole run (the energy test only looks every sample).
            if buffer > 0.0 and vmax2 * dt * dt > buffer * buffer:
                status = STATUS_RUNAWAY
                break
            # contact neighbour list
            if use_contact:
                steps_since += 1
                dmax2 = _largest_move2(x, x_ref, snodes)
                if dmax2 > 0.25 * buffer * buffer or (pending_faces and steps_since >= 5):
                    pair_node, pair_edge, node_normal, snodes, cand_node, cand_edge = refresh_pairs(
                        x, surf.edges, surf.active, surf.tri, nodes.vertex, nodes.body, nodes.tri, tris.tri,
                        surf.body_fracturable, buffer, margin, cand_node, cand_edge, x_cand, all_edges,
                        edge_nodes, edge_rigid)
                    x_ref[:, :] = x
                    rebuilds += 1
                    pending_faces = False
                    steps_since = 0
            # forces at t (velocity-dependent terms use the half-step velocity)
            bforce[:, :] = 0.0
            # the stored energies are booked at the output samples only
            sampled = step % settings.sample_every == 0
            Us, Pd = _internal_forces(nodes, tris, is_viscous, M_soa, D_tri, H_tri, W_tri, f, sampled, bodies)
            Psi, dis, nnew, ndam = 0.0, 0.0, 0, 0
            if _joints_awake(bodies):
                Psi, dis, nnew, ndam = joint_forces_into(x, v, joints, js, f, sampled, jw)
            E[4] += dis
            if _book_damage(t, nnew, ndam, js, joints, tris, surf, out):
                pending_faces = True
            Uc, Pf, pen = contact_forces(x, v, pair_node, pair_edge, node_normal, nodes, tris.tri, surf, js, dt,
                                         f, bforce, cs)
            if pen > max_pen:
                max_pen = pen
            E[6] += Pf
            if nh > 0:
                _hist_eval(loads.hist_ptr, loads.hist_t, loads.hist_v, cursor, t, hv)
            E[7] += _tractions(loads, v, hv, f, tr_F, dt)
            P_mass = 0.0
            if settings.alpha_mass > 0.0:
                P_mass = _mass_damping(nodes, settings.alpha_mass, f)
            E[5] += (Pd + P_mass) * dt
            if sleeping:
                sleeping = _wake(bodies, f, t)
            # second half kick
            _kick(nodes, f, dt)
            if nh > 0:
                E[7] += _apply_velocity_bc(v, nodes.mass, loads.vel_nodes, loads.vel_dir, loads.vel_hist, hv)
        while isnap < out.snap_steps.shape[0] and out.snap_steps[isnap] == step:
            _snapshot(x, js.Dmax, js.broken, out.snap_x[isnap], out.snap_D[isnap])
            isnap += 1
        if step % settings.sample_every == 0 and out.track[0] >= 0 and out.peak_info[4] == 0.0:
            _track_peak(out, step, t, bforce, x, js)
        if step % settings.sample_every == 0 and ns < out.t.shape[0]:
            KE = _kinetic(nodes)
            E[0] = KE
            E[1] = Us
            E[2] = Psi
            E[3] = Uc
            _write_sample(out, ns, t, E, bforce, max_pen, nodes, tris, probes, js)
            max_pen = 0.0
            ns += 1
            if not math.isfinite(KE) or not math.isfinite(Us) or not math.isfinite(Psi):
                status = STATUS_NONFINITE
                break
            total = E[0] + E[1] + E[2] + E[3] + E[4] + E[5] + E[6]
            scale = abs(E[7]) + E0
            if scale > scale_max:
                scale_max = scale
            if (settings.energy_guard > 0.0 and step > 100 and scale_max > 0.0
                    and abs(total - E0 - E[7]) > settings.energy_guard * scale_max):
                status = STATUS_ENERGY
                break
    return status, ns, step, E, rebuilds
