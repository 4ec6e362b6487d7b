"""One posterior for every experiment (issue 52): every experiment of every shipped config, the
leave-one-record-out folds they expand to, and every config `python -m shpb init-config` writes report
the same posterior, `emulator_mcmc` (calibration.posterior: MCMC on the emulator of every run, its
likelihood self-calibrated, the emulator's error heteroscedastic and measured at a refinement batch),
the form the validation harness (benchmarks/bench_coverage.py) scores; the default run's summaries say
so, and its diagnosis's base model is that posterior."""
from __future__ import annotations

import json

import pytest

from _shipped import REPO, shipped_experiments
from calibration.closing import base_posterior_mismatches, loro_folds
from shpb.lab.init_config import init_config

ONE = {"posterior": "emulator_mcmc", "self_calibrate": True, "emulator_error": "heteroscedastic"}
RUN = REPO / "benchmarks" / "results" / "default_run"


def _form(exp: dict) -> dict:
    em = exp.get("emulated") or {}
    return {"posterior": exp.get("posterior"), "self_calibrate": em.get("self_calibrate"),
            "emulator_error": em.get("emulator_error")}


def test_every_shipped_experiment_and_fold_reports_the_one_posterior():
    experiments = shipped_experiments()
    assert len(experiments) >= 20
    for key, (name, exp) in experiments.items():
        assert _form(exp) == ONE, key
        # a refinement batch measures the emulator's error where the posterior lies
        assert exp["emulated"]["refine_runs"] >= len(exp["parameters"]) + 2, key
        if exp.get("kind") == "measured" and (exp.get("diagnosis") or {}).get("validation") == "loro":
            for fold, fexp in loro_folds(name, exp).items():
                assert _form(fexp) == ONE, (key, fold)


def test_init_config_writes_the_one_posterior():
    disc = REPO / "data" / "examples" / "granite_disc" / "granite_disc.yaml"
    _, doc = init_config([disc])
    (exp,) = doc["experiments"].values()
    assert _form(exp) == ONE and exp["emulated"]["refine_runs"] == exp["ensemble_size"]


@pytest.mark.parametrize("exp", ["twin_ref", "marble_loop"])
def test_the_default_runs_summaries_name_the_one_posterior(exp):
    summary = json.loads((RUN / exp / "summary.json").read_text())
    assert summary["posterior_method"] == "emulator_mcmc"


def test_the_default_runs_diagnosis_base_model_is_its_posterior():
    summary = json.loads((RUN / "marble_loop" / "summary.json").read_text())
    report = json.loads((RUN / "marble_loop" / "diagnosis" / "report.json").read_text())
    assert report["base_posterior"] == "workflow"
    assert base_posterior_mismatches(summary, report) == []
