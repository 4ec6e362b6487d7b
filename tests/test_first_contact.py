"""First contact with the workflow (issue 34): file modes of the outputs, the Slurm extra's pin, config
errors that name their file, ``python -m shpb --version`` and the summary at the end of a run.

The Snakemake runs here are dry runs (``-n``) or one cheap job (the Latin hypercube), a few seconds each.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pandas as pd
import pytest
from packaging.requirements import Requirement

from calibration.config_files import config_sources, error_origin, load_config_file
from calibration.contracts import atomic_write_csv, atomic_write_json
from calibration.run_summary import experiment_lines, experiments_of_run, run_summary
from calibration.workflow_io import ConfigError, validate_config
from shpb.atomic import atomic_write_text

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"


@contextlib.contextmanager
def umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def snakemake(workdir: Path, *args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(workdir),
           "--workflow-profile", "none", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=workdir)


@pytest.fixture
def workdir(tmp_path) -> Path:
    """A working folder like the repository root: the shipped config/config.yaml and the data."""
    (tmp_path / "config").mkdir()
    shutil.copy(REPO / "config" / "config.yaml", tmp_path / "config" / "config.yaml")
    (tmp_path / "data").symlink_to(REPO / "data", target_is_directory=True)
    return tmp_path


# --------------------------------------------------------------------------------------------------
# 1. atomically written files get the mode of a normally created file
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o027, 0o640)])
def test_atomic_writers_give_files_the_mode_of_a_normally_created_file(tmp_path, mask, mode):
    with umask(mask):
        paths = [atomic_write_text(tmp_path / "a.txt", "text\n"),
                 atomic_write_json(tmp_path / "sub" / "b.json", {"x": 1.0}),
                 atomic_write_csv(pd.DataFrame({"x": [1.0, 2.0]}), tmp_path / "c.csv")]
        with open(tmp_path / "plain.txt", "w") as fh:  # what the writers must match
            fh.write("x")
    assert oct((tmp_path / "plain.txt").stat().st_mode & 0o777) == oct(mode)
    for p in paths:
        assert oct(p.stat().st_mode & 0o777) == oct(mode), p
    assert json.loads((tmp_path / "sub" / "b.json").read_text()) == {"x": 1.0}
    # still a temporary file renamed into place: nothing else is left in the folders
    assert sorted(q.name for q in tmp_path.rglob("*")) == ["a.txt", "b.json", "c.csv", "plain.txt", "sub"]


def test_a_rewritten_file_gets_the_new_mode_and_the_snapshot_pictures_too(tmp_path):
    from shpb.snapshots import failure_card

    target = tmp_path / "run.json"
    target.write_text("{}")
    target.chmod(0o600)
    with umask(0o022):
        atomic_write_json(target, {"status": "ok"})
        png = failure_card(tmp_path / "fracture.png", "no picture: the forecast failed")
    assert oct(target.stat().st_mode & 0o777) == oct(0o644)
    assert oct(png.stat().st_mode & 0o777) == oct(0o644)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(q.name for q in tmp_path.iterdir()) == ["fracture.png", "run.json"]


def test_no_module_creates_private_temporary_files():
    """tempfile.mkstemp / NamedTemporaryFile make 0600 files: none is left in the workflow's code."""
    found = [f"{p.relative_to(REPO)}: {m.group(0)}"
             for pkg in ("shpb", "calibration", "scripts", "enkf", "fdem") for p in (REPO / pkg).rglob("*.py")
             for m in re.finditer(r"\b(?:mkstemp|NamedTemporaryFile)\s*\(", p.read_text())]
    assert found == []


# --------------------------------------------------------------------------------------------------
# 2. the slurm extra pins the plugin version profiles/slurm needs
# --------------------------------------------------------------------------------------------------
def slurm_requirement() -> Requirement:
    with open(REPO / "pyproject.toml", "rb") as fh:
        extra = tomllib.load(fh)["project"]["optional-dependencies"]["slurm"]
    (req,) = [Requirement(r) for r in extra if Requirement(r).name == "snakemake-executor-plugin-slurm"]
    return req


def test_the_slurm_extra_requires_a_plugin_with_the_status_command_option():
    # slurm-status-command (profiles/slurm) exists from 2.0.1 on; 1.9.2 and 2.0.0 reject it
    spec = slurm_requirement().specifier
    assert "slurm-status-command" in (REPO / "profiles" / "slurm" / "config.yaml").read_text()
    assert not spec.contains("1.9.2") and not spec.contains("2.0.0")
    assert spec.contains("2.0.1") and spec.contains("2.8.0")


def test_the_installed_slurm_plugin_satisfies_the_pin_and_the_profile_dry_runs(workdir):
    installed = metadata.version("snakemake-executor-plugin-slurm")  # the [test] extra installs it
    assert slurm_requirement().specifier.contains(installed)
    out = snakemake(workdir, "--profile", str(REPO / "profiles" / "slurm"), "-n")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "This was a dry-run" in out.stdout + out.stderr


