"""A record's simulation takes nothing from the record's response: neither its transmitted wave nor the
modulus the lab computed from its own stress-strain curve. A held-out record's prediction is built from
its incident wave, its specimen's size and the rock, so corrupting the rest leaves the model unchanged.

The checks compare the assembled model (``shpb.simulate.build``: the material constants and the
traction history the incident wave drives) with and without the corruption, on one Freiburg record and
on the synthetic granite disc's sheet (a stand-in with a csv record)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import shpb.lab.records as records
from shpb.simulate import build

REPO = Path(__file__).resolve().parents[1]
CAMA004 = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
DISC = REPO / "data/examples/granite_disc"
PARAMS = {"sigma_t": 4.0e7, "E_t": 1000.0}


def _same_model(a: dict, b: dict) -> None:
    assert a["params"] == b["params"]
    assert a["geometry"].specimen_dims == b["geometry"].specimen_dims
    assert len(a["traction_bcs"]) == len(b["traction_bcs"]) > 0
    for bc_a, bc_b in zip(a["traction_bcs"], b["traction_bcs"]):
        np.testing.assert_array_equal(bc_a.times, bc_b.times)
        np.testing.assert_array_equal(bc_a.traction, bc_b.traction)


def test_a_freiburg_record_is_modelled_without_its_transmitted_wave_or_its_own_modulus(monkeypatch):
    clean = build("cylinder", "fast", PARAMS, record=CAMA004, window_s=1.0e-4)
    # the rock's modulus (CaMa, PetrophysicalProperties.xlsx), not the spreadsheet row's 33.9 GPa
    assert clean["params"]["E"] == pytest.approx(44.8e9)

    read, specimen = records.read_freiburg_raw, records.freiburg_specimen
    rng = np.random.default_rng(7)

    def corrupted_raw(path):
        raw = read(path)
        # another test's answer: reversed, tripled and noisy, still finite
        raw.transmitted = 3.0 * raw.transmitted[:, ::-1] + rng.normal(0.0, 1e-3, raw.transmitted.shape)
        return raw

    def corrupted_row(path):
        return dict(specimen(path), E_Pa=3.0 * specimen(path)["E_Pa"])

    monkeypatch.setattr(records, "read_freiburg_raw", corrupted_raw)
    monkeypatch.setattr(records, "freiburg_specimen", corrupted_row)
    assert records.freiburg_specimen(CAMA004)["E_Pa"] == pytest.approx(3 * 33.9e9)
    _same_model(clean, build("cylinder", "fast", PARAMS, record=CAMA004, window_s=1.0e-4))


def test_the_disc_stand_in_is_modelled_without_its_transmitted_wave_or_a_stated_test_modulus(tmp_path):
    sheet = yaml.safe_load((DISC / "granite_disc.yaml").read_text())
    signals = np.genfromtxt(DISC / "signals.csv", delimiter=",", names=True)
    clean = build("brazilian_disc", "fast", PARAMS, record=DISC / "granite_disc.yaml")

    rng = np.random.default_rng(11)
    signals["transmitted_strain"] = (5.0 * signals["transmitted_strain"][::-1]
                                     + rng.normal(0.0, 1e-5, signals.shape))
    np.savetxt(tmp_path / "signals.csv", np.column_stack([signals[n] for n in signals.dtype.names]),
               delimiter=",", header=",".join(signals.dtype.names), comments="", fmt="%.9e")
    sheet["metadata"]["test_modulus_Pa"] = 12.0e9
    (tmp_path / "granite_disc.yaml").write_text(yaml.safe_dump(sheet))
    _same_model(clean, build("brazilian_disc", "fast", PARAMS, record=tmp_path / "granite_disc.yaml"))
