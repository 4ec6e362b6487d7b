"""Readers of measured SHPB records: Freiburg DAQ files and spreadsheets, paths, errors.

The records are those shipped in ``data/`` (each folder's PROVENANCE.md); a missing file fails with a
FileNotFoundError naming it and ``FDEM_DATA_DIR``, never a skip.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from shpb.paths import ENV_DATA_DIR, data_dir, freiburg_data_dir, freiburg_raw_files
from shpb.lab.records import (
    freiburg_specimen,
    read_freiburg_metadata,
    read_freiburg_raw,
    read_petrophysical_properties,
    rock_properties,
)
from shpb.lab.reduction import FREIBURG_BAR, bridge_strain_per_volt


# ------------------------------------------------------------------------------------------------
# synthetic Freiburg-format files
# ------------------------------------------------------------------------------------------------
def _freiburg_text(rows: np.ndarray, decimal: str, sample_rate: float = 2.0e6, block: int | None = None,
                   samplerate_line: str | None = None) -> str:
    header = [
        "Starttime;7/8/2020 11:48:58 AM",
        "Triggertime;11:48:58.000000000000000 ",
        "TriggerSample;-100",
        samplerate_line if samplerate_line is not None else f"Samplerate;{sample_rate:.0f} Hz",
        f"Blocklength;{rows.shape[0] if block is None else block}",
        "",
        "Channel;A1 (0.A1);A2 (0.A2);A3 (0.A3);A4 (0.A4);",
        "Time;Signal;Signal;Signal;Signal;",
        "s;V;V;V;V;",
        "",
        "",
    ]
    body = []
    for r in rows:
        fields = [f"{r[0]:.8e}"] + [f"{v:.5e}" for v in r[1:]]
        line = ";".join(fields)
        body.append(line.replace(".", ",") if decimal == "," else line)
    return "\r\n".join(header + body) + "\r\n"


def _synthetic_rows(n: int = 64, sample_rate: float = 2.0e6, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = -3.0e-5 + np.arange(n) / sample_rate
    volts = np.round(rng.normal(0.0, 0.5, size=(n, 4)), 5)
    return np.column_stack([t, volts])


def test_comma_and_dot_decimal_separators_parse_to_same_numbers(tmp_path):
    rows = _synthetic_rows()
    dot = tmp_path / "dot.txt"
    comma = tmp_path / "comma.txt"
    dot.write_text(_freiburg_text(rows, "."), newline="")
    comma.write_text(_freiburg_text(rows, ","), newline="")
    assert "," in comma.read_text().splitlines()[11] and "." not in comma.read_text().splitlines()[11]
    a, b = read_freiburg_raw(dot), read_freiburg_raw(comma)
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_array_equal(a.incident, b.incident)
    np.testing.assert_array_equal(a.transmitted, b.transmitted)
    # and both equal the numbers written (formatted to 5 significant decimals)
    np.testing.assert_allclose(a.incident, rows[:, 1:3].T, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(a.transmitted, rows[:, 3:5].T, rtol=1e-5, atol=1e-9)
    assert a.sample_rate == b.sample_rate == 2.0e6  # taken from the header, not assumed
    assert a.incident_channels == ("A1", "A2") and a.transmitted_channels == ("A3", "A4")


def test_missing_samplerate_header_names_file_and_field(tmp_path):
    path = tmp_path / "CaMa_SHPB_999_broken.txt"
    path.write_text(_freiburg_text(_synthetic_rows(), ".", samplerate_line="Sampletime;0.8 us"))
    with pytest.raises(ValueError) as err:
        read_freiburg_raw(path)
    assert "CaMa_SHPB_999_broken.txt" in str(err.value) and "Samplerate" in str(err.value)


def test_non_numeric_data_row_names_file_line_and_fields(tmp_path):
    text = _freiburg_text(_synthetic_rows(), ".").splitlines()
    text[20] = text[20].replace(";", ";abc", 1)
    path = tmp_path / "bad_row.txt"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError) as err:
        read_freiburg_raw(path)
    msg = str(err.value)
    assert "bad_row.txt" in msg and "line 21" in msg and "A1..A4" in msg


def test_wrong_column_count_is_rejected(tmp_path):
    text = _freiburg_text(_synthetic_rows(), ".").splitlines()
    text[15] = ";".join(text[15].split(";")[:4])
    path = tmp_path / "short_row.txt"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError, match=r"short_row\.txt: line 16: expected 5"):
        read_freiburg_raw(path)


def test_truncated_file_disagrees_with_blocklength(tmp_path):
    path = tmp_path / "truncated.txt"
    path.write_text(_freiburg_text(_synthetic_rows(), ".", block=100))
    with pytest.raises(ValueError, match=r"truncated\.txt: header 'Blocklength' says 100 samples but 64"):
        read_freiburg_raw(path)


def test_header_only_file_is_rejected(tmp_path):
    path = tmp_path / "empty.txt"
    path.write_text("\n".join(_freiburg_text(_synthetic_rows(), ".").splitlines()[:11]) + "\n")
    with pytest.raises(ValueError, match=r"empty\.txt: expected 11 header lines followed by data rows"):
        read_freiburg_raw(path)


def test_sample_rate_inconsistent_with_time_column_is_rejected(tmp_path):
    path = tmp_path / "rate.txt"
    path.write_text(_freiburg_text(_synthetic_rows(sample_rate=2.0e6), ".", sample_rate=1.25e6))
    with pytest.raises(ValueError, match=r"rate\.txt: time column is not uniform with the header 'Samplerate'"):
        read_freiburg_raw(path)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.txt"):
        read_freiburg_raw(tmp_path / "nope.txt")


# ------------------------------------------------------------------------------------------------
# real Freiburg files
# ------------------------------------------------------------------------------------------------
def _raw(stem: str) -> Path:
    hits = [p for p in freiburg_raw_files() if p.stem.startswith(stem)]
    assert len(hits) == 1, f"expected one Freiburg record starting with {stem}, found {hits}"
    return hits[0]


def test_real_records_with_both_separators_read_at_1_25_MHz():
    # ',' is used by SeeSst_001..015 only; SeeSst_018 and 022..029 use '.' like CaMa and SaLi
    cama = read_freiburg_raw(_raw("CaMa_SHPB_005"))
    sees = read_freiburg_raw(_raw("SeeSst_SHPB_001"))
    assert "decimal separator '.'" in cama.notes and "decimal separator ','" in sees.notes
    assert sees.time[0] == pytest.approx(-4.4893616) and sees.incident[1, 0] == pytest.approx(-18.125e-3)
    for rec, n in ((cama, 2573), (sees, 1714)):
        assert rec.sample_rate == 1.25e6 and math.isclose(rec.dt, 0.8e-6)
        assert rec.n_samples == n and rec.incident.shape == (2, n) and rec.transmitted.shape == (2, n)
        np.testing.assert_allclose(np.diff(rec.time), rec.dt, atol=1e-9)
    # first data row of CaMa_005: 2.42560000e-03;1.87500e-03;-3.12500e-03;1.25000e-03;-9.37500e-03
    assert cama.time[0] == pytest.approx(2.4256e-3)
    np.testing.assert_allclose([cama.incident[0, 0], cama.incident[1, 0], cama.transmitted[0, 0],
                                cama.transmitted[1, 0]], [1.875e-3, -3.125e-3, 1.25e-3, -9.375e-3])
    # incident peaks 0.3-3 V, compression positive (PROVENANCE)
    assert 1.8 < cama.incident.mean(axis=0).max() < 2.2


def test_every_freiburg_record_reads():
    files = freiburg_raw_files()
    counts = {lith: sum(p.parent.name == lith for p in files) for lith in ("CaMa", "SaLi", "SeeSst")}
    assert counts == {"CaMa": 15, "SaLi": 12, "SeeSst": 24}
    for p in files:
        rec = read_freiburg_raw(p)
        assert rec.sample_rate == 1.25e6 and 1529 <= rec.n_samples <= 4327, p.name


def test_freiburg_bar_constants_match_provenance():
    assert FREIBURG_BAR.E == 110e9 and FREIBURG_BAR.rho == 4430.0 and FREIBURG_BAR.diameter == 0.05
    assert FREIBURG_BAR.gauge_distance_incident == 1.25 and FREIBURG_BAR.gauge_distance_transmitted == 1.0
    assert FREIBURG_BAR.c0 == pytest.approx(4983, abs=1)
    # 4 U / (U0 V k) with U0 = 5 V, V = 400, k = 1.99
    assert FREIBURG_BAR.strain_per_volt_incident == pytest.approx(1.005e-3, rel=1e-3)
    assert bridge_strain_per_volt(8.0, 200.0, 2.061, active_arms=2) == pytest.approx(6.065e-4, rel=1e-3)


def test_metadata_in_si_units():
    meta = read_freiburg_metadata(freiburg_data_dir() / "Rae2021" / "CaMa.xlsx")
    row = meta[meta["name"] == "CaMa_SHPB_005_Ti25_60b_Al12b_0_001"].iloc[0]
    assert row["length_m"] == pytest.approx(0.03912)
    assert row["diameter_m"] == pytest.approx(0.03891)
    assert row["failure"] == "Y"
    assert row["strength_Pa"] == pytest.approx(200.2e6) and row["strength_sd_Pa"] == pytest.approx(4.8e6)
    assert row["strain_rate_per_s"] == pytest.approx(117.4)
    assert row["E_Pa"] == pytest.approx(39.9e9)
    assert row["gas_pressure_Pa"] == pytest.approx(6.0e5)
    assert row["reference_stress_Pa"] == row["strength_Pa"]
    assert set(meta["experiment_type"]) == {"UCS", "SHPB"}
    assert (meta["experiment_type"] == "SHPB").sum() == 15


def test_specimen_lookup_uses_max_stress_for_intact_samples():
    spec = freiburg_specimen(_raw("SeeSst_SHPB_004"))
    assert spec["failure"] == "N" and math.isnan(spec["strength_Pa"])
    assert spec["max_stress_Pa"] == pytest.approx(55.8e6)
    assert spec["reference_stress_Pa"] == pytest.approx(55.8e6)
    assert spec["length_m"] == pytest.approx(0.040) and spec["diameter_m"] == pytest.approx(0.041)


def test_specimen_lookup_of_unknown_record_names_spreadsheet(tmp_path):
    src = freiburg_data_dir() / "Rae2021"
    (tmp_path / "Rae2021" / "SHPBdata" / "CaMa").mkdir(parents=True)
    shutil.copy(src / "CaMa.xlsx", tmp_path / "Rae2021" / "CaMa.xlsx")
    fake = tmp_path / "Rae2021" / "SHPBdata" / "CaMa" / "CaMa_SHPB_777_Ti25_60b_Al12b_0_001.txt"
    fake.write_text("")
    with pytest.raises(KeyError, match="CaMa_SHPB_777.*CaMa.xlsx"):
        freiburg_specimen(fake)
    (tmp_path / "Rae2021" / "SHPBdata" / "XxYy").mkdir()
    with pytest.raises(FileNotFoundError, match="XxYy.xlsx"):
        freiburg_specimen(tmp_path / "Rae2021" / "SHPBdata" / "XxYy" / "XxYy_SHPB_001.txt")


def test_petrophysical_properties_in_si_units():
    table = read_petrophysical_properties(freiburg_data_dir() / "PetrophysicalProperties.xlsx")
    granite = table[table["lithology"] == "Malsburg Granite"].iloc[0]
    # PROVENANCE: Malsburg granite E = 36.1 GPa, nu = 0.224, rho = 2.62 g/cm^3
    assert granite["E_Pa"] == pytest.approx(36.1e9)
    assert granite["nu"] == pytest.approx(0.224)
    assert granite["rho_kg_m3"] == pytest.approx(2620, abs=5)
    marble = rock_properties("CaMa")
    assert marble["E"] == pytest.approx(44.8e9) and marble["nu"] == pytest.approx(0.245)
    assert marble["rho"] == pytest.approx(2711, abs=1)
    assert rock_properties("seeberger sandstone")["E"] == pytest.approx(13.8e9)
    assert set(table[table["code"] == "MaGn"]["variant"]) == {"Parallel", "Perpendicular"}
    with pytest.raises(KeyError, match="Granitoid"):
        rock_properties("Granitoid")


def test_data_dir_honours_env_var_and_a_missing_file_names_its_path_and_the_variable(monkeypatch, tmp_path):
    (tmp_path / "freiburg-rae-rock-shpb").mkdir()
    monkeypatch.setenv(ENV_DATA_DIR, str(tmp_path))
    assert data_dir() == tmp_path.resolve()
    assert freiburg_data_dir() == tmp_path.resolve() / "freiburg-rae-rock-shpb"
    with pytest.raises(FileNotFoundError) as err:
        rock_properties("CaMa")  # the user's folder has no PetrophysicalProperties.xlsx
    assert "PetrophysicalProperties.xlsx" in str(err.value) and ENV_DATA_DIR in str(err.value)
    with pytest.raises(FileNotFoundError) as err:
        freiburg_raw_files(["CaMa"])
    assert str(tmp_path) in str(err.value) and "CaMa" in str(err.value)
    monkeypatch.setenv(ENV_DATA_DIR, str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError) as err:
        data_dir()
    assert "missing" in str(err.value) and ENV_DATA_DIR in str(err.value)


def test_default_data_dir_is_the_repositorys_own(monkeypatch):
    """Without the variable the product reads the data shipped in the repository, nothing beside it."""
    monkeypatch.delenv(ENV_DATA_DIR, raising=False)
    repo = Path(__file__).resolve().parents[1]
    assert data_dir() == repo / "data"
    for path in freiburg_raw_files():
        assert repo / "data" in path.parents
