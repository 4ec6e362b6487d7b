"""Validity class of a test (shpb.lab.validity): its metrics on shipped records, its thresholds, a record
made invalid, the class in `python -m shpb reduce`'s output, and the refusal of an invalid calibration
record unless the experiment allows it (no shipped config refused)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from calibration.observations import ObservationFileError, check_record, record_validity
from shpb.__main__ import main
from shpb.lab.lab_reduce import lab_checks, reduce_sheet, transit_time
from shpb.lab.sheet_readers import check_sheet
from shpb.lab.validity import THRESHOLDS, classify

REPO = Path(__file__).resolve().parents[1]
CAMA = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa"
RAW004 = CAMA / "CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
RAW008 = CAMA / "CaMa_SHPB_008_Ti25_55b_Al12b_0_001.txt"
SHEET004 = REPO / "data/examples/sheets/CaMa_SHPB_004.yaml"


def _checks(R=0.02, transits=6.0, shift_ratio=0.2, noise=0.005) -> dict:
    return {"force_balance": {"mean_R_half_peak_to_peak": R},
            "stress_uniformity": {"transits_to_peak": transits},
            "pulse_alignment": {"best_shift_back_s": -shift_ratio * 1e-5, "limit_s": 1e-5},
            "noise": {"noise_over_peak": noise}}


def test_a_shipped_balanced_record_is_valid_with_its_numbers():
    v = record_validity(RAW004)
    assert v["class"] == "valid" and v["reasons"] == []
    m = v["metrics"]
    assert m["force_balance"]["value"] == pytest.approx(0.026, abs=0.002)
    assert m["noise"]["value"] == pytest.approx(0.0043, abs=0.0003)
    # 10 % of the peak to the peak over 42.25 mm of marble at sqrt(2711 / 44.8e9) = 10.4 us: many transits
    assert m["stress_uniformity"]["value"] > THRESHOLDS["stress_uniformity"][0]
    assert m["pulse_alignment"]["value"] <= 1.0
    assert all(m[k]["class"] == "valid" for k in m)


@pytest.mark.parametrize("kw,cls,metric", [
    ({"R": 0.05}, "valid", None), ({"R": 0.07}, "questionable", "force_balance"),
    ({"R": 0.101}, "invalid", "force_balance"), ({"R": math.nan}, "invalid", "force_balance"),
    ({"transits": 4.0}, "valid", None), ({"transits": 3.5}, "questionable", "stress_uniformity"),
    ({"transits": 3.0}, "invalid", "stress_uniformity"),
    ({"shift_ratio": 1.0}, "valid", None), ({"shift_ratio": 1.2}, "invalid", "pulse_alignment"),
    ({"noise": 0.02}, "valid", None), ({"noise": 0.03}, "questionable", "noise"), ({"noise": 0.06}, "invalid", "noise"),
])
def test_each_metric_is_graded_at_its_thresholds(kw, cls, metric):
    v = classify(_checks(**kw))
    assert v["class"] == cls
    if metric is None:
        assert v["reasons"] == []
    else:
        (reason,) = v["reasons"]
        assert reason.startswith(f"{metric} {cls}:")
        assert v["metrics"][metric]["class"] == cls and v["metrics"][metric]["source"]


def test_the_worst_metric_decides():
    v = classify(_checks(R=0.07, noise=0.06))
    assert v["class"] == "invalid" and len(v["reasons"]) == 2


def test_the_unbalanced_shipped_record_is_invalid_and_refused_unless_allowed():
    v = record_validity(RAW008)  # the lab's own checks fail: mean R 0.63, F2 shifted by -30 us
    assert v["class"] == "invalid"
    assert v["metrics"]["force_balance"]["value"] == pytest.approx(0.63, abs=0.02)
    assert v["metrics"]["pulse_alignment"]["class"] == "invalid"
    check_record(RAW008, 3.0e-4)  # not a calibration record: read and reduced, no verdict
    with pytest.raises(ObservationFileError) as err:
        check_record(RAW008, 3.0e-4, refuse_invalid=True)
    msg = str(err.value)
    assert str(RAW008) in msg and "force_balance invalid" in msg and "observations.allow_invalid: true" in msg


def test_a_wrong_gauge_distance_makes_a_valid_sheet_invalid(tmp_path):
    doc = yaml.safe_load(SHEET004.read_text())
    doc["signals"]["file"] = str(RAW004)
    doc["bars"]["gauge_distance_transmitted"] = 1.10  # 10 cm off: F2 read 20 us late
    (tmp_path / "wrong.yaml").write_text(yaml.safe_dump(doc))
    sheet, raw = check_sheet(tmp_path / "wrong.yaml")
    v = lab_checks(reduce_sheet(sheet, raw), transit_time(sheet))["validity"]
    assert v["class"] == "invalid"
    assert v["metrics"]["pulse_alignment"]["value"] > 1.5 and v["metrics"]["force_balance"]["class"] == "invalid"


def test_reduce_prints_and_writes_the_class(tmp_path, capsys):
    assert main(["reduce", str(SHEET004), "--out", str(tmp_path / "r")]) == 0
    assert "  validity: valid" in capsys.readouterr().out
    checks = json.loads((tmp_path / "r" / "checks.json").read_text())
    assert checks["validity"]["class"] == "valid"
    assert checks["stress_uniformity"]["transits_to_peak"] > 4.0


def _measured_experiments():
    for cfg in sorted((REPO / "config").glob("*.yaml")):
        if cfg.name == "schema.yaml":
            continue
        for name, exp in (yaml.safe_load(cfg.read_text()).get("experiments") or {}).items():
            if exp.get("kind") == "measured" and (exp.get("observations") or {}).get("records"):
                yield cfg.name, name, exp["observations"]


def test_no_shipped_config_has_a_refused_record():
    """The Snakefile's rule: a measured experiment's records are refused when invalid, unless allow_invalid."""
    allowed = []
    for cfg, name, obs in _measured_experiments():
        for rec in obs["records"]:
            check_record(REPO / rec, obs["t_end"], refuse_invalid=not obs.get("allow_invalid", False))
            if record_validity(REPO / rec)["class"] == "invalid":
                allowed.append((cfg, name, Path(rec).stem[:15]))
    # the one config that needs the switch: SeeSst_SHPB_027, 028, 029 (mean R 0.119, 0.163, 0.111)
    assert sorted(allowed) == [("validation.yaml", "sandstone_unseen", f"SeeSst_SHPB_02{k}") for k in (7, 8, 9)]
