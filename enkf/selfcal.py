"""Self-calibration of an emulated likelihood on the runs themselves (issue 30).

The reported ``posterior: emulator_mcmc`` (like the emulated analyses) uses ``N(d; em(theta), R + D + C_em)``,
``C_em`` the AR(1) model of the emulator's leave-one-out residuals (per-time rms, one correlation
time). It is only as honest as that covariance: a departure correlated otherwise (a mesh realization's
stiffness moves a whole rise, a crack path a whole post-peak) is counted as more independent
information than it holds, and the posterior is too sure. Nothing in the data can show that; the runs
can. Run ``i`` of the iteration being analysed, plus a draw of the instrument noise ``R``, is a data set
whose parameters ``theta_i`` are known. On the emulator of the other runs (its ``C_em`` from that
emulator's own leave-one-out residuals),

    delta_i = chi2_i(theta_i) - min_theta chi2_i(theta)

is chi-square with ``n`` degrees of freedom when the likelihood is right (``n`` parameters, the profile
likelihood ratio). ``lambda = median(delta) / median(chi2_n)``, at least 1, is the factor by which the
covariance must grow for the runs' own parameters to sit inside their posterior regions at the nominal
rate; the reported posterior then uses ``lambda (R + D + C_em)`` (:func:`enkf.ces.emulator_posterior`; the
loop's analyses are left unscaled, so that its designs and stop rule are the unscaled loop's). This is the calibration of a generalized
posterior's learning rate ``1 / lambda`` so that its credible regions cover (Syring & Martin 2019),
with the simulator's own runs as the replicates of known truth. The median, not the mean or a high
quantile: 25 runs give it to about +-30 % and a run at the box's edge (a truncated region) does not move
it. ``lambda`` is never below 1: a likelihood that looks too wide on 25 runs is left as it is.
With the heteroscedastic likelihood (:mod:`enkf.hetero`, ``C_em`` scaled by ``a(theta)``) ``delta`` is the
deviance's, log-determinant included, and ``1 / lambda`` multiplies the whole log-likelihood.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import linalg, optimize, stats

from ._rng import RngLike, as_generator
from .covariance import ObservationError
from .emulator import CurveEmulator
from .hetero import emulated_deviance
from .sampling import latin_hypercube

__all__ = ["RECALIBRATIONS", "TEMPERINGS", "box_minimum", "location_shift", "pseudo_pits", "pseudo_runs",
           "recalibrated", "self_calibration"]

#: How the factor widens the reported posterior's likelihood (:mod:`enkf.ces`).
TEMPERINGS = ("power", "curvature")
#: How the pseudo-runs move the reported posterior's quantiles besides its width (:func:`pseudo_pits`):
#: ``none``, or ``location``: each parameter's quantile at level ``q`` taken at level ``Phi(mu + Phi^-1(q))``.
RECALIBRATIONS = ("none", "location")
#: PITs kept this far from 0 and 1 before their probit: a run at the box's edge can sit below or above
#: every draw, which would put an infinite value into the mean
PIT_CLIP = 0.005
#: The largest factor the curvature form's search returns: a median delta still above the reference
#: there means the runs sit nowhere near their own likelihood's maximum.
LAMBDA_MAX = 1e12


def box_minimum(chi2: Callable[[np.ndarray], np.ndarray], lo, hi, starts: np.ndarray) -> tuple[float, np.ndarray]:
    """The least ``chi2`` over the box and where it is: the best of ``starts``, polished by L-BFGS-B in the
    unit box."""
    values = chi2(starts)
    best = starts[int(np.argmin(values))]
    res = optimize.minimize(lambda u: float(chi2(lo + u[None, :] * (hi - lo))[0]), (best - lo) / (hi - lo),
                            method="L-BFGS-B", bounds=[(0.0, 1.0)] * lo.size)
    if res.fun < values.min():
        return float(res.fun), lo + np.clip(res.x, 0.0, 1.0) * (hi - lo)
    return float(values.min()), np.array(best, float)


def pseudo_runs(X, Y, latest, obs_error: ObservationError, *, lower, upper, smoothing: float,
                error_model: Callable[[np.ndarray], ObservationError], rng: RngLike, pseudo=None):
    """Each latest run (each run ``pseudo`` flags, where given) as data of known parameters: yields
    ``(i, em, C, y)``, ``em`` the emulator of the other runs, ``C = R + C_em`` (``C_em`` from ``em``'s
    leave-one-out residuals at the other latest runs, as the analysis measures it) and ``y`` run ``i``'s
    curve plus a draw of ``R`` (one draw per run, in the order of the runs)."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    latest = np.asarray(latest, bool)
    pseudo = latest if pseudo is None else np.asarray(pseudo, bool)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    rng = as_generator(rng)
    R = obs_error.dense()
    L_R = linalg.cholesky(R, lower=True)
    for i in np.flatnonzero(pseudo):
        keep = np.arange(X.shape[0]) != i
        em = CurveEmulator(X[keep], Y[keep], lo, hi, smoothing=smoothing)
        C = R + error_model(em.loo_residuals()[latest[keep]]).dense()
        yield i, em, C, Y[i] + L_R @ rng.standard_normal(Y.shape[1])


