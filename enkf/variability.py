"""The simulator's own variability ``S``: what changes between runs that differ only in what should not matter.

A fracture simulator is not a smooth function of its parameters: the same parameters on another
realization of the specimen mesh break along another crack path, and after the failure peak the
curves part by far more than the instrument noise. Runs at one parameter point that differ only in
the mesh realization (``replicates``) measure it. The data model is then

    d = mu(theta) + eta + delta + e,       eta ~ N(0, S),  delta ~ N(0, D),  e ~ N(0, R)

with ``mu`` the mean over mesh realizations, ``eta`` the realization's departure from it, ``delta`` the
model discrepancy and ``e`` the instrument noise. One run ``y_i = mu(theta_i) + eta_i`` is one draw, so
a member's curve and the data differ by two independent realizations: ``2 S`` (the stop test and the
discrepancy's base), while the data scatter about the mean by ``S`` (the likelihood of ``mu``).

``S`` is modelled as a heteroscedastic AR(1) process per record, the structure the replicates show:
zero before the wave arrives, small on the elastic rise, large after the peak, correlated over a few
microseconds. Its per-time variance is the replicates' unbiased sample variance smoothed by a centred
moving average over ``window`` samples (with five or six replicates one time's variance has four or
five degrees of freedom; the average over neighbouring times, which share the crack path, steadies it);
the correlation time comes from the lag-1 autocorrelation of the standardised departures, pooled over
replicates and records (as :func:`enkf.emulated.emulator_error_model`).
"""

from __future__ import annotations

import math

import numpy as np

from .covariance import AR1Error

__all__ = ["SMOOTH_WINDOW", "lag1_correlation", "simulator_variability", "smoothed_variance"]

#: Samples in the centred moving average of the replicates' per-time variance.
SMOOTH_WINDOW = 5


def _smooth(v: np.ndarray, groups: np.ndarray, window: int) -> np.ndarray:
    if window <= 1:
        return v
    out = np.empty_like(v)
    kernel = np.ones(window)
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        num = np.convolve(v[idx], kernel, mode="same")
        den = np.convolve(np.ones(idx.size), kernel, mode="same")
        out[idx] = num / den
    return out


def lag1_correlation(dev: np.ndarray, times: np.ndarray, groups: np.ndarray) -> tuple[float, float]:
    """``(rho, tau)``: the lag-1 correlation of departures ``dev`` (rows: curves; columns: times) and the
    AR(1) correlation time ``-dt / ln rho`` it gives on the median step ``dt``.

    One pooled ratio ``sum a b / sqrt(sum a^2 sum b^2)`` over all neighbouring pairs of times within each
    group and all curves, without standardising: standardising by a smoothed per-time sd blurs a jump of
    the amplitude (a failure peak) into a false loss of correlation, and averaging per-time correlations
    of a few replicates is biased low (a planted 8 us AR(1) gave 4.3 / 5.4 / 6.4 us from 3 / 4 / 6
    replicates that way; pooled: 6.7-7.3 us from 2 to 6; tests/test_simulator_variability.py)."""
    same = groups[1:] == groups[:-1]
    a, b = dev[:, 1:][:, same], dev[:, :-1][:, same]
    den = math.sqrt(float(np.sum(a * a)) * float(np.sum(b * b)))
    rho = float(np.sum(a * b)) / den if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    steps = np.diff(times)[same]
    dt = float(np.median(steps)) if steps.size else 1.0
    return rho, (-dt / math.log(rho) if rho > 0 else 0.0)


def smoothed_variance(dev: np.ndarray, dof: int, groups: np.ndarray, window: int = SMOOTH_WINDOW) -> np.ndarray:
    """Per-time variance ``sum dev^2 / dof`` of departures ``dev`` (rows: curves), smoothed over
    ``window`` neighbouring times within each group (integer labels)."""
    return _smooth(np.sum(dev ** 2, axis=0) / dof, groups, int(window))


def simulator_variability(replicates, times, groups=None, *, window: int = SMOOTH_WINDOW,
                          split_times=None, subtract_variance=None) -> tuple[AR1Error | None, dict]:
    """``(S, info)`` from replicate curves ``(M, m)`` at one parameter point (rows: realizations; a row
    with a non-finite value is a failed run and is left out).

    ``S`` is an :class:`enkf.covariance.AR1Error` with the smoothed per-time std and one correlation
    time; None when fewer than two replicates succeeded (``info["n_replicates"]`` says how many).
    ``split_times``: ``{group: t}`` (e.g. each record's observed peak) for the rms before and after it
    in ``info["groups"]``. ``subtract_variance`` (m,): a per-time variance counted elsewhere, taken off
    the smoothed one (floored at zero); the correlation time stays that of the departures.
    """
    Y = np.array(replicates, dtype=float, ndmin=2)
    t = np.asarray(times, dtype=float)
    if Y.shape[1] != t.size:
        raise ValueError(f"replicates have {Y.shape[1]} columns, the grid {t.size} times")
    g = np.zeros(t.size, int) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
    labels = np.zeros(t.size, object) if groups is None else np.asarray(groups)
    Y = Y[np.all(np.isfinite(Y), axis=1)]
    M = Y.shape[0]
    info = {"n_replicates": int(M), "window_samples": int(window)}
    if M < 2:
        return None, info
    dev = Y - Y.mean(axis=0)
    var = smoothed_variance(dev, M - 1, g, window)
    if subtract_variance is not None:
        var = var - np.asarray(subtract_variance, dtype=float)
    sd = np.sqrt(np.maximum(var, 0.0))
    top = float(sd.max())
    if top <= 1e-12 * max(float(np.max(np.abs(Y))), 1e-300):  # agree to round-off, or nothing left beyond subtract_variance
        return None, {**info, "rms_Pa": 0.0}
    sd = np.maximum(sd, 1e-9 * top)
    rho, corr_time = lag1_correlation(dev, t, g)
    S = AR1Error(sd, t, corr_time, groups=g)
    per = {}
    for lab in dict.fromkeys(labels.tolist()):
        sel = labels == lab
        entry = {"rms_Pa": float(np.sqrt(np.mean(sd[sel] ** 2))), "max_Pa": float(sd[sel].max())}
        ts = (split_times or {}).get(lab)
        if ts is not None:
            pre, post = sel & (t < ts), sel & (t >= ts)
            entry["split_time_s"] = float(ts)
            entry["rms_pre_peak_Pa"] = float(np.sqrt(np.mean(sd[pre] ** 2))) if pre.any() else None
            entry["rms_post_peak_Pa"] = float(np.sqrt(np.mean(sd[post] ** 2))) if post.any() else None
        per[str(lab)] = entry
    info.update({"rms_Pa": float(np.sqrt(np.mean(sd ** 2))), "max_Pa": top, "lag1_correlation": rho,
                 "corr_time_s": corr_time, "groups": per, "sd_Pa": sd.tolist()})
    return S, info
