"""The calibration's verdict (calibration.verdict): a fit made worse, a parameter pinned to its box, a stop rule
not met, each named with its numbers and what to do next; a clean calibration says ok."""
import math

import numpy as np
import pytest

from calibration.verdict import (PIN_FRACTION, REPORT_TOLERANCE, calibration_verdict, pinned_parameters,
                                 reported_iteration, uninformative_parameters)
from enkf.ces import interval_summary
from enkf.scores import INFORMATIVE_RATIO

NAMES = ("sigma_t", "E_t")
LOWER, UPPER = (4e6, 200.0), (60e6, 2400.0)


def _misfits(*chi2):
    return [{"iteration": k, "chi2_per_obs": c, "rmse_Pa": 1e6 * math.sqrt(c)} for k, c in enumerate(chi2)]


def _sample(centre, sd, n=20000, seed=0, lower=LOWER, upper=UPPER):
    """A Gaussian posterior sample of the two parameters (columns), kept inside the box."""
    S = np.random.default_rng(seed).normal(centre, sd, (n, 2))
    return np.clip(S, lower, upper)


def _post(st, et, rel=0.02, lower=LOWER, upper=UPPER):
    """A posterior sample's summary (the path the workflow takes) with 90 % intervals of about +-rel around
    the means (informative by default)."""
    S = _sample((st, et), (st * rel / 1.645, et * rel / 1.645), lower=lower, upper=upper)
    return interval_summary(S, NAMES, lower, upper)


def _decision(converged, reason="discrepancy", target=1.02):
    return {"converged": converged, "reason": reason, "values": {"chi2_target": target}}


def test_a_clean_calibration_is_ok():
    v = calibration_verdict(misfits=_misfits(900.0, 40.0, 3.0, 0.98), decision=_decision(True),
                            posterior=_post(45e6, 500.0), lower=LOWER, upper=UPPER, names=NAMES)
    assert v["verdict"] == "ok" and v["flags"] == []
    assert v["chi2_per_obs"]["best_iteration"] == 3 and v["best_is_last"]
    assert v["chi2_per_obs"]["final_over_prior"] == pytest.approx(0.98 / 900.0)


def test_a_fit_worse_than_the_prior_is_named_first_with_the_best_iteration():
    """The default run's marble calibration of 2026-11-24: chi2/obs 833 (prior) -> 3200 (final)."""
    v = calibration_verdict(misfits=_misfits(833.0, 610.0, 1900.0, 3200.0),
                            decision=_decision(False, "max_iterations"),
                            posterior=_post(79.5e6 * 0.5, 998.0), lower=LOWER, upper=UPPER, names=NAMES)
    assert v["verdict"] == "worse_than_prior"
    assert v["flags"] == ["worse_than_prior", "not_converged", "misfit_unexplained"]
    assert v["chi2_per_obs"]["best"] == 610.0 and v["chi2_per_obs"]["best_iteration"] == 1
    assert not v["best_is_last"]
    assert v["chi2_per_obs"]["final_over_prior"] == pytest.approx(3200.0 / 833.0)
    assert "config/diagnosis.yaml" in v["next_step"]
    # an experiment that runs its own diagnosis is pointed at its report
    v = calibration_verdict(misfits=_misfits(833.0, 610.0, 1900.0, 3200.0),
                            decision=_decision(False, "max_iterations"),
                            posterior=_post(79.5e6 * 0.5, 998.0), lower=LOWER, upper=UPPER, names=NAMES, diagnosed=True)
    assert "diagnosis/report.json" in v["next_step"] and "config/diagnosis.yaml" not in v["next_step"]