def _deviance(em, C, R, C_em, X_keep, lo, hi, heteroscedastic: bool):
    """``theta -> -2 log p(y | theta) + const`` of the emulated likelihood on ``em`` with covariance ``C``
    (``R + C_em``), or ``R + a(theta) C_em`` (:func:`enkf.hetero.emulated_deviance`)."""
    if heteroscedastic:
        return emulated_deviance(em, R, C_em(), X_keep, lo, hi)[0]
    L = linalg.cholesky(C, lower=True)

    def chi2(P, y):
        w = linalg.solve_triangular(L, (em(np.atleast_2d(P)) - y).T, lower=True)
        return np.sum(w * w, axis=0)
    return chi2


def self_calibration(X, Y, latest, obs_error: ObservationError, *, lower, upper, smoothing: float,
                     error_model: Callable[[np.ndarray], ObservationError], rng: RngLike,
                     search_points: int = 1000, heteroscedastic: bool = False, pseudo=None,
                     tempering: str = "power", keep_runs: list | None = None) -> dict:
    """``lambda`` and its evidence (module docstring).

    X, Y : (k, n) / (k, m) every run of the emulator's design; ``latest`` (k,) bool: the runs used as
        pseudo-data (and where each left-out emulator measures its error, as the analysis does).
    obs_error : the likelihood's covariance besides ``C_em`` (``R``, and ``D`` for measured data), drawn
        onto each run: the pseudo-data follow the analysis' own data model.
    smoothing : the analysis' RBF smoothing (kept fixed: choosing it anew per run would be another fit).
    error_model : ``residuals (j, m) -> C_em``, the analysis' model of the emulator's error.
    search_points : size of the Latin hypercube each minimum is searched from.
    heteroscedastic : the likelihood with ``C_em`` scaled by the runs' local misfit
        (:mod:`enkf.hetero`); ``delta`` is then the deviance's (log-determinant included).
    pseudo : (k,) bool, other runs as the pseudo-data (default ``latest``; ``C_em`` is still measured at
        ``latest``), e.g. the prior's hypercube for truths from the whole box
        (``studies/posterior_candidates.py``).
    tempering : the form ``lambda`` widens the likelihood in (:mod:`enkf.ces`): ``power`` divides
        ``delta`` by it; ``curvature`` brings each run's parameters ``sqrt(lambda)`` times closer to its
        likelihood's maximum, and ``lambda`` is the least for which the median ``delta`` is the reference.
    keep_runs : a list that receives ``(theta_i, deviance_i)`` of each pseudo-run, ``deviance_i(P)`` its
        ``-2 log`` likelihood on its own emulator (:func:`pseudo_pits` reads them).
    """
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    latest = np.asarray(latest, bool)
    pseudo = latest if pseudo is None else np.asarray(pseudo, bool)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    n = lo.size
    rng = as_generator(rng)
    idx = np.flatnonzero(pseudo)
    if idx.size < 3 or X.shape[0] - 1 < n + 2:
        raise ValueError(f"self-calibration needs at least 3 pseudo-data runs and {n + 3} runs; got {idx.size} "
                         f"and {X.shape[0]}")
    starts = np.vstack([latin_hypercube(lo, hi, search_points, rng), X[latest]])
    if tempering not in TEMPERINGS:
        raise ValueError(f"tempering must be one of {TEMPERINGS}, got {tempering!r}")
    deltas, stretched, R = [], [], obs_error.dense()
    for i, em, C, y in pseudo_runs(X, Y, latest, obs_error, lower=lo, upper=hi, smoothing=smoothing,
                                   error_model=error_model, rng=rng, pseudo=pseudo):
        keep = np.arange(X.shape[0]) != i
        dev = _deviance(em, C, R, lambda em=em, keep=keep: error_model(em.loo_residuals()[latest[keep]]).dense(),
                        X[keep], lo, hi, heteroscedastic)

        def chi2(P, dev=dev, y=y):
            return dev(P, y)

        if keep_runs is not None:
            keep_runs.append((X[i].copy(), chi2))
        least, at = box_minimum(chi2, lo, hi, starts)
        deltas.append(max(0.0, float(chi2(X[i])[0]) - least))
        stretched.append(lambda lam, chi2=chi2, x=X[i], at=at, least=least:
                         max(0.0, float(chi2(at + (x - at) / np.sqrt(lam))[0]) - least))
    deltas = np.array(deltas)
    if tempering == "power":
        lam = max(1.0, float(np.median(deltas) / stats.chi2.median(n)))
        adjusted = deltas / lam
    else:
        lam = _curvature_lambda(stretched, stats.chi2.median(n))
        adjusted = np.array([f(lam) for f in stretched])
    return {"lambda": lam, "tempering": tempering, "runs": int(idx.size),
            "median_delta_chi2": float(np.median(deltas)), "reference_median": float(stats.chi2.median(n)),
            "fraction_inside_90": float(np.mean(deltas <= stats.chi2.ppf(0.90, n))),
            "fraction_inside_90_at_lambda": float(np.mean(adjusted <= stats.chi2.ppf(0.90, n))),
            "delta_chi2": deltas.tolist()}


