r"""Reduction of measured SHPB records to specimen stress, strain rate, strain and force balance.

The reduction of docs/measured-records.md. Input: a :class:`shpb.lab.records.RawRecord`
(time axis + raw gauge channels of both bars) and a :class:`BarSetup`. Output: a :class:`ReducedRecord`
on a common time axis at the specimen faces. Conventions: SI units, **compression positive**.

Steps (each one a function below, with its equation):

1. Volts to strain, compression positive: :math:`\varepsilon_k(t) = s\,f\,U_k(t)` with the bridge
   factor :math:`f` [strain/V] (:func:`bridge_strain_per_volt`) and the sign :math:`s=\pm 1` of a
   compressive signal in the record.
2. Provisional noise of every channel from the first samples, :math:`\hat\sigma = 1.4826\,\mathrm{MAD}`;
   isolated spikes removed (:func:`despike`); provisional baseline = mean of the first samples.
3. Arrival of the incident wave at the incident gauge (:func:`detect_arrival`): first *sustained*
   exceedance of :math:`h = \max(k\,\hat\sigma, \phi\,\max\varepsilon)` by the smoothed signal, walked
   back to the last sample at noise level (the foot of the pulse).
4. Gauge averaging: opposite gauges on a bar are averaged, :math:`\bar\varepsilon = (\varepsilon_1 +
   \varepsilon_2)/2`, which cancels bending. A gauge that saturates (sticks at the DAQ rail) inside the
   analysed span, or that is much rougher than its partner while the two disagree, is dropped and the
   other gauge is used alone (:func:`select_gauges`). The decision is recorded in the result.
5. Baseline: the mean of the pre-trigger part (all samples before the arrival, minus a guard) is
   subtracted; its standard deviation is the channel's noise level (the calibration's observation
   error).
6. Time shifts to the specimen faces (:math:`c_0=\sqrt{E_b/\rho_b}`, gauge distances :math:`x_I`,
   :math:`x_T`, arrival time :math:`t_a` at the incident gauge), on the common axis
   :math:`\tau \ge 0` with :math:`\tau = 0` the arrival of the incident wave at the front face:

   .. math::
      \varepsilon_I(\tau) = \bar\varepsilon_{inc}(t_a + \tau),\quad
      \varepsilon_R(\tau) = \bar\varepsilon_{inc}(t_a + 2x_I/c_0 + \tau),\quad
      \varepsilon_T(\tau) = \bar\varepsilon_{tra}(t_a + (x_I + x_T)/c_0 + \tau)

   (linear interpolation between samples). The window length is :math:`2x_I/c_0` by default: the
   time during which the incident gauge sees the incident wave alone.
7. Bar forces, stresses and rates (:math:`A_b = \pi D_b^2/4`, :math:`A_s = \pi D_s^2/4`, specimen
   length :math:`L_s`):

   .. math::
      F_1 = E_b A_b (\varepsilon_I + \varepsilon_R),\qquad F_2 = E_b A_b\,\varepsilon_T,\qquad
      \sigma = F_2 / A_s,\qquad \sigma_1 = F_1/A_s,\qquad \sigma_{mean} = (F_1+F_2)/(2A_s)

   .. math::
      \dot\varepsilon_s = \frac{c_0}{L_s}(\varepsilon_I - \varepsilon_R - \varepsilon_T),\qquad
      \varepsilon_s(\tau) = \int_0^\tau \dot\varepsilon_s\,d\tau',\qquad
      R(\tau) = \frac{2\,|F_1 - F_2|}{F_1 + F_2}

   :math:`R` is reported only where :math:`F_1 + F_2` exceeds 10 % of its maximum (NaN elsewhere,
   where the ratio of two small numbers means nothing).

Optional, off by default (``dispersion_nu``): between steps 5 and 6 the bar signals are corrected for
Pochhammer-Chree dispersion over the gauge distances (:mod:`shpb.lab.dispersion`): the incident wave
forward over :math:`x_I`, the reflected wave back over :math:`x_I`, the transmitted wave back over
:math:`x_T`; the 1D shifts of step 6 stay as they are. The noise levels and the incident wave at its
gauge are those of the uncorrected signals.

The specimen stress used for calibration is the back-face (transmitted, "1-wave") stress
:math:`\sigma = F_2/A_s`; it does not contain the incident-reflected superposition and is the less noisy
of the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .bars import FREIBURG_BAR, BarSetup, bridge_strain_per_volt, freiburg_bar
from .errors import ReductionError
from .signals import (QUIET_PRETRIGGER, cumulative_trapezoid, despike, detect_arrival, pretrigger_ratio, robust_std,
                      saturation_onset, select_gauges, stuck_runs)

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from .records import RawRecord

__all__ = [
    "BarSetup",
    "FREIBURG_BAR",
    "freiburg_bar",
    "bridge_strain_per_volt",
    "ReducedRecord",
    "reduce_record",
    "reduced_to_dataframe",
    "write_reduced_csv",
    "detect_arrival",
    "despike",
    "saturation_onset",
    "stuck_runs",
    "robust_std",
    "select_gauges",
    "CSV_COLUMNS",
]


# --------------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------------
#: Column names of the reduced-record CSV (SI units).
CSV_COLUMNS = ("time_s", "stress_Pa", "stress_front_Pa", "stress_back_Pa", "strain_rate_per_s", "strain",
               "force_balance", "eps_incident", "eps_reflected", "eps_transmitted")


@dataclass
class ReducedRecord:
    """A reduced SHPB record on the common time axis at the specimen faces (SI, compression positive).

    Arrays (all of length ``n``, on ``time``):

    ``time`` [s] (0 = arrival of the incident wave at the specimen front face), ``eps_incident``,
    ``eps_reflected``, ``eps_transmitted`` (bar strains shifted to the faces; the reflected strain of a
    compression test is negative), ``force_front``, ``force_back`` [N], ``stress_front``,
    ``stress_back``, ``stress_mean`` [Pa], ``stress`` [Pa] (= ``stress_back``, the specimen stress),
    ``strain_rate`` [1/s], ``strain`` [-], ``force_balance`` [-] (NaN where undefined).

    Incident wave at the incident gauge, for injecting it into a simulation at the gauge position:
    ``incident_gauge_time`` [s] (0 = arrival at the gauge; the DAQ time of that instant is
    ``arrival_time_gauge``) and ``incident_gauge_strain``, covering the :math:`2x_I/c_0` during which
    the gauge sees the incident wave alone (or to the end of the record). See
    :meth:`incident_wave_at_gauge`.

    Timing: ``arrival_time_gauge`` (DAQ time of the incident foot at the gauge), ``shift_reflected`` and
    ``shift_transmitted`` (the gauge-time offsets used, s: nominally :math:`2x_I/c_0` and
    :math:`(x_I+x_T)/c_0` plus any user shift).

    Noise (standard deviation of the baseline-free pre-trigger part): ``noise_std_strain`` with keys
    ``incident``, ``reflected``, ``transmitted`` (the averaged bar signals) and one per gauge channel;
    ``noise_std_Pa`` with keys ``stress`` (= ``stress_back``), ``stress_back``, ``stress_front``,
    ``stress_mean`` and one per gauge channel (its strain noise times :math:`E_b A_b/A_s`);
    ``noise_std_strain_rate`` [1/s].
    """

    name: str
    time: np.ndarray
    eps_incident: np.ndarray
    eps_reflected: np.ndarray
    eps_transmitted: np.ndarray
    force_front: np.ndarray
    force_back: np.ndarray
    stress_front: np.ndarray
    stress_back: np.ndarray
    stress_mean: np.ndarray
    strain_rate: np.ndarray
    strain: np.ndarray
    force_balance: np.ndarray
    incident_gauge_time: np.ndarray
    incident_gauge_strain: np.ndarray
    noise_std_strain: dict[str, float]
    noise_std_Pa: dict[str, float]
    noise_std_strain_rate: float
    bar: BarSetup
    specimen_length: float
    specimen_diameter: float
    arrival_time_gauge: float
    shift_reflected: float
    shift_transmitted: float
    channels_used: dict[str, tuple[str, ...]]
    spikes_removed: dict[str, int]
    notes: list[str] = field(default_factory=list)

    @property
    def stress(self) -> np.ndarray:
        """Specimen stress [Pa]: the back-face stress :math:`F_2/A_s`."""
        return self.stress_back

    @property
    def dt(self) -> float:
        return float(self.time[1] - self.time[0]) if self.time.size > 1 else float("nan")

    @property
    def peak_index(self) -> int:
        """Index of the maximum specimen stress in the window."""
        return int(np.nanargmax(self.stress_back))

    @property
    def peak_stress(self) -> float:
        """Peak specimen (back-face) stress [Pa]."""
        return float(self.stress_back[self.peak_index])

    @property
    def peak_time(self) -> float:
        """Time of the peak specimen stress on the face axis [s]."""
        return float(self.time[self.peak_index])

    @property
    def force_balance_at_peak(self) -> float:
        """:math:`R = 2|F_1-F_2|/(F_1+F_2)` at the peak specimen stress."""
        return float(self.force_balance[self.peak_index])

    @property
    def strain_rate_at_peak(self) -> float:
        """Strain rate at the peak specimen stress [1/s]."""
        return float(self.strain_rate[self.peak_index])

    @property
    def peak_strain_rate(self) -> float:
        """Maximum strain rate up to the peak specimen stress [1/s]."""
        return float(np.nanmax(self.strain_rate[: self.peak_index + 1]))

    def mean_strain_rate_loading(self, level: float = 0.5) -> float:
        """Mean strain rate [1/s] while the stress rises from ``level`` x peak to the peak.

        The loading-phase strain rate usually quoted for a test (Rae et al. average it over the part of
        the rise above half the peak).
        """
        i = self.peak_index
        sel = self.stress_back[: i + 1] >= level * self.peak_stress
        return float(np.mean(self.strain_rate[: i + 1][sel]))

    def front_face_displacement(self) -> np.ndarray:
        """Travel of the incident bar's face toward the specimen [m] from ``t = 0``:
        :math:`u_1(t) = c_0 \\int_0^t (\\varepsilon_I - \\varepsilon_R)\\,dt` (1D wave theory; trapezoidal rule);
        0 before ``t = 0``."""
        v = self.bar.c0 * (self.eps_incident - self.eps_reflected)
        u = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(self.time))])
        k0 = int(np.searchsorted(self.time, 0.0))
        return np.where(self.time >= self.time[k0], u - u[k0], 0.0)

    def closure_before_load(self, level: float = 0.02) -> float:
        """Travel of the incident bar's face [m] from ``t = 0`` until the specimen (back-face) stress first
        exceeds ``level`` x its peak: closure the specimen did not resist. Its own elastic shortening at
        that stress, ``level * peak * L / E``, is a few micrometres for rock; anything beyond is seating
        or a gap at the faces (the ``face_gap`` effect)."""
        i = int(np.flatnonzero((self.time >= 0.0) & (self.stress_back > level * self.peak_stress))[0])
        return float(self.front_face_displacement()[i])

    def incident_wave_at_gauge(self) -> tuple[np.ndarray, np.ndarray]:
        """(time [s], strain) of the incident wave at the incident gauge, time 0 = its arrival there."""
        return self.incident_gauge_time, self.incident_gauge_strain


# --------------------------------------------------------------------------------------------------
# The reduction
# --------------------------------------------------------------------------------------------------
def _specimen(raw: "RawRecord", bar: BarSetup | None, L: float | None, D: float | None
              ) -> tuple[BarSetup, float, float]:
    """The bar set-up and the specimen's length and diameter [m]: the arguments, else the record's."""
    bar = bar if bar is not None else raw.bar
    if bar is None:
        raise ValueError(f"{raw.name}: no BarSetup given and the record carries none")
    L_s = L if L is not None else raw.specimen_length
    D_s = D if D is not None else raw.specimen_diameter
    if L_s is None or D_s is None or not (L_s > 0 and D_s > 0):
        raise ValueError(f"{raw.name}: specimen length and diameter [m] are required, got {L_s}, {D_s}")
    return bar, L_s, D_s


@dataclass
class _Channels:
    """Every gauge channel of a record, incident bar first (steps 1-2)."""

    names_i: tuple[str, ...]
    names_t: tuple[str, ...]
    volts: np.ndarray    # the recorded values
    eps: np.ndarray      # compression-positive strain, despiked
    eps0: np.ndarray     # eps less the provisional baseline
    sig0: np.ndarray     # provisional noise (robust, first n0 samples)
    n0: int
    spikes: dict[str, int]

    @property
    def names(self) -> tuple[str, ...]:
        return self.names_i + self.names_t

    @property
    def n_i(self) -> int:
        return len(self.names_i)


def _to_strain(raw: "RawRecord", bar: BarSetup) -> tuple[np.ndarray, np.ndarray]:
    """Compression-positive strain of every gauge channel (step 1)."""
    if raw.unit == "strain":
        fi = ft = 1.0
    else:
        fi, ft = bar.strain_per_volt_incident, bar.strain_per_volt_transmitted
    s = bar.compression_sign
    return s * fi * raw.incident, s * ft * raw.transmitted


def _channels(raw: "RawRecord", bar: BarSetup, despike_signals: bool) -> _Channels:
    """Steps 1-2: strain, provisional noise and baseline from the first samples, spikes removed."""
    n = raw.n_samples
    names_i, names_t = tuple(raw.incident_channels), tuple(raw.transmitted_channels)
    eps_i_raw, eps_t_raw = _to_strain(raw, bar)
    volts = np.vstack([raw.incident, raw.transmitted])
    eps = np.vstack([eps_i_raw, eps_t_raw])
    names = names_i + names_t
    n0 = int(min(max(50, n // 10), 200, n))
    sig0 = np.array([robust_std(e[:n0]) for e in eps])
    sig0 = np.where(sig0 > 0, sig0, 1e-12)
    spikes: dict[str, int] = {}
    if despike_signals:
        for k in range(eps.shape[0]):
            eps[k], spikes[names[k]] = despike(eps[k], sig0[k])
    else:
        spikes = {nm: 0 for nm in names}
    # mean, not median, after despiking: the median of coarsely quantized noise is biased by up to
    # half a quantum, which would hold a smoothed baseline-free signal above the foot level
    base0 = eps[:, :n0].mean(axis=1)
    eps0 = eps - base0[:, None]
    return _Channels(names_i, names_t, volts, eps, eps0, sig0, n0, spikes)


def _first_arrival(name: str, ch: _Channels, dt: float, exclude_channels: tuple[str, ...], k_sigma: float,
                   threshold_fraction: float) -> int:
    """Step 3: the arrival at the incident gauge, the earliest of its channels' (garbage from a failing
    gauge starts after the pulse, never before the pulse foot)."""
    arrivals = []
    for k in range(ch.n_i):
        if ch.names[k] in exclude_channels:
            continue
        try:
            arrivals.append(detect_arrival(ch.eps0[k], ch.sig0[k], dt, k_sigma, threshold_fraction))
        except ValueError:
            continue
    if not arrivals:
        raise ReductionError(
            f"{name}: no incident pulse found on {ch.names_i}: expected a compressive pulse rising {k_sigma:g} "
            f"noise levels out of a quiet pre-trigger (the first {ch.n0} samples at noise level, no pulse in "
            f"them); a flipped compression sign or a record that starts inside the pulse gives this",
            ("compression_sign", "time"))
    return min(arrivals)


@dataclass(frozen=True)
class _Timing:
    """Where the waves are on the gauge signals: the reflected wave ``t_refl`` and the transmitted wave
    ``t_tran`` after the incident wave [s] (step 6), and the common window's length."""

    name: str
    n: int
    dt: float
    x_i: float
    c0: float
    t_refl: float
    t_tran: float
    window_s: float | None

    def window_samples(self, i_arr: int) -> int:
        """Samples on the common axis: the requested length, cut at the end of the record."""
        T = 2.0 * self.x_i / self.c0 if self.window_s is None else float(self.window_s)
        avail = (self.n - 1 - i_arr) * self.dt
        T = min(T, avail - self.t_refl, avail - self.t_tran)
        if T <= 10 * self.dt:
            raise ReductionError(
                f"{self.name}: record too short after the incident arrival: the reflected wave comes "
                f"2 x_I / c0 = {self.t_refl:.4g} s and the transmitted wave (x_I + x_T) / c0 = {self.t_tran:.4g} s "
                f"after it (gauge distances x_I {self.x_i:.4g} m, c0 = sqrt(E/rho) {self.c0:.5g} m/s), the record "
                f"holds {avail:.4g} s ({self.n} samples of {self.dt:.4g} s): expected at least 10 samples of "
                f"window (got {T:.3g} s; a flipped compression sign takes the reflected wave for the incident one)",
                ("gauge_distance_incident", "gauge_distance_transmitted", "E", "rho", "window_s", "time",
                 "compression_sign"))
        return int(math.floor(T / self.dt + 1e-9)) + 1


