"""Reduction of the measured Freiburg records (Rae et al.) against the authors' spreadsheets.

Acceptance of issue 4: the peak specimen stress matches the spreadsheet ``Strength`` / ``Max. Stress``
within 5 % for at least 90 % of the CaMa and SeeSst records. All records (SaLi included) are reduced
and the table is printed (``pytest -s`` shows it; ``python -m shpb.lab.reduction_table`` prints it too).
Reads the full Freiburg set shipped in ``data/freiburg-rae-rock-shpb``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from shpb.paths import freiburg_raw_files
from shpb.lab.reduction_table import (
    markdown_table,
    readme_section,
    reduce_freiburg_record,
    reduction_table,
    summarize,
    update_readme,
)


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return reduction_table()


def _record(stem: str):
    hits = [p for p in freiburg_raw_files() if p.stem.startswith(stem)]
    assert len(hits) == 1, stem
    return reduce_freiburg_record(hits[0])


def test_peak_stress_within_5_percent_for_90_percent_of_cama_and_seesst(table):
    print("\n" + markdown_table(table))
    summary = summarize(table)
    print("\n" + summary.to_string(index=False))
    sub = table[table["lithology"].isin(["CaMa", "SeeSst"])]
    fraction = sub["within_tolerance"].mean()
    assert len(sub) == 39
    assert fraction >= 0.90, f"only {fraction:.0%} of CaMa+SeeSst within 5 %"
    # per lithology too (measured: CaMa 14/15, SeeSst 23/24)
    for lith in ("CaMa", "SeeSst"):
        assert table[table["lithology"] == lith]["within_tolerance"].mean() >= 0.9, lith


def test_every_record_reduces_including_sali(table):
    assert len(table) == 51
    assert set(table["lithology"]) == {"CaMa", "SaLi", "SeeSst"}
    assert table["peak_stress_Pa"].between(15e6, 260e6).all()
    # SaLi: back-face stress 5-20 % below the authors' values (PROVENANCE), never above +5 %
    sali = table[table["lithology"] == "SaLi"]
    assert sali["rel_error"].between(-0.25, 0.05).all()
    assert sali["rel_error"].median() < -0.05


def test_loading_strain_rate_matches_the_spreadsheet(table):
    # mean strain rate over sigma >= peak/2 before the peak, the authors' definition
    good = table[table["lithology"].isin(["CaMa", "SeeSst"]) & (table["notes"] == "")]
    rel = good["mean_strain_rate_per_s"] / good["reference_strain_rate_per_s"] - 1.0
    assert (rel.abs() < 0.15).mean() >= 0.9, rel.describe()


def test_cama_005_matches_the_provenance_check_value():
    red, spec = _record("CaMa_SHPB_005")
    # PROVENANCE: the plain rebuild from the raw voltages gives 195.5 MPa (spreadsheet 200.2 MPa)
    assert red.peak_stress == pytest.approx(195.5e6, rel=0.01)
    assert red.peak_stress == pytest.approx(spec["strength_Pa"], rel=0.05)
    red22, spec22 = _record("SeeSst_SHPB_022")
    assert red22.peak_stress == pytest.approx(67.2e6, rel=0.01)


def test_cama_005_forces_balance_near_the_peak():
    """Stated tolerance: R = 2|F1-F2|/(F1+F2) <= 0.08 at the peak and averaged over the 20 us before it.

    PROVENANCE reports "within about 5 %" for the good tests; here R = 0.057 at the peak and 0.061 on
    average over the preceding 20 us, without dispersion correction.
    """
    red, _ = _record("CaMa_SHPB_005")
    i = red.peak_index
    k = int(round(20e-6 / red.dt))
    assert red.force_balance_at_peak <= 0.08
    assert np.nanmean(red.force_balance[i - k:i + 1]) <= 0.08
    # the strain rate at failure is of the order of the spreadsheet's loading rate (117 /s)
    assert 80 < red.mean_strain_rate_loading() < 150


def test_saturated_transmission_gauge_of_cama_013_is_dropped():
    red, spec = _record("CaMa_SHPB_013")
    assert red.channels_used["transmitted"] == ("A3",)
    # with both gauges the -5.12 V rail would give 443 MPa (PROVENANCE check column)
    assert red.peak_stress == pytest.approx(spec["strength_Pa"], rel=0.05)


def test_noise_levels_match_the_provenance():
    # 4-8 mV per channel pre-trigger std (a few reach 10-35 mV) -> strain via 1.005e-3 /V
    red, _ = _record("CaMa_SHPB_005")
    for ch in ("A1", "A2", "A3", "A4"):
        volts = red.noise_std_strain[ch] / 1.005e-3
        assert 2e-3 < volts < 10e-3, (ch, volts)
    # specimen-stress noise: E_b (D_b/D_s)^2 * noise of the averaged transmitted strain
    factor = 110e9 * (0.05 / red.specimen_diameter) ** 2
    assert red.noise_std_Pa["stress"] == pytest.approx(factor * red.noise_std_strain["transmitted"])
    assert 0.2e6 < red.noise_std_Pa["stress"] < 1.5e6


def test_incident_wave_at_gauge_of_cama_005():
    red, _ = _record("CaMa_SHPB_005")
    t, e = red.incident_wave_at_gauge()
    assert t[0] == 0.0 and t[-1] == pytest.approx(2 * 1.25 / red.bar.c0, abs=red.dt)
    # incident peak about 2.0 V -> 2.05e-3
    assert e.max() == pytest.approx(2.05e-3, rel=0.03)
    np.testing.assert_array_equal(e[: red.time.size], red.eps_incident[: e.size])


def test_readme_section_is_replaced_in_place(tmp_path, table):
    readme = tmp_path / "measured-records.md"
    readme.write_text("# title\n\nintro\n\n## Other section\n\nkeep me\n")
    update_readme(readme, readme_section(table.head(3)))
    first = readme.read_text()
    assert first.startswith("# title\n\nintro\n\n## Other section\n\nkeep me\n")
    assert first.count("# Measured records: reduction check") == 1
    update_readme(readme, readme_section(table.head(5)))
    second = readme.read_text()
    assert second.count("# Measured records: reduction check") == 1
    assert second.count("| CaMa_SHPB_") == 5 and "keep me" in second
