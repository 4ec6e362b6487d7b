"""The population distribution of a per-record effect (enkf.diagnosis.population) and a held-out
record predicted from it alone (issue 32, item 1), on the vectorised stand-in of tests/_protocol_standin.py.

Planted per-record effect: a face gap (the arrival is delayed by gap / 10 m/s) drawn per record from
N(100 um, 25 um); five calibration records at loading slopes 0.6-1.4 MPa/us, one held-out record
(0.9 MPa/us) whose gap is put at mu + 1.3 tau = 132.5 um, where a population that ignores the spread
between tests (a fixed-effect centre +- 1.645 se) cannot reach it. Candidates face_gap, gauge_gain (both
per record) and rate_strength (shared), 80 members, 4 ES-MDA steps.

Measured on 30 other draws of the whole scenario (every gap, the held-out one included, drawn from the
population; ``_protocol_standin.heldout_gap_coverage(range(30))``: face_gap and gauge_gain offered, one
addition): face_gap chosen 30/30; the held-out record's true gap inside its predictive 90 % interval
26/30 (the t predictive's coverage at five records is 84-91 %, population.py); its RMSE after / before
median 0.13, at most 0.64.
"""

import math

import numpy as np
import pytest

from _protocol_standin import BASE, OBS_T, TRUTH, StandIn, observe, record_errors
from enkf.diagnosis import fit_population, heldout_evaluation, select_effects
from shpb import effects as fx

# ----------------------------------------------------------------------------------------------
# the estimator
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["reml", "dl"])
def test_equal_record_sds_give_the_closed_form_tau(method):
    # with equal within-record sds both estimators reduce to tau^2 = max(0, var(x) - s^2)
    x = np.array([80e-6, 110e-6, 95e-6, 130e-6, 70e-6])
    s = 5e-6
    pop = fit_population({r: (v, s) for r, v in zip("ABCDE", x)}, param="g", lower=0.0, upper=4e-4,
                         method=method, summary=True)
    assert pop.tau_work == pytest.approx(math.sqrt(np.var(x, ddof=1) - s ** 2), rel=1e-5)
    assert pop.mu_work == pytest.approx(x.mean()) and pop.se_mu_work == pytest.approx(
        math.sqrt((pop.tau_work ** 2 + s ** 2) / 5))
    assert pop.df == 3 and pop.tau_source == method
    # spread smaller than the within-record sds: tau = 0, not negative
    tight = fit_population({r: (1e-4 + d, 20e-6) for r, d in zip("ABC", (-1e-6, 0.0, 1e-6))}, param="g",
                           lower=0.0, upper=4e-4, method=method, summary=True)
    assert tight.tau_work == 0.0


def test_reml_maximises_the_restricted_likelihood_for_unequal_sds():
    x, s = np.array([1.0, 2.5, 0.4, 1.9, 3.0]), np.array([0.2, 0.9, 0.3, 0.5, 1.2])
    pop = fit_population({r: (a, b) for r, a, b in zip("ABCDE", x, s)}, param="p", lower=-10, upper=10,
                         summary=True)

    def restricted_loglik(t2):
        v = s ** 2 + t2
        w = 1 / v
        mu = np.sum(w * x) / w.sum()
        return -0.5 * (np.sum(np.log(v)) + np.log(w.sum()) + np.sum(w * (x - mu) ** 2))
    grid = np.linspace(0.0, 5.0, 50001)
    best = grid[np.argmax([restricted_loglik(t) for t in grid])]
    assert pop.tau_work ** 2 == pytest.approx(best, abs=2e-4)


