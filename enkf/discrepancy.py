"""Model discrepancy: a time-correlated error term for what the model lacks (Kennedy & O'Hagan 2001).

The data model of one record is ``d = y(theta) + delta + e`` with the instrument noise ``e ~ N(0, R)``
and the discrepancy ``delta ~ N(0, D)``, an AR(1) (Ornstein-Uhlenbeck) process of correlation time
``tau_d`` whose marginal std ``s(t)`` may differ before and after a split time ``t_s`` (the record's
observed peak, where a fracture model's error changes character: the elastic rise is smooth, the
post-peak carries which crack wins):

    D_ij = s(t_i) s(t_j) exp(-|t_i - t_j| / tau_d),   s(t) = sigma_pre (t < t_s), sigma_post (t >= t_s),

records independent. Without a split time ``sigma_pre = sigma_post`` (a stationary AR(1)).

Why AR(1): a missing effect leaves a residual that is smooth on the scale of the observation step
(a shifted onset, a peak too high, a fall too fast), so a white inflation would count each of the
``m`` correlated residuals as independent evidence; AR(1) is the simplest Markov process with a
correlation time.

How ``h = (sigma_pre, sigma_post, tau_d)`` is estimated: by maximum likelihood jointly with the
parameters, the parameters restricted to the ensemble's members (a profile likelihood over the sample
of ``theta`` the ensemble is), one ``h`` per record (records at different strain rates miss by
different amounts): ``max_i max_h sum_g log N(d_g; y_ig, R_g + D_g(h_g))``, found by coordinate ascent
(fit the member of smallest residual, rank every member at its ``h``, refit the best if it differs).
Called at every analysis on that iteration's members, this is an iterative re-weighting: early
(prior) ensembles carry parameter error in their best residual and get a larger ``D``, which damps
their update; as the ensemble closes in, ``D`` falls to what the best parameters cannot explain. A
zero discrepancy is always a candidate, so a model that fits to the noise gets none. The estimate is
biased low by the choice of the best member among N, which matters after the peak, where a record
holds few correlation times.

The simplest honest baseline, an inflation of ``R`` by the factor that brings the best member's
chi^2 per observation to 1 (:func:`inflated_noise_factor`), is reported beside it for comparison.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize

from .covariance import DenseError, ObservationError
from .diagnostics import alive_mask

__all__ = ["RecordDiscrepancy", "DiscrepancyEstimate", "ar1_covariance", "record_loglik",
           "fit_record_discrepancy", "estimate_discrepancy", "inflated_noise_factor", "combined_error"]

_LOG_2PI = math.log(2.0 * math.pi)


def _amplitude(sigma_pre: float, sigma_post: float, split_time: float | None, t: np.ndarray) -> np.ndarray:
    if split_time is None:
        return np.full(t.size, float(sigma_pre))
    return np.where(t < split_time, float(sigma_pre), float(sigma_post))


def ar1_covariance(sigma: float, corr_time: float, times, sigma_post: float | None = None,
                   split_time: float | None = None) -> np.ndarray:
    """``s_i s_j exp(-|t_i - t_j| / tau)`` on ``times`` (one record), ``s = sigma`` before ``split_time``
    and ``sigma_post`` from it on (``sigma`` everywhere without a split); zeros where ``s = 0``."""
    t = np.asarray(times, float)
    s = _amplitude(sigma, sigma if sigma_post is None else sigma_post, split_time, t)
    if not np.any(s > 0.0):
        return np.zeros((t.size, t.size))
    rho = np.eye(t.size) if corr_time <= 0.0 else np.exp(-np.abs(t[:, None] - t[None, :]) / corr_time)
    return s[:, None] * rho * s[None, :]


def record_loglik(residual, noise_cov: np.ndarray, times, sigma: float, corr_time: float,
                  sigma_post: float | None = None, split_time: float | None = None) -> float:
    """``log N(residual; 0, R + D)`` of one record (``residual = d - y``)."""
    r = np.asarray(residual, float)
    C = noise_cov + ar1_covariance(sigma, corr_time, times, sigma_post, split_time)
    try:
        L = linalg.cholesky(C, lower=True, check_finite=False)
    except linalg.LinAlgError:
        return -math.inf
    z = linalg.solve_triangular(L, r, lower=True, check_finite=False)
    return float(-0.5 * (z @ z) - np.sum(np.log(np.diag(L))) - 0.5 * r.size * _LOG_2PI)


@dataclass(frozen=True)
class RecordDiscrepancy:
    """The estimated discrepancy of one record and what it buys in likelihood. ``sigma``: the RMS of
    ``s(t)`` over the record's observations, the discrepancy's size in one number."""

    sigma_pre: float
    sigma_post: float
    corr_time: float
    split_time: float | None
    loglik: float
    loglik_noise_only: float
    n_obs: int
    noise_sigma: float
    sigma: float

    def term(self) -> tuple:
        return (self.sigma_pre, self.sigma_post, self.corr_time, self.split_time)

    def to_dict(self) -> dict:
        return {"sigma": self.sigma, "sigma_pre": self.sigma_pre, "sigma_post": self.sigma_post,
                "corr_time_s": self.corr_time, "split_time_s": self.split_time,
                "sigma_over_noise": self.sigma / self.noise_sigma if self.noise_sigma > 0 else None,
                "noise_sigma": self.noise_sigma, "loglik": self.loglik, "loglik_noise_only": self.loglik_noise_only,
                "n_obs": self.n_obs}


def fit_record_discrepancy(residual, noise_cov: np.ndarray, times, split_time: float | None = None) -> RecordDiscrepancy:
    """Maximum-likelihood ``(sigma_pre, sigma_post, tau_d)`` of one record's residual (zero allowed).

    Searched in logs with each ``sigma`` from 1e-3 to 10 times the residual's RMS and ``tau`` from half
    the smallest time step to the record's span; the start is the best point of a coarse grid, so the
    optimum found does not hinge on one start. A split time outside the record's span (or None) fits
    one amplitude.
    """
    r = np.asarray(residual, float)
    t = np.asarray(times, float)
    noise_sigma = float(np.sqrt(np.mean(np.diag(noise_cov))))
    l0 = record_loglik(r, noise_cov, t, 0.0, 0.0)
    none = RecordDiscrepancy(0.0, 0.0, 0.0, None, l0, l0, int(r.size), noise_sigma, 0.0)
    rms = float(np.sqrt(np.mean(r * r)))
    if rms <= 0.0 or t.size < 4:
        return none
    if split_time is not None and not (t[0] < split_time <= t[-1]):
        split_time = None
    span, step = float(t[-1] - t[0]), float(np.min(np.diff(t)))
    n_amp = 1 if split_time is None else 2
    lo = np.array([math.log(1e-3 * rms)] * n_amp + [math.log(0.5 * step)])
    hi = np.array([math.log(10.0 * rms)] * n_amp + [math.log(span)])

    def unpack(u):
        a = np.exp(u[:n_amp])
        return a[0], a[-1], math.exp(u[-1])

    def nll(u):
        s_pre, s_post, tau = unpack(u)
        return -record_loglik(r, noise_cov, t, s_pre, tau, s_post, split_time)

    amps = np.linspace(lo[0] + 0.5 * (hi[0] - lo[0]), hi[0] - 1.0, 3)
    taus = np.linspace(lo[-1], hi[-1], 4)
    grid = [np.array([*a, b]) for a in (np.array(np.meshgrid(*[amps] * n_amp)).reshape(n_amp, -1).T) for b in taus]
    start = min(grid, key=nll)
    res = optimize.minimize(nll, start, method="L-BFGS-B", bounds=list(zip(lo, hi)))
    l1 = -float(res.fun)
    if not math.isfinite(l1) or l1 <= l0:
        return none
    s_pre, s_post, tau = unpack(res.x)
    rms = float(np.sqrt(np.mean(_amplitude(s_pre, s_post, split_time, t) ** 2)))
    return RecordDiscrepancy(s_pre, s_post, tau, split_time, l1, l0, int(r.size), noise_sigma, rms)


@dataclass(frozen=True)
class DiscrepancyEstimate:
    """Per-record discrepancies (keyed by group label) and the member whose residual gave them."""

    records: dict
    member: int
    labels: tuple

    def covariance(self, noise: ObservationError, times, groups) -> np.ndarray:
        """``R + D`` of the whole observation vector (block diagonal over records)."""
        return combined_error(noise, times, groups, {g: d.term() for g, d in self.records.items()}, as_matrix=True)

    def error_model(self, noise: ObservationError, times, groups) -> DenseError:
        return DenseError(self.covariance(noise, times, groups), _symmetric=True)

    def to_dict(self, names: Sequence[str] | None = None) -> dict:
        names = list(names) if names is not None else [str(g) for g in self.labels]
        return {"model": "ar1", "estimated_by": "profile maximum likelihood over the ensemble members",
                "member": self.member,
                "records": {names[k]: self.records[g].to_dict() for k, g in enumerate(self.labels)}}


def combined_error(noise: ObservationError, times, groups, terms: Mapping, *, as_matrix: bool = False):
    """``R`` plus one AR(1) term per group, ``terms = {group: (sigma_pre, sigma_post, tau, split_time)}``
    (``split_time`` None: one amplitude, ``sigma_pre``; missing groups: none).

    Returns the dense matrix or (default) a :class:`DenseError`.
    """
    t = np.asarray(times, float)
    g = np.zeros(t.size, int) if groups is None else np.asarray(groups)
    C = noise.dense()
    for label, term in terms.items():
        s_pre, s_post, tau, split = term
        idx = np.flatnonzero(g == label)
        if idx.size and (s_pre > 0 or s_post > 0):
            C[np.ix_(idx, idx)] += ar1_covariance(float(s_pre), float(tau), t[idx], float(s_post), split)
    return C if as_matrix else DenseError(C, _symmetric=True)


def _group_blocks(noise: ObservationError, times, groups):
    t = np.asarray(times, float)
    g = np.zeros(t.size, int) if groups is None else np.asarray(groups)
    R = noise.dense()
    labels = tuple(dict.fromkeys(g.tolist()))
    return [(lab, np.flatnonzero(g == lab)) for lab in labels], R, t, labels


def estimate_discrepancy(residuals, noise: ObservationError, times, groups=None, alive=None,
                         split_times: Mapping | None = None) -> DiscrepancyEstimate:
    """Profile-likelihood discrepancy from member residuals ``d - y_i`` (rows = members, NaN = failed).

    The member with the largest summed maximised log-likelihood gives the estimate (see the module
    docstring), found by coordinate ascent (the comment in the body). ``split_times``: ``{group: t_s}``,
    where the amplitude may change (none: one amplitude per record).
    """
    Rr = np.atleast_2d(np.asarray(residuals, float))
    ok = alive_mask(Rr, alive)
    if not np.any(ok):
        raise ValueError("no alive member with a finite residual to estimate the discrepancy from")
    blocks, R, t, labels = _group_blocks(noise, times, groups)
    split_times = split_times or {}

    def fit(i):
        return {lab: fit_record_discrepancy(Rr[i, idx], R[np.ix_(idx, idx)], t[idx], split_times.get(lab))
                for lab, idx in blocks}

    def score(i, fits):
        return sum(record_loglik(Rr[i, idx], R[np.ix_(idx, idx)], t[idx], fits[lab].sigma_pre, fits[lab].corr_time,
                                 fits[lab].sigma_post, fits[lab].split_time) for lab, idx in blocks)

    # Coordinate ascent on (member, hyperparameters), cheaper than a full fit per member: fit the member
    # of smallest RMS residual, rank every member at those hyperparameters, refit the best if it differs.
    alive_idx = np.flatnonzero(ok)
    i0 = int(alive_idx[np.argmin(np.mean(Rr[alive_idx] ** 2, axis=1))])
    best_i, best_fits = i0, fit(i0)
    i1 = int(alive_idx[np.argmax([score(i, best_fits) for i in alive_idx])])
    if i1 != i0:
        fits1 = fit(i1)
        if sum(f.loglik for f in fits1.values()) > sum(f.loglik for f in best_fits.values()):
            best_i, best_fits = i1, fits1
    return DiscrepancyEstimate(records=best_fits, member=best_i, labels=labels)


def inflated_noise_factor(residual, noise: ObservationError) -> float:
    """The baseline: the factor ``s^2`` with ``chi^2(residual; s^2 R) / m = 1``, i.e. ``chi^2 / m``."""
    r = np.asarray(residual, float)
    return float(noise.chi2(r) / r.size)