def test_a_mean_within_two_percent_of_a_bound_is_pinned_and_one_just_outside_is_not():
    """E_t at 4,796 J/m^2 in a box topped at 5,000 (issue 17): 4 % of the width below it is not pinned
    at 2 %; 1 % below it is."""
    lo, hi = (4e6, 200.0), (60e6, 5000.0)
    width = hi[1] - lo[1]
    box = {"lower": lo, "upper": hi}
    assert pinned_parameters(_post(45e6, hi[1] - 0.04 * width, **box), lo, hi, NAMES) == {}
    assert pinned_parameters(_post(45e6, hi[1] - 0.01 * width, **box), lo, hi, NAMES) == {"E_t": "upper"}
    assert pinned_parameters(_post(lo[0] + 0.5 * PIN_FRACTION * (hi[0] - lo[0]), 600.0, **box), lo, hi, NAMES) == {
        "sigma_t": "lower"}
    v = calibration_verdict(misfits=_misfits(100.0, 5.0), decision=_decision(True),
                            posterior=_post(45e6, hi[1] - 0.01 * width, **box), lower=lo, upper=hi, names=NAMES)
    assert v["verdict"] == "box_limited" and v["pinned_to_box"] == {"E_t": "upper"}
    assert "widen the box" in v["next_step"] and "E_t" in v["next_step"]


def test_a_budget_spent_above_the_target_is_not_converged_with_its_numbers():
    v = calibration_verdict(misfits=_misfits(900.0, 40.0, 14.0), decision=_decision(False, "max_iterations"),
                            posterior=_post(30.7e6, 281.0), lower=LOWER, upper=UPPER, names=NAMES)
    assert v["verdict"] == "not_converged" and v["flags"] == ["not_converged", "misfit_unexplained"]
    assert "max_iterations" in v["next_step"] and "14" in v["next_step"] and "1.02" in v["next_step"]


def test_failed_iterations_do_not_count_as_best():
    v = calibration_verdict(misfits=_misfits(50.0, float("nan"), 20.0), decision=_decision(False, "max_iterations"),
                            posterior=_post(30e6, 300.0), lower=LOWER, upper=UPPER, names=NAMES)
    assert v["chi2_per_obs"]["best_iteration"] == 2 and v["best_is_last"]


def test_the_last_ensemble_is_reported_unless_it_fits_markedly_worse_than_the_best():
    """Near convergence the last step may be a few per cent worse by sampling noise (the standard twin:
    0.94 -> 1.01): the last, the ES-MDA posterior, is kept. A last step that made the fit markedly worse
    (marble 610 -> 2,019) is not reported: the best iteration is."""
    assert reported_iteration([3.52, 1.74, 0.944, 1.01]) == 3
    assert reported_iteration([610.0, 1025.0, 1500.0, 2019.0]) == 0
    assert reported_iteration([500.0, 120.0, 120.0 * (1 + REPORT_TOLERANCE) * 1.001]) == 1
    assert reported_iteration([500.0, 120.0, 120.0 * (1 + REPORT_TOLERANCE) * 0.999]) == 2
    assert reported_iteration([50.0, 20.0, float("nan")]) == 1      # a failed last iteration is never reported
    assert reported_iteration([float("nan")] * 2) == 1


