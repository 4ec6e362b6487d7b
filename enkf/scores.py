"""Proper scores of a parameter's reported intervals, and what a posterior expects to score.

The weighted interval score (Bracher et al. 2021, *PLoS Comput. Biol.* 17, e1008618) of the 50 % and
90 % central intervals and the median, ``WIS = (|y - m| / 2 + sum_k alpha_k / 2 IS_alpha_k) / (K + 1/2)``
with the interval score ``IS_alpha = (u - l) + 2 / alpha (l - y)_+ + 2 / alpha (y - u)_+`` (Gneiting &
Raftery 2007, eq. 43): an approximation of the CRPS that rewards sharpness and penalises misses.

A box's uniform prior scores, on truths drawn from the box, ``0.144`` of the box width on average
(:func:`prior_expected_wis`). A posterior expects to score ``E_{y ~ posterior} WIS(its quantiles, y)``
(:func:`expected_wis`): for a calibrated posterior, its mean over many experiments is the mean score it
gets against their truths. The ratio of the two (:func:`expected_score_over_prior`) is therefore what a
coverage benchmark's ``wis_over_prior`` measures, read off one posterior without a truth: 1 for the prior
itself, about ``3.45 sd / width`` for a Gaussian posterior well inside the box. It is how far the data
went beyond the box, and it is the product's test of whether a parameter was learned
(:data:`INFORMATIVE_RATIO`; :mod:`calibration.verdict`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["INFORMATIVE_RATIO", "INTERVALS", "QUANTILES", "expected_score_over_prior", "expected_wis", "interval_score",
           "prior_expected_wis", "prior_quantiles", "weighted_interval_score"]

#: Quantiles reported per parameter: the 90 % and 50 % central intervals and the median.
QUANTILES = {"q05": 0.05, "q25": 0.25, "q50": 0.5, "q75": 0.75, "q95": 0.95}
#: the central intervals of the score: (alpha, lower quantile key, upper quantile key)
INTERVALS = ((0.5, "q25", "q75"), (0.1, "q05", "q95"))
#: A parameter is learned when its posterior expects to score at most this fraction of the prior's: the
#: loosest of issue 52's bars for a posterior's score over the prior's (0.55, for ``E_t``), the same bar
#: as a predictive band's (:data:`enkf.diagnosis.band.SCORE_RATIO_BAR`). For a Gaussian posterior it
#: is a 90 % interval of about 0.53 of the box.
INFORMATIVE_RATIO = 0.55
# truths on which the uniform prior's expected score is averaged (the midpoints of equal cells: exact to
# 1e-6 of the box for this piecewise-quadratic integrand)
_PRIOR_GRID = 4001


def interval_score(lo, hi, y, alpha: float) -> np.ndarray:
    """The interval score of the central ``1 - alpha`` interval ``[lo, hi]`` at the truth ``y``: its
    width plus ``2 / alpha`` times the distance by which the truth falls outside it."""
    lo, hi, y = (np.asarray(v, float) for v in (lo, hi, y))
    return (hi - lo) + 2.0 / alpha * (np.maximum(lo - y, 0.0) + np.maximum(y - hi, 0.0))


def weighted_interval_score(q: Mapping, y, median: float | None = None) -> np.ndarray:
    """WIS of the quantiles ``q`` (``q05, q25, q75, q95``; the median ``median`` or ``q["q50"]``) at the
    truth or truths ``y``."""
    m = float(q["q50"]) if median is None else float(median)
    y = np.asarray(y, float)
    total = 0.5 * np.abs(y - m)
    for alpha, lo, hi in INTERVALS:
        total = total + 0.5 * alpha * interval_score(float(q[lo]), float(q[hi]), y, alpha)
    return total / (len(INTERVALS) + 0.5)


def prior_quantiles(lower: float, upper: float) -> dict:
    """The quantiles of the uniform prior on ``[lower, upper]``."""
    w = float(upper) - float(lower)
    return {k: float(lower) + f * w for k, f in QUANTILES.items()}


def prior_expected_wis(lower: float, upper: float) -> float:
    """The uniform prior's mean WIS over truths drawn from its own box (0.144 of the box width)."""
    lo, hi = float(lower), float(upper)
    y = lo + (hi - lo) * (np.arange(_PRIOR_GRID) + 0.5) / _PRIOR_GRID
    return float(weighted_interval_score(prior_quantiles(lo, hi), y).mean())


def expected_wis(draws) -> float:
    """A posterior's WIS expected under itself: its draws' quantiles scored at the draws."""
    d = np.asarray(draws, float)
    q = {k: float(np.quantile(d, f)) for k, f in QUANTILES.items()}
    return float(weighted_interval_score(q, d).mean())


def expected_score_over_prior(draws, lower: float, upper: float) -> float:
    """:func:`expected_wis` of the draws over :func:`prior_expected_wis` of the box (module docstring)."""
    return expected_wis(draws) / prior_expected_wis(lower, upper)
