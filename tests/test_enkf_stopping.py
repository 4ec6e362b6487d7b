"""Stopping rules and their reasons."""

import json
import math

import numpy as np
import pytest

from enkf import StopCriteria, check_stop

PRIOR = np.array([1.8, 1.8])


def _check(iteration, chi2, nrmse=0.2, spread=(0.5, 0.5), **kw):
    criteria = kw.pop("criteria", StopCriteria())
    return check_stop(iteration, chi2_per_obs=chi2, nrmse=nrmse, n_obs=200, spread=np.array(spread),
                      prior_spread=PRIOR, criteria=criteria, **kw)


def test_default_discrepancy_target_is_two_standard_deviations_of_the_noise_chi_square():
    assert StopCriteria().target(200) == pytest.approx(1.0 + 2.0 * math.sqrt(2.0 / 200))  # 1.2
    assert StopCriteria(chi2_target=1.5).target(200) == 1.5


def test_discrepancy_principle_stops_as_converged():
    d = _check(2, 1.15)
    assert (d.stop, d.converged, d.reason) == (True, True, "discrepancy")
    d = _check(2, 1.25)
    assert (d.stop, d.reason) == (False, "continue")


def test_user_tolerance_on_nrmse_stops_as_converged():
    crit = StopCriteria(nrmse_tol=0.05)
    assert _check(1, 30.0, nrmse=0.049, criteria=crit).reason == "tolerance"
    assert _check(1, 30.0, nrmse=0.051, criteria=crit).reason == "continue"


def test_collapse_guard_stops_without_convergence():
    d = _check(3, 50.0, spread=(0.5, 1.7e-3))  # 1.7e-3 / 1.8 < 1e-3
    assert (d.stop, d.converged, d.reason) == (True, False, "collapse")
    assert "parameter 1" in d.message
    assert _check(3, 50.0, spread=(0.5, 1.9e-3)).reason == "continue"
    # no collapse verdict on the prior ensemble itself
    assert _check(0, 50.0, spread=(0.5, 1e-6)).reason == "continue"


def test_iteration_budget():
    crit = StopCriteria(max_iterations=4)
    assert _check(3, 50.0, criteria=crit).reason == "continue"
    d = _check(4, 50.0, criteria=crit)
    assert (d.stop, d.converged, d.reason) == (True, False, "max_iterations")


def test_convergence_can_be_suspended_until_a_schedule_ends_and_decision_is_json_ready():
    d = _check(1, 0.9, allow_convergence=False)
    assert d.reason == "continue"
    d = _check(2, math.nan, nrmse=math.nan)
    blob = json.loads(json.dumps(d.to_dict(), allow_nan=False))
    assert blob["values"]["chi2_per_obs"] is None and blob["reason"] == "continue"


def test_a_model_target_replaces_the_default_but_not_the_users():
    assert StopCriteria().target(200, model_target=1.9) == 1.9
    assert StopCriteria(chi2_target=1.5).target(200, model_target=1.9) == 1.5
    d = _check(3, 1.6, model_target=1.9)
    assert (d.converged, d.reason, d.values["chi2_target"]) == (True, "discrepancy", 1.9)
    assert _check(3, 1.6).reason == "continue"  # against 1 + 2 sqrt(2/200) = 1.2


def _standardized_draws(C_true, C_model, n, seed):
    """The standardised and the whitened misfit per observation of ``n`` residuals drawn from ``C_true``
    scored against the model ``C_model``."""
    from enkf import DenseError
    from enkf.diagnostics import chi2_per_obs, standardized_chi2_per_obs

    rng = np.random.default_rng(seed)
    r = (np.linalg.cholesky(C_true) @ rng.standard_normal((C_true.shape[0], n))).T
    model = DenseError(C_model)
    return standardized_chi2_per_obs(r, 0.0, model), chi2_per_obs(r, 0.0, model)


def test_the_standardized_statistic_has_the_mean_and_sd_its_target_assumes():
    """Residuals drawn from the model itself: the statistic's mean is 1 and its sd sqrt(2 tr P^2)/m, the
    numbers the target 1 + 2 sd is made of (4,000 draws: the mean to +-0.01, the sd to +-3 %, 4 se)."""
    from enkf import AR1Error, DiagonalError
    from enkf.diagnostics import standardized_target

    m = 161
    t = np.arange(m) * 1e-6
    sd = np.where(t > 100e-6, 6.0, 1.0)  # heteroscedastic: large after a "peak", like R + 2S
    model = AR1Error(sd, t, 20e-6)
    C = model.dense()
    P = C / np.outer(sd, sd)
    sd_stat = math.sqrt(2.0 * np.sum(P * P)) / m
    assert standardized_target(model) == pytest.approx(1.0 + 2.0 * sd_stat, rel=1e-12)
    assert standardized_target(DiagonalError(np.full(m, 3.0))) == pytest.approx(1.0 + 2.0 * math.sqrt(2.0 / m))
    s, _ = _standardized_draws(C, C, 4000, 1)
    assert s.mean() == pytest.approx(1.0, abs=4 * sd_stat / math.sqrt(4000))
    assert s.std(ddof=1) == pytest.approx(sd_stat, rel=0.03 * 4 / 3)
    assert np.mean(s <= standardized_target(model)) > 0.95


def test_a_wrong_correlation_model_inflates_the_whitened_misfit_but_not_the_standardized_one():
    """The stop test's reason for standardising: departures rougher than the model's AR(1) assumes (the
    same variances, a correlation time of 2 us against the model's 50 us, as a crack path's jumps make
    them) score a whitened chi^2 per observation far above its target, the standardised one about 1
    (its mean is tr(D^-1 C_true)/m = 1 exactly)."""
    from enkf import AR1Error

    m = 161
    t = np.arange(m) * 1e-6
    sd = np.full(m, 2.0)
    s, w = _standardized_draws(AR1Error(sd, t, 2e-6).dense(), AR1Error(sd, t, 50e-6).dense(), 2000, 2)
    assert np.median(w) > 3.0            # the whitened statistic rejects residuals of the right size
    assert np.mean(s) == pytest.approx(1.0, abs=0.05)
