"""The confirmed model re-fitted on real runs (calibration.refit): on the analytic stand-in of
tests/_protocol_standin.py, where the anchored surrogate's chords between runs at 0, 100 and 200 um blend
two onsets and put the fitted face gaps 10-16 um short of the planted ones, the refit's rounds of runs
around the fit move them onto the planted gaps; the design, the spans and the pooling of meshes against
exact values."""

import numpy as np
import pandas as pd
import pytest

from _protocol_standin import BASE, OBS_T, StandIn, noise_model
from calibration.refit import (MIN_STEP, STEP_SD, first_round, inflate, misfit_scale, next_round, real_misfit,
                              refit_design, refit_summary, spans, verify_inflation)
from enkf.diagnosis.crossval import Fit
from test_anchored_selection import ANCHOR, GAP_K, GAPS, _anchored_standin, _select, _with_own_error

SETTINGS = {"seed": 3, "n_members": 60, "esmda_steps": 4}
#: each "mesh" k of the stand-in starts its record's load this much late: a realization's own departure
MESH_SHIFT_S = {0: 0.0, 1: 0.3e-6, 2: -0.3e-6}


def _selection():
    model = _anchored_standin(ANCHOR)
    sel = _select(model, 3, errors=_with_own_error(model))
    assert sel.rounds[0]["chosen"] == "face_gap"
    return sel, model.emulated


def _runs(rows, late=0.0):
    """The stand-in as the simulator: each row's parameters, its mesh as a small onset shift (``late``
    more: a departure of the real model the surrogate's runs did not show)."""
    out = []
    for row in rows:
        names = list(row["simulator"]) + ["trigger_shift.dt_s"]
        x = list(row["simulator"].values()) + [MESH_SHIFT_S[row["replicate"]] + late]
        y = StandIn(GAP_K).forward(names, [row["record"]])(np.array([x]))[0]
        out.append(pd.DataFrame({"time_s": OBS_T, "stress_Pa": y}))
    return out


def _walk(sel, model, obs, replicates, rounds=3, verify_late=0.0):
    state, curves = first_round(sel, 1, model), {}
    while state["phase"] != "done":
        curves[state["round"]] = _runs(state["rows"], verify_late if state["phase"] == "verify" else 0.0)
        state = next_round(state, curves.__getitem__, model, obs, {r: noise_model() for r in GAP_K}, {}, SETTINGS,
                           rounds=rounds, replicates=replicates)
    return state


def _obs():
    from _protocol_standin import TRUTH, observe
    return observe(StandIn(GAP_K), {r: {**TRUTH, "gap": GAPS[r]} for r in GAP_K}, seed=3)


def test_the_refit_moves_the_blended_gaps_onto_the_planted_ones():
    """Seed 3 with the anchored model's own error: the selection's gaps 0.5-5.9 um off the planted ones
    (49.5, 144.9, 88.5, 114.1 um for 50, 150, 90, 120); one locate round of 7 runs per record puts them
    at 48.3, 147.7, 89.8, 120.1 um, its means inside its runs (converged), 3 of 4 planted inside the 90 %
    intervals (B's 145.5-149.8 um misses 150: ES-MDA's 60 members on the noise, 0.3 MPa)."""
    sel, model = _selection()
    shipped = sel.steps[1].final.posterior()
    before = [abs(shipped[f"face_gap.gap_m@{r}"]["mean"] - GAPS[r]) for r in GAP_K]
    assert max(before) > 5e-6
    state = _walk(sel, model, _obs(), replicates=1)
    out = refit_summary(state)
    assert out["converged"] and [h["phase"] for h in out["history"]] == ["locate", "verify"]
    assert out["runs"] == 4 * 7 + 4  # the verify round: one real run per record at the fit's mean
    post = [out["posterior"][f"face_gap.gap_m@{r}"] for r in GAP_K]
    after = [abs(p["mean"] - GAPS[r]) for p, r in zip(post, GAP_K)]
    assert max(after) < 3e-6 and max(after) < 0.5 * max(before), (before, after)
    assert sum(p["q05"] <= GAPS[r] <= p["q95"] for p, r in zip(post, GAP_K)) >= 3
    assert out["selection_posterior"] == {n: {k: v[k] for k in ("mean", "q05", "q95")} for n, v in shipped.items()}


