"""Constant-strain triangles: co-rotational elastic forces (a scalar kernel, and the vectorised
three-pass kernel the integrator uses) and the Cauchy stress of one triangle.

Every force kernel *adds* into the force buffer ``f`` (shape (n_nodes, 2), N) and returns the energy
terms it owns, so the integrator can close the energy balance.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _edges(x, tri, e):
    """Edge vectors of triangle e: (x_j - x_i, x_k - x_i) as (d11, d21, d12, d22)."""
    i = tri[e, 0]
    j = tri[e, 1]
    k = tri[e, 2]
    return x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], x[k, 0] - x[i, 0], x[k, 1] - x[i, 1]


@njit(cache=True, inline="always")
def _stress(d11, d21, d12, d22, m11, m12, m21, m22, lam_e, mu_e):
    """Deformation gradient F of a triangle from its edge vectors and Dm^-1, and its co-rotational
    stress.

    Polar decomposition F = R U in closed form (2D: R rotates by atan2(F21 - F12, F11 + F22)), Biot
    strain b = U - I with U = R^T F (symmetric by construction of R), Biot stress
    B = lam tr(b) I + 2 mu b, first Piola-Kirchhoff stress P = R B.
    Returns (F11, F12, F21, F22, P11, P12, P21, P22, strain energy density b : B / 2).
    """
    F11 = d11 * m11 + d12 * m21
    F12 = d11 * m12 + d12 * m22
    F21 = d21 * m11 + d22 * m21
    F22 = d21 * m12 + d22 * m22
    rr = math.sqrt((F11 + F22) ** 2 + (F21 - F12) ** 2)
    cR = (F11 + F22) / rr
    sR = (F21 - F12) / rr
    b11 = cR * F11 + sR * F21 - 1.0
    b22 = -sR * F12 + cR * F22 - 1.0
    b12 = 0.5 * ((cR * F12 + sR * F22) + (-sR * F11 + cR * F21))
    tr = b11 + b22
    B11 = lam_e * tr + 2.0 * mu_e * b11
    B22 = lam_e * tr + 2.0 * mu_e * b22
    B12 = 2.0 * mu_e * b12
    w = 0.5 * (B11 * b11 + B22 * b22 + 2.0 * B12 * b12)
    return (F11, F12, F21, F22, cR * B11 - sR * B12, cR * B12 - sR * B22, sR * B11 + cR * B12,
            sR * B12 + cR * B22, w)


@njit(cache=True, inline="always")
def _corotational(x, tri, dminv, lam, mu, e):
    """_stress of triangle e at coordinates x."""
    d11, d21, d12, d22 = _edges(x, tri, e)
    return _stress(d11, d21, d12, d22, dminv[e, 0, 0], dminv[e, 0, 1], dminv[e, 1, 0], dminv[e, 1, 1],
                   lam[e], mu[e])


@njit(cache=True, inline="always")
def _nodal(P11, P12, P21, P22, m11, m12, m21, m22, V):
    """Force terms (H11, H12, H21, H22) on nodes j and k of a triangle of volume V (node i takes
    minus their sum)."""
    return (-V * (P11 * m11 + P12 * m12), -V * (P11 * m21 + P12 * m22), -V * (P21 * m11 + P22 * m12),
            -V * (P21 * m21 + P22 * m22))


@njit(cache=True, inline="always")
def _scatter(f, tri, e, H11, H12, H21, H22):
    i = tri[e, 0]
    j = tri[e, 1]
    k = tri[e, 2]
    f[j, 0] += H11
    f[j, 1] += H21
    f[k, 0] += H12
    f[k, 1] += H22
    f[i, 0] -= H11 + H12
    f[i, 1] -= H21 + H22


@njit(cache=True)
def triangle_forces_scalar(x, v, tri, dminv, vol0, lam, mu, eta, f, energy=True):
    """Internal forces of 3-node constant-strain triangles in plane stress.

    Co-rotational linear elasticity, total Lagrangian: deformation gradient F = Ds Dm^-1, polar
    decomposition F = R U in closed form, Biot strain e = U - I, Biot stress B = lam tr(e) I + 2 mu e
    with the plane-stress lam = E nu / (1 - nu^2), first Piola-Kirchhoff stress P = R B (the exact
    derivative of W = e : B / 2 per unit volume). e is exactly zero for any rigid rotation, so a
    rotated body carries no stress; unlike St. Venant-Kirchhoff the stiffness does not vanish under
    strong compression, so crushed fragments do not collapse or invert. vol0 = reference area *
    thickness [m^3]. Optional viscous stress S_v = eta dE/dt on the Green-Lagrange rate (eta [Pa s]),
    whose dissipated power is returned. energy=False skips the strain energy (returned as 0).

    Returns (strain energy [J], damping power [W]).
    """
    return triangle_forces_scalar_range(x, v, tri, dminv, vol0, lam, mu, eta, f, energy, np.uint64(0),
                                        np.uint64(tri.shape[0]))


@njit(cache=True)
def triangle_forces_scalar_range(x, v, tri, dminv, vol0, lam, mu, eta, f, energy, lo, hi):
    """triangle_forces_scalar over the triangles lo <= e < hi (unsigned, as in triangle_forces_into)."""
    U = 0.0
    P_damp = 0.0
    for e in range(lo, hi):
        i = tri[e, 0]
        j = tri[e, 1]
        k = tri[e, 2]
        m11 = dminv[e, 0, 0]
        m12 = dminv[e, 0, 1]
        m21 = dminv[e, 1, 0]
        m22 = dminv[e, 1, 1]
        F11, F12, F21, F22, P11, P12, P21, P22, w = _corotational(x, tri, dminv, lam, mu, e)
        V = vol0[e]
        if energy:
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
        H11, H12, H21, H22 = _nodal(P11, P12, P21, P22, m11, m12, m21, m22, V)
        _scatter(f, tri, e, H11, H12, H21, H22)
    return U, P_damp


# Why the vectorised path: Numba's float division raises ZeroDivisionError by default, and the branch
# that checks for it keeps LLVM from vectorising a loop; with error_model="numpy" a division by zero
# gives inf/nan (the integrator's non-finite check stops such a run) and the stress loop runs in SIMD
# registers, with the same IEEE operations in the same order (bit-identical to the scalar kernel).
@njit(cache=True, error_model="numpy")
def _triangle_gather(x, tri, D, lo, hi):
    """Edge vectors of the triangles lo <= e < hi, D[:, e] = (x_j - x_i, x_k - x_i) as (d11, d21, d12, d22)."""
    for e in range(lo, hi):
        D[0, e], D[1, e], D[2, e], D[3, e] = _edges(x, tri, e)


@njit(cache=True, error_model="numpy")
def _triangle_stress(D, M, lam, mu, vol0, H, W, lo, hi):
    """Nodal force terms H[:, e] = (H11, H12, H21, H22) and strain energy W[e] of the triangles
    lo <= e < hi from their edge vectors (_stress, _nodal: the scalar kernel's arithmetic), one loop
    without branches or gathers, so that LLVM vectorises it."""
    for e in range(lo, hi):
        m11 = M[0, e]
        m12 = M[1, e]
        m21 = M[2, e]
        m22 = M[3, e]
        _, _, _, _, P11, P12, P21, P22, w = _stress(D[0, e], D[1, e], D[2, e], D[3, e], m11, m12, m21, m22,
                                                     lam[e], mu[e])
        V = vol0[e]
        W[e] = V * w
        H[0, e], H[1, e], H[2, e], H[3, e] = _nodal(P11, P12, P21, P22, m11, m12, m21, m22, V)


@njit(cache=True)
def triangle_forces_into(x, tri, M, lam, mu, vol0, f, energy, D, H, W, lo, hi):
    """triangle_forces without viscous stress over the triangles lo <= e < hi, on preallocated buffers:
    M = dminv as rows (m11, m12, m21, m22) x n_triangles (soa_dminv), D and H (4, n_triangles), W
    (n_triangles,). Returns their strain energy [J] (0 unless energy). lo and hi are unsigned (np.uint64):
    with a signed start Numba keeps its negative-index check in the loops, and LLVM then does not
    vectorise the stress loop (2.5x slower, measured)."""
    _triangle_gather(x, tri, D, lo, hi)
    _triangle_stress(D, M, lam, mu, vol0, H, W, lo, hi)
    U = 0.0
    for e in range(lo, hi):
        _scatter(f, tri, e, H[0, e], H[1, e], H[2, e], H[3, e])
        if energy:
            U += W[e]
    return U


@njit(cache=True)
def soa_dminv(dminv):
    """dminv (n, 2, 2) as the rows (m11, m12, m21, m22) that triangle_forces_into reads."""
    M = np.empty((4, dminv.shape[0]))
    for e in range(dminv.shape[0]):
        M[0, e] = dminv[e, 0, 0]
        M[1, e] = dminv[e, 0, 1]
        M[2, e] = dminv[e, 1, 0]
        M[3, e] = dminv[e, 1, 1]
    return M


@njit(cache=True)
def viscous(eta) -> bool:
    """Whether any triangle has viscous stress (then the scalar kernel is used)."""
    for e in range(eta.shape[0]):
        if eta[e] > 0.0:
            return True
    return False


@njit(cache=True)
def triangle_forces(x, v, tri, dminv, vol0, lam, mu, eta, f, energy=True):
    """Internal forces of the triangles (triangle_forces_scalar), through the vectorised path when
    no triangle has viscous stress. Returns (strain energy [J], damping power [W])."""
    if viscous(eta):
        return triangle_forces_scalar(x, v, tri, dminv, vol0, lam, mu, eta, f, energy)
    nt = tri.shape[0]
    U = triangle_forces_into(x, tri, soa_dminv(dminv), lam, mu, vol0, f, energy, np.empty((4, nt)),
                             np.empty((4, nt)), np.empty(nt), np.uint64(0), np.uint64(nt))
    return U, 0.0


@njit(cache=True)
def triangle_cauchy(x, tri, dminv, lam, mu, e):
    """Cauchy stress (sxx, syy, sxy) [Pa] of triangle e: sigma = P F^T / det F, P = R B."""
    F11, F12, F21, F22, A11, A12, A21, A22, _ = _corotational(x, tri, dminv, lam, mu, e)
    J = F11 * F22 - F12 * F21
    sxx = (A11 * F11 + A12 * F12) / J
    syy = (A21 * F21 + A22 * F22) / J
    sxy = (A11 * F21 + A12 * F22) / J
    return sxx, syy, sxy
