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
from .kernels import contact_forces, joint_forces
from .softening import z
from .triangles import soa_dminv, triangle_cauchy, triangle_forces_into, triangle_forces_scalar, viscous

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
    """Copy the coordinates and each joint's damage (larger of its two Gauss points, 1 if broken)."""
    for i in range(x.shape[0]):
        out_x[i, 0] = x[i, 0]
        out_x[i, 1] = x[i, 1]
    for j in range(Dmax.shape[0]):
        d = Dmax[j, 0] if Dmax[j, 0] > Dmax[j, 1] else Dmax[j, 1]
        out_D[j] = 1.0 if (broken[j] or d > 1.0) else d


@njit(cache=True)
def run_loop(x, v, mass, inv_mass, tri, dminv, vol0, lam, mu, eta,
             jn, jarea, kn, kt, ft, fs, dn, dtm, tanphi, jedges, sa, sb, sc, Dmax, broken, jrate,
             edges, edge_tri, edge_active, edge_dlim, edge_thick, tri_edges, edge_joint,
             node_body, node_vertex, node_tri, node_thick, body_fracturable, n_bodies,
             p_c, mu_tab, buffer, use_contact,
             vel_nodes, vel_dir, vel_hist, tr_nodes, tr_dir, tr_area, tr_imp, tr_hist,
             hist_ptr, hist_t, hist_v, alpha_mass,
             eg_ptr, eg_el, ng_ptr, ng_nodes, x0,
             dt, n_steps, sample_every,
             out_t, out_energy, out_bforce, out_stress, out_nodes, out_broken, out_pen,
             energy_guard, j_onset, j_break, snap_steps, snap_x, snap_D, track, peak_x, peak_D,
             peak_info):
    """Advance the model n_steps steps of size dt from t = 0 and record samples.

    Fracture record: j_onset[j] / j_break[j] receive the time [s] at which joint j first reached its
    strength (damage > 0) and broke (-1 if never). Snapshots: at the steps listed (ascending) in
    snap_steps the deformed coordinates go to snap_x[k] and each joint's damage max(D) (1 once broken)
    to snap_D[k]. track = (body, direction, sign) with body >= 0 keeps a snapshot of the sampled state
    where sign * (contact force on that body) is largest (the peak of a force curve) in peak_x /
    peak_D, with peak_info = (time, force, step, drop, frozen, floor): with drop > 0 the search stops
    once the force has fallen below (1 - drop) x its running maximum, that maximum being above floor
    [N] (the first peak, not a later one; the floor keeps noise before the load arrives out).

    Returns (status, samples written, steps done, energy state (8,), contact rebuilds).
    """
    n = x.shape[0]
    f = np.zeros((n, 2))
    nh = hist_ptr.shape[0] - 1
    cursor = np.zeros(max(nh, 1), np.int64)
    hv = np.zeros(max(nh, 1))
    newly = np.empty(max(jn.shape[0], 1), np.int64)
    newly_dam = np.empty(max(jn.shape[0], 1), np.int64)
    jdif = np.ones((jn.shape[0], 2))
    slip_p = np.zeros((jn.shape[0], 2))
    kappa = np.zeros((jn.shape[0], 2))
    # z(Dmax) per joint, kept up to date by joint_forces (a model handed in with damage starts from it)
    zeta_j = np.ones(jn.shape[0])
    for j in range(jn.shape[0]):
        if Dmax[j, 0] > 0.0:
            zeta_j[j] = z(Dmax[j, 0], sa, sb, sc)
    bforce = np.zeros((n_bodies, 2))
    contact_edge = -np.ones(n, np.int64)
    contact_d = np.zeros(n)
    stick_edge = -np.ones(n, np.int64)
    stick_u = np.zeros((n, 2))
    E = np.zeros(8)
    # Contact state
    snodes = surface_nodes(edges, edge_active, n)
    # candidate pairs within buffer + margin, from which the contact list is filtered (refresh_pairs)
    margin = CANDIDATE_MARGIN * buffer
    all_edges = np.arange(edges.shape[0])
    edge_nodes = surface_nodes(edges, np.ones(edges.shape[0], np.bool_), n)
    edge_rigid = np.zeros(edges.shape[0], np.bool_)
    for e in range(edges.shape[0]):
        edge_rigid[e] = not body_fracturable[node_body[edges[e, 0]]]
    x_cand = x.copy()
    cand_node = np.zeros(0, np.int64)
    cand_edge = np.zeros(0, np.int64)
    if use_contact:
        pair_node, pair_edge, node_normal, snodes, cand_node, cand_edge = refresh_pairs(
            x, edges, edge_active, edge_tri, node_vertex, node_body, node_tri, tri, body_fracturable,
            buffer, margin, cand_node, cand_edge, x_cand, all_edges, edge_nodes, edge_rigid)
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
        _hist_eval(hist_ptr, hist_t, hist_v, cursor, 0.0, hv)
        E[7] += _apply_velocity_bc(v, mass, vel_nodes, vel_dir, vel_hist, hv)
    # triangles without viscous stress go through the vectorised kernel, on buffers allocated once
    is_viscous = viscous(eta)
    M_soa = soa_dminv(dminv)
    D_tri = np.empty((4, tri.shape[0]))
    H_tri = np.empty((4, tri.shape[0]))
    W_tri = np.empty(tri.shape[0])
    if is_viscous:
        Us, Pd = triangle_forces_scalar(x, v, tri, dminv, vol0, lam, mu, eta, f)
    else:
        Us = triangle_forces_into(x, tri, M_soa, lam, mu, vol0, f, True, D_tri, H_tri, W_tri)
        Pd = 0.0
    Psi, dis, nnew, ndam = joint_forces(x, v, jn, jarea, kn, kt, ft, fs, dn, dtm, tanphi, sa, sb,
                                        sc, Dmax, broken, f, newly, newly_dam, jrate, jdif, slip_p,
                                        kappa, zeta_j)
    Uc, Pf, pen = contact_forces(x, v, pair_node, pair_edge, pair_node.shape[0],
                                 node_normal, edges, edge_tri, edge_joint, broken, Dmax, edge_dlim, edge_thick, node_thick, node_body,
                                 node_tri, tri, node_vertex, body_fracturable, p_c, mu_tab, dt, f, bforce,
                                 contact_edge, contact_d, stick_edge, stick_u)
    tr_F = np.zeros(tr_nodes.shape[0])
    for k in range(tr_nodes.shape[0]):
        nn = tr_nodes[k]
        d = tr_dir[k]
        F = tr_area[k] * (hv[tr_hist[k]] - tr_imp[k] * v[nn, d])
        f[nn, d] += F
        tr_F[k] = F
    scale_max = 0.0
    isnap = 0
    ns = 0
    status = STATUS_OK
    step = 0
    E0 = 0.0
    for i in range(n):
        E0 += 0.5 * mass[i] * (v[i, 0] ** 2 + v[i, 1] ** 2)
    E0 += Us + Psi + Uc
    for step in range(n_steps + 1):
        if step > 0:
            # half kick, with mass damping and external tractions booked at the half-step velocity
            vmax2 = 0.0
            if vel_nodes.shape[0] == 0:
                # no prescribed velocity to impose between kick and drift: one pass over the nodes,
                # which also clears the force buffer for this step's forces (same arithmetic)
                for i in range(n):
                    v[i, 0] += 0.5 * dt * f[i, 0] * inv_mass[i]
                    v[i, 1] += 0.5 * dt * f[i, 1] * inv_mass[i]
                    f[i, 0] = 0.0
                    f[i, 1] = 0.0
                    x[i, 0] += dt * v[i, 0]
                    x[i, 1] += dt * v[i, 1]
                    vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
                    if vv > vmax2:
                        vmax2 = vv
                if nh > 0:
                    _hist_eval(hist_ptr, hist_t, hist_v, cursor, t + 0.5 * dt, hv)
            else:
                for i in range(n):
                    v[i, 0] += 0.5 * dt * f[i, 0] * inv_mass[i]
                    v[i, 1] += 0.5 * dt * f[i, 1] * inv_mass[i]
                if nh > 0:
                    _hist_eval(hist_ptr, hist_t, hist_v, cursor, t + 0.5 * dt, hv)
                    E[7] += _apply_velocity_bc(v, mass, vel_nodes, vel_dir, vel_hist, hv)
                for i in range(n):
                    x[i, 0] += dt * v[i, 0]
                    x[i, 1] += dt * v[i, 1]
                    vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
                    if vv > vmax2:
                        vmax2 = vv
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
                dmax2 = 0.0
                for k in range(snodes.shape[0]):
                    s_ = snodes[k]
                    ddx = x[s_, 0] - x_ref[s_, 0]
                    ddy = x[s_, 1] - x_ref[s_, 1]
                    dd = ddx * ddx + ddy * ddy
                    if dd > dmax2:
                        dmax2 = dd
                if dmax2 > 0.25 * buffer * buffer or (pending_faces and steps_since >= 5):
                    pair_node, pair_edge, node_normal, snodes, cand_node, cand_edge = refresh_pairs(
                        x, edges, edge_active, edge_tri, node_vertex, node_body, node_tri, tri,
                        body_fracturable, buffer, margin, cand_node, cand_edge, x_cand, all_edges,
                        edge_nodes, edge_rigid)
                    for i in range(n):
                        x_ref[i, 0] = x[i, 0]
                        x_ref[i, 1] = x[i, 1]
                    rebuilds += 1
                    pending_faces = False
                    steps_since = 0
            # forces at t (velocity-dependent terms use the half-step velocity)
            bforce[:, :] = 0.0
            # the stored energies are booked at the output samples only
            sampled = step % sample_every == 0
            if is_viscous:
                Us, Pd = triangle_forces_scalar(x, v, tri, dminv, vol0, lam, mu, eta, f, sampled)
            else:
                Us = triangle_forces_into(x, tri, M_soa, lam, mu, vol0, f, sampled, D_tri, H_tri, W_tri)
            Psi, dis, nnew, ndam = joint_forces(x, v, jn, jarea, kn, kt, ft, fs, dn, dtm, tanphi, sa,
                                                sb, sc, Dmax, broken, f, newly, newly_dam, jrate, jdif,
                                                slip_p, kappa, zeta_j, sampled)
            E[4] += dis
            for k in range(ndam):
                j_onset[newly_dam[k]] = t
            for k in range(nnew):
                j_break[newly[k]] = t
            # A joint that starts to soften exposes all edges of its two triangles to contact while
            # they still fit together, so no overlap can build up unseen before the faces part.
            for k in range(ndam):
                for side in range(2):
                    t_ = edge_tri[jedges[newly_dam[k], side]]
                    for le in range(3):
                        ed = tri_edges[t_, le]
                        if ed >= 0 and not edge_active[ed]:
                            edge_active[ed] = True
                            pending_faces = True
            for k in range(nnew):
                for side in range(2):
                    ed = jedges[newly[k], side]
                    if not edge_active[ed]:
                        edge_active[ed] = True
                        pending_faces = True
            Uc, Pf, pen = contact_forces(x, v, pair_node, pair_edge, pair_node.shape[0],
                                         node_normal, edges, edge_tri, edge_joint, broken, Dmax, edge_dlim, edge_thick, node_thick,
                                         node_body, node_tri, tri, node_vertex, body_fracturable,
                                         p_c, mu_tab, dt, f, bforce, contact_edge, contact_d, stick_edge, stick_u)
            if pen > max_pen:
                max_pen = pen
            E[6] += Pf
            if nh > 0:
                _hist_eval(hist_ptr, hist_t, hist_v, cursor, t, hv)
            # Work of the boundary tractions over the drift: trapezoidal in force, times the
            # half-step velocity that moved the node (second order, like the integrator).
            W_tr = 0.0
            for k in range(tr_nodes.shape[0]):
                nn = tr_nodes[k]
                d = tr_dir[k]
                F = tr_area[k] * (hv[tr_hist[k]] - tr_imp[k] * v[nn, d])
                f[nn, d] += F
                W_tr += 0.5 * (F + tr_F[k]) * v[nn, d] * dt
                tr_F[k] = F
            E[7] += W_tr
            P_mass = 0.0
            if alpha_mass > 0.0:
                for i in range(n):
                    fx = -alpha_mass * mass[i] * v[i, 0]
                    fy = -alpha_mass * mass[i] * v[i, 1]
                    f[i, 0] += fx
                    f[i, 1] += fy
                    P_mass -= fx * v[i, 0] + fy * v[i, 1]
            E[5] += (Pd + P_mass) * dt
            # second half kick
            for i in range(n):
                v[i, 0] += 0.5 * dt * f[i, 0] * inv_mass[i]
                v[i, 1] += 0.5 * dt * f[i, 1] * inv_mass[i]
            if nh > 0:
                E[7] += _apply_velocity_bc(v, mass, vel_nodes, vel_dir, vel_hist, hv)
        while isnap < snap_steps.shape[0] and snap_steps[isnap] == step:
            _snapshot(x, Dmax, broken, snap_x[isnap], snap_D[isnap])
            isnap += 1
        if step % sample_every == 0 and track[0] >= 0 and peak_info[4] == 0.0:
            fpk = track[2] * bforce[track[0], track[1]]
            if peak_info[2] < 0.0 or fpk > peak_info[1]:
                peak_info[0] = t
                peak_info[1] = fpk
                peak_info[2] = step
                _snapshot(x, Dmax, broken, peak_x, peak_D)
            elif (peak_info[3] > 0.0 and peak_info[1] > peak_info[5]
                  and fpk < (1.0 - peak_info[3]) * peak_info[1]):
                peak_info[4] = 1.0
        if step % sample_every == 0 and ns < out_t.shape[0]:
            KE = 0.0
            for i in range(n):
                KE += 0.5 * mass[i] * (v[i, 0] ** 2 + v[i, 1] ** 2)
            E[0] = KE
            E[1] = Us
            E[2] = Psi
            E[3] = Uc
            out_t[ns] = t
            for q in range(8):
                out_energy[ns, q] = E[q]
            for b in range(n_bodies):
                out_bforce[ns, b, 0] = bforce[b, 0]
                out_bforce[ns, b, 1] = bforce[b, 1]
            for g in range(eg_ptr.shape[0] - 1):
                sxx = 0.0
                syy = 0.0
                sxy = 0.0
                A = 0.0
                for m in range(eg_ptr[g], eg_ptr[g + 1]):
                    e = eg_el[m]
                    a_, b_, c_ = triangle_cauchy(x, tri, dminv, lam, mu, e)
                    w = vol0[e]
                    sxx += w * a_
                    syy += w * b_
                    sxy += w * c_
                    A += w
                out_stress[ns, g, 0] = sxx / A
                out_stress[ns, g, 1] = syy / A
                out_stress[ns, g, 2] = sxy / A
            for g in range(ng_ptr.shape[0] - 1):
                ux = 0.0
                uy = 0.0
                vx = 0.0
                vy = 0.0
                cnt = ng_ptr[g + 1] - ng_ptr[g]
                for m in range(ng_ptr[g], ng_ptr[g + 1]):
                    nn = ng_nodes[m]
                    ux += x[nn, 0] - x0[nn, 0]
                    uy += x[nn, 1] - x0[nn, 1]
                    vx += v[nn, 0]
                    vy += v[nn, 1]
                out_nodes[ns, g, 0] = ux / cnt
                out_nodes[ns, g, 1] = uy / cnt
                out_nodes[ns, g, 2] = vx / cnt
                out_nodes[ns, g, 3] = vy / cnt
            nb = 0
            for jj in range(broken.shape[0]):
                if broken[jj]:
                    nb += 1
            out_broken[ns] = nb
            out_pen[ns] = max_pen
            max_pen = 0.0
            ns += 1
            if not math.isfinite(KE) or not math.isfinite(Us) or not math.isfinite(Psi):
                status = STATUS_NONFINITE
                break
            total = E[0] + E[1] + E[2] + E[3] + E[4] + E[5] + E[6]
            scale = abs(E[7]) + E0
            if scale > scale_max:
                scale_max = scale
            if (energy_guard > 0.0 and step > 100 and scale_max > 0.0
                    and abs(total - E0 - E[7]) > energy_guard * scale_max):
                status = STATUS_ENERGY
                break
    return status, ns, step, E, rebuilds
