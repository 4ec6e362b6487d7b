r"""Reduction of measured SHPB records to specimen stress, strain rate, strain and force balance.

This is DESIGN section 4 ("Data reduction of measured records"). Input: a :class:`shpb.records.RawRecord`
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

The specimen stress used for calibration is the back-face (transmitted, "1-wave") stress
:math:`\sigma = F_2/A_s`; it does not contain the incident-reflected superposition and is the less noisy
of the two. No dispersion correction is applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy.integrate import cumulative_trapezoid
from scipy.ndimage import median_filter, uniform_filter1d

if TYPE_CHECKING:  # pragma: no cover
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
# Bars and measurement chain
# --------------------------------------------------------------------------------------------------
def bridge_strain_per_volt(excitation_V: float, gain: float, gauge_factor: float, active_arms: int = 1) -> float:
    r"""Strain per volt of amplified Wheatstone-bridge output.

    For :math:`n` active arms carrying the same axial strain, :math:`U = G\,U_0\,n\,k\,\varepsilon/4`, so

    .. math:: \varepsilon = \frac{4}{n\,U_0\,G\,k}\,U

    Freiburg (quarter bridge per gauge, :math:`U_0=5` V, :math:`G=400`, :math:`k=1.99`):
    1.005e-3 /V. LANL HopPyBar (two active arms): :math:`2/(k\,G\,U_0)`.
    """
    if excitation_V <= 0 or gain <= 0 or gauge_factor <= 0 or active_arms < 1:
        raise ValueError("excitation, gain, gauge factor and active arms must be positive")
    return 4.0 / (active_arms * excitation_V * gain * gauge_factor)


@dataclass(frozen=True)
class BarSetup:
    """Bars and measurement chain of an SHPB (incident and transmission bar of the same material).

    Attributes
    ----------
    E : float
        Bar Young's modulus [Pa].
    rho : float
        Bar density [kg/m^3].
    diameter : float
        Bar diameter [m] (equivalent diameter for a square bar).
    gauge_distance_incident : float
        Distance from the incident-bar gauges to the specimen front face [m].
    gauge_distance_transmitted : float
        Distance from the transmission-bar gauges to the specimen back face [m].
    strain_per_volt_incident, strain_per_volt_transmitted : float
        Volts-to-strain factors [1/V] (magnitude; 1.0 for records already in strain).
    compression_sign : int
        Sign of a compressive strain in the recorded signal (+1: compression reads positive, as in the
        Freiburg and LANL standard records; -1: compression reads negative, as in the Yao records).
    name : str
        Free label.
    """

    E: float
    rho: float
    diameter: float
    gauge_distance_incident: float
    gauge_distance_transmitted: float
    strain_per_volt_incident: float
    strain_per_volt_transmitted: float
    compression_sign: int = 1
    name: str = ""

    def __post_init__(self) -> None:
        for f in ("E", "rho", "diameter", "gauge_distance_incident", "gauge_distance_transmitted",
                  "strain_per_volt_incident", "strain_per_volt_transmitted"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"BarSetup.{f} must be a positive finite number, got {v!r}")
        if self.compression_sign not in (1, -1):
            raise ValueError(f"BarSetup.compression_sign must be +1 or -1, got {self.compression_sign!r}")

    @property
    def c0(self) -> float:
        """One-dimensional bar wave speed :math:`c_0 = \\sqrt{E/\\rho}` [m/s]."""
        return math.sqrt(self.E / self.rho)

    @property
    def area(self) -> float:
        """Bar cross-section :math:`A_b = \\pi D_b^2/4` [m^2]."""
        return math.pi * self.diameter ** 2 / 4.0


#: Freiburg (Rae et al.) titanium bars: E 110 GPa, 4430 kg/m^3, 50 mm, gauges 1.25 m (incident) and
#: 1.00 m (transmission) from the specimen, bridge U0 = 5 V, gain 400, k = 1.99 -> 1.005e-3 strain/V,
#: compression positive (from the authors' script SHPB_v4.0.py, see the folder's PROVENANCE.md).
FREIBURG_BAR = BarSetup(
    E=110.0e9,
    rho=4430.0,
    diameter=0.050,
    gauge_distance_incident=1.25,
    gauge_distance_transmitted=1.00,
    strain_per_volt_incident=bridge_strain_per_volt(5.0, 400.0, 1.99, active_arms=1),
    strain_per_volt_transmitted=bridge_strain_per_volt(5.0, 400.0, 1.99, active_arms=1),
    compression_sign=1,
    name="Freiburg Ti bars",
)


def freiburg_bar() -> BarSetup:
    """The Freiburg bar set-up (:data:`FREIBURG_BAR`)."""
    return FREIBURG_BAR


# --------------------------------------------------------------------------------------------------
# Signal utilities
# --------------------------------------------------------------------------------------------------
def robust_std(x: np.ndarray) -> float:
    r"""Noise scale insensitive to outliers: :math:`1.4826\,\mathrm{median}|x - \mathrm{median}(x)|`.

    Falls back to the plain standard deviation when the MAD is zero (heavily quantized data).
    """
    x = np.asarray(x, dtype=float)
    mad = float(np.median(np.abs(x - np.median(x))))
    s = 1.4826 * mad
    return s if s > 0 else float(np.std(x))


def despike(x: np.ndarray, sigma: float, k_sigma: float = 8.0, k_slope: float = 5.0,
            passes: int = 2) -> tuple[np.ndarray, int]:
    r"""Remove isolated one- or two-sample spikes (DAQ glitches) from a signal.

    Sample :math:`i` is a spike when its departure from the 5-sample running median,
    :math:`d_i = x_i - \mathrm{med}_5(x)_i`, exceeds both :math:`k_\sigma \sigma` (noise) and
    :math:`k_s` times the local step size (median of :math:`|\Delta x|` over 11 samples), so steep
    but smooth pulse fronts and rounded peaks are kept (there :math:`|d|` is at most about one step).
    Spike samples are replaced by linear interpolation between the nearest clean samples.
    Repeated ``passes`` times.

    Returns the cleaned copy and the number of samples replaced.
    """
    y = np.array(x, dtype=float, copy=True)
    if y.size < 11:
        return y, 0
    total = 0
    for _ in range(passes):
        med = median_filter(y, size=5, mode="nearest")
        d = y - med
        step = np.abs(np.diff(y))
        local = median_filter(np.r_[step, step[-1]], size=11, mode="nearest")
        spikes = np.flatnonzero((np.abs(d) > k_sigma * sigma) & (np.abs(d) > k_slope * local))
        if spikes.size == 0:
            break
        good = np.ones(y.size, dtype=bool)
        good[spikes] = False
        y[spikes] = np.interp(spikes, np.flatnonzero(good), y[good])
        total += int(spikes.size)
    return y, total


def stuck_runs(x: np.ndarray, baseline: float, sigma: float, min_run: int = 10,
               k_sigma: float = 20.0) -> list[tuple[int, int]]:
    """Stretches ``[start, end)`` where ``x`` holds one identical value for at least ``min_run`` samples
    while that value lies more than ``k_sigma`` noise levels from ``baseline``."""
    x = np.asarray(x, dtype=float)
    if x.size < min_run:
        return []
    change = np.flatnonzero(np.diff(x) != 0)
    starts = np.r_[0, change + 1]
    ends = np.r_[change + 1, x.size]
    big = np.abs(x[starts] - baseline) > k_sigma * max(sigma, 1e-12)
    hits = np.flatnonzero(((ends - starts) >= min_run) & big)
    return [(int(starts[h]), int(ends[h])) for h in hits]


def saturation_onset(x: np.ndarray, baseline: float, sigma: float, min_run: int = 10,
                     k_sigma: float = 20.0, partner: np.ndarray | None = None,
                     partner_sigma: float | None = None) -> int | None:
    """Index of the first sample of a saturated stretch of a gauge channel, or None.

    A stretch is saturated when at least ``min_run`` consecutive samples hold the *identical* value
    far (``k_sigma`` noise levels) from the baseline while the opposite gauge (``partner``, if given)
    keeps moving (peak-to-peak above 6 of its noise levels over the same samples): the amplifier or
    ADC of this gauge is stuck at its rail while the bar strain is not constant (seen at -5.12 V in
    Freiburg CaMa_013 A4). The partner condition keeps coarse-quantized records (8-bit scopes), whose
    genuine plateaus show on both gauges, from being flagged.
    """
    for s0, e0 in stuck_runs(x, baseline, sigma, min_run, k_sigma):
        if partner is None:
            return s0
        p = np.asarray(partner[s0:e0], dtype=float)
        if np.ptp(p) > 6.0 * float(partner_sigma if partner_sigma is not None else 0.0):
            return s0
    return None


def detect_arrival(signal: np.ndarray, sigma: float, dt: float, k_sigma: float = 6.0,
                   fraction: float = 0.02, smooth_s: float = 2.0e-6, sustain_s: float = 5.0e-6,
                   start: int = 0) -> int:
    r"""Index of the arrival (foot) of a compressive pulse in a baseline-free, compression-positive signal.

    1. Smooth with a centred moving average of :math:`w = \max(1, \mathrm{round}(t_{smooth}/dt))` samples.
    2. Threshold :math:`h = \max(k_\sigma\,\sigma,\ \phi\,\max_t \tilde\varepsilon)`: relative to the
       noise level :math:`\sigma` (pre-trigger standard deviation) and, for very clean records, to the
       pulse amplitude.
    3. The detection is the first index :math:`i \ge` ``start`` from which the smoothed signal stays
       above :math:`h` for :math:`m = \max(3, \mathrm{round}(t_{sustain}/dt))` samples (single spikes and
       noise bursts do not trigger).
    4. Walk back from :math:`i` while the smoothed signal exceeds :math:`2\sigma/\sqrt{w}` (its own noise
       level): the returned index is the foot of the pulse.

    Raises
    ------
    ValueError
        If no sustained exceedance exists (no pulse in the record).
    """
    s = np.asarray(signal, dtype=float)
    w = max(1, int(round(smooth_s / dt)))
    sm = uniform_filter1d(s, size=w, mode="nearest") if w > 1 else s
    seg = sm[start:]
    if seg.size == 0:
        raise ValueError("detect_arrival: empty signal")
    h = max(k_sigma * sigma, fraction * float(np.max(seg)))
    m = max(3, int(round(sustain_s / dt)))
    above = (seg > h).astype(int)
    if above.size < m:
        raise ValueError("detect_arrival: signal shorter than the sustain length")
    run = np.convolve(above, np.ones(m, dtype=int), mode="valid")  # run[i] = sum(above[i:i+m])
    hits = np.flatnonzero(run == m)
    if hits.size == 0:
        raise ValueError(f"detect_arrival: no pulse above the threshold {h:.3g} "
                         f"(noise {sigma:.3g}, {k_sigma} sigma) sustained for {m} samples")
    i = int(hits[0]) + start
    foot = 2.0 * sigma / math.sqrt(w)
    while i > start and sm[i - 1] > foot:
        i -= 1
    return i


def select_gauges(channels: np.ndarray, names: tuple[str, ...], baseline: np.ndarray, sigma: np.ndarray,
                  span: slice, exclude: tuple[str, ...] = (), mismatch_tol: float = 0.25,
                  roughness_ratio: float = 3.0, raw: np.ndarray | None = None) -> tuple[list[int], list[str]]:
    r"""Choose which gauges of one bar to average over the analysed ``span``.

    Rules, in order (each dropped gauge is reported in the returned notes):

    1. gauges named in ``exclude`` are dropped;
    2. if the bar has two or more gauges, one that saturates (:func:`saturation_onset` on the ``raw``
       values, against its partner) inside the span is dropped (a lone gauge cannot be replaced);
    3. if two gauges remain and they disagree, i.e.
       :math:`\mathrm{rms}(\varepsilon_1-\varepsilon_2) > \mathrm{tol}\cdot\max|\bar\varepsilon|`, while one is
       ``roughness_ratio`` times rougher than the other (roughness = rms of the signal minus its
       9-sample moving average, over the span), the rough one is treated as a faulty gauge
       (debonded, broken lead) and dropped.

    Bending makes opposite gauges differ smoothly and antisymmetrically, and averaging cancels it;
    these rules only remove gauges whose signal is not a strain at all. If every gauge would be
    dropped, all are kept and a note says so.
    """
    n = channels.shape[0]
    raw = channels if raw is None else raw
    keep = list(range(n))
    notes: list[str] = []
    for k in list(keep):
        if names[k] in exclude:
            keep.remove(k)
            notes.append(f"{names[k]}: excluded by the caller")
    if len(keep) >= 2:
        flagged = []
        for k in keep:
            others = [j for j in keep if j != k]
            partner = raw[others, span].mean(axis=0)
            psig = float(np.mean(sigma[others]))
            seg = raw[k, span]
            on = saturation_onset(seg, baseline[k], sigma[k], partner=partner, partner_sigma=psig)
            if on is not None:
                flagged.append(k)
                notes.append(f"{names[k]}: saturated (stuck at {seg[on]:.4g} while its partner moves) "
                             f"inside the analysed span, dropped")
        keep = [k for k in keep if k not in flagged]
    if len(keep) == 2:
        a, b = channels[keep[0], span], channels[keep[1], span]
        mean = 0.5 * (a + b)
        scale = float(np.max(np.abs(mean))) if mean.size else 0.0
        mismatch = float(np.sqrt(np.mean((a - b) ** 2))) / scale if scale > 0 else 0.0
        rough = [float(np.std(x - uniform_filter1d(x, 9, mode="nearest"))) for x in (a, b)]
        if mismatch > mismatch_tol and max(rough) > roughness_ratio * max(min(rough), 1e-300):
            bad = keep[int(np.argmax(rough))]
            keep.remove(bad)
            notes.append(f"{names[bad]}: disagrees with its partner (rms difference {mismatch:.0%} of peak) "
                         f"and is {max(rough) / max(min(rough), 1e-300):.1f}x rougher, dropped as faulty")
        elif mismatch > mismatch_tol:
            notes.append(f"{names[keep[0]]}/{names[keep[1]]}: gauges disagree (rms difference {mismatch:.0%} "
                         f"of peak) with no clear faulty one, averaged: treat this bar's waves with care")
    if not keep:
        keep = list(range(n))
        notes.append("every gauge flagged, all kept")
    return keep, notes


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
def _to_strain(raw: "RawRecord", bar: BarSetup) -> tuple[np.ndarray, np.ndarray]:
    """Compression-positive strain of every gauge channel (step 1)."""
    if raw.unit == "strain":
        fi = ft = 1.0
    else:
        fi, ft = bar.strain_per_volt_incident, bar.strain_per_volt_transmitted
    s = bar.compression_sign
    return s * fi * raw.incident, s * ft * raw.transmitted


def reduce_record(raw: "RawRecord", bar: BarSetup | None = None, specimen_length_m: float | None = None,
                  specimen_diameter_m: float | None = None, *, window_s: float | None = None,
                  k_sigma: float = 6.0, threshold_fraction: float = 0.02, despike_signals: bool = True,
                  exclude_channels: tuple[str, ...] = (), shift_reflected_s: float = 0.0,
                  shift_transmitted_s: float = 0.0, guard_s: float = 10.0e-6) -> ReducedRecord:
    r"""Reduce one raw SHPB record (module docstring, steps 1-7).

    Parameters
    ----------
    raw : the record (:mod:`shpb.records` readers).
    bar : bar set-up; default ``raw.bar``.
    specimen_length_m, specimen_diameter_m : specimen size [m]; default ``raw.specimen_length`` /
        ``raw.specimen_diameter`` (Freiburg: take them from :func:`shpb.records.freiburg_specimen`).
    window_s : length of the common time window [s]; default :math:`2x_I/c_0`. Always limited by the
        end of the record for the reflected and transmitted waves.
    k_sigma, threshold_fraction : arrival threshold :math:`h = \max(k\sigma, \phi\max\varepsilon)`
        (:func:`detect_arrival`).
    despike_signals : remove isolated one-sample spikes before everything else (:func:`despike`).
    exclude_channels : gauge channel names to leave out of the averages (expert override).
    shift_reflected_s, shift_transmitted_s : extra time shifts [s] added to the nominal
        :math:`2x_I/c_0` and :math:`(x_I+x_T)/c_0` (fine alignment; 0 by default).
    guard_s : the pre-trigger part ends this long before the detected arrival [s].

    Returns
    -------
    ReducedRecord

    Raises
    ------
    ValueError
        If the bar or specimen is undefined, the pre-trigger part is too short, or no incident pulse is found.
    """
    bar = bar if bar is not None else raw.bar
    if bar is None:
        raise ValueError(f"{raw.name}: no BarSetup given and the record carries none")
    L_s = specimen_length_m if specimen_length_m is not None else raw.specimen_length
    D_s = specimen_diameter_m if specimen_diameter_m is not None else raw.specimen_diameter
    if L_s is None or D_s is None or not (L_s > 0 and D_s > 0):
        raise ValueError(f"{raw.name}: specimen length and diameter [m] are required, got {L_s}, {D_s}")

    dt = raw.dt
    n = raw.n_samples
    names_i, names_t = tuple(raw.incident_channels), tuple(raw.transmitted_channels)
    eps_i_raw, eps_t_raw = _to_strain(raw, bar)
    volts = np.vstack([raw.incident, raw.transmitted])
    eps = np.vstack([eps_i_raw, eps_t_raw])
    names = names_i + names_t
    n_i = len(names_i)
    notes: list[str] = []

    # step 2: provisional baseline / noise from the first samples (robust), despiking
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

    # step 3: arrival at the incident gauge: the earliest channel arrival (garbage from a failing gauge
    # starts after the pulse, never before the pulse foot)
    arrivals = []
    for k in range(n_i):
        if names[k] in exclude_channels:
            continue
        try:
            arrivals.append(detect_arrival(eps0[k], sig0[k], dt, k_sigma, threshold_fraction))
        except ValueError:
            continue
    if not arrivals:
        raise ValueError(f"{raw.name}: no incident pulse found on {names_i}")
    i_a = min(arrivals)

    c0 = bar.c0
    x_i, x_t = bar.gauge_distance_incident, bar.gauge_distance_transmitted
    t_refl = 2.0 * x_i / c0 + shift_reflected_s
    t_tran = (x_i + x_t) / c0 + shift_transmitted_s
    if window_s is not None and window_s > 2.0 * x_i / c0:
        notes.append("window longer than 2 x_I / c0: eps_incident overlaps the reflected wave at its end")

    def window_samples(i_arr: int, t_r: float, t_t: float) -> int:
        """Samples on the common axis: the requested length, cut at the end of the record."""
        T = 2.0 * x_i / c0 if window_s is None else float(window_s)
        avail = (n - 1 - i_arr) * dt
        T = min(T, avail - t_r, avail - t_t)
        if T <= 10 * dt:
            raise ValueError(f"{raw.name}: record too short after the incident arrival for the reflected/"
                             f"transmitted waves (window {T:.3g} s)")
        return int(math.floor(T / dt + 1e-9)) + 1

    n_w = window_samples(i_a, t_refl, t_tran)
    T_w = (n_w - 1) * dt

    # step 4: gauge selection over the spans each bar contributes
    span_i = slice(i_a, min(n, i_a + int(math.ceil((t_refl + T_w) / dt)) + 2))
    span_t = slice(min(n - 1, i_a + int(math.floor(t_tran / dt))), min(n, i_a + int(math.ceil((t_tran + T_w) / dt)) + 2))
    base_v = np.median(volts[:, :n0], axis=1)
    sig_v = np.array([robust_std(v[:n0]) for v in volts])
    keep_i, notes_i = select_gauges(eps0[:n_i], names_i, base_v[:n_i], sig_v[:n_i], span_i,
                                    exclude_channels, raw=volts[:n_i])
    keep_t, notes_t = select_gauges(eps0[n_i:], names_t, base_v[n_i:], sig_v[n_i:], span_t,
                                    exclude_channels, raw=volts[n_i:])
    notes += notes_i + notes_t
    inc = eps[:n_i][keep_i].mean(axis=0)
    tra = eps[n_i:][keep_t].mean(axis=0)

    # re-detect the arrival on the averaged incident signal (cleaner than any single gauge)
    inc_b0 = inc - inc[:n0].mean()
    try:
        i_a2 = detect_arrival(inc_b0, max(robust_std(inc[:n0]), 1e-12), dt, k_sigma, threshold_fraction)
        if abs(i_a2 - i_a) * dt < 0.25 * T_w:
            i_a = i_a2
    except ValueError:
        pass

    # step 5: baseline and noise from the pre-trigger part
    i_pre = i_a - max(1, int(round(guard_s / dt)))
    if i_pre < 20:
        raise ValueError(f"{raw.name}: only {max(i_pre, 0)} pre-trigger samples before the incident "
                         f"arrival; need at least 20 for the baseline")
    pre = slice(0, i_pre)
    inc = inc - inc[pre].mean()
    tra = tra - tra[pre].mean()
    chan = eps - eps[:, pre].mean(axis=1, keepdims=True)
    sd_inc = float(np.std(inc[pre], ddof=1))
    sd_tra = float(np.std(tra[pre], ddof=1))

    # the incident pulse must end before the reflected wave reaches the gauge (2 x_I / c0 later)
    n_g = min(int(math.floor(2.0 * x_i / c0 / dt + 1e-9)) + 1, n - i_a)
    seg = inc[i_a:i_a + n_g]
    j_pk = int(np.argmax(seg))
    h_end = max(k_sigma * sd_inc, threshold_fraction * float(seg[j_pk]))
    below = np.flatnonzero(seg[j_pk:] < h_end)
    overlap = below.size == 0 and i_a + n_g < n
    if overlap:
        notes.append("incident pulse longer than 2 x_I / c0: it overlaps the reflected wave at the "
                     "incident gauge, so eps_reflected (front force, strain rate) is contaminated")

    n_w = window_samples(i_a, t_refl, t_tran)

    # step 6: time shifts to the faces on the common axis
    t_a = raw.time[i_a]
    tau = dt * np.arange(n_w)
    eps_I = inc[i_a:i_a + n_w].copy()
    eps_R = np.interp(t_a + t_refl + tau, raw.time, inc)
    eps_T = np.interp(t_a + t_tran + tau, raw.time, tra)
    gauge_time = dt * np.arange(n_g)
    gauge_strain = inc[i_a:i_a + n_g].copy()

    # step 7: forces, stresses, rates
    A_b = bar.area
    A_s = math.pi * D_s ** 2 / 4.0
    F1 = bar.E * A_b * (eps_I + eps_R)
    F2 = bar.E * A_b * eps_T
    s1, s2 = F1 / A_s, F2 / A_s
    rate = c0 / L_s * (eps_I - eps_R - eps_T)
    strain = cumulative_trapezoid(rate, tau, initial=0.0)
    Fsum = F1 + F2
    with np.errstate(divide="ignore", invalid="ignore"):
        R = 2.0 * np.abs(F1 - F2) / Fsum
    R[~(Fsum > 0.1 * np.nanmax(Fsum))] = np.nan

    k_pa = bar.E * A_b / A_s
    noise_strain = {"incident": sd_inc, "reflected": sd_inc, "transmitted": sd_tra}
    noise_pa = {
        "stress": k_pa * sd_tra,
        "stress_back": k_pa * sd_tra,
        "stress_front": k_pa * math.sqrt(2.0) * sd_inc,
        "stress_mean": 0.5 * k_pa * math.sqrt(2.0 * sd_inc ** 2 + sd_tra ** 2),
    }
    for k, nm in enumerate(names):
        sd = float(np.std(chan[k, pre], ddof=1))
        noise_strain[nm] = sd
        noise_pa[nm] = k_pa * sd
    return ReducedRecord(
        name=raw.name,
        time=tau,
        eps_incident=eps_I,
        eps_reflected=eps_R,
        eps_transmitted=eps_T,
        force_front=F1,
        force_back=F2,
        stress_front=s1,
        stress_back=s2,
        stress_mean=0.5 * (s1 + s2),
        strain_rate=rate,
        strain=strain,
        force_balance=R,
        incident_gauge_time=gauge_time,
        incident_gauge_strain=gauge_strain,
        noise_std_strain=noise_strain,
        noise_std_Pa=noise_pa,
        noise_std_strain_rate=c0 / L_s * math.sqrt(2.0 * sd_inc ** 2 + sd_tra ** 2),
        bar=bar,
        specimen_length=float(L_s),
        specimen_diameter=float(D_s),
        arrival_time_gauge=float(t_a),
        shift_reflected=t_refl,
        shift_transmitted=t_tran,
        channels_used={"incident": tuple(names_i[k] for k in keep_i),
                       "transmitted": tuple(names_t[k] for k in keep_t)},
        spikes_removed=spikes,
        notes=notes,
    )


# --------------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------------
def reduced_to_dataframe(red: ReducedRecord) -> pd.DataFrame:
    """The reduced curves as a DataFrame with the SI column names of :data:`CSV_COLUMNS`."""
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
    from .atomic import atomic_write_text

    atomic_write_text(path, reduced_to_dataframe(red).to_csv(index=False, float_format="%.9g"))
    return path