def test_fewer_than_three_records_take_the_stated_floor():
    two = fit_population({"A": [90e-6, 91e-6, 92e-6], "B": [150e-6, 151e-6, 152e-6]}, param="face_gap.gap_m",
                         lower=0.0, upper=4e-4)
    assert two.tau_source == "floor" and two.tau_work == pytest.approx(0.25 * 4e-4)
    assert "not estimable from 2 record(s)" in two.note and math.isinf(two.df)
    assert two.to_dict()["df"] is None and two.to_dict()["tau_source"] == "floor"
    one = fit_population({"A": [1.05, 1.06]}, param="gauge_gain.g", lower=0.8, upper=1.2, scale="log",
                         floor_fraction=0.1)
    assert one.tau_work == pytest.approx(0.1 * math.log(1.2 / 0.8)) and one.scale == "log"
    assert 0.8 <= one.interval()[0] < one.median() < one.interval()[1] <= 1.2
    with pytest.raises(ValueError, match="not positive for a log scale"):
        fit_population({"A": [1.0]}, param="x", lower=0.0, upper=1.0, scale="log")


def test_a_population_reaching_below_the_box_sits_on_its_bound_and_keeps_its_median():
    pop = fit_population({r: (m, 1e-6) for r, m in zip("ABCD", (5e-6, 40e-6, 10e-6, 25e-6))}, param="face_gap.gap_m",
                         lower=0.0, upper=4e-4, summary=True)
    d = pop.draw(0, 20000)
    assert d.min() == 0.0 and np.mean(d == 0.0) > 0.1 and d.max() <= 4e-4
    assert pop.median() == pytest.approx(pop.mu_work)  # clipping, not truncation, keeps the centre
    assert pop.interval()[0] == 0.0


def test_the_t_predictive_covers_a_new_record_where_the_plug_in_normal_does_not():
    """600 populations of five records (tau = 1, per-record sds 0.25-0.75): a new record's value is inside
    the 90 % interval 87.0 % of the time with the t predictive, 79.8 % with the plug-in normal (measured
    with these seeds; 4,000 populations per cell in population.py's docstring)."""
    rng = np.random.default_rng(12)
    hits = {"t": 0, "normal": 0}
    n = 600
    for _ in range(n):
        s = 0.5 * rng.uniform(0.5, 1.5, 5)
        x = rng.normal(0.0, 1.0, 5) + s * rng.standard_normal(5)
        new = rng.normal(0.0, 1.0)
        for kind in hits:
            pop = fit_population({r: (a, b) for r, a, b in zip("ABCDE", x, s)}, param="p", lower=-50, upper=50,
                                 summary=True, predictive=kind)
            lo, hi = pop.interval(0.90)
            hits[kind] += lo <= new <= hi
    assert hits["t"] / n >= 0.85
    assert hits["normal"] / n <= 0.82 and hits["t"] - hits["normal"] >= 0.05 * n


# ----------------------------------------------------------------------------------------------
# a planted per-record gap, the held-out record predicted from the population alone
# ----------------------------------------------------------------------------------------------

K = {"A": 0.6e12, "B": 0.8e12, "C": 1.0e12, "D": 1.2e12, "E": 1.4e12, "H": 0.9e12}
CALIB = list("ABCDE")
MU, TAU = 100e-6, 25e-6


def planted_gaps():
    rng = np.random.default_rng(3)
    gaps = {r: float(rng.normal(MU, TAU)) for r in CALIB}  # 151.0, 36.1, 110.5, 85.8, 88.7 um
    gaps["H"] = MU + 1.3 * TAU
    return gaps


def run(obs):
    model = StandIn(K)
    return select_effects(model, base_names=BASE, calib_records=CALIB, heldout_records=["H"], obs=obs,
                          errors=record_errors(list(K)), seed=1, n_members=80, esmda_steps=4, max_additions=2,
                          candidates=[fx.get_effect("face_gap"), fx.get_effect("gauge_gain"),
                                      fx.get_effect("rate_strength")])


@pytest.fixture(scope="module")
def planted():
    gaps = planted_gaps()
    obs = observe(StandIn(K), {r: dict(**TRUTH, gap=gaps[r]) for r in K}, seed=5)
    sel = run({r: obs[r] for r in CALIB})  # the held-out curve is not even given: reading it would raise
    return gaps, obs, sel


