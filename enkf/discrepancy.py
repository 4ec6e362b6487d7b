"""Model discrepancy: a time-correlated error term for what the model lacks (Kennedy & O'Hagan 2001).

The data model of one record is ``d = y(theta) + delta + e`` with the instrument noise ``e ~ N(0, R)``
and the discrepancy ``delta ~ N(0, D)``, an AR(1) (Ornstein-Uhlenbeck) process of its own marginal std
``sigma_d`` and correlation time ``tau_d``:

    D_ij = sigma_d^2 exp(-|t_i - t_j| / tau_d),   records independent.

Why AR(1): a missing effect leaves a residual that is smooth on the scale of the observation step
(a shifted onset, a peak too high, a fall too fast), so a white inflation would count each of the
``m`` correlated residuals as independent evidence; AR(1) is the simplest Markov process with a
correlation time, and its two hyperparameters are identifiable from one record of ``m >> T / tau``
samples.

How ``(sigma_d, tau_d)`` are estimated: by maximum likelihood jointly with the parameters, the
parameters restricted to the ensemble's members (a profile likelihood over the sample of ``theta``
the ensemble is). For each alive member ``i`` and record ``g`` the Gaussian log-likelihood
``l_ig(h) = log N(d_g; y_ig, R_g + D_g(h))`` is maximised over ``h = (sigma_d, tau_d)``; the member
with the largest ``sum_g max_h l_ig`` gives the estimate (a hyperparameter per record, because records
at different strain rates miss by different amounts). Called at every analysis on that iteration's
members, this is an iterative re-weighting: early (prior) ensembles carry parameter error in their
best residual and get a larger ``D``, which damps their update; as the ensemble closes in, ``D``
falls to what the best parameters cannot explain. ``sigma_d = 0`` is allowed (the noise-only model
is always a candidate), so a model that fits to the noise gets no discrepancy.

The simplest honest baseline, an inflation of ``R`` by the factor that brings the best member's
chi^2 per observation to 1 (:func:`inflated_noise_factor`), is reported beside it for comparison.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize

from .covariance import DenseError, ObservationError

__all__ = ["RecordDiscrepancy", "DiscrepancyEstimate", "ar1_covariance", "record_loglik",
           "fit_record_discrepancy", "estimate_discrepancy", "inflated_noise_factor", "combined_error"]

_LOG_2PI = math.log(2.0 * math.pi)


def ar1_covariance(sigma: float, corr_time: float, times) -> np.ndarray:
    """``sigma^2 exp(-|t_i - t_j| / tau)`` on ``times`` (one record); zeros for ``sigma = 0``."""
    t = np.asarray(times, float)
    if sigma <= 0.0:
        return np.zeros((t.size, t.size))
    if corr_time <= 0.0:
        return sigma * sigma * np.eye(t.size)
    return sigma * sigma * np.exp(-np.abs(t[:, None] - t[None, :]) / corr_time)


def record_loglik(residual, noise_cov: np.ndarray, times, sigma: float, corr_time: float) -> float:
    """``log N(residual; 0, R + D(sigma, tau))`` of one record (``residual = d - y``)."""
    r = np.asarray(residual, float)
    C = noise_cov + ar1_covariance(sigma, corr_time, times)
    try:
        L = linalg.cholesky(C, lower=True, check_finite=False)
    except linalg.LinAlgError:
        return -math.inf
    z = linalg.solve_triangular(L, r, lower=True, check_finite=False)
    return float(-0.5 * (z @ z) - np.sum(np.log(np.diag(L))) - 0.5 * r.size * _LOG_2PI)


@dataclass(frozen=True)
class RecordDiscrepancy:
    """The estimated discrepancy of one record and what it buys in likelihood."""

    sigma: float
    corr_time: float
    loglik: float
    loglik_noise_only: float
    n_obs: int
    noise_sigma: float

    def to_dict(self) -> dict:
        return {"sigma": self.sigma, "corr_time_s": self.corr_time, "sigma_over_noise": self.sigma / self.noise_sigma
                if self.noise_sigma > 0 else None, "noise_sigma": self.noise_sigma, "loglik": self.loglik,
                "loglik_noise_only": self.loglik_noise_only, "n_obs": self.n_obs}


def fit_record_discrepancy(residual, noise_cov: np.ndarray, times) -> RecordDiscrepancy:
    """Maximum-likelihood ``(sigma_d, tau_d)`` of one record's residual (``sigma_d = 0`` allowed).

    Searched in ``(log sigma, log tau)`` with ``sigma`` from 1e-3 to 10 times the residual's RMS and
    ``tau`` from half the smallest time step to the record's span; the start is the best point of a
    coarse grid, so the optimum found does not hinge on one start.
    """
    r = np.asarray(residual, float)
    t = np.asarray(times, float)
    noise_sigma = float(np.sqrt(np.mean(np.diag(noise_cov))))
    l0 = record_loglik(r, noise_cov, t, 0.0, 0.0)
    rms = float(np.sqrt(np.mean(r * r)))
    span = float(t[-1] - t[0]) if t.size > 1 else 1.0
    step = float(np.min(np.diff(t))) if t.size > 1 else 1.0
    if rms <= 0.0 or t.size < 4:
        return RecordDiscrepancy(0.0, 0.0, l0, l0, int(r.size), noise_sigma)
    lo = np.array([math.log(1e-3 * rms), math.log(0.5 * step)])
    hi = np.array([math.log(10.0 * rms), math.log(span)])

    def nll(u):
        return -record_loglik(r, noise_cov, t, math.exp(u[0]), math.exp(u[1]))

    grid = [(a, b) for a in np.linspace(lo[0] + 0.5 * (hi[0] - lo[0]), hi[0] - 1.0, 4)
            for b in np.linspace(lo[1], hi[1], 5)]
    start = min(grid, key=nll)
    res = optimize.minimize(nll, np.array(start), method="L-BFGS-B", bounds=list(zip(lo, hi)))
    sigma, tau, l1 = math.exp(res.x[0]), math.exp(res.x[1]), -float(res.fun)
    if not math.isfinite(l1) or l1 <= l0:
        return RecordDiscrepancy(0.0, 0.0, l0, l0, int(r.size), noise_sigma)
    return RecordDiscrepancy(sigma, tau, l1, l0, int(r.size), noise_sigma)


@dataclass(frozen=True)
class DiscrepancyEstimate:
    """Per-record discrepancies (keyed by group label) and the member whose residual gave them."""

    records: dict
    member: int
    labels: tuple

    def covariance(self, noise: ObservationError, times, groups) -> np.ndarray:
        """``R + D`` of the whole observation vector (block diagonal over records)."""
        return combined_error(noise, times, groups, {g: (d.sigma, d.corr_time) for g, d in self.records.items()},
                              as_matrix=True)

    def error_model(self, noise: ObservationError, times, groups) -> DenseError:
        return DenseError(self.covariance(noise, times, groups), _symmetric=True)

    def to_dict(self, names: Sequence[str] | None = None) -> dict:
        names = list(names) if names is not None else [str(g) for g in self.labels]
        return {"model": "ar1", "estimated_by": "profile maximum likelihood over the ensemble members",
                "member": self.member,
                "records": {names[k]: self.records[g].to_dict() for k, g in enumerate(self.labels)}}


def combined_error(noise: ObservationError, times, groups, terms: dict, *, as_matrix: bool = False):
    """``R`` plus one AR(1) term per group, ``terms = {group: (sigma, tau)}`` (missing groups: none).

    Returns the dense matrix or (default) a :class:`DenseError`.
    """
    t = np.asarray(times, float)
    g = np.zeros(t.size, int) if groups is None else np.asarray(groups)
    C = noise.dense()
    for label, (sigma, tau) in terms.items():
        idx = np.flatnonzero(g == label)
        if idx.size and sigma > 0:
            C[np.ix_(idx, idx)] += ar1_covariance(float(sigma), float(tau), t[idx])
    return C if as_matrix else DenseError(C, _symmetric=True)


def _group_blocks(noise: ObservationError, times, groups):
    t = np.asarray(times, float)
    g = np.zeros(t.size, int) if groups is None else np.asarray(groups)
    R = noise.dense()
    labels = tuple(dict.fromkeys(g.tolist()))
    return [(lab, np.flatnonzero(g == lab)) for lab in labels], R, t, labels


def estimate_discrepancy(residuals, noise: ObservationError, times, groups=None, alive=None) -> DiscrepancyEstimate:
    """Profile-likelihood discrepancy from member residuals ``d - y_i`` (rows = members, NaN = failed).

    Every alive member is fitted record by record; the member with the largest summed maximised
    log-likelihood gives the estimate (see the module docstring).
    """
    Rr = np.atleast_2d(np.asarray(residuals, float))
    ok = np.all(np.isfinite(Rr), axis=1)
    if alive is not None:
        ok &= np.asarray(alive, bool)
    if not np.any(ok):
        raise ValueError("no alive member with a finite residual to estimate the discrepancy from")
    blocks, R, t, labels = _group_blocks(noise, times, groups)
    best, best_ll = None, -math.inf
    for i in np.flatnonzero(ok):
        fits = {lab: fit_record_discrepancy(Rr[i, idx], R[np.ix_(idx, idx)], t[idx]) for lab, idx in blocks}
        ll = sum(f.loglik for f in fits.values())
        if ll > best_ll:
            best, best_ll = (int(i), fits), ll
    return DiscrepancyEstimate(records=best[1], member=best[0], labels=labels)


def inflated_noise_factor(residual, noise: ObservationError) -> float:
    """The baseline: the factor ``s^2`` with ``chi^2(residual; s^2 R) / m = 1``, i.e. ``chi^2 / m``."""
    r = np.asarray(residual, float)
    return float(noise.chi2(r) / r.size)
