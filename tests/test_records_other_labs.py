"""Records from other labs read into the same RawRecord and reduced by the same code.

Numbers asserted are those of each folder's PROVENANCE.md under ``data/`` (the shipped excerpts).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from shpb.paths import lanl_data_dir, yao_data_dir
from shpb.lab.other_labs import read_lanl_minikolsky, read_lanl_raw, read_yao_record
from shpb.lab.reduction import reduce_record


@pytest.fixture(scope="module")
def lanl_cu():
    return read_lanl_raw(lanl_data_dir() / "LANLstandard" / "Cu"
                         / "20061201_1148HE_CuOFE_273K.raw")


def test_lanl_cu_metadata_in_si(lanl_cu):
    bar = lanl_cu.bar
    assert bar.E == pytest.approx(109.3e9, rel=1e-3)
    assert bar.rho == pytest.approx(4416.0)          # written "4.416" (g/cm^3) in the file
    assert bar.diameter == pytest.approx(9.47e-3)
    assert bar.c0 == pytest.approx(4975, abs=2)
    assert bar.gauge_distance_incident == pytest.approx(0.381) == bar.gauge_distance_transmitted
    # 2 / (GF gain U_exc) with GF 2.061 / 2.062, gain 200, 8 V: about 6.06e-4 /V
    assert bar.strain_per_volt_incident == pytest.approx(6.06e-4, rel=2e-3)
    assert bar.strain_per_volt_transmitted == pytest.approx(6.06e-4, rel=2e-3)
    assert bar.compression_sign == 1
    assert lanl_cu.specimen_diameter == pytest.approx(6.34e-3)
    assert lanl_cu.specimen_length == pytest.approx(3.204e-3)
    assert lanl_cu.sample_rate == pytest.approx(10e6) and lanl_cu.n_samples == 5000
    assert lanl_cu.time[0] == pytest.approx(-5.0e-5)


def test_lanl_cu_signal_levels_match_provenance(lanl_cu):
    assert lanl_cu.incident.max() == pytest.approx(3.62, abs=0.05)
    assert lanl_cu.incident.min() == pytest.approx(-2.85, abs=0.1)
    assert lanl_cu.transmitted.max() == pytest.approx(2.28, abs=0.03)


def test_lanl_cu_reduces_to_336_MPa(lanl_cu):
    red = reduce_record(lanl_cu)
    # PROVENANCE: transmitted 2.28 V -> 1.38e-3 -> bar force 10.6 kN -> specimen stress ~336 MPa
    assert red.peak_stress == pytest.approx(336e6, rel=0.05)
    assert red.force_back.max() == pytest.approx(10.6e3, rel=0.05)
    assert red.eps_transmitted.max() == pytest.approx(1.38e-3, rel=0.05)
    # incident pulse starts at about 0 us (gauge time); pre-trigger noise about 5.5 mV
    assert abs(red.arrival_time_gauge) < 10e-6
    noise_v = red.noise_std_strain["transmitted"] / lanl_cu.bar.strain_per_volt_transmitted
    assert 3e-3 < noise_v < 9e-3
    # the window is the incident gauge's clean time 2 x_I / c0 = 153 us
    assert red.time[-1] == pytest.approx(2 * 0.381 / lanl_cu.bar.c0, abs=red.dt)


def test_lanl_mini_kolsky_pmma():
    raw = read_lanl_minikolsky(lanl_data_dir() / "mini-Kolsky" / "PMMA-13"
                               / "PMMA_13_Input.dat")
    # the shipped excerpt: the first 20,000 of 50,000 samples (-80 to +80 us, PROVENANCE.md)
    assert raw.n_samples == 20_000 and raw.dt == pytest.approx(8e-9)
    assert raw.incident.shape == (2, 20_000) and raw.transmitted.shape == (2, 20_000)
    assert raw.bar.diameter == pytest.approx(2.381e-3, rel=1e-3)
    assert raw.bar.rho == pytest.approx(2810.0) and raw.bar.c0 == pytest.approx(5051, abs=2)
    assert raw.bar.strain_per_volt_incident == pytest.approx(9.52e-4, rel=1e-3)
    assert raw.specimen_diameter == pytest.approx(1.54e-3) and raw.specimen_length == pytest.approx(1.47e-3)
    # first incident pulse about -1.4 V (compression negative on this set-up)
    t = raw.time
    first = (t > 0) & (t < 20e-6)
    assert raw.incident[:, first].mean(axis=0).min() == pytest.approx(-1.4, abs=0.15)
    red = reduce_record(raw)
    # transmitted about -1.0 V -> E_b (D_b/D_s)^2 * 1.0 V * 9.52e-4 /V = 163 MPa
    expected = 71.7e9 * (2.381 / 1.54) ** 2 * 1.0 * 9.52e-4
    assert red.peak_stress == pytest.approx(expected, rel=0.10)
    assert red.channels_used == {"incident": ("Ch1", "Ch2"), "transmitted": ("Ch3", "Ch4")}


def test_yao_voltage_and_microstrain_files_give_the_same_record():
    base = yao_data_dir() / "steel_945" / "sample_02"
    volt = read_yao_record(base / "raw_voltage.xlsx", strain_per_volt=4.96e-4)
    micro = read_yao_record(base / "raw_microstrain.xlsx")
    assert volt.unit == "V" and micro.unit == "strain"
    assert volt.n_samples == micro.n_samples == 20_000
    assert volt.dt == pytest.approx(32e-9, rel=1e-3)
    np.testing.assert_allclose(volt.incident * 4.96e-4, micro.incident, rtol=0.01, atol=2e-6)
    bar = volt.bar
    assert (bar.E, bar.rho, bar.diameter) == (210e9, 7800.0, 0.02)
    assert (bar.gauge_distance_incident, bar.gauge_distance_transmitted) == (1.020, 0.770)
    assert bar.compression_sign == -1
    assert (volt.specimen_diameter, volt.specimen_length) == (0.008, 0.004)
    rv, rm = reduce_record(volt), reduce_record(micro)
    assert rv.peak_stress == pytest.approx(rm.peak_stress, rel=0.01)
    # compression negative in the file -> positive specimen stress; steel flows near 1 GPa
    assert 0.6e9 < rv.peak_stress < 1.5e9
    with pytest.raises(ValueError, match="strain_per_volt"):
        read_yao_record(base / "raw_voltage.xlsx")
    # the old BIFF .xls of sample_01 reads through xlrd into the same kind of record
    xls = read_yao_record(yao_data_dir() / "steel_945" / "sample_01" / "raw_voltage.xls", strain_per_volt=4.96e-4)
    assert xls.n_samples == 20_000 and xls.dt == pytest.approx(32e-9, rel=1e-3)
    assert 0.6e9 < reduce_record(xls).peak_stress < 1.5e9


def test_yao_rounded_time_column_is_rebuilt():
    path = (yao_data_dir() / "epoxy_resin"
            / "sample_01" / "raw_voltage.csv")
    raw = read_yao_record(path, strain_per_volt=5.01e-4)
    assert any("rebuilt" in n for n in raw.notes)
    assert raw.dt == pytest.approx(80e-9, rel=0.01)
    assert np.allclose(np.diff(raw.time), raw.dt)
    assert math.isclose(raw.bar.gauge_distance_incident, 1.018) and math.isclose(raw.specimen_diameter, 0.010)


def test_lanl_malformed_file_names_the_file(tmp_path):
    bad = tmp_path / "broken.raw"
    bad.write_text("Test Date\t12/1/2006\tIncident/Reflected Waveform\tTransmitted Waveform\n"
                   "Test Time\t11:48\t-5.0E-05\t-5.0E-05\nx\t1\t1.0E-07\tabc\n", encoding="cp1252")
    with pytest.raises(ValueError, match=r"broken\.raw: line 3: waveform columns 3-4 should be numbers"):
        read_lanl_raw(bad)
