"""Test sheets (shpb.lab.sheet, shpb.lab.sheet_readers): the shipped example sheets load and read into
the RawRecord of their format with the sheet's bars and specimen; a lithology is looked up in the
shipped table; ten malformed sheets each stop with the sheet, the field and what was expected."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from shpb.lab.bars import FREIBURG_BAR
from shpb.lab.sheet import SheetError, lithology_table, load_sheet
from shpb.lab.sheet_readers import check_sheet

REPO = Path(__file__).resolve().parents[1]
SHEETS = REPO / "data" / "examples" / "sheets"


# --------------------------------------------------------------------------------------------------
# the shipped examples
# --------------------------------------------------------------------------------------------------
def test_every_example_sheet_loads_and_reads():
    names = sorted(p.stem for p in SHEETS.glob("*.yaml"))
    assert {"CaMa_SHPB_004", "LANL_Cu_273K", "LANL_PMMA_13", "Yao_epoxy_01", "Yao_steel945_02"} <= set(names)
    for path in SHEETS.glob("*.yaml"):
        sheet, raw = check_sheet(path)
        assert raw.name == sheet.name == path.stem
        assert raw.bar.diameter == sheet.bar.diameter and raw.specimen_diameter == sheet.specimen_diameter
        assert raw.n_samples > 1000 and np.all(np.isfinite(raw.incident))


def test_the_freiburg_sheet_carries_the_freiburg_bars_and_the_spreadsheet_specimen():
    sheet, raw = check_sheet(SHEETS / "CaMa_SHPB_004.yaml")
    for f in ("E", "rho", "diameter", "gauge_distance_incident", "gauge_distance_transmitted",
              "strain_per_volt_incident", "strain_per_volt_transmitted", "compression_sign"):
        assert getattr(raw.bar, f) == getattr(FREIBURG_BAR, f), f
    # the spreadsheet row of CaMa_SHPB_004: 42.25 mm x 38.94 mm; the rock is the lithology's (CaMa's
    # 44.8 GPa, PetrophysicalProperties.xlsx), not the row's 33.9 GPa, the slope of this test's own curve
    assert sheet.specimen_length == pytest.approx(42.25e-3, rel=1e-12)
    assert sheet.specimen_diameter == pytest.approx(38.94e-3, rel=1e-12)
    assert sheet.rock["E"] == 44.8e9 and sheet.rock["nu"] == 0.245


def test_lanl_sheet_takes_the_files_bridge_factors_and_yao_the_sheets():
    _, cu = check_sheet(SHEETS / "LANL_Cu_273K.yaml")
    # 2 / (GF gain U_exc) with GF 2.061 / 2.062, gain 200, 8 V (the file's metadata)
    assert cu.bar.strain_per_volt_incident == pytest.approx(2 / (2.061 * 200 * 8), rel=2e-3)
    assert cu.bar.compression_sign == 1
    assert any("from the signals file" in n for n in cu.notes)
    _, epoxy = check_sheet(SHEETS / "Yao_epoxy_01.yaml")
    assert epoxy.unit == "V" and epoxy.bar.strain_per_volt_incident == 5.01e-4
    assert epoxy.bar.compression_sign == -1


def test_a_lithology_is_looked_up_in_the_shipped_table(tmp_path):
    doc = _good_doc()
    doc["rock"] = {"lithology": "Carrara Marble"}
    sheet = load_sheet(_write(tmp_path, doc))
    # PetrophysicalProperties.xlsx, Summary: Carrara marble E 44.8 GPa, nu 0.245, rho 2.711 g/cm^3
    assert sheet.rock["E"] == 44.8e9 and sheet.rock["nu"] == 0.245
    assert sheet.rock["rho"] == pytest.approx(2711.08, abs=0.01)
    doc["rock"] = {"lithology": "MaGr", "E": 30.0e9}
    sheet = load_sheet(_write(tmp_path, doc))
    assert sheet.rock["E"] == 30.0e9 and sheet.rock["nu"] == 0.224   # the sheet's E wins, the table's nu
    assert lithology_table()["granite_godinez2021"]["E"] == 35.0e9    # the paper's Table 1


# --------------------------------------------------------------------------------------------------
# malformed sheets
# --------------------------------------------------------------------------------------------------
def _signals_csv(path: Path, n: int = 400, dt_us: float = 0.5) -> pd.DataFrame:
    """A small two-bar record in microstrain: a half-sine incident pulse and its transmitted part."""
    t = dt_us * np.arange(n)
    pulse = np.where((t > 40) & (t < 120), 800.0 * np.sin(np.pi * (t - 40) / 80), 0.0)
    df = pd.DataFrame({"t_us": t, "inc_1": pulse, "inc_2": pulse, "tra": 0.5 * np.roll(pulse, 100)})
    df.to_csv(path, index=False)
    return df


def _good_doc() -> dict:
    return {
        "name": "GrGr_test_1",
        "signals": {"file": "signals.csv", "format": "csv", "compression_sign": 1,
                    "time": {"column": "t_us", "unit": "us"},
                    "incident": {"columns": ["inc_1", "inc_2"], "unit": "microstrain"},
                    "transmitted": {"columns": ["tra"], "unit": "microstrain"}},
        "bars": {"material": "steel", "E": 2.0e11, "rho": 7850.0, "nu": 0.29, "diameter": 0.020,
                 "gauge_distance_incident": 1.0, "gauge_distance_transmitted": 0.5},
        "specimen": {"geometry": "cylinder", "length": 0.016, "diameter": 0.016},
        "rock": {"lithology": "MaGr"},
    }


def _write(folder: Path, doc: dict, name: str = "sheet.yaml") -> Path:
    if not (folder / "signals.csv").exists():
        _signals_csv(folder / "signals.csv")
    path = folder / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _set(doc, dotted, value):
    *head, last = dotted.split(".")
    d = doc
    for k in head:
        d = d[k]
    if value is _DELETE:
        del d[last]
    else:
        d[last] = value


_DELETE = object()


def _nonuniform(folder):
    df = _signals_csv(folder / "signals.csv")
    df.loc[200:, "t_us"] += 3.0        # a 3 us gap (six samples lost)
    df.to_csv(folder / "signals.csv", index=False)


def _nan(folder):
    df = _signals_csv(folder / "signals.csv")
    df.loc[150, "tra"] = np.nan
    df.to_csv(folder / "signals.csv", index=False)


# (what, edit of the sheet or of its signals file, field named, what the message says was expected)
MALFORMED = [
    ("missing field", ("bars.E", _DELETE), "bars.E", "missing; expected bar Young's modulus [Pa]"),
    ("wrong unit", ("signals.incident.unit", "kV"), "signals.incident.unit",
     "expected one of ['V', 'mV', 'strain', 'microstrain'], got 'kV'"),
    ("specimen wider than the bar", ("specimen.diameter", 0.025), "specimen.diameter",
     "expected at most the bar diameter 0.02 m"),
    ("unknown format", ("signals.format", "tdms"), "signals.format", "expected one of ['freiburg', 'lanl_raw'"),
    ("name with a space", ("name", "GrGr test 1"), "name", "no spaces"),
    ("signals file missing", ("signals.file", "scope/ch1.csv"), "signals.file", "expected an existing file"),
    ("columns missing", ("signals.incident.columns", ["inc_1", "inc_3"]), "signals.incident.columns",
     "expected a column of signals.csv (['t_us', 'inc_1', 'inc_2', 'tra']), 'inc_3' not found"),
    ("non-uniform time", _nonuniform, "signals.time.column", "expected a uniform time axis"),
    ("NaN in the signals", _nan, "signals.transmitted.columns", "expected a number on every row of column 'tra'"),
    ("negative size", ("specimen.length", -0.016), "specimen.length", "expected a number > 0"),
]


@pytest.mark.parametrize("what, edit, field, expected", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_a_malformed_sheet_names_the_sheet_the_field_and_the_expectation(tmp_path, what, edit, field, expected):
    doc = copy.deepcopy(_good_doc())
    path = _write(tmp_path, doc)
    check_sheet(path)   # the unedited sheet is valid: the edit alone makes it fail
    if callable(edit):
        edit(tmp_path)
    else:
        _set(doc, *edit)
        path = _write(tmp_path, doc)
    with pytest.raises(SheetError) as info:
        check_sheet(path)
    lines = [ln for ln in info.value.problems if f"{path}: {field}: " in ln]
    assert lines, info.value.problems
    assert any(expected in ln for ln in lines), lines


@pytest.mark.parametrize("what, edit, field, expected", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_a_malformed_sheet_stops_the_config_validation_before_any_job(tmp_path, what, edit, field, expected):
    """The workflow validates its config (and so every sheet it names) before any job runs."""
    from calibration.workflow_io import ConfigError, validate_config

    doc = copy.deepcopy(_good_doc())
    path = _write(tmp_path, doc)
    if callable(edit):
        edit(tmp_path)
    else:
        _set(doc, *edit)
        path = _write(tmp_path, doc)
    cfg = {"experiments": {"byo": {
        "kind": "measured", "geometry": "cylinder", "preset": "fast", "seed": 1, "ensemble_size": 4, "posterior": "ensemble",
        "parameters": {"sigma_t": [1.0e7, 1.2e8], "E_t": [100.0, 5000.0]},
        "simulation": {"t_end": 1.0e-4}, "observations": {"t_end": 1.0e-4, "records": [str(path)]}}}}
    with pytest.raises(ConfigError) as info:
        validate_config(cfg, REPO / "config" / "schema.yaml")
    lines = [ln for ln in str(info.value).splitlines() if f"experiments.byo.observations.records: {path}: {field}: " in ln]
    assert lines and any(expected in ln for ln in lines), str(info.value)


def test_snakemake_stops_on_a_malformed_sheet_before_any_job(tmp_path):
    import os
    import subprocess
    import sys

    doc = _good_doc()
    doc["specimen"]["diameter"] = 0.025
    path = _write(tmp_path, doc)
    cfg = {"run": ["byo"], "experiments": {"byo": {
        "kind": "measured", "geometry": "cylinder", "preset": "fast", "seed": 1, "ensemble_size": 4, "posterior": "ensemble",
        "parameters": {"sigma_t": [1.0e7, 1.2e8], "E_t": [100.0, 5000.0]},
        "simulation": {"t_end": 1.0e-4}, "observations": {"t_end": 1.0e-4, "records": [str(path)]}}}}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg))
    out = subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory",
                          str(tmp_path), "--configfile", str(tmp_path / "config.yaml"), "--workflow-profile", "none",
                          "--cores", "1"], capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert out.returncode != 0
    assert f"{path}: specimen.diameter: expected at most the bar diameter 0.02 m" in out.stderr
    assert not (tmp_path / "results").exists()
