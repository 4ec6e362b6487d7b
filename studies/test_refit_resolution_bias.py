"""The interval score studies/refit_resolution_bias.py reports: width inside, plus 2 / alpha times the miss."""
import pytest

from studies.refit_resolution_bias import interval_score


def test_the_90_interval_score_is_the_width_plus_twenty_times_the_miss():
    q = {"q05": 70.0, "q95": 77.0}
    assert interval_score(q, 75.0) == pytest.approx(7.0)
    assert interval_score(q, 80.0) == pytest.approx(7.0 + 20.0 * 3.0)
    assert interval_score(q, 69.0) == pytest.approx(7.0 + 20.0 * 1.0)
