"""The predictive band of a record the protocol predicts, centred on the real simulator's runs at its
prediction point, and the scores that say whether the band is calibrated and informative.

The data model is ``d = mu(theta) + eta + delta + e`` (:mod:`enkf.variability`). A record predicted at the
point ``theta_0`` (shared parameters at their posterior mean, per-record ones at their population median)
with ``K`` real runs ``y_k = mu(theta_0) + eta_k`` scatters about the runs' mean ``ybar`` by

* ``mu(theta) - mu(theta_0)`` over the posterior members x population draws, read on the emulator
  (``draws - emulated_point``: an emulator bias common to both cancels);
* ``eta - mean_k eta_k``: variance ``S (1 + 1/K)``, ``S`` the simulator's variability;
* ``delta``: the model discrepancy ``D``, read off other records' residuals net of the other terms, the
  per-record values' spread taken from the population's plug-in normal (:func:`plugin_draws`);
* ``e``: the instrument noise ``R``.

The band is pointwise (each time's quantiles), so only the per-time variances of ``S``, ``D`` and ``R``
enter it; their time correlation changes how widely one record's coverage fraction scatters, not its
expectation. Which data may set each term is the caller's rule (calibration.closing: nothing from the
predicted record's own response).

Scores: the coverage (fraction of the observed curve inside) and the interval score of Gneiting &
Raftery (2007, eq. 43) per observation, ``(u - l) + (2/a)(l - y)1{y < l} + (2/a)(y - u)1{y > u}`` with
``a = 1 - level``: a proper score, so a band as wide as the prior's covers but scores no better than it
(:func:`informative`), and a band narrower than its own scatter scores worse where it misses.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..covariance import DiagonalError
from ..predictive import predictive_band
from ..scores import interval_score as _interval_score
from ..variability import SMOOTH_WINDOW, _smooth, smoothed_variance
from .crossval import predict_record

__all__ = ["RunBand", "informative", "interval_score", "plugin_draws", "replicate_variance", "residual_discrepancy",
           "run_band"]

#: The informativeness bar: a band's mean interval score at most this fraction of the prior band's. The
#: loosest of issue 52's bars for a posterior's own interval score over the prior's (0.55, for ``E_t``).
SCORE_RATIO_BAR = 0.55


@dataclass
class RunBand:
    """A pointwise predictive band: ``centre`` (the runs' mean), ``lower``, ``upper`` at ``level``, the rms
    sd of each term (``parts``) and ``replicates`` (K, the runs the centre averages)."""

    centre: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    parts: dict
    replicates: int

    def coverage(self, y) -> float:
        y = np.asarray(y, float)
        return float(np.mean((y >= self.lower) & (y <= self.upper)))

    def width_rms(self) -> float:
        return float(np.sqrt(np.mean((self.upper - self.lower) ** 2)))

    def score(self, y) -> float:
        return interval_score(self.lower, self.upper, y, self.level)

    def summary(self, y) -> dict:
        return {f"predictive_coverage_{round(100 * self.level)}": self.coverage(y),
                "interval_score_Pa": self.score(y), "band_width_rms_Pa": self.width_rms(),
                "replicates": self.replicates, "parts_rms_Pa": dict(self.parts)}


def interval_score(lower, upper, y, level: float) -> float:
    """Mean interval score over the observations (module docstring; units of ``y``)."""
    return float(np.mean(_interval_score(lower, upper, y, 1.0 - float(level))))


def informative(score: float, prior_score: float, bar: float = SCORE_RATIO_BAR) -> bool:
    """Whether a band scores at most ``bar`` of the prior band's interval score on the same curves."""
    return float(score) <= bar * float(prior_score)


def replicate_variance(point_runs: Sequence, window: int = SMOOTH_WINDOW) -> tuple[np.ndarray | None, int]:
    """``(variance per time, degrees of freedom)`` of the real runs' departures from their own point's mean,
    pooled over points (each ``(K, m)``: K runs on K mesh realizations of the record): the simulator's
    variability ``S`` as :func:`enkf.variability.simulator_variability` measures it, with the points' means
    removed. ``(None, 0)`` without two runs at any point."""
    devs, dof = [], 0
    for runs in point_runs:
        Y = np.array(runs, dtype=float, ndmin=2)
        Y = Y[np.all(np.isfinite(Y), axis=1)]
        if Y.shape[0] >= 2:
            devs.append(Y - Y.mean(axis=0))
            dof += Y.shape[0] - 1
    if not dof:
        return None, 0
    dev = np.vstack(devs)
    return smoothed_variance(dev, dof, np.zeros(dev.shape[1], int), window), dof


def plugin_draws(model, spec, fold: Mapping, *, seed: int) -> np.ndarray:
    """The curves of a cross-validated record's prediction (``fold``: :func:`enkf.diagnosis.cross_validate`'s
    fold, its ``fit`` and ``prediction``) with each per-record value drawn from its population's plug-in
    normal, ``N(mu, tau^2 + se(mu)^2)``, instead of the predictive t: what :func:`residual_discrepancy` nets
    out of the record's residual. Why not the t: the residual's expected square holds the value's expected
    squared departure from the point, ``tau^2 + se(mu)^2``; the t's variance is infinite at the one and two
    degrees of freedom of three- and four-record populations, so its draws' variance is set by the box
    that clips them, and ``D`` read net of it comes out near zero. The band still draws from the t (its
    quantiles carry the uncertainty of ``tau``)."""
    pred = fold["prediction"]
    if not spec.per_record:
        return np.asarray(pred.draws, float)
    normal = {p: pop.plugin() for p, pop in pred.populations.items()}
    return np.asarray(predict_record(model, spec, fold["fit"], pred.record, normal, seed=seed).draws, float)


def residual_discrepancy(residuals: Sequence, counted: Sequence, window: int) -> np.ndarray:
    """Per-time variance of the model discrepancy ``D`` read off other records' residuals: ``residuals[i]``
    (m,) a record's data less the mean of its real runs at a point fitted without it (its cross-validation
    point), ``counted[i]`` (m,) the variance the band's other terms already give that residual (parameters,
    their per-record values from the plug-in population, :func:`plugin_draws`; simulator ``S (1 + 1/K)``;
    noise). The mean over records of ``residual^2 - counted``, averaged over
    ``window`` neighbouring times and floored at zero: ``D`` where the model errs (the toe, the peak, the
    post-peak), none where it does not (before the wave arrives)."""
    E = np.array(residuals, dtype=float, ndmin=2)
    C = np.array(counted, dtype=float, ndmin=2)
    if E.shape != C.shape:
        raise ValueError(f"residuals {E.shape} and counted variances {C.shape}: one row per record, one grid")
    raw = np.mean(E ** 2 - C, axis=0)
    return np.maximum(_smooth(raw, np.zeros(raw.size, int), int(window)), 0.0)


def run_band(draws, emulated_point, runs, variances: Mapping[str, np.ndarray], *, rng, level: float = 0.90,
             n_samples: int = 4000) -> RunBand:
    """The band of a record predicted at a point (module docstring).

    draws : (N, m) emulated curves of the posterior members x population draws; emulated_point : (m,) the
        emulated curve at the prediction point; runs : (K, m) or (m,) the real runs there.
    variances : per-time variances of the other terms, by name (``simulator`` is taken as ``S`` and
        multiplied by ``1 + 1/K``; every other term is added as given)."""
    Y = np.array(runs, dtype=float, ndmin=2)
    K = Y.shape[0]
    centre = Y.mean(axis=0)
    shifts = np.asarray(draws, float) - np.asarray(emulated_point, float)
    var = np.zeros_like(centre)
    parts = {"parameters": float(np.sqrt(np.mean(np.var(shifts, axis=0))))}
    for name, v in variances.items():
        v = np.asarray(v, float) * ((1.0 + 1.0 / K) if name == "simulator" else 1.0)
        if v.shape != centre.shape or np.any(v < 0):
            raise ValueError(f"{name}: {v.shape} non-negative variances expected, {centre.shape} observations")
        var = var + v
        parts[name] = float(np.sqrt(np.mean(v)))
    sd = np.sqrt(var)
    # DiagonalError needs sd > 0; where no term acts (before the wave arrives, no noise given) a round-off floor
    sd = np.maximum(sd, 1e-12 * max(float(sd.max()), 1.0))
    lo, hi = predictive_band(centre + shifts, DiagonalError(sd), rng, level=level, n_samples=n_samples)
    return RunBand(centre, lo, hi, float(level), parts, K)
