"""Posterior-predictive checks: does the reported posterior, with every error term, cover its data?

The predictive distribution of the observations is sampled as ``y_i + e`` with ``y_i`` a posterior
member's response and ``e ~ N(0, C)`` a draw of the full error model ``C`` (instrument noise, model
discrepancy, simulator variability: whatever the caller composed). The central ``level`` band of those
samples at each observation is the predictive band; the coverage is the fraction of observations
inside it. A calibrated posterior with an honest error model covers about ``level`` of its own data
(a little more, as the data helped choose the members); a posterior that ignores model error covers
a few per cent on measured data.
"""

from __future__ import annotations

import numpy as np

from ._rng import RngLike, as_generator
from .covariance import ObservationError
from .diagnostics import alive_mask

__all__ = ["predictive_band", "predictive_coverage"]


def predictive_band(responses, error: ObservationError, rng: RngLike, level: float = 0.9,
                    n_samples: int = 4000, alive=None) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)`` of the central ``level`` predictive band, from ``n_samples`` draws spread
    evenly over the alive members (rows of ``responses``)."""
    if not 0.0 < level < 1.0:
        raise ValueError("level must lie in (0, 1)")
    Y = np.atleast_2d(np.asarray(responses, float))
    ok = alive_mask(Y, alive)
    if not np.any(ok):
        raise ValueError("no alive member to build a predictive band from")
    Ya = Y[ok]
    per = max(1, int(np.ceil(n_samples / Ya.shape[0])))
    draws = np.repeat(Ya, per, axis=0) + error.sample(as_generator(rng), per * Ya.shape[0])
    q = 0.5 * (1.0 - level)
    return np.quantile(draws, q, axis=0), np.quantile(draws, 1.0 - q, axis=0)


def predictive_coverage(responses, obs, error: ObservationError, rng: RngLike, level: float = 0.9,
                        groups=None, alive=None, n_samples: int = 4000, n_replicates: int = 0) -> dict:
    """``{"all": fraction, "groups": {label: fraction}}`` of the observations inside the band.

    ``n_replicates > 0`` adds ``"reference"``: per group, the 5 % and 95 % quantiles of the same
    fraction for data sets drawn from the predictive distribution itself (a random member plus an
    error draw). Where the error is correlated over much of the record, a record holds few independent
    pieces of information and even a correct model's coverage fraction scatters widely around
    ``level``; the reference says how widely, so the observed fraction can be judged (a
    posterior-predictive check with the coverage as its statistic).
    """
    gen = as_generator(rng)
    d = np.asarray(obs, float)
    lo, hi = predictive_band(responses, error, gen, level, n_samples, alive)
    inside = (d >= lo) & (d <= hi)
    g = np.zeros(d.size, int) if groups is None else np.asarray(groups)
    labels = list(dict.fromkeys(g.tolist()))
    per = {lab: float(np.mean(inside[g == lab])) for lab in labels}
    out = {"all": float(np.mean(inside)), "groups": per, "level": level}
    if n_replicates > 0:
        Y = np.atleast_2d(np.asarray(responses, float))
        ok = alive_mask(Y, alive)
        pick = gen.choice(np.flatnonzero(ok), n_replicates)
        rep = Y[pick] + error.sample(gen, n_replicates)
        rin = (rep >= lo) & (rep <= hi)
        out["reference"] = {lab: np.quantile(np.mean(rin[:, g == lab], axis=1), [0.05, 0.95]).tolist()
                            for lab in labels}
    return out
