"""Force kernels: cohesive joints, node-to-edge penalty contact (the triangles: fdem.triangles).

Plain loops over structure-of-arrays buffers, compiled with Numba. Every kernel *adds* into the
force buffer ``f`` (shape (n_nodes, 2), N) and returns the energy terms it owns, so the integrator can
close the energy balance.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .softening import z
from .state import JointWork


@njit(cache=True, inline="always")
def _psi_branch(u, k, fmax):
    """Energy per unit area of the elastic-to-peak branch, capped at the strength (J/m^2)."""
    au = abs(u)
    up = fmax / k
    if au <= up:
        return 0.5 * k * au * au
    return 0.5 * fmax * up + fmax * (au - up)


@njit(cache=True, inline="always")
def _joint_gather(x, jn, jj):
    """Joint jj's midline (unnormalised, from the a1/b1 end's midpoint to the a2/b2 end's) and the gaps
    x_B - x_A at its two ends: (tx, ty, g1x, g1y, g2x, g2y)."""
    a1 = jn[jj, 0]
    a2 = jn[jj, 1]
    b1 = jn[jj, 2]
    b2 = jn[jj, 3]
    m1x = 0.5 * (x[a1, 0] + x[b1, 0])
    m1y = 0.5 * (x[a1, 1] + x[b1, 1])
    return (0.5 * (x[a2, 0] + x[b2, 0]) - m1x, 0.5 * (x[a2, 1] + x[b2, 1]) - m1y, x[b1, 0] - x[a1, 0],
            x[b1, 1] - x[a1, 1], x[b2, 0] - x[a2, 0], x[b2, 1] - x[a2, 1])


@njit(cache=True, inline="always")
def _joint_frame(tx, ty, g1x, g1y, g2x, g2y):
    """Unit normal and tangent (normal from A to B) and the gap split into its mean (opening o, slip s)
    and the half-difference of the end gaps (lo, ls, the linear part): (nx, ny, tx, ty, o, s, lo, ls)."""
    L = math.sqrt(tx * tx + ty * ty)
    tx /= L
    ty /= L
    nx = ty
    ny = -tx
    o = 0.5 * ((g1x + g2x) * nx + (g1y + g2y) * ny)
    s = 0.5 * ((g1x + g2x) * tx + (g1y + g2y) * ty)
    lo = 0.5 * ((g2x - g1x) * nx + (g2y - g1y) * ny)
    ls = 0.5 * ((g2x - g1x) * tx + (g2y - g1y) * ty)
    return nx, ny, tx, ty, o, s, lo, ls


@njit(cache=True, inline="always")
def _joint_dif(v, jn, jj, jrate, Dmax, jdif):
    """Dynamic increase factor of a rate-dependent joint: from the current rate until the joint
    damages, frozen (jdif) from then on."""
    if Dmax[jj] > 0.0:
        return jdif[jj]
    a1 = jn[jj, 0]
    a2 = jn[jj, 1]
    b1 = jn[jj, 2]
    b2 = jn[jj, 3]
    vgx = 0.5 * (v[b1, 0] - v[a1, 0] + v[b2, 0] - v[a2, 0])
    vgy = 0.5 * (v[b1, 1] - v[a1, 1] + v[b2, 1] - v[a2, 1])
    rate = math.sqrt(vgx * vgx + vgy * vgy) / jrate[jj, 0]
    dif = 1.0
    if rate > jrate[jj, 2]:
        dif = 1.0 + jrate[jj, 1] * math.log10(rate / jrate[jj, 2])
    jdif[jj] = dif
    return dif


@njit(cache=True, inline="always")
def _joint_forces_of(W, k_n, k_t, zeta, sig, tau, nx, ny, tx, ty, lo, ls):
    """Forces on side A: the mean part (Mx, My) acts equally on both ends, the linear part (+-lo, +-ls
    at the ends) with weight 1/3 of the joint (two-point rule) as (Bx, By)."""
    return (0.5 * W * (sig * nx + tau * tx), 0.5 * W * (sig * ny + tau * ty),
            W * zeta * (k_n * lo * nx + k_t * ls * tx) / 6.0, W * zeta * (k_n * lo * ny + k_t * ls * ty) / 6.0)


@njit(cache=True, inline="always")
def _joint_law(tx, ty, o, s, lo, ls, dif, W, k_n, k_t, ft, fs, tanphi, delta_n, delta_t, abc, dm, slip, kap, zeta,
               energy, Psi, dissipated):
    """joint_forces' law for one joint, on scalars only: its geometry (unit tangent (tx, ty), the
    normal (ty, -tx), the gap parts o, s, lo, ls), its DIF, its constants (area W, penalties,
    strengths, critical displacements, the softening curve's abc = (a, b, c)) and its history (Dmax dm,
    plastic slip, kappa, zeta), with the running energy sums Psi and dissipated. The caller reads and
    writes the arrays: an inlined function that takes arrays costs reference counting per array per
    joint, which made the joint loop 3x slower.
    Returns (Mx, My, Bx, By, Psi, dissipated, slip, kappa, Dmax, zeta, grew, broke): the forces on side
    A, the sums, the history after the update, whether the damage grew and whether the joint broke
    (then it takes no force)."""
    f_t = ft * dif
    sig_c = k_n * o if o < 0.0 else 0.0
    f_s = fs * dif - tanphi * sig_c
    # shear: elastic trial, then return to the capacity zeta f_s (plastic slip)
    tau = k_t * (s - slip)
    cap = zeta * f_s
    if abs(tau) > cap:
        dslip = (abs(tau) - cap) / k_t
        sgn = 1.0 if tau > 0.0 else -1.0
        slip += sgn * dslip
        kap += dslip
        dissipated += W * cap * dslip
        tau = sgn * cap
    o_pos = o if o > 0.0 else 0.0
    ex_o = 0.0  # opening beyond the elastic branch (a closed joint has none: no division)
    if o_pos > 0.0:
        ex_o = o_pos - f_t / k_n
        ex_o = ex_o if ex_o > 0.0 else 0.0
    D = 0.0
    if ex_o > 0.0 or kap > 0.0:
        D = math.sqrt((ex_o * dif / delta_n) ** 2 + (kap * dif / delta_t) ** 2)
    grew = False
    # The stored energy is needed where the damage grows (the release it books) and, for the
    # bookkeeping, when asked (the integrator asks at its output samples only).
    if energy or D > dm:
        psi_n = _psi_branch(o_pos, k_n, f_t)
        # The linear part, integrated by the two-point rule: the Gauss points sit at -+1/sqrt(3)
        # of the half-length, so its energy per unit area is (k lo^2 + k_t ls^2) / 6.
        psi_b = (k_n * lo * lo + k_t * ls * ls) / 6.0
        if D > dm:
            zeta_new = z(D, abc[0], abc[1], abc[2])
            dissipated += W * (zeta - zeta_new) * (psi_n + psi_b)
            dm = D
            zeta = zeta_new
            grew = True
        psi = W * (zeta * (psi_n + psi_b) + 0.5 * sig_c * o + 0.5 * tau * tau / k_t)
        if dm >= 1.0:
            # Breaking releases what the joint still stores (its compressive and elastic shear
            # parts, if any); from now on its faces interact through contact only.
            dissipated += psi
            return 0.0, 0.0, 0.0, 0.0, Psi, dissipated, slip, kap, dm, zeta, grew, True
        Psi += psi
    sig = sig_c + zeta * min(k_n * o_pos, f_t)
    Mx, My, Bx, By = _joint_forces_of(W, k_n, k_t, zeta, sig, tau, ty, -tx, tx, ty, lo, ls)
    return Mx, My, Bx, By, Psi, dissipated, slip, kap, dm, zeta, grew, False


@njit(cache=True, inline="always")
def _joint_scatter(f, jn, jj, Mx, My, Bx, By):
    a1 = jn[jj, 0]
    a2 = jn[jj, 1]
    b1 = jn[jj, 2]
    b2 = jn[jj, 3]
    f[a1, 0] += Mx - Bx
    f[a1, 1] += My - By
    f[a2, 0] += Mx + Bx
    f[a2, 1] += My + By
    f[b1, 0] -= Mx - Bx
    f[b1, 1] -= My - By
    f[b2, 0] -= Mx + Bx
    f[b2, 1] -= My + By


@njit(cache=True)
def joint_forces(x, v, joints, state, f, energy=True):
    """Cohesive 4-node joints (Munjiza's combined single and smeared crack, paper Appendix A).

    Nodes (a1, a2, b1, b2): a1->a2 is the edge of triangle A in its counter-clockwise order, b1/b2 the
    coincident nodes of triangle B; the joint normal n points from A to B. The gap g = x_B - x_A varies
    linearly along the joint; it is split into its mean over the joint (opening o, slip s) and the
    linear part about the midpoint (the relative rotation of the two triangles).

    Constitutive law per unit area (jarea = reference length * thickness), on the mean gap:
    - compression (o < 0): sigma = kn o, never damaged;
    - tension: elastic penalty branch up to the strength, then secant softening,
      sigma = zeta min(kn o, ft) (unloading towards the origin, as a crack closes);
    - shear: elastic slip k_t (s - s_p) with Coulomb-type slip once the shear stress reaches the
      capacity zeta f_s, f_s = sigma_t + tan(phi) sigma_c (Mohr-Coulomb under compression sigma_c,
      optional); s_p is the plastic slip and kappa the slip accumulated beyond the elastic branch.
      The slip is plastic, not a secant branch, because the capacity depends on the normal stress: a
      secant cap tau = zeta f_s(sigma_c) sign(s) returns more work in a cycle of compression and slip
      than it took (measured: paper-resolution discs blew up once joints under the loaded flats
      slid), whereas plastic slip only dissipates;
    - coupled damage (paper Fig. A1): D = sqrt(((o - o_p)+/delta_n)^2 + (kappa/delta_t)^2),
      delta = E / (sigma_max A0) (eqs. A8-A9); Dmax stores its history maximum and zeta = z(Dmax)
      (eq. A3) scales both modes, so unloading and reloading never restores strength;
    - the linear part of the gap is elastic with the same penalties, scaled by zeta (it stiffens the
      pair of triangles against relative rotation, integrated exactly by the two-point Gauss rule).
    Why the strength is checked on the mean and not at each Gauss point: the linear part of the gap
    is how a pair of constant-strain triangles represents a stress gradient across one element, and
    next to a loaded corner it reads tensions the continuum does not have (measured at a loading
    flat's corner: +25 MPa at one Gauss point of a joint whose mean was -80 MPa, while the adjacent
    triangles' largest principal stress was 8 MPa); the mean over the edge is the element-scale
    traction, as the triangles' stress is the element-scale stress.
    In monotonic pure shear the plastic work int zeta sigma_t dkappa = sigma_t delta_t A0 = E_t, as in
    the paper; under compression the frictional part tan(phi) sigma_c adds to it. Dissipation is booked
    as the plastic work zeta f_s |d s_p| plus, when Dmax grows at fixed gap, the energy released
    (zeta_old - zeta_new) (psi_n + psi_bend). A monotonic pull dissipates E + sigma_max^2 / (2 k) per
    unit area (softening branch plus the elastic energy released at breaking). A joint whose damage
    reaches D >= 1 is broken: it carries nothing more and its faces join the contact (with the body's
    crack-face friction). (Keeping a compressive branch on broken joints was tried and pumped energy
    into sliding fragments; see tests/test_fdem_fracture.py for the energy balance.)

    Strain-rate-dependent strength (optional, jrate[:, 1] = k > 0): both strengths are scaled by
    DIF = max(1, 1 + k log10(rate / rate0)), rate = |mean relative face velocity| / h (jrate columns:
    h [m], k, rate0 [1/s]); the DIF follows the current rate until damage starts and is frozen from
    then on (jdif), so the softening branch is a fixed law. The softening displacements shrink by the
    same factor, keeping the fracture energies E_n, E_t.

    Joints whose damage first becomes positive are listed in newly_damaged, so that the integrator
    can expose their triangles to contact before the faces separate. The history holds one value per
    joint (the law acts on the mean gap, so its two Gauss points share it). zeta_j caches z(Dmax) per
    joint (1 while undamaged): the softening curve's exponential and power are then evaluated only
    when the damage grows, not for every damaged joint at every step.

    energy=False skips the stored energy of joints whose damage does not grow (returned as 0); the
    forces and the dissipation are the same.

    x, v: nodal coordinates and velocities; joints: fdem.state.Joints (the law's constants); state:
    fdem.state.JointState (the history this call updates); f: the force buffer it adds into.

    Returns (stored joint energy [J], dissipated energy this call [J], number newly broken,
    number newly damaged).
    """
    return _joints_apply(x, v, joints, state, f, energy, joint_work(joints), False)


# Row of JointWork.G after the six gathered ones (_joint_gather): the DIF.
_G_DIF = 6


@njit(cache=True)
def joint_work(joints):
    """Buffers of joint_forces_into for these joints (fdem.state.Joints). The DIF row is 1 and is only
    written when some joint's strength depends on the rate."""
    n = max(joints.nodes.shape[0], 1)
    G = np.empty((7, n))
    G[_G_DIF, :] = 1.0
    rate = joints.rate
    any_rate = False
    for jj in range(rate.shape[0]):
        if rate[jj, 1] > 0.0:
            any_rate = True
    return JointWork(G, np.empty((4, n)), np.zeros(n, np.bool_), any_rate)


@njit(cache=True)
def _joints_gather(x, v, joints, state, G, any_rate):
    """Pass 1: the gathered rows of every joint, and the DIF of rate-dependent ones (their frozen or
    current factor, as joint_forces takes it)."""
    jn, jrate = joints.nodes, joints.rate
    Dmax, jdif, broken = state.Dmax, state.dif, state.broken
    for jj in range(jn.shape[0]):
        G[0, jj], G[1, jj], G[2, jj], G[3, jj], G[4, jj], G[5, jj] = _joint_gather(x, jn, jj)
        if any_rate:
            dif = 1.0
            if jrate[jj, 1] > 0.0 and not broken[jj]:
                dif = _joint_dif(v, jn, jj, jrate, Dmax, jdif)
            G[_G_DIF, jj] = dif


@njit(cache=True, error_model="numpy")
def _joints_trial(G, kn, kt, ft, fs, tanphi, delta_n, delta_t, area, zeta_j, slip_p, kappa, Dmax, H, slow):
    """Pass 2, without branches or gathers so that LLVM vectorises it: every joint's forces on the
    assumption that it neither slips plastically nor damages further (_joint_law's arithmetic for
    that case, to the bit), and slow[j] where the assumption fails (those joint_forces_into redoes
    with _joint_law). Broken joints get numbers that nothing reads."""
    for jj in range(G.shape[1]):
        nx, ny, tx, ty, o, s, lo, ls = _joint_frame(G[0, jj], G[1, jj], G[2, jj], G[3, jj], G[4, jj], G[5, jj])
        dif = G[_G_DIF, jj]
        k_n = kn[jj]
        k_t = kt[jj]
        f_t = ft[jj] * dif
        sig_c = k_n * o if o < 0.0 else 0.0
        f_s = fs[jj] * dif - tanphi[jj] * sig_c
        zeta = zeta_j[jj]
        tau = k_t * (s - slip_p[jj])
        cap = zeta * f_s
        o_pos = o if o > 0.0 else 0.0
        # _joint_law's ex_o and D: where it skips them (o_pos = 0, or no excess and no slip) these
        # expressions give its 0 exactly
        ex_o = o_pos - f_t / k_n
        ex_o = ex_o if ex_o > 0.0 else 0.0
        D = math.sqrt((ex_o * dif / delta_n[jj]) ** 2 + (kappa[jj] * dif / delta_t[jj]) ** 2)
        slow[jj] = (abs(tau) > cap) | (D > Dmax[jj])
        knop = k_n * o_pos
        sig = sig_c + zeta * (knop if knop < f_t else f_t)
        H[0, jj], H[1, jj], H[2, jj], H[3, jj] = _joint_forces_of(area[jj], k_n, k_t, zeta, sig, tau, nx, ny,
                                                                  tx, ty, lo, ls)


@njit(cache=True)
def joint_forces_into(x, v, joints, state, f, energy, work):
    """joint_forces in passes on the buffers of work (joint_work): gather, the vectorised trial of every
    joint (_joints_trial), the full law for the joints that slip or damage (for all of them when the
    energy is asked), and the scatter in joint order; f, the history and the energy sums are those of
    the full law on every joint (joint_forces) to the bit. Returns what joint_forces returns."""
    return _joints_apply(x, v, joints, state, f, energy, work, True)


@njit(cache=True)
def _joints_apply(x, v, joints, state, f, energy, work, trial):
    """Gather, the trial pass when trial (else the full law for every joint), the full law where the
    trial cannot finish, the scatter."""
    G, H, slow = work.G, work.H, work.slow
    jn = joints.nodes
    _joints_gather(x, v, joints, state, G, work.any_rate)
    if trial:
        _joints_trial(G, joints.kn, joints.kt, joints.ft, joints.fs, joints.tanphi, joints.delta_n, joints.delta_t,
                      joints.area, state.zeta, state.slip_p, state.kappa, state.Dmax, H, slow)
    area, kn, kt, ft, fs, tanphi = joints.area, joints.kn, joints.kt, joints.ft, joints.fs, joints.tanphi
    delta_n, delta_t, abc = joints.delta_n, joints.delta_t, (joints.a, joints.b, joints.c)
    Dmax, slip_p, kappa, zeta_j = state.Dmax, state.slip_p, state.kappa, state.zeta
    broken, newly_damaged, newly_broken = state.broken, state.newly_damaged, state.newly_broken
    Psi = 0.0
    dissipated = 0.0
    nnew = 0
    ndam = 0
    for jj in range(jn.shape[0]):
        if broken[jj] or (trial and not (energy or slow[jj])):
            continue
        _, _, tx, ty, o, s, lo, ls = _joint_frame(G[0, jj], G[1, jj], G[2, jj], G[3, jj], G[4, jj], G[5, jj])
        dm = Dmax[jj]
        (H[0, jj], H[1, jj], H[2, jj], H[3, jj], Psi, dissipated, slip_p[jj], kappa[jj], Dmax[jj], zeta_j[jj], grew,
         broke) = _joint_law(tx, ty, o, s, lo, ls, G[_G_DIF, jj], area[jj], kn[jj], kt[jj], ft[jj], fs[jj], tanphi[jj],
                             delta_n[jj], delta_t[jj], abc, dm, slip_p[jj], kappa[jj], zeta_j[jj], energy, Psi,
                             dissipated)
        if grew and dm <= 0.0:
            newly_damaged[ndam] = jj
            ndam += 1
        if broke:
            broken[jj] = True
            newly_broken[nnew] = jj
            nnew += 1
    for jj in range(jn.shape[0]):
        if not broken[jj]:
            _joint_scatter(f, jn, jj, H[0, jj], H[1, jj], H[2, jj], H[3, jj])
    return Psi, dissipated, nnew, ndam


@njit(cache=True)
def contact_forces(x, v, pair_node, pair_edge, node_normal, nodes, tri, surf, joint_state, dt, f, body_force,
                   cstate):
    """Node-to-edge penalty contact with optional Coulomb friction.

    Edges are oriented counter-clockwise around their triangle, so the outward normal of edge p->q is
    (t_y, -t_x). Each node pushes on at most one edge: among its candidate edges, the one it
    penetrates least (0 < d <= edge_dlim, projection within the edge's span). One edge per node keeps
    the force continuous when a node slides over the common vertex of two edges of a face.
    Candidate edges are rejected when
    - their outward normal does not oppose the node's own outward direction (the side face seen from
      a corner node). A node of a fracturable body belongs to one triangle only, and its direction is
      taken afresh from that triangle's centroid (fragments spin); other nodes use the surface
      normal from the last neighbour search (node_normal);
    - they belong to a joint that is still undamaged (edge_joint >= 0, D = 0): such edges enter the
      neighbour list early, but behind an intact joint face is still the body. Once the joint is
      damaged its faces can open at one end (the triangles' relative rotation) and a piece of
      another fragment can enter the mouth, so they are surfaces from then on (the joint's own
      triangles are excluded, as nodes copying the face's vertices);
    - they are crack faces and the node is not inside the face's own triangle: near a crack tip a
      node can be behind the line of a face without being inside the body.
    The node is pushed out with F_n = p_c w min(d, d_cap), p_c [Pa] the penalty of the body pair
    (a symmetric n_bodies x n_bodies table), w the smaller of the two bodies'
    thicknesses (the real contact width), and the opposite force goes to the edge's nodes, so linear
    momentum is conserved exactly. mu_tab is the Coulomb coefficient of the body pair (a symmetric
    n_bodies x n_bodies table like p_c): the faces of a body's own cracks (node and edge in the same
    body) and a bar-specimen interface are different surfaces with their own friction. d_cap = edge_dlim / 3:
    a node found deep inside is pushed out firmly, not shot out (the potential is linear beyond d_cap).
    Friction is an elastic stick with Coulomb slip (the tangential penalty of FDEM contact): per node,
    stick_u is the tangential spring's extension along the edge it touches (stick_edge), grown by the
    relative tangential motion v_t dt; the force is -k_t u with k_t = k_c / 2 (about a tenth of the
    joint penalty, the usual FDEM friction penalty; its largest eigenvalue stays within the normal
    penalty's share of the stable time step), and
    where |k_t u| would exceed mu F_n the spring slips back to mu F_n / k_t, dissipating mu F_n x the
    slip. The spring's energy is contact energy; it is released (dissipated) when the node leaves
    the contact or moves to another edge. (A velocity-based friction capped at the force that stops
    the sliding within one step was used before; with crack-face friction several nodes press on one
    edge and the caps add up, which overshot and left 9 % energy errors in fragmenting discs.)
    Pairs must be grouped by node (build_pairs does so). contact_edge and contact_d (per node; -1 and
    0 when free) carry the contact from step to step: a node's penetration can only grow as fast as
    it moves relative to the surface, so a node enters contact only as deep as its relative travel
    over six steps allows (a new crack face waits at most five for the rebuild), and moving on to the
    next edge of the same surface (one sharing a mesh vertex) may not deepen it by more. A node found
    deeper crossed a face that was not yet a surface (a crushed zone) or slid round a fragment's
    corner; it is left alone rather than shot out by the penalty energy of an overlap nobody resisted
    (measured: a node slipping round a corner onto an edge 50 um deep gave 5 J of energy to a
    fragmenting disc when only the entry was guarded).

    Arguments: the candidate pairs (pair_node, pair_edge) and the surface normals of the last
    neighbour search; nodes (fdem.state.Nodes: body, vertex, triangle, thickness of each node; x, v
    are passed on their own), the triangles' nodes tri, surf (fdem.state.Surfaces), joint_state
    (fdem.state.JointState: which joints are damaged or broken), the time step dt, the force buffer
    f, and cstate (fdem.state.ContactState: the contact carried from step to step).
    Accumulates per-body contact force into body_force (n_bodies, 2).
    Returns (contact energy [J], friction energy dissipated this call [J], maximum penetration [m]).
    """
    n_pairs = pair_node.shape[0]
    node_body, node_vertex, node_tri, node_thick = nodes.body, nodes.vertex, nodes.tri, nodes.thick
    edges, edge_tri, edge_joint, edge_dlim = surf.edges, surf.tri, surf.joint, surf.dlim
    edge_thick, body_fracturable, p_c, mu_tab = surf.thick, surf.body_fracturable, surf.penalty, surf.friction
    broken, Dmax = joint_state.broken, joint_state.Dmax
    contact_edge, contact_d, stick_edge, stick_u = cstate.edge, cstate.d, cstate.stick_edge, cstate.stick_u
    Uc = 0.0
    P_fric = 0.0
    max_pen = 0.0
    ip = 0
    while ip < n_pairs:
        n = pair_node[ip]
        if body_fracturable[node_body[n]]:
            tn = node_tri[n]
            dnx = x[n, 0] - (x[tri[tn, 0], 0] + x[tri[tn, 1], 0] + x[tri[tn, 2], 0]) / 3.0
            dny = x[n, 1] - (x[tri[tn, 0], 1] + x[tri[tn, 1], 1] + x[tri[tn, 2], 1]) / 3.0
        else:
            dnx = node_normal[n, 0]
            dny = node_normal[n, 1]
        best = -1
        best_d = 0.0
        best_xi = 0.0
        while ip < n_pairs and pair_node[ip] == n:
            ed = pair_edge[ip]
            ip += 1
            je = edge_joint[ed]
            if je >= 0 and Dmax[je] <= 0.0 and not broken[je]:
                continue
            p = edges[ed, 0]
            q = edges[ed, 1]
            ex = x[q, 0] - x[p, 0]
            ey = x[q, 1] - x[p, 1]
            L = math.sqrt(ex * ex + ey * ey)
            rx = x[n, 0] - x[p, 0]
            ry = x[n, 1] - x[p, 1]
            xi = (rx * ex + ry * ey) / (L * L)
            if xi < -1e-6 or xi > 1.0 + 1e-6:
                continue
            d = -(rx * ey - ry * ex) / L
            if d <= 0.0 or d > edge_dlim[ed]:
                continue
            if dnx * ey - dny * ex >= 0.0:
                continue
            if je >= 0:
                te = edge_tri[ed]
                r_ = tri[te, 0]
                if r_ == p or r_ == q:
                    r_ = tri[te, 1]
                    if r_ == p or r_ == q:
                        r_ = tri[te, 2]
                if ((x[r_, 0] - x[q, 0]) * (x[n, 1] - x[q, 1])
                        - (x[r_, 1] - x[q, 1]) * (x[n, 0] - x[q, 0])) < 0.0:
                    continue
                if ((x[p, 0] - x[r_, 0]) * (x[n, 1] - x[r_, 1])
                        - (x[p, 1] - x[r_, 1]) * (x[n, 0] - x[r_, 0])) < 0.0:
                    continue
            if best < 0 or d < best_d:
                best = ed
                best_d = d
                best_xi = min(max(xi, 0.0), 1.0)
        if best < 0:
            contact_edge[n] = -1
            contact_d[n] = 0.0
            if stick_edge[n] >= 0:
                P_fric += 0.5 * stick_u[n, 1] * stick_u[n, 0] * stick_u[n, 0]
                stick_edge[n] = -1
                stick_u[n, 0] = 0.0
            continue
        ed = best
        d = best_d
        xi = best_xi
        # A node that was not in contact a step ago can only enter contact as deep as it can have
        # travelled relative to the edge since the neighbour list last saw it (six steps: a new
        # crack face waits at most five for the rebuild). One found deeper crossed a face that was
        # not yet a surface (a crushed zone); it is left alone rather than shot out by the penalty
        # energy of an overlap nobody resisted.
        prev = contact_edge[n]
        fresh = prev < 0
        if prev >= 0 and prev != ed:
            a0 = node_vertex[edges[prev, 0]]
            a1 = node_vertex[edges[prev, 1]]
            b0 = node_vertex[edges[ed, 0]]
            b1 = node_vertex[edges[ed, 1]]
            fresh = not (a0 == b0 or a0 == b1 or a1 == b0 or a1 == b1)
        pq = edges[ed, 0]
        qq = edges[ed, 1]
        vx_ = v[n, 0] - (1.0 - xi) * v[pq, 0] - xi * v[qq, 0]
        vy_ = v[n, 1] - (1.0 - xi) * v[pq, 1] - xi * v[qq, 1]
        allow = 6.0 * dt * math.sqrt(vx_ * vx_ + vy_ * vy_) + 1e-3 * edge_dlim[ed]
        if d > (0.0 if fresh else contact_d[n]) + allow:
            contact_edge[n] = -1
            contact_d[n] = 0.0
            if stick_edge[n] >= 0:
                P_fric += 0.5 * stick_u[n, 1] * stick_u[n, 0] * stick_u[n, 0]
                stick_edge[n] = -1
                stick_u[n, 0] = 0.0
            continue
        contact_edge[n] = ed
        contact_d[n] = d
        p = edges[ed, 0]
        q = edges[ed, 1]
        ex = x[q, 0] - x[p, 0]
        ey = x[q, 1] - x[p, 1]
        L = math.sqrt(ex * ex + ey * ey)
        tx = ex / L
        ty = ey / L
        wth = node_thick[n] if node_thick[n] < edge_thick[ed] else edge_thick[ed]
        kc = p_c[node_body[n], node_body[p]] * wth
        dcap = edge_dlim[ed] * (1.0 / 3.0)
        if d <= dcap:
            Fn = kc * d
            Uc += 0.5 * kc * d * d
        else:
            Fn = kc * dcap
            Uc += kc * dcap * (d - 0.5 * dcap)
        if d > max_pen:
            max_pen = d
        fx = Fn * ty
        fy = -Fn * tx
        mu_c = mu_tab[node_body[n], node_body[p]]
        if mu_c > 0.0:
            if stick_edge[n] != ed:
                # a new contact, or the node slid onto the next edge: start a fresh stick spring
                P_fric += 0.5 * stick_u[n, 1] * stick_u[n, 0] * stick_u[n, 0]
                stick_edge[n] = ed
                stick_u[n, 0] = 0.0
            vrx = v[n, 0] - (1.0 - xi) * v[p, 0] - xi * v[q, 0]
            vry = v[n, 1] - (1.0 - xi) * v[p, 1] - xi * v[q, 1]
            kt_c = 0.5 * kc
            u = stick_u[n, 0] + (vrx * tx + vry * ty) * dt
            cap = mu_c * Fn / kt_c
            if u > cap:
                P_fric += mu_c * Fn * (u - cap)
                u = cap
            elif u < -cap:
                P_fric += mu_c * Fn * (-cap - u)
                u = -cap
            stick_u[n, 0] = u
            stick_u[n, 1] = kt_c
            Uc += 0.5 * kt_c * u * u
            Ft = -kt_c * u
            fx += Ft * tx
            fy += Ft * ty
        f[n, 0] += fx
        f[n, 1] += fy
        f[p, 0] -= (1.0 - xi) * fx
        f[p, 1] -= (1.0 - xi) * fy
        f[q, 0] -= xi * fx
        f[q, 1] -= xi * fy
        bn = node_body[n]
        be = node_body[p]
        body_force[bn, 0] += fx
        body_force[bn, 1] += fy
        body_force[be, 0] -= fx
        body_force[be, 1] -= fy
    return Uc, P_fric, max_pen