def test_the_spread_round_pools_one_fit_per_mesh():
    sel, model = _selection()
    state = _walk(sel, model, _obs(), replicates=3)
    spread = state["history"][-2]
    assert [h["phase"] for h in state["history"]] == ["locate", "spread", "verify"]
    assert len(spread["posterior_per_mesh"]) == 3 and len(state["history"][-1]["chi2_per_dof_real_per_mesh"]) == 3
    means = [p["face_gap.gap_m@A"]["mean"] for p in spread["posterior_per_mesh"]]
    # a mesh that starts the load 0.3 us later reads as a gap 3 um smaller (the face closes at 10 m/s)
    assert means[1] - means[0] == pytest.approx(-3e-6, abs=0.5e-6)
    assert means[2] - means[0] == pytest.approx(3e-6, abs=0.5e-6)
    members = SETTINGS["n_members"]
    assert np.asarray(state["fit"]["draws"]).shape == (3 * members, len(state["names"]))
    pooled = refit_summary(state)["posterior"]["face_gap.gap_m@A"]
    assert pooled["mean"] == pytest.approx(np.mean(means), abs=1e-9)
    assert pooled["q05"] < min(means) < max(means) < pooled["q95"]
    # the other two meshes repeat the locate round's 7 runs per record; the verify round one run per mesh
    assert refit_summary(state)["runs"] == 4 * 7 * 3 + 4 * 3


def test_the_design_moves_each_fitted_simulator_parameter_by_two_sd_or_the_least_step():
    names = ["sigma_p", "tau_d", "face_gap.gap_m@A", "face_gap.gap_m@B", "gauge_gain.g@A", "gauge_gain.g@B"]
    rng = np.random.default_rng(0)
    sd = np.array([1e6, 0.4e-6, 5e-6, 1e-7, 0.01, 0.01])
    P = np.array([40e6, 45e-6, 100e-6, 150e-6, 1.0, 1.0]) + rng.standard_normal((200, 6)) * sd
    fit = Fit(names, ("A", "B"), P, np.zeros(6), np.ones(6))
    inputs = BASE + ["face_gap.gap_m", "rate_strength.k"]
    lower, upper = np.array([20e6, 10e-6, 0.0, 0.0]), np.array([60e6, 100e-6, 4e-4, 1.0])
    rows = refit_design(fit, ["A", "B"], inputs, lower, upper)
    # per record: the anchor and two runs per simulator parameter (the gauge gain acts on the curve)
    assert [row["axis"] for row in rows[:7]] == [None, "sigma_p", "sigma_p", "tau_d", "tau_d", "face_gap.gap_m",
                                                 "face_gap.gap_m"]
    assert len(rows) == 14 and {row["record"] for row in rows[7:]} == {"B"}
    a = rows[0]["simulator"]
    step_s = STEP_SD * np.std(P[:, 0], ddof=1)
    assert rows[1]["simulator"]["sigma_p"] == pytest.approx(a["sigma_p"] - step_s)
    # twice tau_d's sd (0.8 us) is below the least step: 2 % of its 90 us box
    assert rows[4]["simulator"]["tau_d"] - a["tau_d"] == pytest.approx(MIN_STEP * 90e-6)
    assert rows[7]["simulator"]["face_gap.gap_m"] == pytest.approx(P[:, 3].mean())
    assert rows[12]["simulator"]["face_gap.gap_m"] == pytest.approx(P[:, 3].mean() - MIN_STEP * 4e-4)
    cover = spans(rows, names)
    assert cover["face_gap.gap_m@A"] == pytest.approx((P[:, 2].mean() - STEP_SD * np.std(P[:, 2], ddof=1),
                                                      P[:, 2].mean() + STEP_SD * np.std(P[:, 2], ddof=1)))
    assert "gauge_gain.g@A" not in cover and cover["sigma_p"][0] < a["sigma_p"] < cover["sigma_p"][1]


