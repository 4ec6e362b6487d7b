"""Test covariates across records (issue 32 item 5): every covariate a test sheet gives, in each record's
information and in the residual's trends (calibration.covariates)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.covariates import COVARIATES, covariate_table_trends, covariate_values, pointed_at, record_covariates


def stand_in(n_records: int = 8, beta: float = 3.0, seed: int = 4):
    """Records whose L/D runs 0.74-1.10 (the Freiburg marble's range) and whose strain rates and gas
    pressures are a fixed shuffle of 60-260 1/s and 0.35-0.85 MPa, uncorrelated with L/D (eight records: Spearman's p is exact); the residual
    (200 samples, unit noise) has a mean of beta (1 - L/D) / 0.36 noise sd: a short specimen is
    stiffer / stronger than the model, as an end-friction confinement would make it."""
    rng = np.random.default_rng(seed)
    ld = np.linspace(0.74, 1.10, n_records)
    order = np.array([2, 6, 5, 3, 1, 4, 0, 7])  # a shuffle uncorrelated with the L/D order
    rate = np.linspace(60.0, 260.0, n_records)[order]
    info, resid, sigma = {}, {}, {}
    for k in range(n_records):
        name = f"R{k:02d}"
        D = 0.039
        info[name] = {"strain_rate_at_peak_per_s": rate[k], "specimen_length_m": ld[k] * D, "specimen_diameter_m": D,
                      "gas_pressure_Pa": 2e5 + 2.5e3 * rate[k], "peak_stress_Pa": 180e6}
        sigma[name] = 0.6e6
        resid[name] = sigma[name] * (beta * (1.0 - ld[k]) / 0.36 + rng.standard_normal(200))
    return info, resid, sigma, ld, rate


def test_a_planted_trend_against_L_over_D_is_pointed_at_and_the_strain_rate_is_not():
    info, resid, sigma, ld, rate = stand_in()
    assert abs(np.corrcoef(ld, rate)[0, 1]) < 0.2  # the stand-in's covariates are uncorrelated
    table = record_covariates(info, resid, sigma)
    assert list(table.columns[:5]) == ["record", "strain_rate_per_s", "length_to_diameter", "gas_pressure_Pa",
                                       "striker_velocity_m_s"]
    np.testing.assert_allclose(table["length_to_diameter"], ld, rtol=1e-12)  # from L and D (fallback)
    trends = covariate_table_trends(table)
    # the striker velocity is given by no record: no trend is computed against it
    assert set(trends["covariate"]) == {"strain_rate_per_s", "length_to_diameter", "gas_pressure_Pa"}
    row = trends.set_index(["covariate", "column"])
    ld_row, rate_row = row.loc[("length_to_diameter", "mean_resid_sd")], row.loc[("strain_rate_per_s", "mean_resid_sd")]
    assert ld_row["slope"] == pytest.approx(-3.0 / 0.36, rel=0.1)  # the planted slope, -8.3 sd per unit L/D
    assert ld_row["p_pearson"] < 1e-6 and ld_row["p_spearman"] < 1e-3
    assert rate_row["p_pearson"] > 0.05 and rate_row["p_spearman"] > 0.05
    assert row.loc[("gas_pressure_Pa", "mean_resid_sd")]["p_pearson"] > 0.05
    assert pointed_at(trends) == ["length_to_diameter"]
    print(f"\nL/D: slope {ld_row['slope']:.2f} sd, p {ld_row['p_pearson']:.1e} (Spearman {ld_row['p_spearman']:.1e}); "
          f"strain rate: p {rate_row['p_pearson']:.2f} (Spearman {rate_row['p_spearman']:.2f})")


def test_without_a_trend_nothing_is_pointed_at_and_missing_or_constant_covariates_are_skipped():
    info, resid, sigma, _, _ = stand_in(beta=0.0)
    for rec in info:
        info[rec]["gas_pressure_Pa"] = 5e5  # the same in every test: no trend can be computed
    trends = covariate_table_trends(record_covariates(info, resid, sigma))
    assert set(trends["covariate"]) == {"strain_rate_per_s", "length_to_diameter"}
    assert pointed_at(trends) == []
    two = {k: resid[k] for k in list(resid)[:2]}
    assert covariate_table_trends(record_covariates(info, two, sigma)) is None  # fewer than three records


def test_covariate_values_prefer_the_stored_ratio_and_give_nan_where_nothing_is_known():
    v = covariate_values({"length_to_diameter": 0.8, "specimen_length_m": 0.04, "specimen_diameter_m": 0.04,
                          "gas_pressure_Pa": None, "strain_rate_at_peak_per_s": "n/a"})
    assert v["length_to_diameter"] == 0.8 and set(v) == {c for c, _ in COVARIATES}
    assert np.isnan(v["gas_pressure_Pa"]) and np.isnan(v["strain_rate_per_s"]) and np.isnan(v["striker_velocity_m_s"])


def test_measured_record_information_carries_the_test_covariates():
    """CaMa_SHPB_004: L/D = 42.25 / 38.94 mm, the spreadsheet's gas pressure 5 bar; existing keys kept."""
    from calibration.observations import measured_observations
    from shpb.paths import data_dir, data_file
    raw = data_file(data_dir() / "freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt")
    obs, _ = measured_observations({"CaMa_SHPB_004": raw}, t_start=0.0, t_end=300e-6, dt=1e-6)
    info = obs.meta["record_info"]["CaMa_SHPB_004"]
    assert info["length_to_diameter"] == pytest.approx(42.25 / 38.94, rel=1e-9)
    assert info["gas_pressure_Pa"] == pytest.approx(5e5) and info["striker_velocity_m_s"] is None
    for key in ("strain_rate_at_peak_per_s", "closure_before_load_m", "specimen_length_m", "peak_stress_Pa"):
        assert info[key] is not None
    v = covariate_values(info)
    assert v["gas_pressure_Pa"] == 5e5 and v["strain_rate_per_s"] == info["strain_rate_at_peak_per_s"]
