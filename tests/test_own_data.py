"""The synthetic dynamic Brazilian test of data/examples/granite_disc/ taken the way docs/own-data.md tells a
lab to: `python -m shpb init-config` writes the calibration from the test sheet, the config is shrunk to a
small size (N = 10, two ES-MDA analyses; init-config's own choices kept: window, dt, seed, the Table 2 box)
and the workflow runs it: the measured incident wave drives the disc, its splitting stress is observed,
and `sigma_t`'s 90 % interval holds the truth the example was made with
(data/examples/granite_disc/truth.json). config/own_data.yaml runs the same at full size.

`E_t` is not asserted against its truth. At this size its reported interval is the prior narrowed a
little (q05-q95 521-2236 J/m^2, 0.78 of the box, for a truth of 500 near the box's brittle end). One draw
of a 90 % interval cannot test its coverage; the coverage benchmark does, on the same posterior form
(benchmarks/results/coverage_one_posterior.json: `E_t` 0.85 over 100 twins, its misses at low truths).

Not robust at this size: the Latin hypercube follows the order of the parameters; with E_t listed
first (another draw of the same seed) the two ES-MDA analyses fitted worse than the prior and the
posterior reported is the prior ensemble (verdict worse_than_prior). init-config lists sigma_t first."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SHEET = REPO / "data" / "examples" / "granite_disc" / "granite_disc.yaml"
NAME = "granite_godinez2021_brazilian_disc"


def _snakemake(tmp_path, *args):
    return subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory",
                           str(tmp_path), "--configfile", str(tmp_path / "small.yaml"), "--workflow-profile", "none",
                           *args], capture_output=True, text=True, timeout=900, env=dict(os.environ))


def test_the_granite_disc_sheet_through_init_config_recovers_its_truth_at_a_small_size(tmp_path):
    # the record was simulated at the model's own mesh: no mesh error to carry (docs/own-data.md, section 4)
    made = subprocess.run([sys.executable, "-m", "shpb", "init-config", str(SHEET), "--no-approximation-error",
                           "--out", "written.yaml"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    doc = yaml.safe_load((tmp_path / "written.yaml").read_text())
    assert doc["run"] == [NAME]
    exp = doc["experiments"][NAME]
    assert list(exp["parameters"]) == ["sigma_t", "E_t"] and exp["seed"] == 31
    # the small size: fewer members and plain ES-MDA; the window, dt, box and seed are init-config's
    small = {**exp, "ensemble_size": 10, "method": "esmda", "esmda": {"steps": 2}, "max_rank": 3,
             "simulation": {**exp["simulation"], "sample_dt": 1.0e-6}}
    del small["max_iterations"]
    (tmp_path / "small.yaml").write_text(yaml.safe_dump({**doc, "experiments": {NAME: small}}, sort_keys=False))
    dry = _snakemake(tmp_path, "-n", "--cores", "2")
    assert dry.returncode == 0, (dry.stdout + dry.stderr)[-3000:]
    out = _snakemake(tmp_path, "--cores", "2", f"results/{NAME}/summary.json")
    assert out.returncode == 0, (out.stdout + out.stderr)[-4000:]
    summary = json.loads((tmp_path / f"results/{NAME}/summary.json").read_text())
    truth = json.loads((SHEET.parent / "truth.json").read_text())["params"]
    assert summary["posterior_method"] == "emulator_mcmc"
    post = summary["posterior"]["sigma_t"]
    assert post["q05"] < truth["sigma_t"] < post["q95"], (truth, post)
    # sigma_t is pinned by the peak as far as the simulator itself allows: at `fast` the mesh realization
    # alone moves the disc's peak by about 9 %, i.e. sigma_t's sd from one record is about 4 MPa and an
    # ideal 90 % interval about 13 MPa; ten members double that. Half the 4-60 MPa box or less:
    assert summary["posterior"]["sigma_t"]["q95"] - summary["posterior"]["sigma_t"]["q05"] < 0.5 * 56e6
    run = json.loads((tmp_path / f"results/{NAME}/iter_0/members/000/granite_disc/run.json").read_text())
    assert run["geometry"] == "brazilian_disc" and run["bars"]["E"] == 2.0e11 and run["bars"]["diameter_m"] == 0.05
    assert run["specimen"] == {"diameter_m": 0.05, "thickness_m": 0.025}
