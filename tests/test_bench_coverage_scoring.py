"""The coverage benchmark's scoring can tell a calibrated posterior from an overconfident one and from
the prior (benchmarks/bench_coverage.py ``score``), on synthetic posteriors with known calibration.

Each synthetic twin: a truth drawn from the box; a posterior sample of 25 members drawn around a
centre that is itself drawn from N(truth, s^2), with spread s (calibrated: the truth is then a draw
from the posterior's predictive of the centre), or s/3 (overconfident), or the whole box (the prior).
"""

import numpy as np
import pytest

from benchmarks.bench_coverage import score

NAMES = ("sigma_t", "E_t")
LOWER, UPPER = np.array([4e6, 200.0]), np.array([6e7, 2400.0])


def _records(kind: str, n: int = 200, seed: int = 0, members: int = 400) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        truth = LOWER + (UPPER - LOWER) * rng.uniform(0.2, 0.8, 2)
        s = 0.03 * truth
        if kind == "prior":
            post = LOWER + (UPPER - LOWER) * rng.uniform(0, 1, (members, 2))
        else:
            centre = truth + s * rng.standard_normal(2)
            post = centre + (s if kind == "calibrated" else s / 3) * rng.standard_normal((members, 2))
        rec = {"truth": dict(zip(NAMES, truth)), "converged": True, "stop_reason": "discrepancy", "params": {}}
        for j, p in enumerate(NAMES):
            x = post[:, j]
            q = dict(zip(("q05", "q25", "q75", "q95"), np.quantile(x, [0.05, 0.25, 0.75, 0.95])))
            rec["params"][p] = {"mean": x.mean(), **q, "n": x.size,
                                "sbc_u": (np.sum(x < truth[j]) + 0.5) / (x.size + 1)}
        out.append(rec)
    return out


def test_a_calibrated_posterior_passes_the_coverage_and_rank_checks():
    """Centre ~ N(truth, s^2), posterior N(centre, s^2): the flat-prior posterior of one Gaussian
    observation, calibrated by construction."""
    s = score(_records("calibrated"), LOWER, UPPER, NAMES)
    for p in NAMES:
        r = s["params"][p]
        lo, hi = r["coverage_90"]["ci95"]
        assert lo <= 0.9 <= hi
        lo, hi = r["coverage_50"]["ci95"]
        assert lo <= 0.5 <= hi
        assert r["sbc"]["chi2_p"] > 0.01 and r["sbc"]["ks_p"] > 0.01
        assert r["width_over_prior_median"] < 0.2


def test_overconfidence_fails_the_rank_test_and_the_prior_shows_as_width():
    over = score(_records("overconfident"), LOWER, UPPER, NAMES)
    prior = score(_records("prior"), LOWER, UPPER, NAMES)
    for p in NAMES:
        assert over["params"][p]["coverage_90"]["ci95"][1] < 0.8
        assert over["params"][p]["sbc"]["chi2_p"] < 0.01
        assert prior["params"][p]["coverage_90"]["fraction"] == pytest.approx(1.0, abs=0.05)
        assert prior["params"][p]["width_over_prior_median"] == pytest.approx(1.0, abs=0.05)


def test_a_calibrated_posterior_of_25_members_covers_its_sample_interval_83_percent_of_the_time():
    """The sample 5-95 % interval of 25 exact posterior draws holds the truth with probability
    0.9 x 24 / 26 = 0.831, not 0.9: the reference the benchmark now reports. 2000 twins make the
    difference to 0.9 plain (binomial sd 0.008)."""
    s = score(_records("calibrated", n=2000, seed=4, members=25), LOWER, UPPER, NAMES)
    for p in NAMES:
        c = s["params"][p]["coverage_90"]
        assert c["reference_for_members"] == pytest.approx(0.9 * 24 / 26)
        assert c["p_vs_reference"] > 0.001
        assert c["ci95"][1] < 0.9
        assert s["params"][p]["coverage_50"]["reference_for_members"] == pytest.approx(0.5 * 24 / 26)