# --------------------------------------------------------------------------------------------------
# 3. config errors name their file (and the line, for YAML)
# --------------------------------------------------------------------------------------------------
BAD_YAML = "run: [twin_ref]\nexperiments:\n  twin_ref:\n    method: [esmda\n    seed: 3\n"


def test_a_yaml_syntax_error_names_the_file_and_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD_YAML)
    with pytest.raises(ConfigError) as err:
        config_sources([REPO / "config" / "config.yaml", bad])
    assert str(err.value).startswith(f"{bad}, line 5, column ")
    assert "YAML syntax error" in str(err.value) and "from line 4" in str(err.value)
    assert load_config_file(REPO / "config" / "config.yaml")["run"]  # the shipped config reads


def test_a_schema_error_names_the_config_files_and_the_one_that_set_the_key(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a file inside the working folder is named relative to it
    mine = tmp_path / "mine.yaml"
    mine.write_text("experiments:\n  twin_ref:\n    method: esmd\n")
    sources = config_sources([REPO / "config" / "config.yaml", mine], overrides={"member_retries": "x"})
    merged = load_config_file(REPO / "config" / "config.yaml")
    merged["experiments"]["twin_ref"]["method"] = "esmd"
    merged["member_retries"] = "x"
    with pytest.raises(ConfigError) as err:
        validate_config(merged, SCHEMA, base_dir=REPO, sources=sources)
    msg = str(err.value)
    assert msg.startswith(f"invalid workflow config ({REPO / 'config' / 'config.yaml'} + mine.yaml + --config):"), msg
    assert "experiments.twin_ref.method: 'esmd' is not one of ['esmda', 'enkf', 'emulated_esmda'] (set in mine.yaml)" in msg
    assert "member_retries: 'x' is not of type 'integer' (set in --config)" in msg


def test_error_origin_is_the_last_file_setting_the_key_or_those_inside_the_block():
    sources = [("base.yaml", {"experiments": {"a": {"seed": 1, "method": "esmda"}}}),
               ("mine.yaml", {"experiments": {"a": {"seed": 2}}})]
    assert error_origin("experiments.a.seed: bad", sources) == " (set in mine.yaml)"
    assert error_origin("experiments.a.method: bad", sources) == " (set in base.yaml)"
    assert error_origin("experiments.a: missing key", sources) == " (set in base.yaml, mine.yaml)"
    assert error_origin("run.0: bad name", [("base.yaml", {"run": ["x"]}), ("mine.yaml", {"run": ["y"]})]) \
        == " (set in mine.yaml)"
    assert error_origin("experiments.b: unknown", sources) == ""
    assert error_origin("no key here", sources) == ""


def test_snakemake_dry_run_names_the_configfile_of_a_schema_error(workdir):
    (workdir / "mine.yaml").write_text("experiments:\n  twin_ref:\n    method: esmd\n")
    out = snakemake(workdir, "-n", "--configfile", "mine.yaml")
    assert out.returncode != 0
    err = out.stdout + out.stderr
    assert "invalid workflow config (config/config.yaml + mine.yaml):" in err, err[-3000:]
    assert "experiments.twin_ref.method: 'esmd' is not one of" in err and "(set in mine.yaml)" in err


def test_snakemake_dry_run_names_file_and_line_of_a_yaml_error_in_config_yaml(workdir):
    (workdir / "config" / "config.yaml").write_text(BAD_YAML)
    out = snakemake(workdir, "-n")
    assert out.returncode != 0
    assert "config/config.yaml, line 5, column 9: YAML syntax error" in out.stdout + out.stderr, out.stderr[-3000:]


def test_a_yaml_error_in_a_configfile_shows_file_and_line_with_verbose(workdir):
    """Snakemake reads --configfile before the Snakefile runs and says only 'Config file is not valid
    JSON or YAML'; --verbose (docs/workflow.md) adds the parser's message with the file and line."""
    (workdir / "bad.yaml").write_text(BAD_YAML)
    out = snakemake(workdir, "-n", "--verbose", "--configfile", "bad.yaml")
    assert out.returncode != 0
    err = out.stdout + out.stderr
    assert re.search(r'in "[^"]*bad\.yaml", line 5, column \d+', err), err[-3000:]


def test_a_configfile_is_deep_merged_into_config_yaml(workdir):
    """The docs/workflow.md example: only twin_ref, 10 members, the rest of config/config.yaml kept."""
    (workdir / "my.yaml").write_text("run: [twin_ref]\nexperiments:\n  twin_ref:\n    ensemble_size: 10\n")
    out = snakemake(workdir, "-n", "--configfile", "my.yaml")
    assert out.returncode == 0, out.stderr[-3000:]
    # the first ensemble's batch jobs (at most 8 fast runs each, an even count): 10 members in 2 (25 in 4)
    batches = set(re.findall(r"results/(\w+)/simulate/member/iter_0/batch_(\d+)\.json", out.stdout + out.stderr))
    assert batches == {("twin_ref", "0"), ("twin_ref", "1")}


# --------------------------------------------------------------------------------------------------
# 4. python -m shpb --version
# --------------------------------------------------------------------------------------------------
def pyproject_version() -> str:
    with open(REPO / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)["project"]["version"]


def test_python_m_shpb_version_prints_the_package_version():
    out = subprocess.run([sys.executable, "-m", "shpb", "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"fdem-enkf-shpb {pyproject_version()}"


def test_the_version_falls_back_to_pyproject_without_an_installed_distribution(monkeypatch):
    from shpb.__main__ import package_version

    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "version", missing)
    assert package_version() == pyproject_version()


# --------------------------------------------------------------------------------------------------
# 5. the summary at the end of a run
# --------------------------------------------------------------------------------------------------
SUMMARY = {"experiment": "twin_ref", "stop_reason": "max_iterations", "posterior_method": "ensemble",
           "verdict": {"verdict": "not_converged", "next_step": "..."},
           "posterior": {"sigma_t": {"mean": 4.4643e7, "std": 1e6, "q05": 4.3e7, "q95": 4.61e7},
                         "E_t": {"mean": 539.2, "std": 30.0, "q05": 480.0, "q95": 601.5}}}


def test_experiment_lines_give_verdict_stop_reason_posterior_and_path():
    lines = experiment_lines("twin_ref", SUMMARY, "results/twin_ref/summary.json")
    assert lines[0] == ("twin_ref: verdict not_converged, stop reason max_iterations "
                        "(results/twin_ref/summary.json)")
    assert "90 % interval" in lines[1]
    assert lines[2].split() == ["sigma_t", "4.464e+07", "[4.3e+07,", "4.61e+07]", "Pa"]
    assert lines[3].split() == ["E_t", "539.2", "[480,", "601.5]", "J/m^2"]


def test_run_summary_never_raises_on_missing_broken_or_odd_summaries(tmp_path):
    (tmp_path / "ok").mkdir()
    (tmp_path / "ok" / "summary.json").write_text(json.dumps(SUMMARY))
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "summary.json").write_text("{not json")
    (tmp_path / "odd").mkdir()
    (tmp_path / "odd" / "summary.json").write_text(json.dumps({"verdict": "ok", "posterior": {"a": None}}))
    (tmp_path / "list").mkdir()
    (tmp_path / "list" / "summary.json").write_text("[1, 2]")
    text = run_summary(["ok", "missing", "broken", "odd", "list"], tmp_path).splitlines()
    assert text[0].startswith("Run summary")
    assert f"ok: verdict not_converged, stop reason max_iterations ({tmp_path / 'ok' / 'summary.json'})" in text
    assert f"missing: no summary ({tmp_path / 'missing' / 'summary.json'} does not exist)" in text
    assert any(t.startswith("broken: summary not readable") for t in text)
    assert any(t.startswith("odd: verdict ok, stop reason ?") for t in text)
    assert any(t.split() == ["a", "?", "[?,", "?]"] for t in text)
    assert any(t.startswith("list: summary not readable") for t in text)


def test_the_experiments_of_a_run_are_the_targets_or_the_config_run():
    exps = ["twin_ref", "marble_loop", "twin_standard"]
    assert experiments_of_run([], exps, ["twin_ref", "marble_loop"]) == ["twin_ref", "marble_loop"]
    assert experiments_of_run(["all"], exps, ["twin_ref"]) == ["twin_ref"]
    assert experiments_of_run(["results/twin_standard/summary.json", "/abs/results/twin_ref/plots/x.png"],
                              exps, ["marble_loop"]) == ["twin_standard", "twin_ref"]


def test_a_run_ends_with_the_summary_of_its_experiments(workdir):
    """One real job (twin_ref's Latin hypercube); the onsuccess handler reads a hand-made summary.json."""
    (workdir / "results" / "twin_ref").mkdir(parents=True)
    (workdir / "results" / "twin_ref" / "summary.json").write_text(json.dumps(SUMMARY))
    out = snakemake(workdir, "--cores", "1", "results/twin_ref/iter_0/params.csv")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "Run summary (results/<experiment>/summary.json):" in out.stdout, out.stdout[-2000:]
    assert "twin_ref: verdict not_converged, stop reason max_iterations (results/twin_ref/summary.json)" in out.stdout
    assert (workdir / "results" / "twin_ref" / "iter_0" / "params.csv").is_file()
