"""studies/coverage_misses.py counts the misses, their side and their place in the box right, and its
direction test tells misses that all lie on one side from misses on both."""
import pytest
from scipy import stats

from studies import coverage_misses


def _record(i: int, e_truth: float, e_interval: tuple, converged: bool = False) -> dict:
    """A twin record as bench_coverage.py writes it; sigma_t always covered, E_t in ``e_interval``."""
    lo, hi = e_interval
    s = 2.0e7 + 1.0e6 * i
    disc = {"records": {"synthetic": {"sigma_over_noise": 0.5, "sigma_pre": 1.0e5, "sigma_post": 4.0e5,
                                      "noise_sigma": 2.0e5, "corr_time_s": 5.0e-6}}}
    return {"seed": 1000 + i, "truth": {"sigma_t": s, "E_t": e_truth}, "reported_iteration": 3,
            "stop_reason": "discrepancy" if converged else "max_iterations", "converged": converged,
            "stop_chi2_per_obs": 1.0 if converged else 3.0, "median_chi2_per_obs": 5.0, "discrepancy": disc,
            "params": {"sigma_t": {"mean": s * (1 + 0.001 * (i % 3 - 1)), "q05": 0.95 * s, "q25": 0.98 * s,
                                   "q75": 1.02 * s, "q95": 1.05 * s, "n": 25, "sbc_u": 0.5},
                       "E_t": {"mean": 0.5 * (lo + hi), "q05": lo, "q25": lo, "q75": hi, "q95": hi, "n": 25,
                               "sbc_u": 0.5}}}


def test_misses_all_above_the_interval_give_a_small_direction_p_and_the_right_counts():
    tool = coverage_misses
    covers = [_record(i, 300.0 + 50 * i, (250.0 + 50 * i, 400.0 + 50 * i), converged=True) for i in range(10)]
    # ten truths in the top fifth of the box [200, 2400], each above an interval 300-500 J/m^2 below it
    misses = [_record(10 + i, 2000.0 + 30 * i, (1500.0 + 30 * i, 1700.0 + 30 * i)) for i in range(10)]
    out = tool.analyse(covers + misses)
    e = out["params"]["E_t"]
    s = e["summary"]
    assert (s["n"], s["misses"], s["covers"]) == (20, 10, 10)
    assert s["direction"] == {"above": 10, "below": 0, "binomial_p": pytest.approx(2 * 0.5 ** 10)}
    assert s["direction"]["binomial_p"] < 0.05
    assert [m["side"] for m in e["misses"]] == ["above"] * 10
    assert e["misses"][0]["truth_box_fraction"] == pytest.approx((2000.0 - 200.0) / 2200.0)
    assert e["misses"][0]["half_width_rel"] == pytest.approx(100.0 / 2000.0)
    hi = s["fisher"]["truth_in_highest_fifth_of_box"]
    assert (hi["misses_with"], hi["n_with"], hi["misses_without"], hi["n_without"]) == (10, 10, 0, 10)
    assert hi["p"] < 0.001
    assert s["fisher"]["converged"]["misses_with"] == 0 and s["fisher"]["converged"]["n_with"] == 10
    assert s["stop_reasons"] == {"misses": {"max_iterations": 10}, "covers": {"discrepancy": 10}}
    assert s["medians_misses_vs_covers"]["truth_box_fraction"]["mann_whitney_p"] < 0.001
    assert s["bias"]["fraction_positive"] == pytest.approx(0.5)
    assert out["params"]["sigma_t"]["summary"]["misses"] == 0
    # the prediction intervals reported now: 0.9 expected; 25 members' sample 5-95 % quantiles (until
    # 2026-11-25): 0.9 * 24 / 26
    assert s["expected_coverage"] == {"intervals": "prediction", "n_members": 25, "expected": 0.9,
                                      "p": pytest.approx(stats.binomtest(10, 20, 0.9).pvalue)}
    old = tool.analyse(covers + misses, intervals="sample_quantiles")["params"]["E_t"]["summary"]
    assert old["expected_coverage"]["expected"] == pytest.approx(0.9 * 24 / 26)


def test_misses_on_both_sides_give_no_direction_and_the_interval_ends_count_as_covered():
    tool = coverage_misses
    above = [_record(i, 1500.0, (1000.0, 1400.0)) for i in range(3)]
    below = [_record(3 + i, 1000.0, (1100.0, 1400.0)) for i in range(3)]
    ends = [_record(6, 1000.0, (1000.0, 1400.0)), _record(7, 1400.0, (1000.0, 1400.0))]
    s = tool.analyse(above + below + ends)["params"]["E_t"]["summary"]
    assert s["direction"]["above"] == 3 and s["direction"]["below"] == 3
    assert s["direction"]["binomial_p"] == pytest.approx(1.0)
    assert s["covers"] == 2 and s["coverage_90"] == pytest.approx(0.25)