def test_nothing_is_refitted_when_the_base_model_is_kept():
    sel, model = _selection()
    state = first_round(sel, 0, model)
    assert state["phase"] == "done" and state["rows"] == [] and refit_summary(state)["posterior"] is None
    with pytest.raises(ValueError, match="done"):
        next_round(state, lambda r: [], model, {}, {}, {}, SETTINGS, rounds=3, replicates=3)


class _Line:
    """y = a t on one record: the forward model misfit_scale reads."""
    t = np.linspace(0.0, 1.0, 21)

    def forward(self, names, records):
        return lambda P: np.asarray(P)[:, :1] * self.t


def test_the_misfit_scale_is_the_chi_square_per_degree_of_freedom_at_the_fit_and_never_below_one():
    from enkf import DiagonalError
    from enkf.diagnosis import RecordErrors

    fit = Fit(["a"], ("A",), np.array([[1.9], [2.1]]), np.zeros(1), np.full(1, 5.0))
    sigma = 0.1
    errors = RecordErrors({"A": DiagonalError(np.full(21, sigma))})
    wiggle = np.where(np.arange(21) % 2 == 0, 1.0, -1.0)  # +-1 alternating: |r|^2 = 21 sigma^2 k
    for k, expected in ((9.0, 9.0 * 21 / 20), (0.25, 1.0)):
        obs = {"A": 2.0 * _Line.t + np.sqrt(k) * sigma * wiggle}
        assert misfit_scale(_Line(), fit, obs, errors) == pytest.approx(expected)


def test_the_cost_tables_count_the_refit_s_runs_apart_from_the_check_s(tmp_path):
    from benchmarks.bench_loro import run_stage

    res = tmp_path / "results"
    assert run_stage(res / "e/diagnosis/refit/iter_1/4/run.json", res) == "refit"
    assert run_stage(res / "e/diagnosis/check/12/run.json", res) == "check"
    assert run_stage(res / "e/diagnosis/design/3/PlantGap_01/run.json", res) == "design"
    assert run_stage(res / "e/iter_2/members/007/PlantGap_01/run.json", res) == "member iter_2"


def test_scaled_errors_multiply_every_term_and_keep_their_correlations():
    from enkf import AR1Error, DiagonalError
    from enkf.diagnosis import RecordErrors

    t = np.linspace(0.0, 1e-4, 11)
    ar = AR1Error(2.0, t, 2e-5)
    errors = RecordErrors({"A": DiagonalError(np.full(11, 1.0))}, {"A": ar}, {"A": ar}, 0.3, 1.0,
                          {"A": {"sigma_p": ar}})
    big = errors.scaled(4.0)
    assert np.allclose(big.calibration_error(["A"]).dense(), 4.0 * errors.calibration_error(["A"]).dense())
    assert np.allclose(big.calibration_error(["A"], ["sigma_p"]).dense(),
                       4.0 * errors.calibration_error(["A"], ["sigma_p"]).dense())
    assert (big.model_correlation, big.simulator_correlation) == (0.3, 1.0)