def test_the_emulator_mcmc_intervals_are_scored_with_failed_samplers_counted_as_misses():
    """score_mcmc scores each twin's ``emulator_mcmc`` intervals like the ensemble's; a twin whose sampler
    failed cannot raise the coverage (it counts as a miss in ``fraction_counting_failures_as_misses``),
    and twins recorded before the MCMC was are counted, not scored."""
    from benchmarks.bench_coverage import score_mcmc

    # one seed: the two kinds draw the same truths
    cal, over = _records("calibrated", n=60, seed=5), _records("overconfident", n=60, seed=5)
    records = []
    for i, (a, b) in enumerate(zip(cal, over)):
        assert a["truth"] == b["truth"]
        rec = dict(b)  # the ensemble's intervals overconfident, the MCMC's calibrated
        if i < 50:
            rec["emulator_mcmc"] = {"params": a["params"], "sampler": {"converged_chain": i % 2 == 0}}
        elif i < 55:
            rec["emulator_mcmc"] = {"error": "RuntimeError: chain shorter than its burn-in"}
        records.append(rec)
    ens, mc = score(records, LOWER, UPPER, NAMES), score_mcmc(records, LOWER, UPPER, NAMES)
    assert mc["n_twins"] == 50 and mc["sampler_failed"] == 5 and mc["twins_without_it"] == 5
    assert mc["chains_converged"] == 25
    for p in NAMES:
        c = mc["params"][p]["coverage_90"]
        assert c["fraction_counting_failures_as_misses"] == pytest.approx(c["fraction"] * 50 / 55)
        assert c["fraction"] > ens["params"][p]["coverage_90"]["fraction"] + 0.3
    assert score_mcmc(over, LOWER, UPPER, NAMES) is None


def test_the_readme_table_shows_the_reported_posterior_with_failed_samplers_as_misses():
    """tools/coverage_table.py: with ``reported_posterior: emulator_mcmc`` the table's coverage is the
    MCMC's, a failed sampler counted as a miss, and the ensemble's coverage is named as such beside it."""
    from benchmarks.bench_coverage import score_mcmc
    from tools.coverage_table import table

    cal, over = _records("calibrated", n=20, seed=3), _records("overconfident", n=20, seed=3)
    records = []
    for i, (a, b) in enumerate(zip(cal, over)):
        rec = dict(b)
        rec["params"] = {p: {**v, "interval": "t prediction interval"} for p, v in b["params"].items()}
        rec["emulator_mcmc"] = ({"error": "RuntimeError: short chain"} if i < 2 else
                                {"params": a["params"], "sampler": {"converged_chain": True}})
        records.append(rec)
    mc = score_mcmc(records, LOWER, UPPER, NAMES)
    bench = {"method": "emulated_esmda", "ensemble_size": 25, "window_s": [0.0, 1.6e-4],
             "reported_posterior": "emulator_mcmc", "self_calibrate": True,
             "well_specified": {"planned": 20, "complete": True, "twins": records,
                                "summary": score(records, LOWER, UPPER, NAMES), "summary_emulator_mcmc": mc}}
    text = table([("x.json", bench)])
    row = next(line for line in text.splitlines() if line.startswith("| well-specified")).split("|")
    k = round(mc["params"]["sigma_t"]["coverage_90"]["fraction"] * 18)
    assert row[2].strip() == "`x.json`" and row[3].strip() == "20"
    assert row[4].strip().startswith(f"{100 * k / 20:.0f} %")
    ens = bench["well_specified"]["summary"]["params"]
    assert row[7].strip() == " / ".join(f"{100 * ens[q]['coverage_90']['fraction']:.0f} %" for q in NAMES)
    assert "reported posterior: `emulator_mcmc`, the 5-95 % and 25-75 % quantiles of the MCMC sample" in text
    assert "a sampler that failed counts as a miss" in text


def test_the_misses_are_counted_by_side_and_a_biased_posterior_misses_on_one_side():
    """``misses_90`` splits the 90 % misses by the side the truth falls on (they add up to the misses);
    a posterior centred 10 % low misses with the truth above only, and its mean over the truth shows it."""
    recs = _records("calibrated", n=100, seed=11)
    s = score(recs, LOWER, UPPER, NAMES)["params"]["sigma_t"]
    m = s["misses_90"]
    assert m["truth_above"] + m["truth_below"] == round((1 - s["coverage_90"]["fraction"]) * 100)
    assert m["truth_above"] > 0 and m["truth_below"] > 0
    biased = []
    for r in _records("overconfident", n=100, seed=11):
        r = {**r, "params": {p: {k: (v * 0.9 if k != "n" and k != "sbc_u" else v) for k, v in q.items()}
                             for p, q in r["params"].items()}}
        biased.append(r)
    b = score(biased, LOWER, UPPER, NAMES)["params"]["sigma_t"]
    assert b["misses_90"]["truth_below"] == 0 and b["misses_90"]["truth_above"] > 90
    assert b["mean_over_truth_median"] == pytest.approx(0.9, abs=0.01)


