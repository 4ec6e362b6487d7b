"""The workflow's analysis step (``calibration.experiment.analysis_step``) on a linear twin with exact
expectations: ES-MDA and the emulated analyses recover it and stop when the schedule is spent, failed
members are left out with their reasons, a rugged model stops within noise plus model error, the same
seed gives bit-identical files."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from enkf import EnsembleFailure
from calibration.experiment import ExperimentSpec, analysis_step, final_iteration, initial_ensemble, rng_for
from calibration.observations import observation_grid, twin_observations
from calibration.workflow_io import member_ids, read_responses, validate_config, write_responses
from test_workflow import SCHEMA, twin_config


# --------------------------------------------------------------------------------------------------
# the analysis step
# --------------------------------------------------------------------------------------------------
def _linear_setup(n_members=20):
    cfg = validate_config(twin_config(ensemble_size=n_members, esmda={"steps": 3}), SCHEMA)
    spec = ExperimentSpec.from_config("twin", cfg["experiments"]["twin"])
    t = observation_grid(0.0, 1e-4, 2e-6)

    def model(P):
        P = np.atleast_2d(P)
        return P[:, :1] * np.sin(np.pi * t / 1e-4) + 1e4 * P[:, 1:2] * (t / 1e-4)

    truth = np.array([45e6, 500.0])
    frame = pd.DataFrame({"time_s": t, "stress_Pa": model(truth)[0]})
    obs = twin_observations(frame, t, rng=rng_for(spec.seed, "noise"), relative_sigma=0.01)
    return spec, obs, model, truth


def next_params(analysis: dict) -> pd.DataFrame:
    """The next iteration's params.csv frame from an analysis dict."""
    params = pd.DataFrame(analysis["next_params"]["values"], columns=analysis["next_params"]["names"])
    params.insert(0, "member", range(len(params)))
    return params


def assert_recovered(K, decision, post, truth):
    """Three analyses, stopped by the rule, the twin's truth within the issue's 2 % / 10 % bar."""
    assert K == 3 and decision["reason"] in ("discrepancy", "max_iterations")
    assert post["sigma_t"]["mean"] == pytest.approx(truth[0], rel=0.02)
    assert post["E_t"]["mean"] == pytest.approx(truth[1], rel=0.10)


def test_analysis_steps_recover_a_linear_twin_and_stop_when_the_schedule_is_spent():
    spec, obs, model, truth = _linear_setup()
    params0 = initial_ensemble(spec)
    params, analyses = params0, []
    for k in range(4):
        Y = model(params[list(spec.names)].to_numpy())
        status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
        a = analysis_step(spec, k, params, Y, status, obs, params0)
        json.dumps(a, allow_nan=False)  # strict JSON
        analyses.append(a)
        K, decision = final_iteration(spec, analyses)
        if decision is not None:
            break
        params = next_params(a)
    assert_recovered(K, decision, analyses[-1]["posterior"], truth)
    assert analyses[-1]["misfit"]["rmse_Pa"] < 0.2 * analyses[0]["misfit"]["rmse_Pa"]


def test_failed_members_are_left_out_and_their_reasons_recorded_and_too_many_failures_stop():
    spec, obs, model, _ = _linear_setup(10)
    params = initial_ensemble(spec)
    Y = model(params[list(spec.names)].to_numpy())
    Y[2] = np.nan
    Y[7, 5:] = np.nan  # ok status, but the curve does not cover the grid
    status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
    status.loc[2, ["status", "reason"]] = ["failed", "synthetic: numerical failure: energy balance diverged"]
    a = analysis_step(spec, 0, params, Y, status, obs, params)
    assert a["n_alive"] == 8 and a["alive"][2] is False and a["alive"][7] is False
    reasons = {f["member"]: f["reason"] for f in a["failed_members"]}
    assert "energy balance diverged" in reasons[2] and "does not cover the observation grid" in reasons[7]
    assert sorted(a["update"]["replaced_members"]) == [2, 7]
    assert all(np.isfinite(np.array(a["next_params"]["values"])).ravel())
    status.loc[:6, "status"] = "failed"
    with pytest.raises(EnsembleFailure, match="only 2 of 10 members succeeded"):
        analysis_step(spec, 0, params, Y, status, obs, params)


