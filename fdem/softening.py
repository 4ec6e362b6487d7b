"""Munjiza's displacement-softening curve z(x) and the joint constants derived from it.

Paper (Godinez & Rougier 2021, Appendix A):
    z(x) = [1 - (a+b-1)/(a+b) * exp(x (a + c b) / ((a+b)(1-a-b)))] * [a (1-x) + b (1-x)^c]   (A3)
    A0   = integral_0^1 z(x) dx                                                             (A6)
    delta_n_max = E_n / (sigma_n_max A0),  delta_t_max = E_t / (sigma_t_max A0)            (A8, A9)
so that the energy under the softening branch, sigma_max * delta_max * A0, equals E whatever (a, b, c).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

DEFAULT_A = 0.63
DEFAULT_B = 1.8
DEFAULT_C = 6.0
#: ``A0`` of the default curve, the value ``A0``'s quadrature gives (tests/test_fdem_joints.py checks the
#: bits): importing scipy.integrate took 0.9 s of every simulation's 1.7 s of imports.
A0_DEFAULT = 0.38630729474394265


@njit(cache=True, inline="always")
def z(x, a, b, c):
    """Softening curve z(x) of eq. (A3); z(0) = 1, z(1) = 0. x is clipped to [0, 1]."""
    if x <= 0.0:
        return 1.0
    if x >= 1.0:
        return 0.0
    s = a + b
    return (1.0 - (s - 1.0) / s * math.exp(x * (a + c * b) / (s * (1.0 - s)))) * (
        a * (1.0 - x) + b * (1.0 - x) ** c)


def z_numpy(x, a=DEFAULT_A, b=DEFAULT_B, c=DEFAULT_C):
    """Vectorised z(x) for plotting and quadrature."""
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
    s = a + b
    return (1.0 - (s - 1.0) / s * np.exp(x * (a + c * b) / (s * (1.0 - s)))) * (
        a * (1.0 - x) + b * (1.0 - x) ** c)


@lru_cache(maxsize=256)
def A0(a: float = DEFAULT_A, b: float = DEFAULT_B, c: float = DEFAULT_C) -> float:
    """Area under the softening curve, eq. (A6), by adaptive Gauss-Kronrod quadrature (~1e-12)."""
    if not (a > 0 and b > 0 and c > 0):
        raise ValueError(f"softening parameters must be positive, got a={a}, b={b}, c={c}")
    if (a, b, c) == (DEFAULT_A, DEFAULT_B, DEFAULT_C):
        return A0_DEFAULT
    from scipy.integrate import quad  # only for a curve other than the default (a heavy import)

    val, _ = quad(lambda x: float(z_numpy(x, a, b, c)), 0.0, 1.0, epsabs=1e-13, epsrel=1e-12)
    return float(val)


def delta_max(E: float, sigma_max: float, a=DEFAULT_A, b=DEFAULT_B, c=DEFAULT_C) -> float:
    """Maximum post-peak displacement delta_max = E / (sigma_max A0) [m], eqs. (A8)-(A9).

    E: specific fracture energy [J/m^2]; sigma_max: strength [Pa].
    """
    if E <= 0 or sigma_max <= 0:
        raise ValueError(f"need E > 0 J/m^2 and sigma_max > 0 Pa, got E={E}, sigma_max={sigma_max}")
    return E / (sigma_max * A0(a, b, c))
