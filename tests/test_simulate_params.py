"""calibration.ensemble_files.simulation_params: where each simulation rule's parameters come from
(the `parameters` param of rules/simulate.smk, read by scripts/simulate.py), with the experiment's fixed
parameters underneath and the order the simulator's argv lists them in."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from calibration.ensemble_files import simulation_params
from calibration.workflow_io import validate_config

REPO = Path(__file__).resolve().parents[1]
FIXED = {"rho": 2650.0, "sigma_t": 1.0}


def _csv(tmp_path: Path, rows: list[dict]) -> Path:
    path = tmp_path / "params.csv"
    cols = list(rows[0])
    path.write_text(",".join(cols) + "\n" + "".join(",".join(str(r[c]) for c in cols) + "\n" for r in rows))
    return path


def test_given_values_sit_over_the_fixed_parameters_in_the_argv_order():
    out = simulation_params({"values": {"E_t": 500.0, "sigma_t": 4.5e7}}, FIXED)
    assert out == {"rho": 2650.0, "sigma_t": 4.5e7, "E_t": 500.0}
    assert list(out) == ["rho", "sigma_t", "E_t"]


def test_a_row_of_the_design_with_held_parameters_between_fixed_and_row(tmp_path):
    path = _csv(tmp_path, [{"member": 0, "E_t": 300.0}, {"member": 1, "E_t": 700.0}])
    assert simulation_params({"row": "001"}, FIXED, path) == {"rho": 2650.0, "sigma_t": 1.0, "E_t": 700.0}
    out = simulation_params({"row": "0", "held": {"sigma_t": 3.0e7, "E_t": 1.0}}, FIXED, path)
    assert out == {"rho": 2650.0, "sigma_t": 3.0e7, "E_t": 300.0}
    with pytest.raises(KeyError, match="member 002 not found"):
        simulation_params({"row": "002"}, FIXED, path)


def test_a_mapping_of_a_json_file(tmp_path):
    path = tmp_path / "params.json"
    path.write_text(json.dumps({"params": {"E_t": 812.5}, "source": "ensemble"}))
    assert simulation_params({"key": "params"}, FIXED, path) == {**FIXED, "E_t": 812.5}


def test_the_ensemble_mean_is_taken_in_the_unbounded_space(tmp_path):
    cfg = validate_config(yaml.safe_load((REPO / ".test" / "config" / "config.yaml").read_text()),
                          REPO / "config" / "schema.yaml")
    one = _csv(tmp_path, [{"member": 0, "sigma_t": 2.0e7, "E_t": 900.0}])
    mean = simulation_params({"ensemble_mean": "tiny"}, {"rho": 2650.0}, one, cfg["experiments"])
    assert list(mean) == ["rho", "sigma_t", "E_t"]
    assert math.isclose(mean["sigma_t"], 2.0e7, rel_tol=1e-12) and math.isclose(mean["E_t"], 900.0, rel_tol=1e-12)
    # sigma_t box 4e6-6e7 (logit transform): members at 5e6 and 3.2e7 have logits -4.0 and 0, whose mean
    # -2.0 maps to 1.07e7, not to the arithmetic mean 1.85e7
    two = _csv(tmp_path, [{"member": 0, "sigma_t": 5.0e6, "E_t": 300.0}, {"member": 1, "sigma_t": 3.2e7, "E_t": 300.0}])
    mean = simulation_params({"ensemble_mean": "tiny"}, {}, two, cfg["experiments"])
    lo, hi = 4.0e6, 6.0e7
    logit = [math.log((x - lo) / (hi - x)) for x in (5.0e6, 3.2e7)]
    z = sum(logit) / 2
    assert math.isclose(mean["sigma_t"], lo + (hi - lo) / (1 + math.exp(-z)), rel_tol=1e-9)
    assert 1.06e7 < mean["sigma_t"] < 1.08e7 and math.isclose(mean["E_t"], 300.0, rel_tol=1e-12)


@pytest.mark.parametrize("source", [{}, {"rows": 1}, {"value": {"E_t": 1.0}}])
def test_a_source_without_a_known_key_is_refused_naming_it(source):
    with pytest.raises(ValueError, match=r"source .* has none of the keys values, row, key, ensemble_mean"):
        simulation_params(source, FIXED)
