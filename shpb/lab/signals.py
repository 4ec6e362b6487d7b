"""Signal utilities of the reduction: robust noise level, despiking, stuck and saturated gauges, the
arrival of a pulse, and the choice of gauges of a bar (:func:`shpb.lab.reduction.reduce_record`)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["cumulative_trapezoid", "running_mean", "running_median", "robust_std", "despike", "stuck_runs", "saturation_onset", "detect_arrival", "select_gauges"]


def cumulative_trapezoid(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.integrate.cumulative_trapezoid(y, x, initial=0.0)`` of 1-D arrays, in scipy's own arithmetic
    (the same floats). Here because importing ``scipy.integrate`` takes 0.3-0.4 s, and every simulation
    driven by a measured record reduces that record in a fresh process (tests/test_records_reduction_synthetic.py
    checks it against scipy's)."""
    y, x = np.asarray(y, float), np.asarray(x, float)
    return np.concatenate(([0.0], np.cumsum(np.diff(x) * (y[1:] + y[:-1]) / 2.0)))


def _edge_padded(x: np.ndarray, size: int) -> np.ndarray:
    """``x`` extended by its first value ``size // 2`` times and its last ``size - size // 2 - 1`` times:
    the window of ``scipy.ndimage``'s ``mode="nearest"`` around every sample."""
    before = size // 2
    return np.concatenate((np.full(before, x[0]), x, np.full(size - before - 1, x[-1])))


def running_mean(x: np.ndarray, size: int) -> np.ndarray:
    """``scipy.ndimage.uniform_filter1d(x, size, mode="nearest")`` of a 1-D array, in scipy's arithmetic (a
    running sum, updated by the sample entering minus the sample leaving, divided by ``size``): the same
    floats. Here, like :func:`cumulative_trapezoid`, to keep ``scipy.ndimage``'s import out of every
    simulation driven by a measured record (tests/test_records_reduction_synthetic.py checks it)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return x.copy()
    xp = _edge_padded(x, size)
    first = 0.0
    for v in xp[:size]:  # scipy's first window: a sequential sum
        first += v
    steps = xp[size:size + x.size - 1] - xp[:x.size - 1]
    return np.cumsum(np.concatenate(([first], steps))) / size  # cumsum adds in sequence, as scipy's loop


def running_median(x: np.ndarray, size: int) -> np.ndarray:
    """``scipy.ndimage.median_filter(x, size=size, mode="nearest")`` of a 1-D array, ``size`` odd (the
    median of an odd window is one of its samples, so the result is exactly scipy's)."""
    if size % 2 != 1:
        raise ValueError(f"running_median: size must be odd, got {size}")
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return x.copy()
    return np.median(np.lib.stride_tricks.sliding_window_view(_edge_padded(x, size), size), axis=1)


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
        med = running_median(y, 5)
        d = y - med
        step = np.abs(np.diff(y))
        local = running_median(np.r_[step, step[-1]], 11)
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
    sm = running_mean(s, w) if w > 1 else s
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
        rough = [float(np.std(x - running_mean(x, 9))) for x in (a, b)]
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


#: Largest pre-trigger excursion over the pulse's peak a record may have (:func:`pretrigger_ratio`): 3.5 x
#: the worst shipped record's 0.14 (SaLi_SHPB_006), well below a flipped sign's (1.3 on CaMa_SHPB_004).
QUIET_PRETRIGGER = 0.5


def pretrigger_ratio(x: np.ndarray, pre: slice, start: int, n: int) -> float:
    """Largest excursion of the baseline-free ``x`` before the pulse (``pre``) over the pulse's peak in
    ``x[start:start + n]``: about 0.1 on a quiet record (the shipped records: at most 0.14); above 1 when
    the sign is flipped, the first (tensile-looking) pulse then sitting in the pre-trigger."""
    peak = float(np.max(x[start:start + n])) if n > 0 else 0.0
    return float(np.max(np.abs(x[pre]))) / peak if peak > 0 else math.inf