def test_real_runs_at_the_fit_that_miss_the_records_widen_its_interval_by_birges_ratio():
    """The verify round's real runs start the load 2 us late, a departure the design's runs did not show:
    the real chi-square per degree of freedom at the fit's mean, recomputed here from those runs, sets
    the factor on the spread; the means stay, the intervals widen by it."""
    sel, model = _selection()
    obs = _obs()
    plain = _walk(sel, model, obs, replicates=1)
    late = _walk(sel, model, obs, replicates=1, verify_late=2e-6)
    verify = late["history"][-1]
    assert plain["history"][-1]["inflation"] == pytest.approx(1.0, abs=0.05)
    draws = np.asarray(plain["fit"]["draws"])  # the plain walk's last fit is this one's before the factor
    fit = Fit(plain["names"], tuple(plain["records"]), draws, *_box(model))
    anchor = [row for row in refit_design(fit, list(GAP_K), model.input_names, *_box(model)) if row["axis"] is None]
    runs = _runs(anchor, 2e-6)
    chi2, m = 0.0, 0
    for row, run in zip(anchor, runs):
        y = np.interp(model.obs_times[row["record"]], run["time_s"], run["stress_Pa"])
        d = obs[row["record"]] - y
        chi2 += float(d @ np.linalg.solve(noise_model().dense(), d))
        m += d.size
    real = chi2 / (m - len(plain["names"]))
    assert verify["chi2_per_dof_real_per_mesh"] == [pytest.approx(real, rel=1e-6)]
    assert real > 3.0 and verify["inflation"] == pytest.approx(np.sqrt(real / verify["fit_misfit_scale"]), rel=1e-6)
    widened = np.asarray(late["fit"]["draws"])
    assert widened.mean(axis=0) == pytest.approx(draws.mean(axis=0), rel=1e-9)
    assert widened.std(axis=0) == pytest.approx(verify["inflation"] * draws.std(axis=0), rel=1e-9)


def _box(model):
    emu0 = next(iter(model.emulators.values()))
    return emu0.lower, emu0.upper


def test_the_factor_is_one_where_real_runs_fit_as_the_surrogate_claimed_and_the_box_bounds_the_draws():
    assert verify_inflation([0.9, 1.1], 1.5) == 1.0
    assert verify_inflation([], 3.0) == 1.0  # every verify run failed: nothing measured, nothing changed
    assert verify_inflation([6.0, 12.0], 1.5) == pytest.approx(np.sqrt(6.0))
    assert verify_inflation([4.0], 0.5) == pytest.approx(2.0)  # a scale below 1 was never applied
    draws = np.array([[0.0, 10.0], [2.0, 20.0], [4.0, 30.0]])
    out = inflate(draws, 3.0, [-1.0, 0.0], [100.0, 100.0])
    assert out[:, 1].tolist() == [0.0, 20.0, 50.0] and out[:, 0].tolist() == [-1.0, 2.0, 8.0]


def test_a_mesh_with_a_failed_verify_run_is_left_out_of_the_real_misfit():
    """Runs at the truth on mesh 0 (no shift) read as the noise; mesh 1, with record A's run failed, is
    left out rather than scored on three records."""
    from _protocol_standin import TRUTH

    _, model = _selection()
    rows = [{"record": r, "replicate": k, "axis": None, "simulator": {**TRUTH, "face_gap.gap_m": GAPS[r]}}
            for r in GAP_K for k in range(2)]
    runs = _runs(rows)
    runs[1] = None  # record A's run on mesh 1
    real = real_misfit(rows, runs, model, dict(TRUTH), _obs(), {r: noise_model() for r in GAP_K}, {})
    assert len(real) == 1 and 0.7 < real[0] < 1.3


def test_summary_html_says_how_far_real_runs_at_the_refit_miss_and_the_factor():
    from calibration.report_summary import _refit

    refit = {"model": "base + face_gap", "runs": 62, "rounds": 4, "converged": True,
             "posterior": {"sigma_t": {"mean": 24.1e6, "q05": 23.6e6, "q95": 24.6e6}},
             "selection_posterior": {"sigma_t": {"mean": 23.9e6, "q05": 23.0e6, "q95": 24.8e6}},
             "history": [{"phase": "locate"}, {"phase": "spread"},
                         {"phase": "verify", "chi2_per_dof_real_per_mesh": [9.93, 9.31, 9.90],
                          "fit_misfit_scale": 1.61, "inflation": 2.4547}]}
    text = "".join(_refit(refit))
    assert "9.3-9.9 on its check meshes, against 1.6 on its surrogate" in text and "2.45 times as wide" in text
    del refit["history"][-1]
    assert "times as wide" not in "".join(_refit(refit)) and "24.1 [23.6, 24.6]" in "".join(_refit(refit))