def _bench(seed: int, kind: str) -> dict:
    """A bench_coverage JSON of 10 synthetic misspecified twins of one seed (the reported MCMC = the sample)."""
    recs = _records(kind, n=10, seed=seed)
    for i, r in enumerate(recs):
        r.update(seed=1000 * seed + i, emulator_mcmc={"params": r["params"], "sampler": {"converged_chain": True},
                                                      "self_calibration_lambda": 2.0})
    return {"experiment": "twin_ref", "method": "emulated_esmda", "reported_posterior": "emulator_mcmc",
            "misspecified": {"twins": recs, "summary_emulator_mcmc": None}, "wall_s_this_call": 1.0}


def test_pooled_sets_count_every_twin_once():
    """benchmarks/pool_coverage.py scores the union of two seeds' twins (the covered counts add up) and
    refuses the same seed twice or two different twin settings."""
    from benchmarks.pool_coverage import pool

    a, b = _bench(41, "calibrated"), _bench(43, "overconfident")
    out = pool("misspecified", {"a.json": a, "b.json": b})
    assert out["n_twins"] == 20 and out["sources"]["b.json"]["twin_seeds"] == [43000 + i for i in range(10)]
    # the pooled set's verdict is its own bar (coverage >= 0.80) on its reported posterior, which the
    # overconfident half fails
    from benchmarks.scores import misspecified_verdict
    assert out["verdict"] == misspecified_verdict(out["summary_emulator_mcmc"]) and not out["verdict"]["passes"]
    for p in NAMES:
        k = [round(score(x["misspecified"]["twins"], LOWER, UPPER, NAMES)["params"][p]["coverage_90"]["fraction"] * 10)
             for x in (a, b)]
        assert out["summary_emulator_mcmc"]["params"][p]["coverage_90"]["fraction"] == pytest.approx(sum(k) / 20)
    with pytest.raises(SystemExit, match="same twin seed twice"):
        pool("misspecified", {"a.json": a, "c.json": _bench(41, "calibrated")})
    with pytest.raises(SystemExit, match="reported_posterior"):
        pool("misspecified", {"a.json": a, "b.json": {**b, "reported_posterior": "ensemble"}})
    # twins with the refinement batch are another reported posterior than those without it
    with pytest.raises(SystemExit, match="refine_runs"):
        pool("misspecified", {"a.json": a, "b.json": {**b, "refine_runs": 25}})


def test_the_table_has_a_row_per_set_in_order_and_refuses_to_mix_settings():
    """tools/coverage_table.py: one row per set with twins, in the order the JSONs are given, each naming
    its file; JSONs of different twin settings (here with and without the refinement batch) are refused."""
    from benchmarks.bench_coverage import score_mcmc
    from tools.coverage_table import table

    def bench(seed, refine, name="well_specified"):
        recs = _records("calibrated", n=10, seed=seed)
        for i, r in enumerate(recs):
            r.update(seed=1000 * seed + i, emulator_mcmc={"params": r["params"], "sampler": {"converged_chain": True}})
        return {"experiment": "twin_ref", "method": "emulated_esmda", "ensemble_size": 25, "window_s": [0.0, 1.6e-4],
                "reported_posterior": "emulator_mcmc", "emulator_error": "heteroscedastic", "refine_runs": refine,
                "approximation_pairs": 24 if name == "misspecified" else 0,
                name: {"twins": recs, "summary": score(recs, LOWER, UPPER, NAMES),
                       "summary_emulator_mcmc": score_mcmc(recs, LOWER, UPPER, NAMES)}}

    text = table([("b/well.json", bench(64, 25)), ("b/mis.json", bench(65, 25, "misspecified")),
                  ("b/again.json", bench(66, 25))])
    rows = [line.split("|") for line in text.splitlines() if line.startswith("| ") and "`" in line.split("|")[2]]
    assert [(r[1].strip(), r[2].strip(), r[3].strip()) for r in rows] == [
        ("well-specified", "`well.json`", "10"),
        ("misspecified (data from the `standard` mesh, approximation error from 24 paired runs)", "`mis.json`", "10"),
        ("well-specified", "`again.json`", "10")]
    assert text.startswith("From `b/well.json`, `b/mis.json`, `b/again.json` (emulated_esmda, N = 25")
    with pytest.raises(ValueError, match="b/old.json differs from b/well.json in refine_runs"):
        table([("b/well.json", bench(64, 25)), ("b/old.json", bench(62, 0))])
    with pytest.raises(ValueError, match="no benchmark JSON"):
        table([])


