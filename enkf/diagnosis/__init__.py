"""Diagnosis of a calibrated model's residual and the choice of model extensions ("effects").

Generic: it sees residual vectors, sensitivities (Jacobian columns, finite-difference or ensemble
estimates), candidate names and null values; it knows nothing about FDEM or SHPB. Conventions:

* residual ``r = obs - sim`` (data minus model), whitened ``w = L^{-1} r`` with the observation error
  model ``R = L L^T`` (:mod:`enkf.covariance`); under a correct model and correct ``R``, ``w`` is
  standard white noise.
* sensitivities ``S = d sim / d theta`` (``m x n``, one column per parameter, the caller's parameter
  units or the unbounded ones; only spans and ratios matter), whitened ``L^{-1} S``.

Steps (issue 8, "Diagnosis"), one module each: :mod:`.structure` (1-2), :mod:`.ranking` (3),
:mod:`.acceptance` and :mod:`.loop` (4), :mod:`.report` (5):

1. :func:`whitened_residual`.
2. :func:`structure_tests`: chi-square (``|w|^2`` against ``chi2(m - n_params)``, upper tail), the
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
3. :func:`score_test` / :func:`rank_candidates`: with ``P`` the projector onto the orthogonal complement
   of the whitened base sensitivities' span, the score (Lagrange-multiplier) statistic of a candidate
   with whitened sensitivity columns ``C`` (``k`` parameters) at its null is::

       T = (C^T P w)^T (C^T P C)^{-1} (C^T P w)   ~ chi2(k) under the null           (k = 1: (w^T P c)^2 / c^T P c)

   the squared length of the residual's projection on the candidate's new directions. It is the
   drop in chi-square a linearised re-fit with the candidate would give; the Gauss-Newton step from
   the null is ``(C^T P C)^{-1} C^T P w``. Collinearity with the base: ``1 - lambda_min`` where
   ``lambda_min`` is the smallest eigenvalue of ``Q_c^T P Q_c`` (``Q_c`` an orthonormal basis of ``C``),
   i.e. ``cos^2`` of the smallest principal angle between the candidate's and the base's spans; for
   one column ``1 - |P c|^2 / |c|^2``. "Explained excess" = ``(T - k) / (|P w|^2 - (m - rank))``, the
   fraction of the residual energy above its noise expectation the candidate accounts for.
4. :func:`bic` with :func:`effective_sample_size`, :func:`accept_effect`, and the driver
   :func:`diagnose_loop` (score-rank, re-calibrate, accept or stop). The score test is local: where
   the curve responds sharply and nonlinearly (a failure peak whose time moves with the strength),
   the linearised share of the residual a candidate explains can be a few percent although the
   re-calibrated model explains nearly all of it. The loop therefore screens by significance only and
   judges "how much it explains" after re-calibration: the drop in chi-square as a fraction of the
   residual's excess over its noise expectation (the criterion that keeps a candidate which merely
   projects a sliver of an out-of-catalogue structure from being claimed).
5. :func:`report_to_json` and :func:`write_report` (tables, JSON and plots for
   ``results/<experiment>/diagnosis/``).

The frozen protocol (issue 32), which replaces steps 3-4's gates where a held-out record must stay
unread: :mod:`.population` (the population of a per-record effect, :func:`fit_population`),
:mod:`.crossval` (leave-one-calibration-record-out cross-validation, :func:`cross_validate`, and the test
of a difference of cross-validated errors, :func:`compare_cv`, :func:`squared_error_difference`),
:mod:`.protocol` (:func:`select_effects`, :func:`confirm_additions`, :func:`heldout_evaluation`,
:func:`leave_one_record_out`).

BIC: ``BIC = chi2_min + k ln(n_eff)`` where ``chi2_min = |L^{-1}(obs - sim)|^2`` is ``-2 ln L`` up to a
constant for Gaussian errors with covariance ``R``, ``k`` the number of calibrated parameters, and
``n_eff`` the effective number of independent observations, so that the penalty (``ln det`` of the
Fisher information, Schwarz's derivation) is not overstated for a correlated dense curve. For an error
model ``R`` the exact value for a common level is ``n_eff = 1^T C^{-1} 1`` with ``C`` the correlation
matrix, computed as ``|L^{-1} sigma|^2``; for AR(1) with lag-one correlation ``rho_1`` it is
``(m - (m - 2) rho_1) / (1 + rho_1) ~ m (1 - rho_1) / (1 + rho_1)``. From a residual, the AR(1)
formula with its sample ``rho_1`` (clipped at 0).
"""


from __future__ import annotations

from .crossval import (CVResult, Fit, ForwardModel, ModelSpec, Prediction, RecordErrors, calibrate, compare_cv,
                       cross_validate, fit_populations, holm, predict_record, squared_error_difference)
from .population import Population, fit_population, record_name, split_name
from .protocol import ModelStep, Selection, confirm_additions, heldout_evaluation, leave_one_record_out, select_effects
from .acceptance import accept_effect, bic, curve_errors, effective_sample_size, pinned_at_bounds
from .loop import VERDICTS, CalibrationResult, Candidate, diagnose_loop
from .ranking import chi2_log10_sf, ensemble_sensitivity, finite_difference_sensitivity, rank_candidates, score_test
from .report import report_to_json, write_report
from .structure import (autocorrelation, covariate_trends, default_windows, durbin_watson, ljung_box, runs_test,
                        spearman_exact, structure_tests, whitened_residual)

__all__ = ["VERDICTS", "CalibrationResult", "Candidate", "accept_effect", "autocorrelation", "bic", "chi2_log10_sf",
           "covariate_trends", "curve_errors", "default_windows", "diagnose_loop", "durbin_watson",
           "effective_sample_size", "ensemble_sensitivity", "finite_difference_sensitivity", "ljung_box",
           "pinned_at_bounds", "rank_candidates", "report_to_json", "runs_test", "score_test", "spearman_exact",
           "structure_tests", "whitened_residual", "write_report"]
# the frozen protocol (issue 32): population of per-record effects, cross-validated selection, confirmation
__all__ += ["CVResult", "Fit", "ForwardModel", "ModelSpec", "ModelStep", "Population", "Prediction", "RecordErrors",
            "Selection", "calibrate", "compare_cv", "confirm_additions", "cross_validate", "fit_population",
            "fit_populations", "heldout_evaluation", "holm", "leave_one_record_out", "predict_record",
            "record_name", "select_effects", "split_name", "squared_error_difference"]
