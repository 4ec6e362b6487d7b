r"""Pochhammer-Chree dispersion of the bars and its correction of the bar signals (optional step of the
reduction, off by default; a test sheet turns it on with ``reduction: {dispersion_correction: true}``).

A wave in a bar of radius :math:`a` is not one-dimensional: its first longitudinal mode travels at a
phase velocity :math:`c_p` that falls with frequency, from :math:`c_0 = \sqrt{E/\rho}` (long waves) to
the Rayleigh wave speed :math:`c_R` (waves short against the radius). A gauge a distance :math:`d` from the
specimen therefore sees a pulse that differs from the one at the bar's face: its rise is rounded and
followed by ringing. The 1D reduction shifts the gauge signal by :math:`d/c_0` and ignores this.

**The frequency equation** (Pochhammer 1876, Chree 1889; Graff, *Wave motion in elastic solids*, 8.2) of
the longitudinal modes of a free cylinder, wavenumber :math:`k`, angular frequency :math:`\omega`,
:math:`\alpha^2 = \omega^2/c_1^2 - k^2`, :math:`\beta^2 = \omega^2/c_2^2 - k^2` with the dilatational and
shear speeds :math:`c_1^2 = c_0^2 (1-\nu)/((1+\nu)(1-2\nu))`, :math:`c_2^2 = c_0^2/(2(1+\nu))`:

.. math::
   \frac{2\alpha}{a}(\beta^2+k^2)J_1(\alpha a)J_1(\beta a) - (\beta^2-k^2)^2 J_0(\alpha a)J_1(\beta a)
   - 4k^2\alpha\beta J_1(\alpha a)J_0(\beta a) = 0 .

Divided by :math:`\beta a` it holds only the even functions :math:`J_0(x)` and :math:`J_1(x)/x` of
:math:`x = \alpha a, \beta a`, i.e. functions of :math:`\alpha^2 a^2, \beta^2 a^2`, which are real on both
sides of zero (:math:`I_0(y)`, :math:`I_1(y)/y` for :math:`x = iy` below the shear or dilatational speed);
:func:`frequency_equation` evaluates it so, scaled by :math:`e^{-|\alpha a|-|\beta a|}` where those are
imaginary so that it stays finite. In the nondimensional wavenumber :math:`\xi = ka` (:math:`\xi = \pi
D/\Lambda` for the wavelength :math:`\Lambda`) and :math:`v = c_p/c_0` it depends on :math:`\nu` alone:
:func:`phase_velocity_ratio` finds the first mode's :math:`v(\xi)`, the smallest root above
:math:`0.9\,c_R/c_0` (the first mode dips some 0.4 % below :math:`c_R` before it approaches it; the
trivial root :math:`v = 0` lies below).

**The correction** (the frequency-domain phase shift of Follansbee & Frantz 1983, Gong et al. 1990): the
gauge signal is Fourier transformed, each component :math:`\omega` is moved by the phase the first mode
gains over the distance :math:`d` from the gauge to the face beyond the 1D one,

.. math:: \hat\varepsilon_{face}(\omega) = \hat\varepsilon_{gauge}(\omega)\,
   \exp\!\left[-i\omega d\left(\frac{1}{c_p(\omega)} - \frac{1}{c_0}\right)\right]

(:math:`d > 0` toward the direction the wave travels: the incident wave from its gauge to the front face;
:math:`d < 0` back against it: the reflected wave from the front face and the transmitted wave from the
back face, recorded after they travelled), and transformed back. The 1D delay :math:`d/c_0` stays with
the reduction's time shifts (:mod:`shpb.lab.reduction`, step 6), so with the correction off, or at
:math:`d = 0`, the signal is unchanged. Limits, as in most SHPB practice:

* first mode only: every component is given the first mode's phase, also above the second longitudinal
  mode's cut-off (:math:`\omega a/c_0 \approx 2.2` for :math:`\nu = 0.32`, about 70 kHz on the Freiburg
  50 mm titanium bars), where part of a wave's energy may travel in other modes;
* phase only: the amplitude factors of Davies (1948) / Tyas & Pope (2005), the ratio of the strain at
  the bar's surface, where the gauges are, to the mean strain over the section, which departs from 1
  at high frequency, are ignored (taken as 1);
* the gauge signal is treated as periodic: it is padded beyond its end with a smooth (cosine) return
  from its last value to its first, longer than the largest dispersive delay, so nothing shifted off one
  end of the record comes back in at the other.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq
from scipy.special import i0e, i1e, j0, j1

__all__ = ["frequency_equation", "rayleigh_speed_ratio", "phase_velocity_ratio", "DispersionCurve",
           "dispersion_curve", "phase_velocity", "dispersion_shift", "correct_bar_signals"]

#: Nondimensional wavenumbers xi = k a of the tabulated curve: fine where the curve bends, sparse far out.
_XI_GRID = np.concatenate([np.linspace(0.0, 30.0, 1501), np.geomspace(30.0, 1000.0, 301)[1:]])
_N_SCAN = 400


def _speeds_sq(nu: float) -> tuple[float, float]:
    """(c1^2, c2^2) / c0^2: dilatational and shear speeds over the bar speed, squared."""
    c2sq = 1.0 / (2.0 * (1.0 + nu))
    return c2sq * 2.0 * (1.0 - nu) / (1.0 - 2.0 * nu), c2sq


def _even_bessel(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""For :math:`s = x^2` (negative: :math:`x = iy`): :math:`J_0(x)` and :math:`J_1(x)/x`, both scaled by
    :math:`e^{-y}` where :math:`x = iy` (:math:`I_0(y)`, :math:`I_1(y)/y`), and the exponent :math:`y` (0 where
    :math:`s \ge 0`)."""
    y = np.sqrt(np.abs(s))
    pos = s >= 0.0
    tiny = y < 1.0e-6
    ysafe = np.where(tiny, 1.0, y)
    f0 = np.where(pos, j0(y), i0e(y))
    g = np.where(pos, j1(y), i1e(y)) / ysafe
    g = np.where(tiny, 0.5 - s / 16.0, g)   # J1(x)/x = 1/2 - x^2/16 + ..., both signs of s
    return f0, g, np.where(pos, 0.0, y)