def _timing(raw: "RawRecord", bar: BarSetup, window_s: float | None, shift_reflected_s: float,
            shift_transmitted_s: float, notes: list[str]) -> _Timing:
    """The nominal shifts :math:`2x_I/c_0` and :math:`(x_I+x_T)/c_0` plus the user's."""
    c0 = bar.c0
    x_i, x_t = bar.gauge_distance_incident, bar.gauge_distance_transmitted
    t_refl = 2.0 * x_i / c0 + shift_reflected_s
    t_tran = (x_i + x_t) / c0 + shift_transmitted_s
    if window_s is not None and window_s > 2.0 * x_i / c0:
        notes.append("window longer than 2 x_I / c0: eps_incident overlaps the reflected wave at its end")
    return _Timing(raw.name, raw.n_samples, raw.dt, x_i, c0, t_refl, t_tran, window_s)


def _average_gauges(ch: _Channels, i_a: int, tm: _Timing, n_w: int, exclude_channels: tuple[str, ...]
                    ) -> tuple[np.ndarray, np.ndarray, list[int], list[int], list[str]]:
    """Step 4: each bar's mean of its usable gauges over the spans the bar contributes to the window.
    Returns (incident-bar strain, transmission-bar strain, gauges kept on each, notes)."""
    n, dt, n_i, n0 = tm.n, tm.dt, ch.n_i, ch.n0
    T_w = (n_w - 1) * dt
    span_i = slice(i_a, min(n, i_a + int(math.ceil((tm.t_refl + T_w) / dt)) + 2))
    span_t = slice(min(n - 1, i_a + int(math.floor(tm.t_tran / dt))),
                   min(n, i_a + int(math.ceil((tm.t_tran + T_w) / dt)) + 2))
    volts = ch.volts
    base_v = np.median(volts[:, :n0], axis=1)
    sig_v = np.array([robust_std(v[:n0]) for v in volts])
    keep_i, notes_i = select_gauges(ch.eps0[:n_i], ch.names_i, base_v[:n_i], sig_v[:n_i], span_i,
                                    exclude_channels, raw=volts[:n_i])
    keep_t, notes_t = select_gauges(ch.eps0[n_i:], ch.names_t, base_v[n_i:], sig_v[n_i:], span_t,
                                    exclude_channels, raw=volts[n_i:])
    inc = ch.eps[:n_i][keep_i].mean(axis=0)
    tra = ch.eps[n_i:][keep_t].mean(axis=0)
    return inc, tra, keep_i, keep_t, notes_i + notes_t


