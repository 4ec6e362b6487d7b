"""The frozen protocol in the workflow (calibration.closing, rules/diagnosis.smk): candidates, the error
terms a held-out record gets, leave-one-record-out folds and their table, and the DAG of a series."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration.closing import candidate_effects, loro_folds, loro_table, protocol_errors
from calibration.observations import Observations
from calibration.workflow_io import ConfigError, load_yaml, validate_config
from shpb import effects as fx

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"


def test_the_whole_catalogue_is_offered_unless_the_config_leaves_an_effect_out():
    everything = [e.name for e in fx.effects()]
    assert candidate_effects({}) == everything
    assert "closure" in everything and "interface_friction" in everything
    assert candidate_effects({"exclude": ["damping", "seating"]}) == [e for e in everything
                                                                       if e not in ("damping", "seating")]
    assert candidate_effects({"candidates": ["face_gap", "gauge_gain"], "exclude": ["gauge_gain"]}) == ["face_gap"]


def _series(validation="loro", held=()):
    base = load_yaml(REPO / "config" / "diagnosis.yaml")
    exp = base["experiments"]["marble_loro"]
    exp["diagnosis"] = {**exp["diagnosis"], "validation": validation, "heldout_records": list(held)}
    return {"run": ["marble_loro"], "experiments": {"marble_loro": exp}}


def test_leave_one_record_out_folds_hold_each_record_out_once_and_change_nothing_else():
    cfg = validate_config(_series(), SCHEMA, base_dir=REPO)
    exp = cfg["experiments"]["marble_loro"]
    folds = loro_folds("marble_loro", exp)
    records = exp["observations"]["records"]
    assert len(folds) == len(records) == 4
    held = []
    for name, fold in folds.items():
        (h,) = fold["diagnosis"]["heldout_records"]
        held.append(h)
        assert name == "marble_loro__" + Path(h).name.split("_Ti")[0]
        assert fold["observations"]["records"] == [r for r in records if r != h]
        assert fold["diagnosis"]["validation"] == "holdout" and fold["loro_of"] == "marble_loro"
        assert fold["seed"] == exp["seed"] and fold["parameters"] == exp["parameters"]
    assert sorted(held) == sorted(records)


def test_a_record_keeps_its_series_position_in_every_fold_so_its_prior_runs_are_the_same_requests():
    from calibration.diagnosis_config import series_position
    from calibration.model_error import run_mesh_seed

    cfg = validate_config(_series(), SCHEMA, base_dir=REPO)
    experiments = {**cfg["experiments"], **loro_folds("marble_loro", cfg["experiments"]["marble_loro"])}
    names = [Path(r).name.split("_Ti")[0] for r in cfg["experiments"]["marble_loro"]["observations"]["records"]]
    for position, record in enumerate(names):
        folds = [f for f, e in experiments.items() if e.get("loro_of") and record in f"{e['observations']['records']}"]
        assert len(folds) == 3  # calibrated in every fold but its own
        seeds = {run_mesh_seed(experiments[f], "member", 0, 5, series_position(experiments, f, record)) for f in folds}
        assert len(seeds) == 1 and series_position(experiments, "marble_loro", record) == position
    # the fold's own list would have moved the records after the held-out one (the old key)
    fold = next(iter(f for f in experiments if f.endswith(names[0])))
    assert series_position(experiments, fold, names[1]) == 1 != experiments[fold]["observations"]["records"].index(
        cfg["experiments"]["marble_loro"]["observations"]["records"][1])


def test_a_series_that_also_lists_held_out_records_or_has_two_records_is_refused():
    with pytest.raises(ConfigError, match="validation loro every record"):
        validate_config(_series(held=["data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/"
                                      "CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"]), SCHEMA, base_dir=REPO)
    cfg = _series()
    cfg["experiments"]["marble_loro"]["observations"]["records"] = cfg["experiments"]["marble_loro"]["observations"]["records"][:2]
    with pytest.raises(ConfigError, match="at least 3 records"):
        validate_config(cfg, SCHEMA, base_dir=REPO)


def test_a_dry_run_of_a_series_runs_its_folds_and_not_the_series_itself(tmp_path):
    cfg = _series()
    o = cfg["experiments"]["marble_loro"]["observations"]
    o["records"] = [str(REPO / r) for r in o["records"]]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    dag = subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory",
                          str(tmp_path), "--configfile", str(tmp_path / "config.yaml"), "--workflow-profile", "none",
                          "-n", "--cores", "1", "--printshellcmds", "--summary"], capture_output=True, text=True,
                         timeout=300)
    assert dag.returncode == 0, dag.stderr[-3000:]
    text = dag.stdout
    for rec in ("CaMa_SHPB_016", "CaMa_SHPB_006", "CaMa_SHPB_015", "CaMa_SHPB_019"):
        assert f"results/marble_loro__{rec}/iter_0/params.csv" in text
        # each fold is re-fitted and gated as a held-out experiment is (the table scores what one ships)
        assert f"results/marble_loro__{rec}/diagnosis/refit.json" in text
    assert "results/marble_loro/loro/summary.json" in text and "results/marble_loro/loro/summary.html" in text
    assert "results/marble_loro/iter_0/params.csv" not in text


def _obs(values, sigma, records, t):
    import pandas as pd

    from calibration.observations import OBS_COLUMNS

    frame = pd.DataFrame({"record": np.repeat(records, t.size), "time_s": np.tile(t, len(records)),
                          "stress_Pa": values, "sigma_Pa": sigma})
    assert list(frame.columns) == list(OBS_COLUMNS)
    return Observations(frame, "ar1", {r: 2e-6 for r in records})


def test_a_held_out_record_takes_its_noise_and_the_calibration_records_average_variability_never_its_curve():
    t = np.arange(0.0, 40e-6, 2e-6)
    m = t.size
    cal = _obs(np.zeros(2 * m), np.full(2 * m, 1e5), ["A", "B"], t)
    sd = np.concatenate([np.full(m, 2e5), np.full(m, 4e5)])
    analysis = {"model_error": {"simulator_variability": {"sd_Pa": sd.tolist(), "corr_time_s": 5e-6},
                                "discrepancy": {"records": {
                                    r: {"sigma_pre": s, "sigma_post": s, "corr_time_s": 1e-5, "split_time_s": None}
                                    for r, s in (("A", 1e6), ("B", 3e6))}}}}
    held = _obs(np.linspace(0, 5e7, m), np.full(m, 2e5), ["H"], t)
    noise, sim = protocol_errors(cal, analysis, held)
    corrupted = _obs(np.random.default_rng(0).normal(0, 1e8, m), np.full(m, 2e5), ["H"], t)
    noise2, sim2 = protocol_errors(cal, analysis, corrupted)
    assert np.array_equal(noise["H"].dense(), noise2["H"].dense()) and np.array_equal(sim["H"].dense(), sim2["H"].dense())
    # its own noise (0.2 MPa), the calibration records' average S (0.04 + 0.16)/2 MPa^2; the discrepancy,
    # fitted to the base model's residual, is not a term of the selection's gate
    assert noise["H"].dense()[0, 0] == pytest.approx(0.04e12, rel=1e-9)
    assert sim["H"].dense()[0, 0] == pytest.approx(0.10e12, rel=1e-6)
    assert noise["A"].dense()[0, 0] == pytest.approx(0.01e12, rel=1e-9)


def test_the_series_table_reports_each_fold_and_the_mean_change_with_its_spread():
    def rep(h, before, after, added, cv=((5.0, 4.0), (5.0, 6.0))):
        cal = {f"c{i}": {"data": "calibration (cross-validated)", "before": {"rmse": b},
                         "after": {"rmse": a if added else b}} for i, (b, a) in enumerate(cv)}
        return {"heldout": {h: {"before": {"rmse": before, "peak_error": 1.0, "time_to_peak_error": 0.0},
                                "after": {"rmse": after, "peak_error": 0.5, "time_to_peak_error": 0.0,
                                          "point": {}, "intervals": {}}}},
                "selection": {"steps": [{"index": 0, "posterior": {}}, {"index": 1, "posterior": {"k": {"mean": 0.3}}}]},
                "shipped_step": 1 if added else 0, "calib_records": ["x"], "added": added,
                "verdict": "confirmed" if added else "base_kept",
                "errors_per_record": {**cal, h: {"data": "heldout", "before": {"rmse": before}, "after": {"rmse": after}}}}
    grouped = {**rep("A", 10.0, 6.0, ["face_gap"]), "identification": [{"effects": ["face_gap", "trigger_shift"]}]}
    t = loro_table({"s__A": grouped, "s__B": rep("B", 8.0, 8.0, []),
                    "s__C": rep("C", 12.0, 7.0, ["face_gap", "closure"])}, {"A": {"strain_rate_at_peak_per_s": 100.0}})
    # each fold's groups as its report gives them; None for a report that predates them
    assert [r["groups"] for r in t["rows"]] == [[["face_gap", "trigger_shift"]], None, None]
    tot = t["totals"]
    assert tot["folds"] == 3 and tot["folds_worse"] == 0 and tot["folds_better"] == 2
    assert tot["mean_rmse_change"] == pytest.approx(-3.0)
    assert tot["sd_rmse_change"] == pytest.approx(np.std([-4.0, 0.0, -5.0], ddof=1))
    assert tot["effects_kept"] == {"closure": 1, "face_gap": 2}
    assert t["rows"][0]["strain_rate_per_s"] == 100.0 and t["rows"][0]["estimates"] == {"k": {"mean": 0.3}}
    # the risk of a worse prediction, from the calibration records' real CV runs of the two folds that
    # shipped an addition (the held-out records are not counted; the base-kept fold has none)
    risk = tot["cv_risk_worse_than_base"]
    assert (risk["worse"], risk["records"]) == (2, 4) and risk["fraction"] == 0.5
    assert risk["p_no_fold_worse"] == pytest.approx(0.5 ** 3)
    lo, hi = risk["ci90"]
    assert lo == pytest.approx(0.0976, abs=1e-3) and hi == pytest.approx(0.9024, abs=1e-3)  # exact binomial, 2 of 4


def test_a_fold_that_shipped_an_alternative_reports_the_alternatives_estimates():
    """The walk may confirm an alternative in place of the emulator's step (its index follows the nested
    steps'): the series table reads that step's posterior, not a nested step's (an index past the nested
    steps stopped a five-record series at its last job)."""
    ev = {"rmse": 9.0, "peak_error": 1.0, "time_to_peak_error": 0.0, "point": {}, "intervals": {}}
    rep = {"heldout": {"H": {"before": dict(ev), "after": {**ev, "rmse": 6.0}}},
           "selection": {"steps": [{"index": 0, "posterior": {}}, {"index": 1, "posterior": {"k": {"mean": 0.3}}}],
                         "alternatives": [{"index": 2, "alternative_to": 1, "posterior": {"g": {"mean": 7.0}}}]},
           "shipped_step": 2, "calib_records": ["x"], "added": ["seating"], "verdict": "confirmed",
           "errors_per_record": {}}
    row = loro_table({"s__H": rep})["rows"][0]
    assert row["estimates"] == {"g": {"mean": 7.0}} and row["effects"] == ["seating"]
    with pytest.raises(KeyError, match="no step 5"):
        loro_table({"s__H": {**rep, "shipped_step": 5}})


def test_the_risk_of_a_worse_prediction_is_zero_records_when_the_base_is_kept():
    from calibration.closing import cv_risk

    errs = {"a": {"data": "calibration (cross-validated)", "before": {"rmse": 1.0}, "after": {"rmse": 2.0}}}
    assert cv_risk(errs, 0)["records"] == 0 and cv_risk(errs, 0)["fraction"] is None
    r = cv_risk(errs, 1)
    assert (r["worse"], r["records"]) == (1, 1) and r["ci90"][0] == pytest.approx(0.05 ** 1, abs=1e-12)


def test_the_selection_sees_a_held_out_record_blind():
    """scripts/diagnosis.py hands the selection the held-out records blinded: their times and noise, their
    curves NaN (a leak would poison the selection instead of informing it)."""
    from calibration.closing import blind

    t = np.arange(0.0, 40e-6, 2e-6)
    held = _obs(np.linspace(0, 5e7, t.size), np.full(t.size, 2e5), ["H"], t)
    b = blind(held)
    assert np.all(np.isnan(b.values)) and np.array_equal(b.time, held.time)
    assert np.array_equal(b.error_model().dense(), held.error_model().dense())
    assert not np.any(np.isnan(held.values))  # the original is untouched


def test_a_corrected_held_out_record_is_blind_to_its_curve_as_observed_and_keeps_its_mesh_scatter():
    """With an approximation error, the held-out record's obs.csv holds the curve as observed as well
    (stress_uncorrected_Pa): blinded too; the pairs' scatter (from its incident wave) stays in its noise."""
    from calibration.closing import blind
    from calibration.observations import with_approximation_error
    from enkf.covariance import DenseError

    t = np.arange(0.0, 40e-6, 2e-6)
    M = DenseError(np.diag(np.full(t.size, 9e10)), _symmetric=True)
    held = with_approximation_error(_obs(np.linspace(0, 5e7, t.size), np.full(t.size, 2e5), ["H"], t),
                                    np.full(t.size, 1e6), M, {"sd_Pa": [3e5] * t.size})
    b = blind(held)
    assert np.all(np.isnan(b.values)) and np.all(np.isnan(b.frame["stress_uncorrected_Pa"]))
    assert np.allclose(b.error_model().std, np.sqrt(4e10 + 9e10), rtol=1e-12)
    assert np.array_equal(b.error_model().dense(), held.error_model().dense())
