"""Force kernels: constant-strain triangles, cohesive joints, node-to-edge penalty contact.

Plain loops over structure-of-arrays buffers, compiled with Numba. Every kernel *adds* into the
force buffer ``f`` (shape (n_nodes, 2), N) and returns the energy terms it owns, so the integrator can
close the energy balance.
"""
from __future__ import annotations

import math

from numba import njit

from .softening import z

# Two-point Gauss rule on [0, 1] for the joint traction integral.
_G0 = 0.5 - 0.5 / math.sqrt(3.0)
_G1 = 0.5 + 0.5 / math.sqrt(3.0)


@njit(cache=True, inline="always")
def _corotational(x, tri, dminv, lam, mu, e):
    """Deformation gradient F of triangle e and its co-rotational stress.

    Polar decomposition F = R U in closed form (2D: R rotates by atan2(F21 - F12, F11 + F22)), Biot
    strain b = U - I with U = R^T F (symmetric by construction of R), Biot stress
    B = lam tr(b) I + 2 mu b, first Piola-Kirchhoff stress P = R B.
    Returns (F11, F12, F21, F22, P11, P12, P21, P22, strain energy density b : B / 2).
    """
    i = tri[e, 0]
    j = tri[e, 1]
    k = tri[e, 2]
    d11 = x[j, 0] - x[i, 0]
    d21 = x[j, 1] - x[i, 1]
    d12 = x[k, 0] - x[i, 0]
    d22 = x[k, 1] - x[i, 1]
    F11 = d11 * dminv[e, 0, 0] + d12 * dminv[e, 1, 0]
    F12 = d11 * dminv[e, 0, 1] + d12 * dminv[e, 1, 1]
    F21 = d21 * dminv[e, 0, 0] + d22 * dminv[e, 1, 0]
    F22 = d21 * dminv[e, 0, 1] + d22 * dminv[e, 1, 1]
    rr = math.sqrt((F11 + F22) ** 2 + (F21 - F12) ** 2)
    cR = (F11 + F22) / rr
    sR = (F21 - F12) / rr
    b11 = cR * F11 + sR * F21 - 1.0
    b22 = -sR * F12 + cR * F22 - 1.0
    b12 = 0.5 * ((cR * F12 + sR * F22) + (-sR * F11 + cR * F21))
    tr = b11 + b22
    B11 = lam[e] * tr + 2.0 * mu[e] * b11
    B22 = lam[e] * tr + 2.0 * mu[e] * b22
    B12 = 2.0 * mu[e] * b12
    w = 0.5 * (B11 * b11 + B22 * b22 + 2.0 * B12 * b12)
    return (F11, F12, F21, F22, cR * B11 - sR * B12, cR * B12 - sR * B22, sR * B11 + cR * B12,
            sR * B12 + cR * B22, w)


@njit(cache=True)
def triangle_forces(x, v, tri, dminv, vol0, lam, mu, eta, f):
    """Internal forces of 3-node constant-strain triangles in plane stress.

    Co-rotational linear elasticity, total Lagrangian: deformation gradient F = Ds Dm^-1, polar
    decomposition F = R U in closed form, Biot strain e = U - I, Biot stress B = lam tr(e) I + 2 mu e
    with the plane-stress lam = E nu / (1 - nu^2), first Piola-Kirchhoff stress P = R B (the exact
    derivative of W = e : B / 2 per unit volume). e is exactly zero for any rigid rotation, so a
    rotated body carries no stress; unlike St. Venant-Kirchhoff the stiffness does not vanish under
    strong compression, so crushed fragments do not collapse or invert. vol0 = reference area *
    thickness [m^3]. Optional viscous stress S_v = eta dE/dt on the Green-Lagrange rate (eta [Pa s]),
    whose dissipated power is returned.

    Returns (strain energy [J], damping power [W]).
    """
    U = 0.0
    P_damp = 0.0
    for e in range(tri.shape[0]):
        i = tri[e, 0]
        j = tri[e, 1]
        k = tri[e, 2]
        m11 = dminv[e, 0, 0]
        m12 = dminv[e, 0, 1]
        m21 = dminv[e, 1, 0]
        m22 = dminv[e, 1, 1]
        F11, F12, F21, F22, P11, P12, P21, P22, w = _corotational(x, tri, dminv, lam, mu, e)
        V = vol0[e]
        U += V * w
        if eta[e] > 0.0:
            w11 = v[j, 0] - v[i, 0]
            w21 = v[j, 1] - v[i, 1]
            w12 = v[k, 0] - v[i, 0]
            w22 = v[k, 1] - v[i, 1]
            G11 = w11 * m11 + w12 * m21
            G12 = w11 * m12 + w12 * m22
            G21 = w21 * m11 + w22 * m21
            G22 = w21 * m12 + w22 * m22
            R11 = F11 * G11 + F21 * G21
            R22 = F12 * G12 + F22 * G22
            R12 = 0.5 * (F11 * G12 + F21 * G22 + G11 * F12 + G21 * F22)
            Sv11 = eta[e] * R11
            Sv22 = eta[e] * R22
            Sv12 = eta[e] * R12
            P_damp += V * (Sv11 * R11 + Sv22 * R22 + 2.0 * Sv12 * R12)
            # viscous first Piola-Kirchhoff stress F S_v
            P11 += F11 * Sv11 + F12 * Sv12
            P12 += F11 * Sv12 + F12 * Sv22
            P21 += F21 * Sv11 + F22 * Sv12
            P22 += F21 * Sv12 + F22 * Sv22
        H11 = -V * (P11 * m11 + P12 * m12)
        H12 = -V * (P11 * m21 + P12 * m22)
        H21 = -V * (P21 * m11 + P22 * m12)
        H22 = -V * (P21 * m21 + P22 * m22)
        f[j, 0] += H11
        f[j, 1] += H21
        f[k, 0] += H12
        f[k, 1] += H22
        f[i, 0] -= H11 + H12
        f[i, 1] -= H21 + H22
    return U, P_damp


