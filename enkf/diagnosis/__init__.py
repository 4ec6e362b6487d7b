"""Diagnosis of a calibrated model's residual and the choice of model extensions ("effects").

Generic: it sees residual vectors, sensitivities (Jacobian columns, finite-difference or ensemble
estimates), candidate names and null values; it knows nothing about FDEM or SHPB. Conventions:

* residual ``r = obs - sim`` (data minus model), whitened ``w = L^{-1} r`` with the observation error
  model ``R = L L^T`` (:mod:`enkf.covariance`); under a correct model and correct ``R``, ``w`` is
  standard white noise.
* sensitivities ``S = d sim / d theta`` (``m x n``, one column per parameter, the caller's parameter
  units or the unbounded ones; only spans and ratios matter), whitened ``L^{-1} S``.

Three parts:

1. Structure (:mod:`.structure`): is the residual white noise? :func:`whitened_residual`, and
   :func:`structure_tests`: chi-square (``|w|^2`` against ``chi2(m - n_params)``, upper tail), the
   Wald-Wolfowitz runs test on the signs of ``w`` (normal approximation, two-sided), the Ljung-Box
   portmanteau ``Q = m (m + 2) sum_{k=1}^{h} rho_k^2 / (m - k)`` against ``chi2(h)`` with the lag
   ``h = min(10, m // 5)`` by default (Hyndman & Athanasopoulos' rule for non-seasonal series), the
   Durbin-Watson statistic ``DW = sum (w_i - w_{i-1})^2 / sum w_i^2 ~ 2 (1 - rho_1)`` (reported, no
   p-value), and the RMS of ``w`` per named time window (:func:`default_windows`: before arrival,
   rise, peak, post-peak). The residual "passes" when the three p-values all exceed ``alpha / 3``
   (Bonferroni: ``alpha``, default 0.01, is the family-wise false-alarm rate; three separate 1% tests
   would flag about 3.4% of white-noise records, measured over 5,000 seeds of length 300).
   :func:`covariate_trends`: across records, a statistic (mean residual, a fitted parameter) against
   a covariate such as the strain rate (least-squares slope, Pearson and Spearman tests).
2. Ranking (:mod:`.ranking`): :func:`score_test` / :func:`rank_candidates`, used only to order the
   candidates the protocol tries (linearised and in-sample: never a gate). With ``P`` the projector
   onto the orthogonal complement of the whitened base sensitivities' span, the score
   (Lagrange-multiplier) statistic of a candidate with whitened sensitivity columns ``C`` (``k``
   parameters) at its null is::

       T = (C^T P w)^T (C^T P C)^{-1} (C^T P w)   ~ chi2(k) under the null           (k = 1: (w^T P c)^2 / c^T P c)

   the squared length of the residual's projection on the candidate's new directions. It is the
   drop in chi-square a linearised re-fit with the candidate would give; the Gauss-Newton step from
   the null is ``(C^T P C)^{-1} C^T P w``. Collinearity with the base: ``1 - lambda_min`` where
   ``lambda_min`` is the smallest eigenvalue of ``Q_c^T P Q_c`` (``Q_c`` an orthonormal basis of ``C``),
   i.e. ``cos^2`` of the smallest principal angle between the candidate's and the base's spans; for
   one column ``1 - |P c|^2 / |c|^2``. "Explained excess" = ``(T - k) / (|P w|^2 - (m - rank))``, the
   fraction of the residual energy above its noise expectation the candidate accounts for.
3. The frozen protocol (issue 32), which chooses effects with every held-out record unread until the
   end: :mod:`.population` (the population of a per-record effect, :func:`fit_population`: how an unseen
   record's value is predicted), :mod:`.crossval` (leave-one-calibration-record-out cross-validation,
   :func:`cross_validate`, and the test of a difference of cross-validated errors, :func:`compare_cv`,
   :func:`squared_error_difference`; on replicated real runs :func:`compare_replicated`), :mod:`.protocol` (:func:`select_effects`, :func:`confirm_additions`,
   :func:`heldout_evaluation`, :func:`leave_one_record_out`), and the errors it reports,
   :func:`curve_errors` (:mod:`.acceptance`). Each round's chosen effect comes with its group
   (:mod:`.identification`): the candidates the calibration records do not tell apart from it.
"""


from __future__ import annotations

from .crossval import (CVResult, Fit, ForwardModel, ModelSpec, Prediction, RecordErrors, calibrate, compare_cv,
                       compare_replicated, cross_validate, fit_populations, given_fit, holm, predict_record,
                       box_draws, squared_error_difference)
from .population import Population, fit_population, record_name, split_name
from .protocol import (ModelStep, Selection, confirm_additions, heldout_evaluation, leave_one_record_out,
                       real_identification, replicated, select_effects, walk_weights)
from .acceptance import curve_errors, replicate_curve_errors
from .identification import group_text, identification_group
from .ranking import chi2_log10_sf, ensemble_sensitivity, finite_difference_sensitivity, rank_candidates, score_test
from .structure import (autocorrelation, covariate_trends, default_windows, durbin_watson, ljung_box, runs_test,
                        spearman_exact, structure_tests, whitened_residual)

__all__ = ["autocorrelation", "chi2_log10_sf", "covariate_trends", "curve_errors", "default_windows", "durbin_watson",
           "ensemble_sensitivity", "finite_difference_sensitivity", "ljung_box", "rank_candidates",
           "replicate_curve_errors", "runs_test", "score_test", "spearman_exact", "structure_tests", "whitened_residual"]
# the frozen protocol (issue 32): population of per-record effects, cross-validated selection, confirmation
__all__ += ["CVResult", "Fit", "ForwardModel", "ModelSpec", "ModelStep", "Population", "Prediction", "RecordErrors",
            "Selection", "calibrate", "compare_cv", "compare_replicated", "confirm_additions", "cross_validate", "fit_population",
            "fit_populations", "given_fit", "heldout_evaluation", "holm", "leave_one_record_out", "predict_record",
            "box_draws", "real_identification", "record_name", "replicated", "select_effects", "split_name", "squared_error_difference",
            "walk_weights"]
# identification: the group of candidates the calibration records do not tell apart from the chosen one
__all__ += ["group_text", "identification_group"]