def test_pooling_compares_the_form_that_ran_and_refuses_to_mix_forms():
    from benchmarks.pool_coverage import setting

    legacy = {"approximation_pairs": 24, "model_error": {"simulator_replicates": 6,
              "approximation_error": {"preset": None, "pairs": 0, "coarse_realizations": 2}}}
    filled = {"approximation_pairs": 24, "coarse_variability": "counted", "model_error": {"simulator_replicates": 6,
              "approximation_error": {"preset": None, "pairs": 0, "coarse_variability": "subtracted"}}}
    current = {"approximation_pairs": 24, "coarse_variability": "subtracted", "model_error": {"simulator_replicates": 6}}
    # a JSON from before the key existed ran the raw-scatter form
    assert setting(legacy, "coarse_variability") == "counted" == setting(filled, "coarse_variability")
    assert setting(current, "coarse_variability") == "subtracted"
    # the twin block's (off) approximation_error, however recorded, is not a setting that differs
    assert setting(legacy, "model_error") == setting(filled, "model_error") == setting(current, "model_error")
    assert setting({"model_error": {"simulator_replicates": 3}}, "model_error") != setting(current, "model_error")
    assert setting({"approximation_pairs": 0}, "coarse_variability") is None


def test_pooling_refuses_json_of_different_forms():
    from benchmarks.pool_coverage import pool

    a = {"experiment": "twin_ref", "approximation_pairs": 24, "coarse_variability": "subtracted",
         "misspecified": {"twins": []}}
    b = dict(a, coarse_variability="counted")
    with pytest.raises(SystemExit, match=r"twin settings \['coarse_variability'\] differ"):
        pool("misspecified", {"a.json": a, "b.json": b})


def test_kept_runs_are_reused_only_for_the_same_loop():
    # bench_coverage --keep-runs scores another reported posterior on a twin's kept runs; a kept file of
    # another loop (another seed, another ensemble size) is refused
    from dataclasses import replace

    from calibration.experiment import ExperimentSpec

    from benchmarks import bench_coverage as bc

    spec = ExperimentSpec.from_config(bc.EXPERIMENT, {**bc.twin_experiment(), "seed": 60003})
    assert bc._same_spec(spec, replace(spec))
    assert not bc._same_spec(spec, replace(spec, seed=60004))
    assert not bc._same_spec(spec, replace(spec, ensemble_size=24))
    assert not bc._same_spec(spec, replace(spec, lower=spec.lower * 1.01))


def test_coverage_by_box_third_finds_where_the_misses_are():
    """``coverage_90_by_box_third`` counts twins and covered truths per third of the box: shifting the
    intervals of the twins whose truth lies in the lowest third away from it leaves that third uncovered
    and the other two as they were."""
    recs = _records("calibrated", n=300, seed=5)
    base = score(recs, LOWER, UPPER, NAMES)["params"]["E_t"]["coverage_90_by_box_third"]
    low = LOWER[1] + (UPPER[1] - LOWER[1]) / 3
    moved = []
    for r in recs:
        q = r["params"]["E_t"]
        if r["truth"]["E_t"] < low:  # the interval moved wholly above the truth
            shift = r["truth"]["E_t"] - q["q05"] + 1.0
            q = {k: (v + shift if k.startswith("q") or k == "mean" else v) for k, v in q.items()}
        moved.append({**r, "params": {**r["params"], "E_t": q}})
    out = score(moved, LOWER, UPPER, NAMES)["params"]["E_t"]["coverage_90_by_box_third"]
    assert [c["twins"] for c in out] == [c["twins"] for c in base] and sum(c["twins"] for c in out) == 300
    assert out[0]["twins"] > 0 and out[0]["covered"] == 0
    assert out[1:] == base[1:] and base[0]["covered"] / base[0]["twins"] > 0.6


