"""A dry run of the default workflow imports nothing the DAG's build does not need (issue 54).

What the ``Snakefile`` and ``rules/*.smk`` import while Snakemake parses them and builds the DAG is paid
by every ``snakemake`` call, a dry run included. SciPy's stats alone took ~1.5 s of it
(``enkf.sampling``, ``shpb.effects``'s ``scipy.signal``), Numba, matplotlib and the FDEM engine are
never needed before a job runs. These tests fail if any of them comes back: the first on a real dry run
of the shipped config, the second naming the module of ours that pulls it in.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from calibration.config_files import safe_load
from test_first_contact import workdir  # noqa: F401  (a folder like the repository root: config and data)

REPO = Path(__file__).resolve().parents[1]
#: Top-level packages a dry run must not import (any of their submodules counts).
HEAVY = ("scipy", "numba", "matplotlib", "enkf", "fdem")


def _imported(importtime_stderr: str) -> set[str]:
    """Module names from ``python -X importtime``'s report (one ``import time: self | cumulative | name``
    line per module imported)."""
    names = set()
    for line in importtime_stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            names.add(line.rsplit("|", 1)[1].strip())
    return names


def _heavy(names) -> list[str]:
    return sorted(n for n in names if n.split(".")[0] in HEAVY)


def _dry_run(workdir: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-X", "importtime", "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"),
           "--directory", str(workdir), "--workflow-profile", "none", "-n", "--cores", "1"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=workdir, env=env)


def test_a_dry_run_of_the_default_config_imports_no_scipy_numba_matplotlib_enkf_or_fdem(workdir):
    # the first run reduces each record for the parse-time record check (that reduction may use SciPy)
    # and keeps its verdict under .snakemake/fdem-records/; every later dry run reads the verdict
    first = _dry_run(workdir)
    assert first.returncode == 0, first.stderr[-3000:]
    warm = _dry_run(workdir)
    assert warm.returncode == 0, warm.stderr[-3000:]
    # the DAG was built: the default run's three experiments start with their prior ensembles
    for exp in ("twin_ref", "marble_loop", "planted_gap"):
        assert f"results/{exp}/iter_0/params.csv" in warm.stdout
    names = _imported(warm.stderr)
    assert {"snakemake", "calibration.config_check", "calibration.workflow_io"} <= names  # the report was read
    assert _heavy(names) == []


#: What the Snakefile and rules/*.smk import at parse time, in their order, and the modules their
#: parse-time calls import on the way (config_check's diagnosis and sensitivity checks).
PARSE_MODULES = ("calibration.config_files", "calibration.observations", "calibration.record_check",
                 "calibration.workflow_io", "calibration.heal", "calibration.approximation",
                 "calibration.model_error", "calibration.diagnosis_config", "calibration.sensitivity",
                 "shpb.effects")


def test_no_module_the_workflow_parse_imports_pulls_in_scipy_or_enkf():
    code = ("import importlib, json, sys\n"
            f"heavy = {HEAVY!r}\n"
            "out = {}\n"
            f"for m in {PARSE_MODULES!r}:\n"
            "    importlib.import_module(m)\n"
            "    out[m] = sorted(n for n in sys.modules if n.split('.')[0] in heavy)\n"
            "print(json.dumps(out))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=REPO,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert res.returncode == 0, res.stderr[-3000:]
    after = json.loads(res.stdout.splitlines()[-1])
    assert list(after) == list(PARSE_MODULES)
    assert {m: h for m, h in after.items() if h} == {}  # names the first module that pulls one in


def test_the_light_diagnosis_names_are_the_ones_the_rest_of_the_package_uses():
    from calibration import closing, diagnosis_config, experiment

    assert closing.candidate_effects is diagnosis_config.candidate_effects
    assert closing.loro_folds is diagnosis_config.loro_folds
    assert closing.FOLD_SEPARATOR == diagnosis_config.FOLD_SEPARATOR == "__"
    assert experiment.diagnosis_settings is diagnosis_config.diagnosis_settings


@pytest.mark.parametrize("path", sorted((REPO / "config").glob("*.yaml")), ids=lambda p: p.name)
def test_the_fast_yaml_reader_gives_the_data_yaml_safe_load_gives(path):
    text = path.read_text(encoding="utf-8")
    fast, slow = safe_load(text), yaml.safe_load(text)
    assert fast == slow
    # types too (YAML 1.1's resolver in both: "1e-3" stays a string, 1.0e-3 a float)
    assert json.dumps(fast, sort_keys=True, default=repr) == json.dumps(slow, sort_keys=True, default=repr)


def test_the_fast_yaml_reader_uses_libyaml_here_and_fails_as_yaml_safe_load_does(monkeypatch):
    assert getattr(yaml, "CSafeLoader", None) is not None  # else safe_load is yaml.safe_load itself
    loaders = []
    real_load = yaml.load
    monkeypatch.setattr(yaml, "load", lambda text, Loader: loaders.append(Loader) or real_load(text, Loader=Loader))
    assert safe_load("a: [1, 2]\nb: 1e-3\n") == {"a": [1, 2], "b": "1e-3"}
    assert loaders[0] is yaml.CSafeLoader
    bad = "experiments:\n  twin: {seed: 1\n  other: 2\n"
    with pytest.raises(yaml.YAMLError) as slow:
        yaml.safe_load(bad)
    with pytest.raises(yaml.YAMLError) as fast:
        safe_load(bad)
    assert type(fast.value) is type(slow.value) and str(fast.value) == str(slow.value)
    # the pure-Python parser's message, its snippet and caret included (libyaml's says "did not find
    # expected ',' or '}'" and shows no line of the document)
    assert "expected ',' or '}', but got ':'" in str(fast.value) and "line 3, column 8:\n      other: 2" in str(fast.value)
