"""The closing-the-loop on a Brazilian-disc series, the paper's test (issue 53, item 5), at a small size:
three synthetic granite discs made by the repository's series maker (tools/make_planted_series.py: the
simulator at `fast`, 1D-wave bar strains with the Freiburg records' noise, test sheets), configured by
`python -m shpb init-config --diagnosis` as a lab would, shrunk to a CI budget (six members, one ES-MDA
step, four refinement runs of the reported posterior instead of 25, eight design points a record, two
candidates) and run with `snakemake --cores 2`: about two minutes.

Nothing is planted (the null case), so the frozen protocol must keep the base model: a confirmation
of either candidate would be a false positive of the walk, whose level is 0.05 over its steps."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from test_workflow import snakemake

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tools.make_planted_series import make_series  # noqa: E402

EXP = "granite_godinez2021_brazilian_disc"
TRUTH = {"sigma_t": 3.8e7, "E_t": 650.0}


def _small(cfg: dict) -> dict:
    exp = cfg["experiments"][EXP]
    exp.update(ensemble_size=6, esmda={"steps": 1})
    exp.setdefault("emulated", {})["refine_runs"] = 4
    exp["simulation"]["sample_dt"] = 1.0e-6
    exp["observations"]["dt"] = 2.0e-6
    exp["observations"]["model_error"] = {"simulator_replicates": 2}
    d = exp["diagnosis"]
    d.pop("exclude", None)
    d.update(candidates=["rate_strength", "gauge_gain"], design_points=8, members=24,
             physical_upper={"rate_strength.k": 0.6},
             # the selection on real runs too, at a CI size (the rate law fitted from its null, no profile; three
             # check meshes; a resolution round on two meshes a preset): its rounds through the workflow; the
             # profile is tested on a stand-in (test_realrun.py)
             realrun_selection={"candidates": ["rate_strength"], "profile": 0, "check_meshes": 3,
                                "resolution": {"preset": "standard", "meshes": 2}})
    return cfg


def test_a_disc_series_runs_the_loop_and_keeps_the_base_model_when_nothing_is_planted(tmp_path):
    made = make_series(tmp_path / "series", geometry="brazilian_disc", drivers=["pulse:2.4", "pulse:2.9", "pulse:3.4"],
                       params=TRUTH, plant={}, spread={}, preset="fast", seed=5392, prefix="TinyDisc",
                       lithology="granite_godinez2021", t_end=1.8e-4)
    assert not made["effect"] and not made["plant"] and len(made["tests"]) == 3
    sheets = [f"series/TinyDisc_0{i}.yaml" for i in (1, 2, 3)]
    # the discs were made at the model's own mesh: no mesh error to carry (docs/own-data.md, section 4)
    done = subprocess.run([sys.executable, "-m", "shpb", "init-config", "--out", "written.yaml", "--diagnosis",
                           "--no-approximation-error", *sheets],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    cfg = yaml.safe_load((tmp_path / "written.yaml").read_text())
    assert cfg["experiments"][EXP]["diagnosis"]["heldout_records"] == [sheets[2]]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(_small(cfg), sort_keys=False))

    out = snakemake(tmp_path, "--cores", "2", timeout=1200)
    assert out.returncode == 0, out.stderr[-4000:]
    res = tmp_path / "results" / EXP
    runs = list(res.rglob("run.json"))
    assert len(runs) > 60 and {json.loads(p.read_text())["geometry"] for p in runs} == {"brazilian_disc"}

    report = json.loads((res / "diagnosis" / "report.json").read_text())
    assert report["calib_records"] == ["TinyDisc_01", "TinyDisc_02"] and report["heldout_records"] == ["TinyDisc_03"]
    assert report["base_posterior"] == "workflow"
    assert report["verdict"] == "base_kept" and report["added"] == []
    tried = {e for part in ("confirmation", "selection") for step in report[part]["steps"]
             for e in step.get("effects") or []}
    assert tried <= {"rate_strength", "gauge_gain"}

    held = json.loads((res / "diagnosis" / "check.json").read_text())["heldout"]["TinyDisc_03"]
    for when in ("before", "after"):
        h = held[when]
        assert h["replicates"] == 3 and 0.0 <= h["band_coverage"] <= 1.0
        assert 0.0 <= h["predictive_coverage_90"] <= 1.0 and h["interval_score_over_box"] > 0.0
        # the held-out disc's peak is about 33 MPa: its prediction misses it by less than half
        assert h["peak_rel_error"] < 0.5
    assert "base_kept" in (res / "summary.html").read_text()
    # the selection on real runs, on the calibration records only, names nothing either
    real = json.loads((res / "diagnosis" / "realrun.json").read_text())
    assert real["records"] == ["TinyDisc_01", "TinyDisc_02"] and real["named"] == "base_kept" and real["group"] == []
    rate = real["candidates"]["rate_strength"]
    assert set(rate["cv_points"]) == {"TinyDisc_01", "TinyDisc_02"} and 0.0 <= rate["fit"]["rate_strength.k"] <= 0.6
    # per record: the weights' 3 runs; the base's 3 linearisations of 3 names on 2 fit meshes and its 3 check
    # runs; the rate law's 3 linearisations of 4 names on 2 fit meshes and its 3 check runs; the resolution
    # round of the reported (base) fit: a linearisation of 3 names on 2 meshes, 2 runs at each preset
    assert real["runs"] == 2 * (3 + 3 * 3 * 2 + 3 + 3 * 4 * 2 + 3 + 3 * 2 + 2 + 2) and real["rounds"] == 5
    realrun_runs = [json.loads(p.read_text()) for p in runs if "realrun" in p.parts]
    assert len(realrun_runs) == real["runs"]
    assert {r["record"] for r in realrun_runs} == {"TinyDisc_01", "TinyDisc_02"}
    # the finer preset's runs are the resolution round's, and only those
    assert sorted((r["kind"], r["preset"]) for r in realrun_runs if r["preset"] != "fast") == [("fine", "standard")] * 4
    res_fit = real["resolution"]
    assert res_fit["track"] == "base" and res_fit["preset"] == "standard" and set(res_fit["bias_rms"]) == {
        "TinyDisc_01", "TinyDisc_02"}
    iv = res_fit["interval_90"]
    assert iv["q05"]["sigma_t"] <= res_fit["fit"]["sigma_t"] <= iv["q95"]["sigma_t"]
    # the held-out disc predicted at the reported (base, corrected) fit on the 3 check meshes, on the walk's
    # held-out realizations, and scored against its record
    held_runs = [json.loads(p.read_text()) for p in runs if "realrun_heldout" in p.parts]
    assert sorted((r["record"], r["model"], r["mesh"]) for r in held_runs) == [("TinyDisc_03", "before", m)
                                                                                 for m in range(3)]
    from calibration.model_error import run_mesh_seed

    exp_cfg = yaml.safe_load((tmp_path / "config.yaml").read_text())["experiments"][EXP]
    assert sorted(r["mesh_seed"] for r in held_runs) == sorted(run_mesh_seed(exp_cfg, "check", 0, m, 2)
                                                                for m in range(3))
    assert held_runs[0]["params"]["sigma_t"] == pytest.approx(res_fit["fit"]["sigma_t"])
    rh = json.loads((res / "diagnosis" / "realrun_heldout.json").read_text())
    assert list(rh["records"]) == ["TinyDisc_03"] and "after" not in rh["records"]["TinyDisc_03"]
    assert rh["records"]["TinyDisc_03"]["before"]["replicates"] == 3 and rh["failed"] == 0
    assert "The held-out records predicted from these fits" in (res / "summary.html").read_text()
    # a lab's series reports the shipped posterior, the form the coverage harness scores
    summary = json.loads((res / "summary.json").read_text())
    assert summary["posterior_method"] == "emulator_mcmc" and summary["posterior_form"]["emulator_error"] == "ar1"