def frequency_equation(xi, v, nu: float) -> np.ndarray:
    r"""The Pochhammer-Chree frequency equation of the longitudinal modes (module docstring), divided by
    :math:`\beta a` and scaled to stay finite, at nondimensional wavenumber ``xi`` :math:`= ka` and phase
    velocity ``v`` :math:`= c_p/c_0` (broadcast against each other), for Poisson's ratio ``nu``. Zero on
    a mode; in units of :math:`1/a^4`."""
    xi, v = np.broadcast_arrays(np.asarray(xi, float), np.asarray(v, float))
    c1sq, c2sq = _speeds_sq(nu)
    k2 = xi ** 2
    A = k2 * (v ** 2 / c1sq - 1.0)    # (alpha a)^2
    B = k2 * (v ** 2 / c2sq - 1.0)    # (beta a)^2
    J0a, ga, _ = _even_bessel(A)
    J0b, gb, _ = _even_bessel(B)
    return 2.0 * A * (B + k2) * ga * gb - (B - k2) ** 2 * J0a * gb - 4.0 * k2 * A * ga * J0b


def rayleigh_speed_ratio(nu: float) -> float:
    r""":math:`c_R/c_0`: the Rayleigh surface wave's speed, root of
    :math:`(2-X)^2 = 4\sqrt{1 - X c_2^2/c_1^2}\sqrt{1-X}` with :math:`X = c_R^2/c_2^2 \in (0, 1)`."""
    c1sq, c2sq = _speeds_sq(nu)
    r = c2sq / c1sq
    X = brentq(lambda X: (2.0 - X) ** 2 - 4.0 * math.sqrt(1.0 - r * X) * math.sqrt(1.0 - X), 0.5, 1.0,
               xtol=1e-15, rtol=1e-15)
    return math.sqrt(X * c2sq)


def phase_velocity_ratio(xi, nu: float) -> np.ndarray:
    r"""First longitudinal mode's phase velocity over :math:`c_0` at nondimensional wavenumbers ``xi``
    :math:`= ka` (array), for Poisson's ratio ``nu``: the smallest root of :func:`frequency_equation` above
    :math:`0.9\,c_R/c_0`, bracketed on a grid of :math:`v` and bisected to machine precision. 1 at
    :math:`\xi = 0`; below :math:`\xi = 10^{-6}` the long-wave limit :math:`1 - \nu^2\xi^2/4` (Rayleigh)."""
    if not 0.0 < nu < 0.5:
        raise ValueError(f"Poisson's ratio of the bar must lie in (0, 0.5), got {nu}")
    xi = np.atleast_1d(np.asarray(xi, float))
    out = 1.0 - nu ** 2 * xi ** 2 / 4.0
    big = xi >= 1.0e-6
    if not big.any():
        return out
    x = xi[big][:, None]
    grid = np.linspace(0.9 * rayleigh_speed_ratio(nu), 1.0 + 1.0e-4, _N_SCAN)
    f = frequency_equation(x, grid[None, :], nu)
    change = np.signbit(f[:, :-1]) != np.signbit(f[:, 1:])
    if not change.any(axis=1).all():
        raise ValueError(f"no first-mode root found for xi = {xi[big][~change.any(axis=1)][:3]} (nu = {nu})")
    j = np.argmax(change, axis=1)
    lo, hi = grid[j], grid[j + 1]
    f_lo = f[np.arange(j.size), j]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = frequency_equation(x[:, 0], mid, nu)
        same = np.signbit(f_mid) == np.signbit(f_lo)
        lo, f_lo = np.where(same, mid, lo), np.where(same, f_mid, f_lo)
        hi = np.where(same, hi, mid)
    out[big] = 0.5 * (lo + hi)
    return out


