"""studies/engine_bits.py's comparison on hand-made records: shifts in units of machine A's 90 % width."""
import pytest

from studies.engine_bits import pair_rows, summarise


def _rec(seed, q, mean, stop=1.0):
    truth = {"sigma_t": 40e6, "E_t": 800.0}
    params = {p: dict(zip(("q05", "q50", "q95"), q[p])) for p in q}
    return {"seed": seed, "truth": truth, "stop_chi2_per_obs": stop,
            "params": {p: {"mean": mean[p]} for p in mean}, "emulator_mcmc": {"params": params}}


def test_shifts_are_in_units_of_the_first_machines_width():
    a = _rec(1, {"sigma_t": (30e6, 40e6, 50e6), "E_t": (400.0, 800.0, 1200.0)}, {"sigma_t": 40e6, "E_t": 800.0})
    b = _rec(1, {"sigma_t": (32e6, 43e6, 50e6), "E_t": (500.0, 900.0, 1300.0)}, {"sigma_t": 40.4e6, "E_t": 800.0})
    r = pair_rows(a, b)
    assert r["sigma_t"]["median_shift_over_width"] == pytest.approx(0.15)
    assert r["sigma_t"]["q05_shift_over_width"] == pytest.approx(0.10)
    assert r["sigma_t"]["width_ratio"] == pytest.approx(0.9)
    assert r["sigma_t"]["last_ensemble_mean_ratio"] == pytest.approx(1.01)
    # both E_t intervals hold the truth (800)
    assert r["E_t"]["holds_truth"] == [True, True]
    s = summarise([r, pair_rows(a, a)])
    assert s["sigma_t"]["median_shift_over_width_abs"]["median"] == pytest.approx(0.075)
    assert s["E_t"]["truth_held_by_one_only"] == 0


def test_records_of_other_twins_are_refused():
    a = _rec(1, {"sigma_t": (1, 2, 3), "E_t": (1, 2, 3)}, {"sigma_t": 1, "E_t": 1})
    with pytest.raises(ValueError, match="not the same twin"):
        pair_rows(a, {**a, "seed": 2})
