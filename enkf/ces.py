"""Calibrate-emulate-sample: the reported posterior as an MCMC sample of the emulator's posterior.

Why: an ensemble smoother's ensemble is a Gaussian-linear approximation of the posterior. For the
disc's step-like, rugged response its spread is not a calibrated interval (the project's seed sweep:
the 90 % intervals of the emulator-assisted ES-MDA covered the truth in 7/9 and 5/9 twins). The
simulated runs are kept, so once the loop has put its last ensemble where the posterior is, the
posterior itself can be sampled on the emulator of all runs (Cleary et al. 2021, "Calibrate, emulate,
sample"):

    p(theta | d)  ~  1[theta in box]  N(d; f_em(theta), R + C_em)

with ``f_em`` the interpolating emulator of every successful run (:class:`enkf.emulator.CurveEmulator`),
``R`` the observation error and ``C_em`` the emulator's error measured by leave-one-out refits at the
runs of the last iteration (where the posterior is), per time with AR(1) correlation
(:func:`enkf.emulated.emulator_error_model`). ``C_em`` also carries the simulator's own ruggedness (the
scatter of neighbouring runs), so the intervals admit what no smooth model can fit. The prior is the
uniform box of the calibration (the LHS prior). With ``heteroscedastic`` the emulator's error is
``a(theta) C_em``, scaled by the runs' own local misfit (:mod:`enkf.hetero`): the simulator's
scatter differs across the box.

The self-calibration's factor ``lambda`` (:mod:`enkf.selfcal`) widens the likelihood in one of two ways
(``tempering``). ``power``: the log-likelihood divided by ``lambda`` (a generalized posterior's learning
rate, Syring & Martin 2019). ``curvature``: the likelihood's shape kept and stretched by ``sqrt(lambda)``
about its maximum ``theta_hat`` in the box, ``L(theta_hat + (theta - theta_hat) / sqrt(lambda))`` (the
curvature adjustment of Chandler & Bate 2007 and Ribatet et al. 2012). Both widen a quadratic
log-likelihood alike; they part where it is not quadratic. The disc's likelihood rises steeply towards
low ``sigma_t`` (the specimen fails early and the whole post-peak moves) and slowly towards high: the
power form flattens that slow side into a long tail, so the median moves away from the maximum (on
development twins ``sigma_t``'s median sat 2-4 % above the truth with it and at the truth without the
factor: ``studies/tempering_forms.py``); the curvature form keeps the tail as long, relative to the
width, as the untempered likelihood's. Stretching about ``theta_hat`` maps the box into itself, so the
emulator is never asked outside it. The power form is the reported one: on the same development twins
the curvature form removed the shift but doubled ``sigma_t``'s interval score, because where the curve
is still rising at the window's end the likelihood's maximum can sit on a spurious mode, and a posterior
stretched about it misses the truth by far.

Sampler: ``emcee``'s affine-invariant ensemble sampler (Foreman-Mackey et al. 2013), in unit-box
coordinates (so no parameter's units dominate), walkers started from the last ensemble. The chain is
checked, not trusted: the integrated autocorrelation time ``tau`` is estimated and the run is extended
until it is at least ``min_tau_multiple`` times the longest ``tau`` (emcee's guidance: 50); the burn-in
of ``burn_tau`` x ``tau`` steps is dropped and the chain thinned by ``tau / 2``. The diagnostics
(acceptance, tau, effective samples) go into the result.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import linalg

from ._rng import RngLike, as_generator
from .covariance import DenseError, ObservationError
from .diagnostics import default_names, jsonable
from .emulated import emulator_error_model
from .emulator import design_arrays, smoothed_emulator
from .hetero import emulated_deviance
from .sampling import latin_hypercube
from .scores import QUANTILES, expected_score_over_prior
from .selfcal import (RECALIBRATIONS, TEMPERINGS, box_minimum, location_shift, pseudo_pits, recalibrated,
                      self_calibration)

__all__ = ["EmulatorPosterior", "emulator_posterior", "interval_summary", "QUANTILES", "RECALIBRATIONS",
           "TEMPERINGS"]



def interval_summary(samples, names: Sequence[str], lower=None, upper=None) -> dict:
    """``{param: {mean, std, q05, q25, q50, q75, q95}}`` of samples ``(S, n)``; with the prior box
    (``lower``, ``upper``) also ``score_over_prior``, the score the sample expects over the prior's
    (:func:`enkf.scores.expected_score_over_prior`)."""
    S = np.asarray(samples, float)
    out = {}
    for j, name in enumerate(names):
        col = S[:, j]
        out[name] = {"mean": float(col.mean()), "std": float(col.std(ddof=1)),
                     **{k: float(np.quantile(col, q)) for k, q in QUANTILES.items()}}
        if lower is not None:
            out[name]["score_over_prior"] = expected_score_over_prior(col, lower[j], upper[j])
    return out


class EmulatorPosterior:
    """``samples`` (S, n) of the emulator posterior, their ``summary`` and the sampler ``diagnostics``."""

    def __init__(self, samples: np.ndarray, names: Sequence[str], diagnostics: dict, lower=None, upper=None):
        self.samples = samples
        self.names = list(names)
        self.diagnostics = diagnostics
        self.lower, self.upper = lower, upper

    @property
    def summary(self) -> dict:
        return interval_summary(self.samples, self.names, self.lower, self.upper)

    def to_dict(self) -> dict:
        return jsonable({"posterior": self.summary, **self.diagnostics})


def _loglik(em, obs_error, emu_err, X, lo, hi, d, heteroscedastic: bool, emu_info: dict, scale: float = 1.0):
    """``P (k, n) -> (log L + const) / scale`` of the emulated likelihood, vectorised over points (written
    as the power form always computed it, so that its arithmetic is unchanged)."""
    if heteroscedastic:
        deviance, het = emulated_deviance(em, obs_error.dense(), emu_err.dense(), X, lo, hi)
        emu_info["heteroscedastic"] = het.describe()
        return lambda P: -0.5 * deviance(P, d) / scale
    C = DenseError(scale * (obs_error.dense() + (0.0 if emu_err is None else emu_err.dense())), _symmetric=True)
    # L^-1 once: the likelihood is then one matrix product per batch of walkers (a triangular solve
    # per call costs more in SciPy's wrapper than the product)
    Linv_T = linalg.solve_triangular(C.cholesky, np.eye(C.m), lower=True).T

    def loglik(P):
        w = (em(np.atleast_2d(P)) - d) @ Linv_T
        return -0.5 * np.einsum("ij,ij->i", w, w)
    return loglik


def _tempered(loglik, lam: float, tempering: str, lo, hi, starts):
    """``(loglik, theta_hat)``: the log-likelihood widened by ``lam`` (module docstring); ``loglik(scale)``
    the likelihood's ``P -> log L / scale``; ``theta_hat`` the untempered likelihood's maximum in the box
    for ``curvature`` (None for ``power``), searched from ``starts()`` (drawn only here, so that the power
    form's random stream is what it was)."""
    if tempering == "power" or lam == 1.0:
        return loglik(lam), None
    base = loglik(1.0)
    _, theta_hat = box_minimum(lambda P: -2.0 * base(P), lo, hi, starts())
    shrink = 1.0 / math.sqrt(lam)
    return (lambda P: base(theta_hat + (P - theta_hat) * shrink)), theta_hat


#: points of the quasi-random grid on which each pseudo-run's posterior is read (``recalibrate``): 2^14,
#: about the 121 x 121 grid of studies/pit_recalibration.py for two parameters
RECALIBRATION_POINTS = 2**14


def _location_recalibrated(samples, pseudo, lam: float, lo, hi, rng, names, emu_info: dict) -> np.ndarray:
    """The sample moved by the pseudo-runs' mean PIT probit (``recalibrate: location``); the evidence into
    ``emu_info``'s self-calibration record."""
    from scipy.stats import qmc

    points = qmc.scale(qmc.Sobol(lo.size, scramble=True, seed=rng).random(RECALIBRATION_POINTS), lo, hi)
    pits, ess = pseudo_pits(pseudo, lam, points)
    mu = location_shift(pits)
    emu_info["self_calibration"]["recalibration"] = {
        "form": "location", "mu": dict(zip(names, mu.tolist())),
        "pit_mean": dict(zip(names, pits.mean(axis=0).tolist())), "points": RECALIBRATION_POINTS,
        "effective_points_median": float(np.median(ess)), "effective_points_min": float(np.min(ess))}
    return recalibrated(samples, mu)


def _check_forms(temper: float, tempering: str, recalibrate: str, self_calibrate: bool, emulator_error: bool):
    if not temper >= 1.0:
        raise ValueError(f"temper must be at least 1, got {temper}")
    if tempering not in TEMPERINGS:
        raise ValueError(f"tempering must be one of {TEMPERINGS}, got {tempering!r}")
    if recalibrate not in RECALIBRATIONS:
        raise ValueError(f"recalibrate must be one of {RECALIBRATIONS}, got {recalibrate!r}")
    if recalibrate != "none" and not (self_calibrate and emulator_error and tempering == "power"):
        raise ValueError("recalibrate reads the self-calibration's pseudo-runs under the power form: it needs "
                         "self_calibrate, emulator_error and tempering 'power'")


def emulator_posterior(design_params, design_responses, latest, obs, obs_error: ObservationError, *,
                       lower, upper, times, groups=None, rng: RngLike, start=None,
                       names: Sequence[str] | None = None, walkers: int = 32, min_steps: int = 2000,
                       max_steps: int = 40000, min_tau_multiple: float = 50.0, burn_tau: float = 5.0,
                       emulator_error: bool = True, smoothing="loo", loo_scale=None,
                       self_calibrate: bool = False, heteroscedastic: bool = False,
                       temper: float = 1.0, tempering: str = "power",
                       recalibrate: str = "none") -> EmulatorPosterior:
    """Sample ``p(theta | d)`` on the emulator of every run (module docstring).

    design_params, design_responses : (k, n) / (k, m) every successful run so far (finite curves).
    latest : (k,) bool, the runs of the last iteration: where the emulator's error is measured.
    obs, obs_error : the observations and ``R``. times, groups : their times and record labels.
    lower, upper : the prior box. start : (N, n) points inside the box to start the walkers from
        (default: the latest runs); ``walkers`` of them are drawn with replacement and jittered.
    emulator_error : add ``C_em`` to ``R`` (False only to test the sampler on an exact emulator).
    smoothing : the RBF smoothing, or ``"loo"``: the value of ``enkf.emulator.SMOOTHING_GRID`` with the
        least leave-one-out error at the latest runs, each time divided by ``loo_scale`` (m,) where given
        (as the emulated ES-MDA does, :func:`enkf.emulator.smoothed_emulator`).
    self_calibrate : scale ``R + C_em`` by the factor the latest runs ask for as pseudo-data of known
        parameters (:func:`enkf.selfcal.self_calibration`; needs ``emulator_error``).
    heteroscedastic : ``C_em`` scaled by ``a(theta)``, the runs' local leave-one-out misfit
        (:class:`enkf.hetero.HeteroscedasticError`; the log-determinant enters the likelihood, and with
        ``self_calibrate`` the whole log-likelihood is divided by ``lambda``: a learning rate).
    temper : the likelihood widened by this factor besides ``lambda``: a tempered posterior, wider
        than the reported one (where :func:`enkf.refine.refinement_design` puts the refinement runs).
    tempering : how ``lambda * temper`` widens the likelihood: ``"power"`` or ``"curvature"`` (module
        docstring).
    recalibrate : ``"location"``: the sample moved so that each parameter's quantile at level ``q`` is the
        tempered posterior's at ``Phi(mu + Phi^-1(q))``, ``mu`` the mean probit of the self-calibration's
        pseudo-runs' PITs under their own posteriors (:func:`enkf.selfcal.pseudo_pits`): the same runs
        that set the width set the location (needs ``self_calibrate`` and the power form).
    """
    _check_forms(temper, tempering, recalibrate, self_calibrate, emulator_error)
    X, Y, latest, d = design_arrays(design_params, design_responses, latest, obs)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    n = lo.size
    names = default_names(n, names)
    if walkers < 2 * n or walkers % 2:
        raise ValueError(f"walkers must be even and at least 2 n = {2 * n}, got {walkers}")
    if emulator_error and latest.sum() < 2:
        raise ValueError("the emulator error needs at least 2 runs of the latest iteration")
    import emcee  # a heavy import, needed only here

    rng = as_generator(rng)
    em, smoothing_info = smoothed_emulator(X, Y, lo, hi, names, latest, smoothing, loo_scale)
    emu_info = {"n_residuals": 0}
    if heteroscedastic and not emulator_error:
        raise ValueError("heteroscedastic scales the emulator's error: it needs emulator_error")
    lam, width, emu_err, pseudo = 1.0, hi - lo, None, []
    if emulator_error:
        emu_err, emu_info = emulator_error_model(em.loo_residuals()[latest], times, groups)
        if self_calibrate:
            emu_info["self_calibration"] = self_calibration(
                X, Y, latest, obs_error, lower=lo, upper=hi, smoothing=smoothing_info["smoothing"],
                error_model=lambda r: emulator_error_model(r, times, groups)[0], rng=rng,
                heteroscedastic=heteroscedastic, tempering=tempering,
                keep_runs=pseudo if recalibrate != "none" else None)
            lam = emu_info["self_calibration"]["lambda"]
    lam *= float(temper)
    loglik, theta_hat = _tempered(
        lambda scale: _loglik(em, obs_error, emu_err, X, lo, hi, d, heteroscedastic, emu_info, scale), lam,
        tempering, lo, hi, lambda: np.vstack([latin_hypercube(lo, hi, 1000, rng), X[latest]]))

    def log_prob(U):
        # U: (walkers, n) in the unit box; vectorised over walkers. Outside the box: prior zero.
        U = np.atleast_2d(U)
        lp = np.full(U.shape[0], -np.inf)
        inside = np.all((U >= 0.0) & (U <= 1.0), axis=1)
        if inside.any():
            lp[inside] = loglik(lo + U[inside] * width)
        return lp

    P0 = np.array(X[latest] if start is None else start, float, ndmin=2)
    U0 = (P0 - lo) / width
    if np.any(U0 < 0) or np.any(U0 > 1):
        raise ValueError("the walkers' start points must lie inside the box")
    pick = rng.integers(0, U0.shape[0], walkers)
    spread = np.maximum(U0.std(axis=0), 1e-3)
    init = np.clip(U0[pick] + 0.1 * spread * rng.standard_normal((walkers, n)), 1e-6, 1 - 1e-6)

    sampler = emcee.EnsembleSampler(walkers, n, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**32))).get_state()
    state, steps, tau = init, 0, np.full(n, np.inf)
    chunk = min_steps
    while True:
        state = sampler.run_mcmc(state, chunk, progress=False)
        steps += chunk
        tau = sampler.get_autocorr_time(tol=0)
        if steps >= min_tau_multiple * np.max(tau) or steps >= max_steps:
            break
        chunk = min(steps, max_steps - steps)  # double the chain
    tau_max = float(np.max(tau))
    burn = int(math.ceil(burn_tau * tau_max))
    thin = max(1, int(tau_max / 2))
    if burn >= steps:
        raise RuntimeError(f"the chain of {steps} steps is shorter than its burn-in ({burn}); tau = {tau}")
    U = sampler.get_chain(discard=burn, thin=thin, flat=True)
    samples = lo + U * width
    if recalibrate == "location":
        samples = _location_recalibrated(samples, pseudo, lam, lo, hi, rng, names, emu_info)
    w = obs_error.whiten(em(samples.mean(axis=0))[0] - d)
    diagnostics = {
        "method": "emcee on the emulator (calibrate-emulate-sample)",
        "design_points": int(X.shape[0]), "latest_points": int(latest.sum()),
        "emulator_error": emu_info, "emulator": smoothing_info, "temper": float(temper), "tempering": tempering,
        "likelihood_maximum": None if theta_hat is None else dict(zip(names, theta_hat.tolist())),
        "walkers": walkers, "steps": steps, "burn_in": burn, "thin": thin,
        "autocorr_time": dict(zip(names, tau.tolist())),
        "converged_chain": bool(steps >= min_tau_multiple * tau_max),
        "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
        "n_samples": int(samples.shape[0]),
        "effective_samples": float(walkers * (steps - burn) / tau_max),
        "emulated_mean_chi2_per_obs": float(np.dot(w, w) / d.size),
    }
    return EmulatorPosterior(samples, names, jsonable(diagnostics), lo, hi)
