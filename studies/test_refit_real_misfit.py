import numpy as np
import pytest

from studies.refit_real_misfit import misfit, points_of


def test_the_misfit_splits_at_the_peak_and_weighs_by_the_error_terms():
    y, f = np.array([1.0, 3.0, 2.0, 0.0]), np.array([0.0, 3.0, 0.0, 1.0])
    out = misfit(y, f, np.diag([1.0, 1.0, 4.0, 1.0]), peak=1)
    assert out["chi2"] == pytest.approx(1.0 + 0.0 + 1.0 + 1.0)
    assert out["chi2_to_peak"] == pytest.approx(1.0)
    assert out["rms_to_peak_MPa"] == pytest.approx(np.sqrt(0.5) / 1e6)
    assert out["rms_after_peak_MPa"] == pytest.approx(np.sqrt(2.5) / 1e6)


def test_the_mixtures_take_the_base_from_one_point_and_the_added_parameter_from_the_other():
    names = ["sigma_t", "E_t", "face_gap.gap_m@A", "face_gap.gap_m@B"]
    truth = {"sigma_t": 25.0, "E_t": 12.0, "face_gap.gap_m@A": 100.0, "face_gap.gap_m@B": 80.0}
    refit = {n: {"mean": v - 1.0} for n, v in truth.items()}
    pts = points_of(names, refit, truth, "B")
    assert pts["planted"] == {"sigma_t": 25.0, "E_t": 12.0, "face_gap.gap_m": 80.0}
    assert pts["refit"] == {"sigma_t": 24.0, "E_t": 11.0, "face_gap.gap_m": 79.0}
    assert pts["planted_base_refit_added"] == {"sigma_t": 25.0, "E_t": 12.0, "face_gap.gap_m": 79.0}
    assert pts["refit_base_planted_added"] == {"sigma_t": 24.0, "E_t": 11.0, "face_gap.gap_m": 80.0}