@dataclass(frozen=True, eq=False)
class DispersionCurve:
    r"""The first mode's phase velocity for one Poisson's ratio, tabulated on ``xi`` :math:`= ka`:
    ``v`` :math:`= c_p/c_0` and the nondimensional frequency ``omega`` :math:`= \omega a/c_0 = \xi v`
    (increasing: the group velocity is positive). ``v_rayleigh`` :math:`= c_R/c_0`."""

    nu: float
    xi: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    v_rayleigh: float
    _interp: PchipInterpolator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_interp", PchipInterpolator(self.omega, self.v))

    def ratio_at_frequency(self, omega_nd) -> np.ndarray:
        r""":math:`c_p/c_0` at nondimensional frequencies :math:`\omega a/c_0` (monotone cubic interpolation;
        the Rayleigh limit beyond the table's last :math:`\xi` = 1000)."""
        w = np.abs(np.asarray(omega_nd, float))
        out = np.full(w.shape, self.v_rayleigh)
        inside = w <= self.omega[-1]
        out[inside] = self._interp(w[inside])
        return out


@lru_cache(maxsize=16)
def dispersion_curve(nu: float) -> DispersionCurve:
    """The first mode's curve for Poisson's ratio ``nu`` (computed once per ratio, about 0.3 s)."""
    nu = float(nu)
    v = phase_velocity_ratio(_XI_GRID, nu)
    return DispersionCurve(nu, _XI_GRID.copy(), v, _XI_GRID * v, rayleigh_speed_ratio(nu))


def phase_velocity(frequency_hz, c0: float, diameter: float, nu: float) -> np.ndarray:
    """The first mode's phase velocity [m/s] at ``frequency_hz`` in a bar of wave speed ``c0`` [m/s],
    ``diameter`` [m] and Poisson's ratio ``nu``."""
    omega_nd = 2.0 * math.pi * np.asarray(frequency_hz, float) * (0.5 * diameter) / c0
    return c0 * dispersion_curve(nu).ratio_at_frequency(omega_nd)


def dispersion_shift(signal, dt: float, distance: float, c0: float, diameter: float, nu: float) -> np.ndarray:
    r"""The bar signal ``signal`` (sampled every ``dt`` s) as it would read ``distance`` [m] further along the
    bar in the direction the wave travels (negative: as it read that far before), by the first mode's
    dispersion beyond the 1D delay :math:`d/c_0`, which is left out (module docstring). Same length."""
    x = np.asarray(signal, float)
    n = x.size
    curve = dispersion_curve(nu)
    slowest = min(float(np.min(curve.v)), curve.v_rayleigh)
    lag = abs(distance) / c0 * (1.0 / slowest - 1.0)
    n_pad = max(64, int(math.ceil(lag / dt)) + 32)
    n_fft = next_fast_len(n + n_pad, real=True)
    ramp = 0.5 * (1.0 - np.cos(np.pi * np.arange(1, n_fft - n + 1) / (n_fft - n + 1)))
    padded = np.concatenate([x, x[-1] + (x[0] - x[-1]) * ramp])
    f = rfftfreq(n_fft, dt)
    cp = phase_velocity(f, c0, diameter, nu)
    phase = np.exp(-1j * 2.0 * np.pi * f * distance * (1.0 / cp - 1.0 / c0))
    return irfft(rfft(padded) * phase, n_fft)[:n]


def correct_bar_signals(inc: np.ndarray, tra: np.ndarray, dt: float, bar, nu: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The incident-bar and transmission-bar gauge signals corrected to the specimen's faces: (incident
    wave, ``gauge_distance_incident`` forward; reflected wave, the same distance back; transmitted wave,
    ``gauge_distance_transmitted`` back), for a :class:`~shpb.lab.bars.BarSetup` ``bar`` of Poisson's
    ratio ``nu``."""
    x_i, x_t = bar.gauge_distance_incident, bar.gauge_distance_transmitted
    return (dispersion_shift(inc, dt, x_i, bar.c0, bar.diameter, nu),
            dispersion_shift(inc, dt, -x_i, bar.c0, bar.diameter, nu),
            dispersion_shift(tra, dt, -x_t, bar.c0, bar.diameter, nu))
