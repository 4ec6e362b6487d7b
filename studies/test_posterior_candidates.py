"""studies/posterior_candidates.py's summary: coverage counts, sides and thirds on planted rows."""

from studies.posterior_candidates import summarise, twin_box


def _row(i, e_t, lo, hi):
    q = {"q05": lo, "q25": lo, "q75": hi, "q95": hi, "mean": 0.5 * (lo + hi)}
    return {"i": i, "truth": {"sigma_t": 3e7, "E_t": e_t}, "sigma_t": {"q05": 2e7, "q25": 2.5e7, "q75": 3.5e7,
                                                                      "q95": 4e7, "mean": 3e7}, "E_t": q}


def test_counts_misses_by_side_and_third():
    rows = [_row(0, 300.0, 400.0, 2000.0),    # lowest third, truth below the interval
            _row(1, 1200.0, 1000.0, 1500.0),  # middle third, covered
            _row(2, 2300.0, 900.0, 2100.0),   # top third, truth above
            _row(3, 2350.0, 2000.0, 2400.0)]  # top third, covered
    lower, upper = twin_box()
    assert (lower["E_t"], upper["E_t"]) == (200.0, 2400.0)  # the twin's Table 2 box, J/m^2
    s = summarise(rows, lower, upper)
    assert s["sigma_t"]["covered_90"] == 4
    e = s["E_t"]
    assert e["covered_90"] == 2 and e["covered_50"] == 2
    assert e["misses_90"] == {"truth_above": 1, "truth_below": 1}
    assert [t["covered"] for t in e["coverage_90_by_box_third"]] == [0, 1, 1]
    assert [t["twins"] for t in e["coverage_90_by_box_third"]] == [1, 1, 2]
    # widths over the prior's 90 % width (0.9 x 2200 J/m^2): 1600, 500, 1200, 400 -> median 850
    assert abs(e["width_over_prior_median"] - 850.0 / 1980.0) < 1e-12