def test_emulated_analyses_use_every_successful_run_so_far_and_recover_the_linear_twin():
    spec, obs, model, truth = _linear_setup()
    cfg = validate_config(twin_config(ensemble_size=20, method="emulated_esmda", max_iterations=3,
                                      emulated={"inner_members": 200}), SCHEMA)
    spec = ExperimentSpec.from_config("twin", cfg["experiments"]["twin"])
    params0 = initial_ensemble(spec)
    params, history, analyses = params0, [], []
    for k in range(4):
        Y = model(params[list(spec.names)].to_numpy())
        status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
        if k == 1:
            Y[3] = np.nan
            status.loc[3, ["status", "reason"]] = ["failed", "numerical failure: unstable"]
        with pytest.raises(ValueError, match="needs the runs of iterations"):
            analysis_step(spec, k, params, Y, status, obs, params0, history[:-1] if k else [history])
        a = analysis_step(spec, k, params, Y, status, obs, params0, history)
        json.dumps(a, allow_nan=False)
        analyses.append(a)
        # every successful run so far, the failed one left out; the last analysis untempered
        assert a["update"]["design_points"] == 20 * (k + 1) - (1 if k >= 1 else 0)
        assert a["update"]["temper"] == 4.0 ** max(0, 2 - k)
        K, decision = final_iteration(spec, analyses)
        if decision is not None:
            break
        history.append((params, Y))
        params = next_params(a)
    assert_recovered(K, decision, analyses[-1]["posterior"], truth)
    # the emulator of a linear model is exact: its error adds nothing and the fit is at the noise level
    m = analyses[-1]["misfit"]
    assert m["chi2_per_obs_model_error"] <= m["chi2_per_obs"] * (1 + 1e-9)
    assert decision["reason"] == "discrepancy" and decision["converged"]  # against R alone


def test_a_rugged_model_fits_within_noise_and_model_error_and_the_mcmc_posterior_holds_the_truth():
    """The linear twin plus a roughness of 6 noise sd per run (smooth in time, a deterministic function
    of the parameters, as the disc's fragment pattern): the ensemble-mean curve cannot come within R
    alone (the mean of 20 rough curves keeps ~1.3 sd of roughness), but it does within R plus the
    emulator's measured leave-one-out error, which holds the roughness (recorded in analysis.json as a
    diagnostic; the stop test stays against R, see calibration.experiment._misfit_for_decide)."""
    spec, obs, smooth, truth = _linear_setup()
    t = obs.time
    sigma = float(obs.error_model().std[0])

    def model(P):
        P = np.atleast_2d(P)
        out = smooth(P)
        for i, p in enumerate(P):
            seed = int.from_bytes(np.asarray(p, float).tobytes()[:8], "little") % 2**32
            z = np.random.default_rng(seed).standard_normal(t.size + 10)
            out[i] += 6.0 * sigma * np.convolve(z, np.ones(10) / np.sqrt(10), "valid")[:t.size]
        return out

    cfg = validate_config(twin_config(ensemble_size=20, method="emulated_esmda", max_iterations=3,
                                      emulated={"inner_members": 200}), SCHEMA)
    spec = ExperimentSpec.from_config("twin", cfg["experiments"]["twin"])
    params0 = params = initial_ensemble(spec)
    history, analyses = [], []
    for k in range(4):
        Y = model(params[list(spec.names)].to_numpy())
        status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
        analyses.append(analysis_step(spec, k, params, Y, status, obs, params0, history))
        K, decision = final_iteration(spec, analyses)
        if decision is not None:
            break
        history.append((params, Y))
        params = next_params(analyses[-1])
    m = analyses[-1]["misfit"]
    target = 1 + 2 * np.sqrt(2 / obs.m)
    assert K == 3 and m["chi2_per_obs"] > target >= m["chi2_per_obs_model_error"]
    assert decision["reason"] == "max_iterations" and not decision["converged"]
    # The last ensemble misses the truth here (sigma_t 41.7 MPa [38.5, 44.2], E_t 784 [566, 1018]); the
    # MCMC posterior on the smoothed emulator of all 80 runs holds it (5 of 5 seeds, 3-7, measured)
    from enkf.ces import emulator_posterior
    from calibration.experiment import all_runs

    runs = [p for p, _ in history] + [params]
    X, Yall, latest = all_runs(spec, runs, [y for _, y in history] + [Y], np.ones(20, bool))
    post = emulator_posterior(X, Yall, latest, obs.values, obs.error_model(), lower=spec.lower, upper=spec.upper,
                              times=t, rng=1, names=spec.names)
    assert post.diagnostics["converged_chain"] and post.diagnostics["emulator"]["smoothing"] > 0
    s = post.summary
    assert all(s[p]["q05"] <= v <= s[p]["q95"] for p, v in zip(("sigma_t", "E_t"), truth)), s