def test_the_planted_gap_is_chosen_and_estimated_per_calibration_record(planted):
    gaps, _, sel = planted
    assert [s.spec.effect_names for s in sel.steps] == [[], ["face_gap"]]
    first = {t["effect"]: t for t in sel.rounds[0]["trials"]}
    assert first["face_gap"]["accepted"] and first["face_gap"]["z"] > 20
    assert sel.rounds[1]["chosen"] is None and not any(t["accepted"] for t in sel.rounds[1]["trials"])
    post = sel.last.final.posterior()
    for r in CALIB:
        assert abs(post[f"face_gap.gap_m@{r}"]["mean"] - gaps[r]) < 5e-6, r
    for b in BASE:  # the base parameters come back to the truth once the gaps carry the delay
        assert abs(post[b]["mean"] / TRUTH[b] - 1) < 0.01
    assert abs(sel.steps[0].final.posterior()["sigma_p"]["mean"] / TRUTH["sigma_p"] - 1) > 0.1


def test_a_heldout_record_is_predicted_from_the_population_alone(planted):
    gaps, obs, sel = planted
    pop = sel.last.populations["face_gap.gap_m"]
    assert pop.records == tuple(CALIB) and pop.tau_source == "reml" and pop.df == 3
    # the population: the calibration records' spread (sample sd of the planted gaps 41 um)
    assert abs(pop.mu_work - np.mean([gaps[r] for r in CALIB])) < 5e-6
    assert 30e-6 < pop.tau_work < 55e-6
    pred = sel.last.heldout["H"]
    lo, hi = pred.intervals()["face_gap.gap_m@H"]
    assert lo <= gaps["H"] <= hi, (lo, gaps["H"], hi)  # 132.5 um in [0, 205] um
    # without the spread between tests (fixed-effect centre +- 1.645 se) it would not be covered
    assert gaps["H"] > pop.mu_work + 1.645 * pop.se_mu_work
    assert pred.point["face_gap.gap_m@H"] == pop.median()
    ev = heldout_evaluation(sel, obs, {r: OBS_T for r in K}, errors=record_errors(list(K)))["H"]
    before, after = ev["before"], ev["after"]
    assert after["rmse"] < 0.35 * before["rmse"]  # 5.57 -> 1.59 MPa
    assert abs(after["time_to_peak_error"]) < abs(before["time_to_peak_error"])  # 20 -> 4 us early
    assert abs(after["peak_error"]) < abs(before["peak_error"])
    assert after["predictive_coverage"] > 0.9  # the band of members x population draws plus the noise
    assert before["point"] == {n: v for n, v in sel.steps[0].final.mean().items()}


def test_the_heldout_prediction_never_reads_the_heldout_curve(planted):
    gaps, obs, sel = planted
    corrupted = {**obs, "H": obs["H"][::-1] * 3.0 + 7e6}
    again = run(corrupted)
    for a, b in zip(sel.steps, again.steps):
        pa, pb = a.heldout["H"], b.heldout["H"]
        assert pa.point == pb.point
        assert np.array_equal(pa.curve, pb.curve) and np.array_equal(pa.draws, pb.draws)
    # the evaluation does read it (and only it does)
    ev = heldout_evaluation(again, corrupted, {r: OBS_T for r in K})["H"]
    assert ev["after"]["rmse"] > 10 * heldout_evaluation(sel, obs, {r: OBS_T for r in K})["H"]["after"]["rmse"]


def test_the_per_record_name_is_spelt_alike_on_both_sides_of_the_layer():
    """enkf may not import shpb (docs/architecture.md), so the separator of a per-record copy's name is
    stated in both; the simulator's name and the inference's parse of it must agree."""
    from enkf.diagnosis.population import RECORD_SEP, record_name, split_name
    from shpb import effects

    assert RECORD_SEP == effects.RECORD_SEP
    name = effects.record_param("face_gap.gap_m", "CaMa_SHPB_004")
    assert name == record_name("face_gap.gap_m", "CaMa_SHPB_004")
    assert split_name(name) == ("face_gap.gap_m", "CaMa_SHPB_004")