@njit(cache=True)
def triangle_cauchy(x, tri, dminv, lam, mu, e):
    """Cauchy stress (sxx, syy, sxy) [Pa] of triangle e: sigma = P F^T / det F, P = R B."""
    F11, F12, F21, F22, A11, A12, A21, A22, _ = _corotational(x, tri, dminv, lam, mu, e)
    J = F11 * F22 - F12 * F21
    sxx = (A11 * F11 + A12 * F12) / J
    syy = (A21 * F21 + A22 * F22) / J
    sxy = (A11 * F21 + A12 * F22) / J
    return sxx, syy, sxy


@njit(cache=True, inline="always")
def _psi_branch(u, k, fmax):
    """Energy per unit area of the elastic-to-peak branch, capped at the strength (J/m^2)."""
    au = abs(u)
    up = fmax / k
    if au <= up:
        return 0.5 * k * au * au
    return 0.5 * fmax * up + fmax * (au - up)


@njit(cache=True)
def joint_forces(x, v, jn, jarea, kn, kt, ft, fs, dn, dt_, tanphi, a, b, c, Dmax, broken, f,
                 newly_broken, newly_damaged, jrate, jdif):
    """Cohesive 4-node joints (Munjiza's combined single and smeared crack, paper Appendix A).

    Nodes (a1, a2, b1, b2): a1->a2 is the edge of triangle A in its counter-clockwise order, b1/b2 the
    coincident nodes of triangle B; the joint normal n points from A to B. At two Gauss points the gap
    g = x_B - x_A gives the opening o = g.n and slip s = g.t.

    Constitutive law per unit area (jarea = reference length * thickness):
    - compression (o < 0): sigma = kn o, never damaged;
    - tension / shear: elastic penalty branch up to the strength, sigma = zeta min(kn o, ft),
      tau = zeta sign(s) min(kt |s|, fs), with fs = sigma_t - tan(phi) sigma (Mohr-Coulomb, optional);
    - coupled damage (paper Fig. A1): D = sqrt(((o - o_p)+/delta_n)^2 + ((|s| - s_p)+/delta_t)^2),
      delta = E / (sigma_max A0) (eqs. A8-A9); Dmax stores its history maximum, zeta = z(Dmax)
      (eq. A3) scales both modes, so unloading and reloading never restores strength.
    The energy released when Dmax grows at fixed gap is the dissipated energy (psi(zeta_old) -
    psi(zeta_new)); a monotonic pull dissipates E + sigma_max o_p / 2 per unit area. A joint whose
    two Gauss points reach D >= 1 is broken: it carries nothing more and its faces join the contact.
    (Keeping a compressive branch on broken joints was tried and pumped energy into sliding
    fragments; see tests/test_fdem_fracture.py for the energy balance this choice achieves.)

    Strain-rate-dependent strength (optional, jrate[:, 1] = k > 0): both strengths are scaled by
    DIF = max(1, 1 + k log10(rate / rate0)), rate = |relative face velocity| / h at the Gauss
    point (jrate columns: h [m], k, rate0 [1/s]); the DIF follows the current rate until damage
    starts and is frozen from then on (jdif), so the softening branch is a fixed potential. The
    softening displacements shrink by the same factor, keeping the fracture energies E_n, E_t.

    Joints whose damage first becomes positive are listed in newly_damaged, so that the integrator
    can expose their triangles to contact before the faces separate.

    Returns (stored joint energy [J], dissipated energy this call [J], number newly broken,
    number newly damaged).
    """
    Psi = 0.0
    dissipated = 0.0
    nnew = 0
    ndam = 0
    for jj in range(jn.shape[0]):
        if broken[jj]:
            continue
        a1 = jn[jj, 0]
        a2 = jn[jj, 1]
        b1 = jn[jj, 2]
        b2 = jn[jj, 3]
        m1x = 0.5 * (x[a1, 0] + x[b1, 0])
        m1y = 0.5 * (x[a1, 1] + x[b1, 1])
        tx = 0.5 * (x[a2, 0] + x[b2, 0]) - m1x
        ty = 0.5 * (x[a2, 1] + x[b2, 1]) - m1y
        L = math.sqrt(tx * tx + ty * ty)
        tx /= L
        ty /= L
        nx = ty
        ny = -tx
        g1x = x[b1, 0] - x[a1, 0]
        g1y = x[b1, 1] - x[a1, 1]
        g2x = x[b2, 0] - x[a2, 0]
        g2y = x[b2, 1] - x[a2, 1]
        w = 0.5 * jarea[jj]
        k_n = kn[jj]
        k_t = kt[jj]
        n_broken_gp = 0
        psi_gp0 = 0.0
        psi_gp1 = 0.0
        T0x = 0.0
        T0y = 0.0
        T1x = 0.0
        T1y = 0.0
        for gp in range(2):
            xi = _G0 if gp == 0 else _G1
            gx = (1.0 - xi) * g1x + xi * g2x
            gy = (1.0 - xi) * g1y + xi * g2y
            o = gx * nx + gy * ny
            s = gx * tx + gy * ty
            dif = 1.0
            if jrate[jj, 1] > 0.0:
                if Dmax[jj, gp] > 0.0:
                    dif = jdif[jj, gp]
                else:
                    vgx = (1.0 - xi) * (v[b1, 0] - v[a1, 0]) + xi * (v[b2, 0] - v[a2, 0])
                    vgy = (1.0 - xi) * (v[b1, 1] - v[a1, 1]) + xi * (v[b2, 1] - v[a2, 1])
                    rate = math.sqrt(vgx * vgx + vgy * vgy) / jrate[jj, 0]
                    if rate > jrate[jj, 2]:
                        dif = 1.0 + jrate[jj, 1] * math.log10(rate / jrate[jj, 2])
                    jdif[jj, gp] = dif
            f_t = ft[jj] * dif
            sig_c = k_n * o if o < 0.0 else 0.0
            f_s = fs[jj] * dif - tanphi[jj] * sig_c
            o_pos = o if o > 0.0 else 0.0
            ex_o = o_pos - f_t / k_n
            ex_s = abs(s) - f_s / k_t
            ex_o = ex_o if ex_o > 0.0 else 0.0
            ex_s = ex_s if ex_s > 0.0 else 0.0
            D = math.sqrt((ex_o * dif / dn[jj]) ** 2 + (ex_s * dif / dt_[jj]) ** 2)
            psi_pos = _psi_branch(o_pos, k_n, f_t) + _psi_branch(s, k_t, f_s)
            psi_neg = 0.5 * sig_c * o
            dm = Dmax[jj, gp]
            zeta = 1.0 if dm <= 0.0 else z(dm, a, b, c)
            if D > dm:
                if dm <= 0.0 and Dmax[jj, 1 - gp] <= 0.0:
                    newly_damaged[ndam] = jj
                    ndam += 1
                zeta_new = z(D, a, b, c)
                dissipated += w * (zeta - zeta_new) * psi_pos
                Dmax[jj, gp] = D
                zeta = zeta_new
            if Dmax[jj, gp] >= 1.0:
                n_broken_gp += 1
            psi = w * (zeta * psi_pos + psi_neg)
            sig = sig_c + zeta * min(k_n * o_pos, f_t)
            tau = zeta * min(k_t * abs(s), f_s)
            if s < 0.0:
                tau = -tau
            Tx = w * (sig * nx + tau * tx)
            Ty = w * (sig * ny + tau * ty)
            if gp == 0:
                psi_gp0 = psi
                T0x = Tx
                T0y = Ty
            else:
                psi_gp1 = psi
                T1x = Tx
                T1y = Ty
        if n_broken_gp == 2:
            # Breaking releases what the joint still stores (its compressive part, if any); from
            # now on its faces interact through contact only.
            dissipated += psi_gp0 + psi_gp1
            broken[jj] = True
            newly_broken[nnew] = jj
            nnew += 1
            continue
        Psi += psi_gp0 + psi_gp1
        fa1x = (1.0 - _G0) * T0x + (1.0 - _G1) * T1x
        fa1y = (1.0 - _G0) * T0y + (1.0 - _G1) * T1y
        fa2x = _G0 * T0x + _G1 * T1x
        fa2y = _G0 * T0y + _G1 * T1y
        f[a1, 0] += fa1x
        f[a1, 1] += fa1y
        f[a2, 0] += fa2x
        f[a2, 1] += fa2y
        f[b1, 0] -= fa1x
        f[b1, 1] -= fa1y
        f[b2, 0] -= fa2x
        f[b2, 1] -= fa2y
    return Psi, dissipated, nnew, ndam