def test_the_same_seed_gives_bit_identical_analysis_files():
    spec, obs, model, _ = _linear_setup()
    p = initial_ensemble(spec)
    Y = model(p[list(spec.names)].to_numpy())
    st = pd.DataFrame({"member": p["member"], "status": "ok", "reason": ""})
    one = json.dumps(analysis_step(spec, 0, p, Y, st, obs, p))
    two = json.dumps(analysis_step(spec, 0, initial_ensemble(spec), Y, st, obs, p))
    assert one == two


def test_responses_file_round_trips(tmp_path):
    Y = np.array([[1.0, 2.5e7, np.nan], [3.0, 4.0, 5.0]])
    st = [{"status": "failed", "reason": "x, with a comma"}, {"status": "ok", "reason": "", "wall_s": 2.0}]
    write_responses(tmp_path / "r.csv", [0, 1], st, Y)
    status, back = read_responses(tmp_path / "r.csv")
    assert np.array_equal(back, Y, equal_nan=True)
    assert status["reason"].tolist() == ["x, with a comma", ""] and status["wall_s"].tolist() == [0.0, 2.0]
    assert member_ids(8) == ["000", "001", "002", "003", "004", "005", "006", "007"]


def test_the_rank_cap_keeps_exactly_that_many_singular_values():
    from enkf import esmda_update
    from calibration.experiment import capped_truncation

    spec, obs, model, _ = _linear_setup(20)
    p = initial_ensemble(spec)
    rng = np.random.default_rng(0)
    Y = model(p[list(spec.names)].to_numpy()) + 3e5 * rng.standard_normal((20, obs.m))  # rank-19 anomalies
    err, alive = obs.error_model(), np.ones(20, bool)
    for cap in (1, 2, 3, 7):
        tr = capped_truncation(Y, alive, err, 0.99, cap)
        res = esmda_update(p[list(spec.names)].to_numpy(), Y, obs.values, err, alpha=3.0, rng=1, truncation=tr,
                           transform=spec.transform)
        assert res.rank == cap
    assert capped_truncation(Y, alive, err, 0.99, None) == 0.99
    assert capped_truncation(Y, alive, err, 0.5, 19) == 0.5  # the cap never keeps more than base would


def test_each_analysis_prints_its_misfit_line_for_the_log():
    """scripts/analysis.py prints calibration.run_summary.analysis_line of every analysis: the stop test's
    statistic and target, the median member against the noise alone, the members that ran, the decision."""
    from calibration.run_summary import analysis_line

    spec, obs, model, _ = _linear_setup(10)
    params = initial_ensemble(spec)
    Y = model(params[list(spec.names)].to_numpy())
    Y[3] = np.nan
    status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
    status.loc[3, ["status", "reason"]] = ["failed", "numerical failure: energy balance diverged"]
    a = analysis_step(spec, 0, params, Y, status, obs, params)
    line = analysis_line(a)
    stat, target = a["decision"]["values"]["chi2_per_obs"], a["decision"]["values"]["chi2_target"]
    assert line.startswith("twin iteration 0: median member chi2/obs "), line
    assert f"chi2/obs {stat:.4g} (stop at {target:.4g}; {a['misfit']['median_chi2_per_obs']:.4g} against the noise " \
           f"alone), 9/10 members ok (1 failed" in line, line
    assert line.endswith("-> continue") and "\n" not in line
    # a stop is said with its reason; an odd dict gives a line, never an error
    stopped = {**a, "failed_members": [], "n_alive": 10, "decision": {**a["decision"], "stop": True,
                                                                     "reason": "max_iterations"}}
    assert analysis_line(stopped).endswith("10/10 members ok -> stop: max_iterations")
    assert analysis_line({"experiment": "x"}).startswith("x iteration ?: median member chi2/obs ? (stop at ?")
    assert analysis_line(None).startswith("(no misfit line")
