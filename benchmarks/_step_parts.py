"""The integrator's per-node loops and its stress sampling as separate compiled functions, so that
benchmarks/profile_engine.py can time them alone (they mirror fdem/integrator.run_loop)."""
from __future__ import annotations

from numba import njit

from fdem.kernels import triangle_cauchy


@njit(cache=False)
def node_update(x, v, f, inv_mass, dt, snodes, x_ref, g):
    """Two half kicks, the drift with the largest speed, the zeroing of the force buffer and the
    surface nodes' travel check of the contact list: the per-node work of one step."""
    n = x.shape[0]
    for i in range(n):
        v[i, 0] += 0.5 * dt * f[i, 0] * inv_mass[i]
        v[i, 1] += 0.5 * dt * f[i, 1] * inv_mass[i]
    vmax2 = 0.0
    for i in range(n):
        x[i, 0] += dt * v[i, 0]
        x[i, 1] += dt * v[i, 1]
        vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
        if vv > vmax2:
            vmax2 = vv
    dmax2 = 0.0
    for k in range(snodes.shape[0]):
        s_ = snodes[k]
        ddx = x[s_, 0] - x_ref[s_, 0]
        ddy = x[s_, 1] - x_ref[s_, 1]
        dd = ddx * ddx + ddy * ddy
        if dd > dmax2:
            dmax2 = dd
    g[:, :] = 0.0
    for i in range(n):
        v[i, 0] += 0.5 * dt * f[i, 0] * inv_mass[i]
        v[i, 1] += 0.5 * dt * f[i, 1] * inv_mass[i]
    return vmax2 + dmax2


@njit(cache=False)
def sample_stress(x, tri, dminv, lam, mu, vol0, eg_ptr, eg_el):
    """The probes' mean Cauchy stress, as one sample of run_loop computes it."""
    s = 0.0
    for g in range(eg_ptr.shape[0] - 1):
        for m in range(eg_ptr[g], eg_ptr[g + 1]):
            e = eg_el[m]
            a_, b_, c_ = triangle_cauchy(x, tri, dminv, lam, mu, e)
            s += vol0[e] * (a_ + b_ + c_)
    return s
