"""`python -m shpb reduce SHEET.yaml` (shpb.lab.lab_reduce): the shipped LANL and Yao records reduce
from their sheets; a Freiburg record reduces through its sheet to today's curve; the lab checks give
their numbers and catch a wrong gauge distance; a disc's stress is 2F/(pi D t)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from shpb.__main__ import main
from shpb.lab.lab_reduce import REDUCED_COLUMNS, lab_checks, reduce_sheet, transit_time
from shpb.lab.sheet import load_sheet
from shpb.lab.sheet_readers import check_sheet

REPO = Path(__file__).resolve().parents[1]
SHEETS = REPO / "data" / "examples" / "sheets"
CAMA004 = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"


def test_a_freiburg_record_reduces_through_its_sheet_to_todays_curve():
    from calibration.observations import reduce_measured_record

    today, _, _ = reduce_measured_record(CAMA004)
    sheet, raw = check_sheet(SHEETS / "CaMa_SHPB_004.yaml")
    via_sheet = reduce_sheet(sheet, raw)
    assert via_sheet.time.size == today.time.size
    np.testing.assert_allclose(via_sheet.time, today.time, rtol=0, atol=1e-15)
    for f in ("stress_back", "stress_front", "strain_rate", "force_front", "force_back"):
        a, b = getattr(via_sheet, f), getattr(today, f)
        assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(b)), f
    assert via_sheet.peak_stress == pytest.approx(today.peak_stress, rel=1e-12)


@pytest.mark.parametrize("name, peak_lo, peak_hi", [
    ("LANL_Cu_273K", 320e6, 353e6),        # PROVENANCE: ~336 MPa (tests/test_records_other_labs.py)
    ("LANL_PMMA_13", 100e6, 250e6),
    ("Yao_epoxy_01", 100e6, 400e6),
    ("Yao_steel945_02", 0.6e9, 1.5e9),      # 945 steel flows near 1 GPa
])
def test_lanl_and_yao_records_reduce_through_the_command(tmp_path, capsys, name, peak_lo, peak_hi):
    out = tmp_path / name
    assert main(["reduce", str(SHEETS / f"{name}.yaml"), "--out", str(out)]) == 0
    curves = pd.read_csv(out / "curves.csv")
    assert tuple(curves.columns) == REDUCED_COLUMNS
    assert peak_lo < curves["stress_Pa"].max() < peak_hi
    # the specimen stress is the back-face force over the specimen's area
    sheet = load_sheet(SHEETS / f"{name}.yaml")
    area = math.pi * sheet.specimen_diameter ** 2 / 4
    np.testing.assert_allclose(curves["stress_Pa"], curves["force_back_N"] / area, rtol=1e-8)
    checks = json.loads((out / "checks.json").read_text())
    assert set(checks) >= {"force_balance", "pulse_alignment", "noise"}
    assert (out / "force_balance.png").stat().st_size > 10_000
    assert "force balance" in capsys.readouterr().out


def test_the_lab_checks_of_cama_004_and_a_wrong_gauge_distance(tmp_path):
    sheet, raw = check_sheet(SHEETS / "CaMa_SHPB_004.yaml")
    red = reduce_sheet(sheet, raw)
    c = lab_checks(red, transit_time(sheet))
    # balanced from half the peak to the peak (mean R 0.026), waves aligned within a sample, 0.43 % noise
    assert c["force_balance"]["ok"] and c["force_balance"]["mean_R_half_peak_to_peak"] == pytest.approx(0.026, abs=0.002)
    assert c["pulse_alignment"]["ok"] and abs(c["pulse_alignment"]["best_shift_back_s"]) <= 1.0e-6
    # 42.25 mm of marble at sqrt(rho/E) = sqrt(2711 / 44.8e9) (the rock's modulus, CaMa): 10.4 us
    assert c["pulse_alignment"]["transit_s"] == pytest.approx(0.04225 * math.sqrt(2711.08 / 44.8e9), rel=1e-4)
    assert c["noise"]["ok"] and c["noise"]["noise_over_peak"] == pytest.approx(0.0043, abs=0.0003)
    # the transmission gauge written 10 cm too far (too near): F2 is read 0.1 m / c0 = 20.1 us too late
    # (early), and it shows as a shift of F2 by -20.1 us (+20.1 us) beyond the 10.4 us limit
    c0 = math.sqrt(110e9 / 4430.0)
    for dx in (0.10, -0.10):
        doc = yaml.safe_load((SHEETS / "CaMa_SHPB_004.yaml").read_text())
        doc["bars"]["gauge_distance_transmitted"] = 1.0 + dx
        doc["signals"]["file"] = str(CAMA004)
        (tmp_path / "wrong.yaml").write_text(yaml.safe_dump(doc))
        s2, r2 = check_sheet(tmp_path / "wrong.yaml")
        c2 = lab_checks(reduce_sheet(s2, r2), transit_time(s2))
        assert not c2["pulse_alignment"]["ok"]
        assert c2["pulse_alignment"]["best_shift_back_s"] == pytest.approx(-dx / c0, abs=1.2e-6)
        assert not c2["force_balance"]["ok"]


def test_a_disc_sheets_stress_is_the_splitting_stress(tmp_path):
    doc = yaml.safe_load((SHEETS / "CaMa_SHPB_004.yaml").read_text())
    doc["signals"]["file"] = str(CAMA004)
    doc["specimen"] = {"geometry": "brazilian_disc", "diameter": 0.040, "thickness": 0.020, "flat_angle_deg": 20.0}
    (tmp_path / "disc.yaml").write_text(yaml.safe_dump(doc))
    sheet, raw = check_sheet(tmp_path / "disc.yaml")
    red = reduce_sheet(sheet, raw)
    np.testing.assert_allclose(red.stress_back, 2 * red.force_back / (math.pi * 0.040 * 0.020), rtol=1e-12)
    np.testing.assert_allclose(red.stress_front, 2 * red.force_front / (math.pi * 0.040 * 0.020), rtol=1e-12)
    assert red.noise_std_Pa["stress"] == pytest.approx(
        red.noise_std_strain["transmitted"] * 110e9 * math.pi * 0.05 ** 2 / 4 * 2 / (math.pi * 0.040 * 0.020), rel=1e-9)


def test_reduce_refuses_a_bad_sheet_with_exit_code_2(tmp_path, capsys):
    doc = yaml.safe_load((SHEETS / "CaMa_SHPB_004.yaml").read_text())
    doc["specimen"]["diameter"] = 0.060
    doc["signals"]["file"] = str(CAMA004)
    (tmp_path / "wide.yaml").write_text(yaml.safe_dump(doc))
    assert main(["reduce", str(tmp_path / "wide.yaml"), "--out", str(tmp_path / "out")]) == 2
    assert "specimen.diameter: expected at most the bar diameter 0.05 m" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_sheet_from_freiburg_writes_the_shipped_example(tmp_path):
    out = tmp_path / "sheets" / "x.yaml"
    assert main(["sheet-from-freiburg", str(CAMA004), "--out", str(out)]) == 0
    mine = yaml.safe_load(out.read_text())
    shipped = yaml.safe_load((SHEETS / "CaMa_SHPB_004.yaml").read_text())
    for key in ("name", "bars", "specimen", "rock", "metadata"):
        assert mine[key] == shipped[key], key
    assert (out.parent / mine["signals"]["file"]).resolve() == CAMA004.resolve()
