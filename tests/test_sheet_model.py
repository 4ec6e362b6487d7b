"""The model's bars and specimen from a test sheet (shpb.simulate, calibration.observations,
calibration.workflow_io): a sheet with steel 20 mm bars and a 16 mm specimen runs a member end to end
through the workflow with those bars in the model (asserted from run.json); the Freiburg sheet gives
the Freiburg model; a bad sheet in a config stops the validation with the sheet's own message."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration.observations import measured_observations
from calibration.workflow_io import ConfigError, validate_config

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"
SHEETS = REPO / "data" / "examples" / "sheets"
EPOXY = REPO / "data/yao-shpb-shtb-metals-epoxy/impact_compression/epoxy_resin/sample_01/raw_voltage.csv"


def steel_sheet(folder: Path, **specimen) -> Path:
    """Steel bars of 20 mm (H. Yao's set-up, its measured incident wave) and a 16 mm granite cylinder."""
    doc = {"name": "steel20_granite16",
           "signals": {"file": str(EPOXY), "format": "yao", "strain_per_volt": 5.01e-4},
           "bars": {"material": "steel", "E": 2.10e11, "rho": 7800.0, "nu": 0.29, "diameter": 0.020,
                    "gauge_distance_incident": 1.018, "gauge_distance_transmitted": 0.741},
           "specimen": {"geometry": "cylinder", "length": 0.016, "diameter": 0.016, **specimen},
           "rock": {"lithology": "MaGr"}}
    path = folder / "steel20_granite16.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def measured_config(record: Path) -> dict:
    return {"run": ["byo"], "experiments": {"byo": {
        "kind": "measured", "geometry": "cylinder", "preset": "fast", "seed": 7, "ensemble_size": 3,
        "method": "esmda", "esmda": {"steps": 1}, "max_rank": 2, "posterior": "ensemble",
        "parameters": {"sigma_t": [1.0e7, 1.2e8], "E_t": [100.0, 5000.0]},
        "simulation": {"t_end": 1.0e-4, "sample_dt": 1.0e-6},
        "observations": {"t_end": 1.0e-4, "dt": 2.0e-6, "records": [str(record)], "error": {"kind": "ar1"}}}}}


def test_a_steel_20mm_sheet_runs_a_member_end_to_end_with_its_bars_in_the_model(tmp_path):
    sheet = steel_sheet(tmp_path)
    cfg = measured_config(sheet)
    # the steel bars' synthetic record is unbalanced (mean R 0.14 from half peak to peak: invalid by
    # shpb.lab.validity); what is tested here is the sheet's bars in the model, so it is allowed
    cfg["experiments"]["byo"]["observations"]["allow_invalid"] = True
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    member = "results/byo/iter_0/members/000/steel20_granite16/run.json"
    out = subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"),
                          "--directory", str(tmp_path), "--configfile", str(tmp_path / "config.yaml"),
                          "--workflow-profile", "none", "--cores", "1", member, "results/byo/observations/obs.csv"],
                         capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-4000:]
    run = json.loads((tmp_path / member).read_text())
    assert run["status"] == "ok"
    bars = run["bars"]
    assert (bars["E"], bars["rho"], bars["nu"], bars["diameter_m"]) == (2.10e11, 7800.0, 0.29, 0.020)
    assert bars["gauge_distance_m"] == [1.018, 0.741]
    assert bars["wave_speed_m_s"] == pytest.approx((2.10e11 / 7800.0) ** 0.5)
    assert run["specimen"]["diameter_m"] == 0.016 and run["specimen"]["length_m"] == 0.016
    # the rock of the sheet's lithology (Malsburg granite: PetrophysicalProperties.xlsx)
    assert (run["params"]["E"], run["params"]["nu"]) == (36.1e9, 0.224)
    curve = (tmp_path / member).with_name("curve.csv").read_text().splitlines()
    assert len(curve) > 90
    obs = (tmp_path / "results/byo/observations/obs.csv").read_text().splitlines()
    assert obs[1].startswith("steel20_granite16,")


def test_the_freiburg_sheet_drives_the_same_model_as_the_freiburg_file():
    from shpb.simulate import build

    raw = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
    params = {"sigma_t": 4.0e7, "E_t": 1000.0}
    a = build("cylinder", "fast", params, record=raw, window_s=1.0e-4)
    b = build("cylinder", "fast", params, record=SHEETS / "CaMa_SHPB_004.yaml", window_s=1.0e-4)
    assert a["geometry"].summary()["bar"] == b["geometry"].summary()["bar"]
    assert a["geometry"].specimen_dims == b["geometry"].specimen_dims
    assert a["params"] == b["params"]
    for bc_a, bc_b in zip(a["traction_bcs"], b["traction_bcs"]):
        np.testing.assert_array_equal(bc_a.times, bc_b.times)
        np.testing.assert_allclose(bc_a.traction, bc_b.traction, rtol=1e-9, atol=0)


def test_measured_observations_from_a_sheet_and_from_the_freiburg_file_agree():
    raw = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
    kw = {"t_start": 0.0, "t_end": 3.0e-4, "dt": 2.0e-6}
    a, _ = measured_observations({"CaMa_SHPB_004": raw}, **kw)
    b, _ = measured_observations({"CaMa_SHPB_004": SHEETS / "CaMa_SHPB_004.yaml"}, **kw)
    np.testing.assert_allclose(b.values, a.values, rtol=1e-9, atol=0)
    np.testing.assert_allclose(b.sigma, a.sigma, rtol=1e-9)
    assert b.corr_time["CaMa_SHPB_004"] == pytest.approx(a.corr_time["CaMa_SHPB_004"], rel=1e-9)


def test_a_bad_sheet_or_an_unsafe_record_name_fails_the_config_validation(tmp_path):
    wide = steel_sheet(tmp_path, diameter=0.025)
    with pytest.raises(ConfigError) as info:
        validate_config(measured_config(wide), SCHEMA)
    assert (f"experiments.byo.observations.records: {wide}: specimen.diameter: expected at most the bar "
            f"diameter 0.02 m") in str(info.value)
    spaced = tmp_path / "GrGr test 1.yaml"
    spaced.write_text(steel_sheet(tmp_path).read_text())
    with pytest.raises(ConfigError, match="record name 'GrGr test 1' .* not safe as a Snakemake wildcard"):
        validate_config(measured_config(spaced), SCHEMA)
    validate_config(measured_config(steel_sheet(tmp_path)), SCHEMA)   # the good sheet passes