def test_summary_reports_the_best_ensemble_when_the_last_step_made_the_fit_worse():
    """Three iterations where the middle one fitted best by far: summary.json keeps its ensemble as
    best_ensemble and reports it as the posterior (posterior_iteration 1, the verdict says so)."""
    import numpy as np
    import pandas as pd

    from calibration.experiment import ExperimentSpec, summary

    exp = {"kind": "measured", "geometry": "cylinder", "preset": "fast", "method": "esmda", "ensemble_size": 4,
           "seed": 1, "parameters": {"sigma_t": [4e6, 60e6], "E_t": [200.0, 2400.0]}, "esmda": {"steps": 2}}
    spec = ExperimentSpec.from_config("m", exp)
    rng = np.random.default_rng(0)
    params = [pd.DataFrame({"sigma_t": rng.uniform(10e6, 50e6, 4), "E_t": rng.uniform(300, 2000, 4)})
              for _ in range(3)]
    chi2 = [500.0, 120.0, 900.0]
    analyses = [{"iteration": k, "n_alive": 4, "alive": [True] * 4, "failed_members": {},
                 "misfit": {"rmse_Pa": 1e6 * c ** 0.5, "nrmse": 0.1, "chi2_per_obs": c},
                 "misfit_per_record": {"r": {"rmse_Pa": 1.0, "chi2_per_obs": c}}, "n_obs": 50,
                 "prior_spread_unbounded": {"sigma_t": 1.0, "E_t": 1.0}, "next_params": [[0.0, 0.0]]}
                for k, c in enumerate(chi2)]
    decision = {"iteration": 2, "converged": False, "reason": "max_iterations", "message": "",
                "values": {"chi2_target": 1.02}}
    out = summary(spec=spec, exp=exp, analyses=analyses, decision=decision, final_params=params[2],
                  final_alive=np.ones(4, bool), forecast_misfit={"r": None}, n_simulations=13, wall_s=None,
                  simulation_wall_s=0.0, iteration_params=params)
    assert out["verdict"]["verdict"] == "worse_than_prior"
    b = out["best_ensemble"]
    assert b["iteration"] == 1 and b["chi2_per_obs"] == 120.0
    assert b["posterior"]["sigma_t"]["mean"] == pytest.approx(params[1]["sigma_t"].mean(), rel=1e-12)
    assert out["posterior_iteration"] == 1 and out["verdict"]["reported_iteration"] == 1
    assert out["posterior"]["E_t"]["mean"] == pytest.approx(params[1]["E_t"].mean(), rel=1e-12)
    assert "iteration 1's ensemble" in out["verdict"]["next_step"]
    # the forecast runs at the mean of the same ensemble
    from calibration.posterior import forecast_parameters

    fc = forecast_parameters(spec, analyses, params)
    assert fc["iteration"] == 1 and fc["posterior"] == "ensemble"
    assert fc["params"]["sigma_t"] == pytest.approx(out["posterior"]["sigma_t"]["mean"], rel=1e-12)
    # the plots take the same verdict from the stored iterations alone
    from calibration.experiment import final_verdict

    v = final_verdict(spec, analyses, params)
    assert v["verdict"] == out["verdict"]["verdict"] and v["flags"] == out["verdict"]["flags"]
    assert v["chi2_per_obs"]["best_iteration"] == 1 and v["chi2_per_obs"]["final"] == 900.0
    # with an MCMC posterior the plots read the same sample as the summary: one verdict, its flags included
    import pandas as pd

    wide = pd.DataFrame(np.random.default_rng(2).uniform(spec.lower, spec.upper, (4000, 2)), columns=list(spec.names))
    out = summary(spec=spec, exp=exp, analyses=analyses, decision=decision, final_params=params[2],
                  final_alive=np.ones(4, bool), forecast_misfit={"r": None}, n_simulations=13, wall_s=None,
                  simulation_wall_s=0.0, iteration_params=params, posterior_samples=wide,
                  posterior_sampler={"converged_chain": True})
    v = final_verdict(spec, analyses, params, posterior_samples=wide, posterior_sampler={"converged_chain": True})
    assert "uninformative" in out["verdict"]["flags"] and v["flags"] == out["verdict"]["flags"]
    assert v["score_over_prior"] == out["verdict"]["score_over_prior"]