@njit(cache=True)
def contact_forces(x, v, inv_mass, pair_node, pair_edge, n_pairs, node_normal, edges, edge_tri,
                   edge_joint, broken, Dmax, edge_dlim, edge_thick, node_thick, node_body, node_tri, tri,
                   node_vertex, body_fracturable, p_c, mu_c, dt, f, body_force, in_contact):
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
    - they belong to a joint that is not broken (edge_joint >= 0): such edges enter the neighbour
      list early, but behind an intact joint face is still the body;
    - they are crack faces and the node is not inside the face's own triangle: near a crack tip a
      node can be behind the line of a face without being inside the body.
    The node is pushed out with F_n = p_c w min(d, d_cap), p_c [Pa] the penalty of the body pair
    (a symmetric n_bodies x n_bodies table), w the smaller of the two bodies'
    thicknesses (the real contact width), and the opposite force goes to the edge's nodes, so linear
    momentum is conserved exactly. d_cap = edge_dlim / 3: a node found deep inside is pushed out
    firmly, not shot out (the potential is linear beyond d_cap). Friction opposes the relative
    tangential velocity with |F_t| <= mu_c F_n, and never more than the force that stops the sliding
    within one step (a stable regularisation of sticking). Pairs must be grouped by node
    (build_pairs does so). in_contact (per node) carries the contact state from step to step:
    a node enters contact only as deep as its relative travel over six steps allows, then stays in
    contact while it penetrates.

    Accumulates per-body contact force into body_force (n_bodies, 2).
    Returns (contact energy [J], friction power [W], maximum penetration [m]).
    """
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
            if je >= 0 and not broken[je]:
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
            in_contact[n] = False
            continue
        ed = best
        d = best_d
        xi = best_xi
        # A node that was not in contact a step ago can only enter contact as deep as it can have
        # travelled relative to the edge since the neighbour list last saw it (six steps: a new
        # crack face waits at most five for the rebuild). One found deeper crossed a face that was
        # not yet a surface (a crushed zone); it is left alone rather than shot out by the penalty
        # energy of an overlap nobody resisted.
        if not in_contact[n]:
            pq = edges[ed, 0]
            qq = edges[ed, 1]
            vx_ = v[n, 0] - (1.0 - xi) * v[pq, 0] - xi * v[qq, 0]
            vy_ = v[n, 1] - (1.0 - xi) * v[pq, 1] - xi * v[qq, 1]
            if d > 6.0 * dt * math.sqrt(vx_ * vx_ + vy_ * vy_) + 1e-3 * edge_dlim[ed]:
                continue
        in_contact[n] = True
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
        if mu_c > 0.0:
            vrx = v[n, 0] - (1.0 - xi) * v[p, 0] - xi * v[q, 0]
            vry = v[n, 1] - (1.0 - xi) * v[p, 1] - xi * v[q, 1]
            vt = vrx * tx + vry * ty
            invm = inv_mass[n] + (1.0 - xi) ** 2 * inv_mass[p] + xi * xi * inv_mass[q]
            Ft = mu_c * Fn
            Fstop = 0.5 * abs(vt) / (dt * invm)
            if Fstop < Ft:
                Ft = Fstop
            if vt > 0.0:
                Ft = -Ft
            P_fric += -Ft * vt
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