def test_the_verdict_passes_a_sharp_calibrated_posterior_and_fails_the_prior_and_overconfidence():
    """benchmarks.scores.verdict on the synthetic sets: a calibrated posterior 3 % wide meets every bar
    (its WIS a few hundredths of the prior's); the prior fails the WIS bars (the prior on truths drawn
    from the whole box: tests/test_harness_informative.py); the overconfident one fails coverage and ranks."""
    from benchmarks.scores import verdict

    cal = score(_records("calibrated"), LOWER, UPPER, NAMES)
    v = verdict(cal)
    assert v["passes"] and v["failed"] == [] and len(v["met"]) == 6
    assert all(cal["params"][p]["wis_over_prior"] < 0.1 and cal["params"][p]["uninformative_share"] == 0.0
               for p in NAMES)
    prior = score(_records("prior"), LOWER, UPPER, NAMES)
    # its truths in the middle 60 % of the box, it also over-covers and ranks in the middle: every bar fails
    bars = ("coverage_90", "sbc", "wis_over_prior")
    assert verdict(prior)["failed"] == [f"{bar} {p}" for p in NAMES for bar in bars]
    for p in NAMES:
        # 400 prior draws per twin: its WIS is the prior box's to within the sample quantiles' noise
        assert prior["params"][p]["wis_over_prior"] == pytest.approx(1.0, abs=0.05)
        assert prior["params"][p]["uninformative_share"] == 1.0
    over = verdict(score(_records("overconfident"), LOWER, UPPER, NAMES))
    assert {f"{bar} {p}" for bar in ("coverage_90", "sbc") for p in NAMES} <= set(over["failed"])


def test_a_planted_effect_reaches_the_data_run_only():
    """The misspecified_rate set's undeclared rate dependence is a parameter of the data's run: the
    twin's task carries it beside the calibrated parameters, the members' tasks (no ``planted``) do not,
    and the simulator reads it as its own parameter (a rate-dependent strength changes the disc's curve
    by more than the 1 % noise at the planted k)."""
    from benchmarks import bench_coverage as bc

    exp = bc.twin_experiment()
    names = ["sigma_t", "E_t"]
    data = bc.twin_task(exp, names, [45e6, 500.0], "fast", 7, {"rate_strength.k": 0.25})
    member = bc.twin_task(exp, names, [45e6, 500.0], "fast", 7)
    assert data[1] == {"sigma_t": 45e6, "E_t": 500.0, "rate_strength.k": 0.25}
    assert member[1] == {"sigma_t": 45e6, "E_t": 500.0}
    assert data[2:4] == member[2:4] and data[5] == member[5] and np.array_equal(data[4], member[4])
    y_data, y_member = bc._simulate(data), bc._simulate(member)
    peak = np.nanmax(y_member)
    assert np.nanmax(np.abs(y_data - y_member)) > 0.01 * peak


def test_every_misspecified_twin_pooled_across_sets():
    """``misspecified+misspecified_rate`` pools both misspecified sets of every JSON (the standard-mesh
    twins of one, the rate twins of another): each twin once, the coverage the count over all of them,
    the verdict the misspecified bar."""
    from benchmarks.pool_coverage import main, pool
    from benchmarks.scores import misspecified_verdict

    a = _bench(41, "calibrated")
    r = _bench(45, "overconfident")
    r["misspecified_rate"] = r.pop("misspecified")
    out = pool("misspecified+misspecified_rate", {"a.json": a, "r.json": r})
    assert out["n_twins"] == 20 and out["sources"]["r.json"]["twin_seeds"] == [45000 + i for i in range(10)]
    for p in NAMES:
        k = [round(score(x[n]["twins"], LOWER, UPPER, NAMES)["params"][p]["coverage_90"]["fraction"] * 10)
             for x, n in ((a, "misspecified"), (r, "misspecified_rate"))]
        assert out["summary_emulator_mcmc"]["params"][p]["coverage_90"]["fraction"] == pytest.approx(sum(k) / 20)
    assert out["verdict"] == misspecified_verdict(out["summary_emulator_mcmc"])
    # one set alone sees only its own twins
    assert pool("misspecified_rate", {"r.json": r})["n_twins"] == 10
    with pytest.raises(SystemExit):
        main(["well_specified+misspecified", "x.json"])