def test_a_box_cutting_the_posterior_ends_box_limited_end_to_end(tmp_path):
    """The whole workflow with the stand-in simulator of tests/test_workflow.py (peak 0.8 sigma_t): a box
    ending at 30 MPa, just above the truth's sigma_t (29.9 MPa), so that about half of the posterior
    lies beyond it (a twin's truth outside its box is refused as a config error). The data pull the ensemble against the
    bound, and summary.json says so: verdict box_limited, sigma_t pinned at the upper side, and the next
    step names the parameter and says to widen the box. With the box widened the same twin is not
    box-limited (the flag comes from the box, not from the data)."""
    import json

    from test_workflow import snakemake, twin_config, write_config, write_stand_in

    def twin(box):
        exp = twin_config(parameters={"sigma_t": box, "E_t": [200.0, 2400.0]}, method="emulated_esmda",
                          max_iterations=2)["experiments"]["twin"]
        exp["observations"]["truth"] = {"sigma_t": 29.9e6, "E_t": 500.0}
        # 0.2 % noise: a posterior a few tenths of a MPa wide, so that the half of it the box cuts off
        # leaves the mean well inside the pin tolerance (2 % of the 26 MPa box), not on its edge
        exp["observations"]["noise"] = {"relative_sigma": 0.002}
        # members on one mesh: the stand-in's per-mesh ripple (0.5 % of the peak, more than the noise)
        # would otherwise scatter the members and slow the two iterations this flag test affords
        exp.setdefault("simulation", {})["mesh_realizations"] = "shared"
        return exp

    # one workflow, both twins (the same seed, data and members; only the box differs)
    cfg = {"run": ["cut", "wide"], "experiments": {"cut": twin([4.0e6, 30.0e6]), "wide": twin([4.0e6, 60.0e6])},
           "simulator": write_stand_in(tmp_path)}
    write_config(tmp_path, cfg)
    out = snakemake(tmp_path, "--cores", "2")
    assert out.returncode == 0, out.stderr[-4000:]
    wrong, right = (json.loads((tmp_path / f"results/{e}/summary.json").read_text()) for e in ("cut", "wide"))
    v = wrong["verdict"]
    assert v["verdict"] == "box_limited" and v["pinned_to_box"] == {"sigma_t": "upper"}
    assert wrong["posterior"]["sigma_t"]["mean"] > 30.0e6 - PIN_FRACTION * 26.0e6
    assert "widen the box" in v["next_step"] and "sigma_t" in v["next_step"]
    assert "box_limited" not in right["verdict"]["flags"] and right["verdict"]["pinned_to_box"] == {}


def test_a_posterior_equal_to_the_prior_is_flagged_uninformative():
    """The prior box itself, reported as the posterior (a uniform sample over the box), expects to score as
    the prior does (ratio 1): flagged, even when the fit is at the noise level and the stop rule was met."""
    prior_like = interval_summary(np.random.default_rng(1).uniform(LOWER, UPPER, (20000, 2)), NAMES, LOWER, UPPER)
    v = calibration_verdict(misfits=_misfits(1.1, 1.0), decision=_decision(True), posterior=prior_like,
                            lower=LOWER, upper=UPPER, names=NAMES, n_obs=161)
    assert v["verdict"] == "uninformative" and v["flags"] == ["uninformative"]
    assert v["interval_over_box"]["E_t"] == pytest.approx(0.9, abs=0.01)
    assert v["score_over_prior"]["E_t"] == pytest.approx(1.0, abs=0.02)
    assert "sigma_t, E_t" in v["next_step"] and "E_t 1.00" in v["next_step"]
    # one parameter learned (a 90 % interval of 0.1 of the box), the other not
    half = dict(prior_like, sigma_t=_post(45e6, 500.0, rel=0.062)["sigma_t"])
    assert set(uninformative_parameters(half, NAMES)) == {"E_t"}


@pytest.mark.parametrize("width, flagged", [(0.45, False), (0.62, True)])
def test_the_flag_falls_where_a_gaussian_posterior_expects_the_bar(width, flagged):
    """A Gaussian posterior with sd s expects 3.447 s / (box width) of the prior's score (enkf.scores), so
    the bar INFORMATIVE_RATIO sits at a 90 % interval of 3.29 x 0.55 / 3.447 = 0.526 of the box: one a
    little narrower is learned, one a little wider is not."""
    sd = [width * (hi - lo) / 3.29 for lo, hi in zip(LOWER, UPPER)]
    post = interval_summary(_sample([0.5 * (lo + hi) for lo, hi in zip(LOWER, UPPER)], sd), NAMES, LOWER, UPPER)
    for p, (lo, hi), s in zip(NAMES, zip(LOWER, UPPER), sd):
        assert post[p]["score_over_prior"] == pytest.approx(3.447 * s / (hi - lo), rel=0.02)
    assert bool(uninformative_parameters(post, NAMES)) is flagged
    assert INFORMATIVE_RATIO == 0.55


