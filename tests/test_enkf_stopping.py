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
