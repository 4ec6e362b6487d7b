"""The report's peak errors against the test covariates (issue 53 item 3): the calibration records' real
cross-validated peak errors before and after the loop, their trends across the records, in check.json
and on the summary page; a held-out record never enters them."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from calibration.covariates import peak_error_trends
from calibration.report_summary import summary_html

RATES = {"A": 97.0, "B": 150.0, "C": 230.0, "D": 286.0}
LD = {"A": 1.0, "B": 0.9, "C": 1.1, "D": 0.8}


def errors_and_info(slope_per_s: float = -2e-4):
    """Four calibration records whose peak error before the loop falls linearly with the strain rate (a
    rate law the base model lacks: its sigma_t is the records' compromise) and is flat after it, and a
    held-out record "H" with its own covariates."""
    errors, info = {}, {}
    for k, (rec, rate) in enumerate(RATES.items()):
        errors[rec] = {"data": "calibration (cross-validated)",
                       "before": {"peak_rel_error": 0.04 + slope_per_s * (rate - 97.0)},
                       "after": {"peak_rel_error": 0.002 * (-1) ** k}}
        info[rec] = {"strain_rate_at_peak_per_s": rate, "specimen_length_m": LD[rec] * 0.04,
                     "specimen_diameter_m": 0.04}
    errors["H"] = {"data": "heldout", "before": {"peak_rel_error": 0.5}, "after": {"peak_rel_error": -0.5}}
    info["H"] = {"strain_rate_at_peak_per_s": 337.0}
    return errors, info


def test_a_rate_trend_of_the_peak_error_is_measured_on_the_calibration_records_only():
    errors, info = errors_and_info()
    cov = peak_error_trends(errors, info, list(RATES))
    json.dumps(cov, allow_nan=False)  # strict JSON: the missing gas pressure and striker velocity are None
    assert [r["record"] for r in cov["records"]] == list(RATES)  # "H" is not read
    assert [r["strain_rate_per_s"] for r in cov["records"]] == list(RATES.values())
    assert all(r["gas_pressure_Pa"] is None for r in cov["records"])
    t = {(r["covariate"], r["column"]): r for r in cov["trends"]}
    # only the covariates the sheets give and that vary: strain rate and L/D (from L and D)
    assert {c for c, _ in t} == {"strain_rate_per_s", "length_to_diameter"}
    before = t[("strain_rate_per_s", "peak_rel_error_before")]
    assert before["slope"] == pytest.approx(-2e-4, rel=1e-9) and before["r"] == pytest.approx(-1.0, abs=1e-12)
    assert before["n"] == 4 and before["p_pearson"] < 1e-6
    # the exact Spearman p of a perfect rank order of four records: 2 / 4! (both orders)
    assert before["p_spearman"] == pytest.approx(2 / 24, rel=1e-12)
    after = t[("strain_rate_per_s", "peak_rel_error_after")]
    assert abs(after["r"]) < 0.5 and after["p_pearson"] > 0.3


def test_the_summary_page_shows_the_table_and_the_slope_per_100_per_second():
    errors, info = errors_and_info()
    check = {"verdict": "confirmed", "added": ["rate_strength"], "errors_per_record": errors,
             "covariate_trends": peak_error_trends(errors, info, list(RATES))}
    html = summary_html("series", {"experiment": "series"}, check)
    assert "strain rate [1/s]" in html and "L/D" in html and "gas pressure" not in html
    # -2e-4 per 1/s is -2.00 % of the peak per 100 1/s
    assert "before the loop, against strain rate: -2.00 % per 100 1/s (Pearson r = -1.00" in html
    assert "Spearman p = 0.083; 4 records" in html
    cells = re.findall(r"<tr>(.*?)</tr>", html[html.index("against what their sheets give"):])
    rows = [re.findall(r"<td[^>]*>(.*?)</td>", c) for c in cells]
    # each calibration record's row: strain rate, L/D, peak error before and after; no row for "H"
    assert ["A", "97", "1.00", "+4.0", "+0.2"] in rows and ["D", "286", "0.80", "+0.2", "-0.2"] in rows
    assert not any(r and r[0] == "H" for r in rows)


def test_with_two_calibration_records_no_trend_is_tested_and_the_page_says_why():
    errors, info = errors_and_info()
    two = list(RATES)[:2]
    cov = peak_error_trends(errors, info, two)
    assert cov["trends"] is None and len(cov["records"]) == 2
    html = summary_html("series", {"experiment": "series"}, {"verdict": "base_kept", "covariate_trends": cov})
    assert "No trend is tested: that needs three calibration records whose test condition varies; this run has 2." in html