def test_an_mcmc_chain_short_of_its_autocorrelation_rule_is_flagged():
    sampler = {"converged_chain": False, "steps": 400, "autocorr_time": {"sigma_t": 80.0, "E_t": 95.0}}
    v = calibration_verdict(misfits=_misfits(900.0, 1.0), decision=_decision(True), posterior=_post(45e6, 500.0),
                            lower=LOWER, upper=UPPER, names=NAMES, sampler=sampler, n_obs=161)
    assert v["verdict"] == "mcmc_not_converged" and v["flags"] == ["mcmc_not_converged"]
    assert "400 steps" in v["next_step"]
    v = calibration_verdict(misfits=_misfits(900.0, 1.0), decision=_decision(True), posterior=_post(45e6, 500.0),
                            lower=LOWER, upper=UPPER, names=NAMES, sampler={**sampler, "converged_chain": True},
                            n_obs=161)
    assert v["verdict"] == "ok"


def test_a_fit_explained_only_by_an_estimated_discrepancy_is_flagged_unexplained_with_its_size():
    """The members' chi^2 against the instrument noise alone: 1.3 with 161 observations is above the
    noise level (1 + 2 sqrt(2/161) = 1.22); 1.1 is not. The stop rule (against R + D) was met."""
    disc = {"records": {"CaMa_004": {"sigma": 18.5e6, "corr_time_s": 21e-6}}}
    v = calibration_verdict(misfits=_misfits(900.0, 1.3), decision=_decision(True), posterior=_post(45e6, 500.0),
                            lower=LOWER, upper=UPPER, names=NAMES, n_obs=161, discrepancy=disc)
    assert v["verdict"] == "misfit_unexplained" and v["flags"] == ["misfit_unexplained"]
    assert v["chi2_per_obs"]["noise_level"] == pytest.approx(1.0 + 2.0 * math.sqrt(2.0 / 161))
    assert "18.5 MPa over 21 us" in v["next_step"]
    v = calibration_verdict(misfits=_misfits(900.0, 1.1), decision=_decision(True), posterior=_post(45e6, 500.0),
                            lower=LOWER, upper=UPPER, names=NAMES, n_obs=161, discrepancy=disc)
    assert v["verdict"] == "ok"


def test_the_verdict_scores_the_median_member_not_the_mean_curve():
    """Step-like members whose blurred mean fits (chi^2 1.19) while the median member misses (23.1)."""
    misfits = [{"iteration": 0, "chi2_per_obs": 50.0, "median_chi2_per_obs": 80.0},
               {"iteration": 1, "chi2_per_obs": 1.19, "median_chi2_per_obs": 23.1}]
    v = calibration_verdict(misfits=misfits, decision=_decision(False, "max_iterations"),
                            posterior=_post(45e6, 500.0), lower=LOWER, upper=UPPER, names=NAMES, n_obs=200)
    assert "misfit_unexplained" in v["flags"] and v["chi2_per_obs"]["final"] == 23.1


def test_the_standardized_statistics_and_their_own_targets_decide_and_are_quoted():
    """misfit_unexplained reads the standardised statistic against R + 2S with its own target (not the
    whitened one against 1 + 2 sqrt(2/m)); not_converged quotes the stop test's target."""
    def misfits(std_sim, target_sim):
        m = _misfits(900.0, 40.0, 14.0)
        m[-1].update({"median_chi2_per_obs_simulator": 5.0, "standardized_chi2_per_obs_simulator": std_sim,
                      "standardized_target_simulator": target_sim})
        return m

    kw = dict(posterior=_post(30.7e6, 281.0), lower=LOWER, upper=UPPER, names=NAMES, n_obs=161)
    v = calibration_verdict(misfits=misfits(1.5, 1.8), decision=_decision(True, target=1.8), **kw)
    assert v["flags"] == []               # whitened 5.0 > 1.22, but standardised 1.5 <= its 1.8
    assert v["chi2_per_obs"]["noise_level"] == 1.8
    v = calibration_verdict(misfits=misfits(2.5, 1.3), decision=_decision(False, "max_iterations", target=2.34)
                            | {"values": {"chi2_target": 2.34, "chi2_per_obs": 2.68}}, **kw)
    assert v["flags"] == ["not_converged", "misfit_unexplained"]
    assert "2.68 against the stop target 2.34" in v["next_step"]