def _refined_arrival(inc: np.ndarray, n0: int, i_a: int, T_w: float, dt: float, k_sigma: float,
                     threshold_fraction: float) -> int:
    """The arrival detected again on the averaged incident signal (cleaner than any single gauge),
    kept when it is within a quarter window of the first."""
    inc_b0 = inc - inc[:n0].mean()
    try:
        i_a2 = detect_arrival(inc_b0, max(robust_std(inc[:n0]), 1e-12), dt, k_sigma, threshold_fraction)
        if abs(i_a2 - i_a) * dt < 0.25 * T_w:
            i_a = i_a2
    except ValueError:
        pass
    return i_a


@dataclass
class _Baselined:
    """Step 5: the signals less their pre-trigger mean; the pre-trigger part and its noise."""

    inc: np.ndarray
    tra: np.ndarray
    chan: np.ndarray     # every gauge channel
    pre: slice
    sd_inc: float
    sd_tra: float


def _baseline(name: str, inc: np.ndarray, tra: np.ndarray, eps: np.ndarray, i_a: int, dt: float,
              guard_s: float) -> _Baselined:
    i_pre = i_a - max(1, int(round(guard_s / dt)))
    if i_pre < 20:
        raise ReductionError(f"{name}: only {max(i_pre, 0)} pre-trigger samples before the incident arrival: "
                             f"expected a quiet pre-trigger of at least 20 samples for the baseline", ("time",))
    pre = slice(0, i_pre)
    inc = inc - inc[pre].mean()
    tra = tra - tra[pre].mean()
    chan = eps - eps[:, pre].mean(axis=1, keepdims=True)
    return _Baselined(inc, tra, chan, pre, float(np.std(inc[pre], ddof=1)), float(np.std(tra[pre], ddof=1)))


