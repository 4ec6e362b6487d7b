"""The location plan's decision rule (benchmarks/location_decision.py) on synthetic scored sets: a calibrated
candidate is adopted, an over-confident one, a blunter one and one that loses a misspecified set are not,
and a pair of JSONs holding other twins is refused.

Each synthetic twin: a truth from the box and a posterior of 400 draws (1000 well-specified twins: the 90 % coverage of a calibrated set then lies within 0.85-0.95 by five binomial standard deviations), N(centre, s^2) with the centre
~ N(truth, s^2) (calibrated) or N(centre, (s/3)^2) (over-confident); ``s`` sets how sharp it is.
"""
import copy

import numpy as np
import pytest

from benchmarks.bench_coverage import score
from benchmarks.location_decision import decide

NAMES = ("sigma_t", "E_t")
LOWER, UPPER = np.array([4e6, 200.0]), np.array([6e7, 2400.0])


def _records(n: int, seed: int, rel: float, shrink: float = 1.0) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        truth = LOWER + (UPPER - LOWER) * rng.uniform(0.2, 0.8, 2)
        s = rel * truth
        post = truth + s * rng.standard_normal(2) + (s / shrink) * rng.standard_normal((400, 2))
        rec = {"seed": seed * 1000 + i, "truth": dict(zip(NAMES, truth)), "converged": True,
               "stop_reason": "discrepancy", "params": {}}
        for j, p in enumerate(NAMES):
            x = post[:, j]
            q = dict(zip(("q05", "q25", "q50", "q75", "q95"), np.quantile(x, [0.05, 0.25, 0.5, 0.75, 0.95])))
            rec["params"][p] = {"mean": x.mean(), **q, "n": x.size,
                                "sbc_u": (np.sum(x < truth[j]) + 0.5) / (x.size + 1)}
        out.append(rec)
    return out


def _bench(recalibrate: str, rel: float = 0.03, shrink: float = 1.0, rel_rate: float | None = None) -> dict:
    out = {"recalibrate": recalibrate}
    for name, n, seed, r in (("well_specified", 1000, 1, rel), ("misspecified", 60, 2, rel),
                             ("misspecified_rate", 60, 3, rel if rel_rate is None else rel_rate)):
        recs = _records(n, seed, r, shrink if name == "well_specified" else 1.0)
        out[name] = {"complete": True, "twins": [{"seed": x["seed"], "truth": x["truth"]} for x in recs],
                     "summary_emulator_mcmc": score(recs, LOWER, UPPER, NAMES)}
    return out


def test_a_calibrated_candidate_as_sharp_as_the_shipped_form_is_adopted():
    d = decide(_bench("none"), _bench("location"))
    assert d["adopt_candidate"], d["failed"]
    assert d["scores"]["candidate"]["well_specified"]["sigma_t"]["coverage_90"] == pytest.approx(0.9, abs=0.05)


def test_an_over_confident_candidate_fails_its_coverage_and_rank_tests():
    d = decide(_bench("none"), _bench("location", shrink=3.0))
    assert not d["adopt_candidate"]
    for p in NAMES:
        assert f"well_specified coverage_90 {p}" in d["failed"]
        assert f"well_specified rank tests {p}" in d["failed"]


def test_a_calibrated_but_blunter_candidate_fails_on_the_score():
    """Three times wider and still calibrated: coverage and ranks pass, the WIS does not."""
    d = decide(_bench("none"), _bench("location", rel=0.09))
    assert not d["adopt_candidate"]
    assert sorted(d["failed"]) == sorted(f"well_specified wis_over_prior {p}" for p in NAMES)


def test_a_misspecified_set_counts_against_the_shipped_form_as_well_as_the_bar():
    """Below 0.80 on the rate set: failed where the shipped form covers it, met where it does no better."""
    worse = _bench("location")
    worse["misspecified_rate"]["summary_emulator_mcmc"] = score(_records(60, 3, 0.03, 3.0), LOWER, UPPER, NAMES)
    d = decide(_bench("none"), worse)
    assert "misspecified_rate coverage_90 sigma_t" in d["failed"]
    shipped = copy.deepcopy(worse)
    shipped["recalibrate"] = "none"
    assert decide(shipped, worse)["adopt_candidate"]


def test_other_twins_or_an_incomplete_set_are_refused():
    other = _bench("location")
    other["well_specified"]["twins"][0]["truth"] = {"sigma_t": 1e7, "E_t": 300.0}
    with pytest.raises(ValueError, match="other twins"):
        decide(_bench("none"), other)
    partial = _bench("location")
    partial["misspecified"]["complete"] = False
    with pytest.raises(ValueError, match="not complete"):
        decide(_bench("none"), partial)
    with pytest.raises(ValueError, match="expected the shipped form"):
        decide(_bench("location"), _bench("location"))