def _curvature_lambda(stretched, reference: float) -> float:
    """The least ``lambda >= 1`` at which the median over the pseudo-runs of ``delta_i(lambda)``, run
    ``i``'s deviance at its own parameters brought ``sqrt(lambda)`` times closer to its maximum, is
    ``reference`` (bisection in ``log lambda``, at most :data:`LAMBDA_MAX`; ``delta_i`` falls as
    ``lambda`` grows)."""
    def excess(lam):
        return float(np.median([f(lam) for f in stretched])) - reference

    if excess(1.0) <= 0.0:
        return 1.0
    lo, hi = 0.0, math.log(LAMBDA_MAX)
    if excess(LAMBDA_MAX) > 0.0:
        return LAMBDA_MAX
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(math.exp(mid)) > 0.0 else (lo, mid)
    return math.exp(hi)


def pseudo_pits(pseudo, lam: float, points) -> tuple[np.ndarray, np.ndarray]:
    """``(pits, ess)``: ``pits`` (runs, n) the probability integral transform of each pseudo-run's own
    parameters under its own power-tempered posterior ``exp(-deviance_i / (2 lam))`` with the box prior,
    read on ``points`` (N, n) spread evenly over the box (a quasi-random grid: each point's weight is
    its density), and ``ess`` (runs,) the effective number of points behind each. When the reported
    posterior is calibrated these PITs are uniform; their mean probit is how far its location is off
    (Kuleshov et al. 2018's quantile recalibration). Read off the reported posterior's own sample instead
    (importance weights), a pseudo-run whose posterior sits in that sample's tail rests on a handful of
    draws."""
    points = np.asarray(points, float)
    pits, ess = [], []
    for x, deviance in pseudo:
        dev = deviance(points)
        w = np.exp(-0.5 * (dev - dev.min()) / lam)
        w /= w.sum()
        pits.append([float(np.sum(w[points[:, j] < x[j]]) + 0.5 * np.sum(w[points[:, j] == x[j]]))
                     for j in range(points.shape[1])])
        ess.append(1.0 / float(np.sum(w * w)))
    return np.array(pits), np.array(ess)


def location_shift(pits: np.ndarray) -> np.ndarray:
    """``mu`` (n,): the mean probit of the pseudo-runs' PITs (``pits`` (runs, n)) per parameter."""
    return stats.norm.ppf(np.clip(np.asarray(pits, float), PIT_CLIP, 1.0 - PIT_CLIP)).mean(axis=0)


def recalibrated(samples, mu) -> np.ndarray:
    """The draws moved, parameter by parameter and in their order (so the joint's dependence stays), so
    that the quantile at level ``q`` of parameter ``j`` is the original's at ``Phi(mu_j + Phi^-1(q))``."""
    samples = np.asarray(samples, float)
    out = np.empty_like(samples)
    u = (np.arange(samples.shape[0]) + 0.5) / samples.shape[0]
    for j in range(samples.shape[1]):
        order = np.argsort(samples[:, j], kind="stable")
        # Hazen's plotting positions: at mu = 0 each draw maps onto itself
        out[order, j] = np.quantile(samples[:, j], stats.norm.cdf(mu[j] + stats.norm.ppf(u)), method="hazen")
    return out