def _incident_span(inc: np.ndarray, i_a: int, tm: _Timing, sd_inc: float, k_sigma: float,
                   threshold_fraction: float) -> tuple[int, bool]:
    """Samples of the incident wave alone at its gauge (:math:`2x_I/c_0`, or to the end of the record),
    and whether the pulse is still on when the reflected wave arrives (it must have ended)."""
    n_g = min(int(math.floor(2.0 * tm.x_i / tm.c0 / tm.dt + 1e-9)) + 1, tm.n - i_a)
    seg = inc[i_a:i_a + n_g]
    j_pk = int(np.argmax(seg))
    h_end = max(k_sigma * sd_inc, threshold_fraction * float(seg[j_pk]))
    below = np.flatnonzero(seg[j_pk:] < h_end)
    return n_g, bool(below.size == 0 and i_a + n_g < tm.n)


def _shift_to_faces(time: np.ndarray, inc_I: np.ndarray, inc_R: np.ndarray, tra: np.ndarray, i_a: int, n_w: int,
                    tm: _Timing) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Step 6: (tau, eps_I, eps_R, eps_T) on the common axis at the faces, the incident and reflected waves
    from the incident-bar signals ``inc_I`` and ``inc_R`` (the same signal unless corrected for dispersion)."""
    t_a = time[i_a]
    tau = tm.dt * np.arange(n_w)
    eps_I = inc_I[i_a:i_a + n_w].copy()
    eps_R = np.interp(t_a + tm.t_refl + tau, time, inc_R)
    eps_T = np.interp(t_a + tm.t_tran + tau, time, tra)
    return tau, eps_I, eps_R, eps_T


def _forces(bar: BarSetup, L_s: float, D_s: float, tau: np.ndarray, eps_I: np.ndarray, eps_R: np.ndarray,
            eps_T: np.ndarray) -> dict[str, np.ndarray]:
    """Step 7: bar forces, face stresses, strain rate, strain and force balance."""
    A_b = bar.area
    A_s = math.pi * D_s ** 2 / 4.0
    F1 = bar.E * A_b * (eps_I + eps_R)
    F2 = bar.E * A_b * eps_T
    s1, s2 = F1 / A_s, F2 / A_s
    rate = bar.c0 / L_s * (eps_I - eps_R - eps_T)
    strain = cumulative_trapezoid(rate, tau)
    Fsum = F1 + F2
    with np.errstate(divide="ignore", invalid="ignore"):
        R = 2.0 * np.abs(F1 - F2) / Fsum
    R[~(Fsum > 0.1 * np.nanmax(Fsum))] = np.nan
    return {"force_front": F1, "force_back": F2, "stress_front": s1, "stress_back": s2,
            "stress_mean": 0.5 * (s1 + s2), "strain_rate": rate, "strain": strain, "force_balance": R}


def _noise(bar: BarSetup, L_s: float, D_s: float, names: tuple[str, ...], b: _Baselined
           ) -> tuple[dict[str, float], dict[str, float], float]:
    """The noise levels of :class:`ReducedRecord` (strain, Pa, strain rate) from the pre-trigger part."""
    sd_inc, sd_tra = b.sd_inc, b.sd_tra
    k_pa = bar.E * bar.area / (math.pi * D_s ** 2 / 4.0)
    noise_strain = {"incident": sd_inc, "reflected": sd_inc, "transmitted": sd_tra}
    noise_pa = {
        "stress": k_pa * sd_tra,
        "stress_back": k_pa * sd_tra,
        "stress_front": k_pa * math.sqrt(2.0) * sd_inc,
        "stress_mean": 0.5 * k_pa * math.sqrt(2.0 * sd_inc ** 2 + sd_tra ** 2),
    }
    for k, nm in enumerate(names):
        sd = float(np.std(b.chan[k, b.pre], ddof=1))
        noise_strain[nm] = sd
        noise_pa[nm] = k_pa * sd
    return noise_strain, noise_pa, bar.c0 / L_s * math.sqrt(2.0 * sd_inc ** 2 + sd_tra ** 2)


def reduce_record(raw: "RawRecord", bar: BarSetup | None = None, specimen_length_m: float | None = None,
                  specimen_diameter_m: float | None = None, *, window_s: float | None = None,
                  k_sigma: float = 6.0, threshold_fraction: float = 0.02, despike_signals: bool = True,
                  exclude_channels: tuple[str, ...] = (), shift_reflected_s: float = 0.0,
                  shift_transmitted_s: float = 0.0, guard_s: float = 10.0e-6,
                  dispersion_nu: float | None = None) -> ReducedRecord:
    r"""Reduce one raw SHPB record (module docstring, steps 1-7).

    Parameters
    ----------
    raw : the record (:mod:`shpb.lab.records` readers).
    bar : bar set-up; default ``raw.bar``.
    specimen_length_m, specimen_diameter_m : specimen size [m]; default ``raw.specimen_length`` /
        ``raw.specimen_diameter`` (Freiburg: take them from :func:`shpb.lab.records.freiburg_specimen`).
    window_s : length of the common time window [s]; default :math:`2x_I/c_0`. Always limited by the
        end of the record for the reflected and transmitted waves.
    k_sigma, threshold_fraction : arrival threshold :math:`h = \max(k\sigma, \phi\max\varepsilon)`
        (:func:`detect_arrival`).
    despike_signals : remove isolated one-sample spikes before everything else (:func:`despike`).
    exclude_channels : gauge channel names to leave out of the averages (expert override).
    shift_reflected_s, shift_transmitted_s : extra time shifts [s] added to the nominal
        :math:`2x_I/c_0` and :math:`(x_I+x_T)/c_0` (fine alignment; 0 by default).
    guard_s : the pre-trigger part ends this long before the detected arrival [s].
    dispersion_nu : the bars' Poisson ratio: when given, the bar signals are corrected for
        Pochhammer-Chree dispersion (:mod:`shpb.lab.dispersion`); None (default): no correction.

    Returns
    -------
    ReducedRecord

    Raises
    ------
    ValueError
        If the bar or specimen is undefined, the pre-trigger part is too short, or no incident pulse is found.
    """
    bar, L_s, D_s = _specimen(raw, bar, specimen_length_m, specimen_diameter_m)
    dt = raw.dt
    notes: list[str] = []
    ch = _channels(raw, bar, despike_signals)                                                # steps 1-2
    i_a = _first_arrival(raw.name, ch, dt, exclude_channels, k_sigma, threshold_fraction)    # step 3
    tm = _timing(raw, bar, window_s, shift_reflected_s, shift_transmitted_s, notes)
    n_w = tm.window_samples(i_a)
    inc, tra, keep_i, keep_t, gauge_notes = _average_gauges(ch, i_a, tm, n_w, exclude_channels)  # step 4
    notes += gauge_notes
    i_a = _refined_arrival(inc, ch.n0, i_a, (n_w - 1) * dt, dt, k_sigma, threshold_fraction)
    b = _baseline(raw.name, inc, tra, ch.eps, i_a, dt, guard_s)                             # step 5
    if (q := pretrigger_ratio(b.inc, b.pre, i_a, n_w)) > QUIET_PRETRIGGER:
        raise ReductionError(f"{raw.name}: the incident bar moves by {q:.2g} x the incident pulse's peak before its "
                             f"arrival: expected a quiet pre-trigger (at most {QUIET_PRETRIGGER:g}); a flipped "
                             f"compression sign puts the tensile incident pulse there", ("compression_sign", "time"))
    n_g, overlap = _incident_span(b.inc, i_a, tm, b.sd_inc, k_sigma, threshold_fraction)
    if overlap:
        notes.append("incident pulse longer than 2 x_I / c0: it overlaps the reflected wave at the "
                     "incident gauge, so eps_reflected (front force, strain rate) is contaminated")
    n_w = tm.window_samples(i_a)
    inc_I, inc_R, tra = b.inc, b.inc, b.tra
    if dispersion_nu is not None:
        # imported here: the correction is optional, and scipy.fft/interpolate cost every simulation
        # driven by a measured record 0.3 s of start-up
        from .dispersion import correct_bar_signals
        inc_I, inc_R, tra = correct_bar_signals(b.inc, b.tra, dt, bar, dispersion_nu)
        notes.append(f"Pochhammer-Chree dispersion correction of the bar signals (first mode, phase only, "
                     f"bar Poisson ratio {dispersion_nu:g})")
    tau, eps_I, eps_R, eps_T = _shift_to_faces(raw.time, inc_I, inc_R, tra, i_a, n_w, tm)    # step 6
    curves = _forces(bar, L_s, D_s, tau, eps_I, eps_R, eps_T)                                 # step 7
    noise_strain, noise_pa, noise_rate = _noise(bar, L_s, D_s, ch.names, b)
    return ReducedRecord(
        name=raw.name, time=tau, eps_incident=eps_I, eps_reflected=eps_R, eps_transmitted=eps_T, **curves,
        incident_gauge_time=dt * np.arange(n_g), incident_gauge_strain=b.inc[i_a:i_a + n_g].copy(),
        noise_std_strain=noise_strain, noise_std_Pa=noise_pa, noise_std_strain_rate=noise_rate,
        bar=bar, specimen_length=float(L_s), specimen_diameter=float(D_s),
        arrival_time_gauge=float(raw.time[i_a]), shift_reflected=tm.t_refl, shift_transmitted=tm.t_tran,
        channels_used={"incident": tuple(ch.names_i[k] for k in keep_i),
                       "transmitted": tuple(ch.names_t[k] for k in keep_t)},
        spikes_removed=ch.spikes, notes=notes,
    )


# --------------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------------
def reduced_to_dataframe(red: ReducedRecord) -> pd.DataFrame:
    """The reduced curves as a DataFrame with the SI column names of :data:`CSV_COLUMNS`."""
    import pandas as pd  # on call: the simulations that reduce a record never need it

    return pd.DataFrame({
        "time_s": red.time,
        "stress_Pa": red.stress_back,
        "stress_front_Pa": red.stress_front,
        "stress_back_Pa": red.stress_back,
        "strain_rate_per_s": red.strain_rate,
        "strain": red.strain,
        "force_balance": red.force_balance,
        "eps_incident": red.eps_incident,
        "eps_reflected": red.eps_reflected,
        "eps_transmitted": red.eps_transmitted,
    }, columns=list(CSV_COLUMNS))


def write_reduced_csv(red: ReducedRecord, path: str | Path) -> Path:
    """Write :func:`reduced_to_dataframe` to ``path`` atomically (temporary file, then ``os.replace``).

    A reader never sees a half-written file; on error the temporary file is removed.
    """
    path = Path(path)
    from ..atomic import atomic_write_text

    atomic_write_text(path, reduced_to_dataframe(red).to_csv(index=False, float_format="%.9g"))
    return path
