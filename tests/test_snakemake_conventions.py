"""The workflow as Snakemake's catalogue expects it: a log per job (rules/*.smk, calibration.job_log),
config/README.md generated from config/schema.yaml (tools/config_doc.py), one BLAS/OpenMP/Numba thread
per job (rules/common.smk), CI's fast lane (.test/, .ci/run).

`snakemake --lint` and `snakefmt --check` themselves run in .ci/run, the whole .test run too; the
thread-count reproducibility of its results is benchmarks/bench_threads.py (two workflow runs do not fit
the suite's budget).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import yaml

from _rules_text import rule_texts
from tools import config_doc

REPO = Path(__file__).resolve().parents[1]
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def rule_blocks() -> dict[str, str]:
    """{rule name: its text} of rules/*.smk (tests/_rules_text.py: a `use rule` inherits its base's text)."""
    return rule_texts(sorted((REPO / "rules").glob("*.smk")))[0]


#: The rules that declare one simulation each and run no job (rules/simulate.smk: rule simulate runs
#: them in batches and writes their logs): no log and no script of their own.
DECLARATIONS = {"member", "replicate", "refine_member", "forecast", "truth", "approximation_run",
                "sensitivity_member", "diagnosis_member", "diagnosis_check_member", "diagnosis_refit_member",
                "diagnosis_realrun_member", "diagnosis_realrun_heldout_member"}


def job_blocks() -> dict[str, str]:
    return {n: b for n, b in rule_blocks().items() if n not in DECLARATIONS}


def section(block: str, name: str) -> str:
    m = re.search(rf"^    {name}:\n((?:        .*\n|\s*\n)+)", block, re.M)
    return m.group(1) if m else ""


# --------------------------------------------------------------------------------------------------
# logs
# --------------------------------------------------------------------------------------------------
def test_the_simulation_declarations_run_nothing_and_every_other_rule_a_script():
    blocks = rule_blocks()
    assert DECLARATIONS <= set(blocks)
    for name, block in blocks.items():
        actions = [a for a in ("script", "shell", "run") if re.search(rf"^    {a}:", block, re.M)]
        assert actions == ([] if name in DECLARATIONS else ["script"]), (name, actions)


def test_every_rule_logs_to_a_file_of_its_own_wildcards_and_its_script_writes_it():
    blocks = job_blocks()
    assert len(blocks) >= 20, sorted(blocks)  # every job rule but the Snakefile's `all`
    for name, block in blocks.items():
        log = section(block, "log")
        paths = re.findall(r'"([^"]+)"', log)
        assert len(paths) == 1, f"rule {name}: one log file, got {paths}"
        out_wildcards = set(re.findall(r"\{(\w+)\}", "".join(re.findall(r'"(results/[^"]+)"', section(block, "output")))))
        assert set(re.findall(r"\{(\w+)\}", paths[0])) == out_wildcards, f"rule {name}: log {paths[0]}"
        assert paths[0].startswith("results/{exp}/") and paths[0].endswith(".log"), paths[0]
        script = REPO / "rules" / re.search(r'"(\.\./scripts/\w+\.py)"', section(block, "script")).group(1)
        text = script.resolve().read_text()
        assert "log_to(snakemake.log[0])" in text or "log_path=snakemake.log[0]" in text, f"{script.name} ignores its log"


def test_log_paths_of_two_rules_never_coincide():
    logs = [re.findall(r'"([^"]+)"', section(b, "log"))[0] for b in job_blocks().values()]
    assert len(logs) == len(set(logs))


def test_a_jobs_output_goes_to_its_log_and_only_its_traceback_and_console_line_to_the_terminal(tmp_path):
    """Python's print, C-level writes to fd 1 and 2, a subprocess and a warning land in the log; the
    line written to the returned stream and the traceback reach the terminal (stdout, stderr)."""
    log = tmp_path / "job.log"
    job = textwrap.dedent(f"""
        import os, subprocess, sys, warnings
        sys.path.insert(0, {str(REPO)!r})
        from calibration.job_log import log_to
        console = log_to({str(log)!r})
        print("python print")
        os.write(2, b"fd 2 write\\n")
        subprocess.run(["echo", "child process"], check=True)
        warnings.warn("a warning")
        print("tiny iteration 0: the console line", file=console, flush=True)
        raise ValueError("bad value 7")
    """)
    out = subprocess.run([sys.executable, "-c", job], capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    text = log.read_text()
    for expected in ("python print", "fd 2 write", "child process", "UserWarning: a warning", "ValueError: bad value 7"):
        assert expected in text, (expected, text)
    assert out.stdout == "tiny iteration 0: the console line\n"
    assert f"(job log: {log})" in out.stderr and "ValueError: bad value 7" in out.stderr
    assert "python print" not in out.stderr + out.stdout and "child process" not in out.stdout


# --------------------------------------------------------------------------------------------------
# config/README.md
# --------------------------------------------------------------------------------------------------
def test_config_readme_is_the_one_the_schema_gives():
    schema = yaml.safe_load((REPO / "config" / "schema.yaml").read_text())
    assert (REPO / "config" / "README.md").read_text() == config_doc.render(schema), \
        "config/README.md is out of date: run python tools/config_doc.py"


def test_config_readme_lists_every_schema_key_once():
    schema = yaml.safe_load((REPO / "config" / "schema.yaml").read_text())
    text = (REPO / "config" / "README.md").read_text()

    def keys(node, prefix=""):
        for name, child in (node.get("properties") or {}).items():
            yield f"{prefix}{name}"
            yield from keys(child, f"{prefix}{name}.")

    experiment_keys = list(keys(schema["properties"]["experiments"]["additionalProperties"]))
    assert {"kind", "ensemble_size", "observations.noise.relative_sigma", "simulation.t_end"} <= set(experiment_keys)
    for key in [k for k in keys(schema) if k != "experiments"] + experiment_keys:
        assert text.count(f"| `{key}` |") == 1, key


def test_a_key_row_has_its_meaning_type_default_and_unit():
    schema = {"type": "object", "required": ["t_end"], "properties": {
        "t_end": {"type": "number", "description": "end of the window"},
        "sigma_Pa": {"type": ["number", "null"], "default": None},
        "box": {"type": "object", "description": "prior box [lower, upper] in SI units", "default": {"a": 1.5},
                "properties": {"inner": {"enum": ["x", None], "default": "x", "description": "one | two"}}},
        "width": {"anyOf": [{"enum": ["loo"]}, {"type": "number"}], "default": "loo",
                  "description": "the half width [m]"}}}
    assert config_doc.rows(schema) == [
        ("t_end", "end of the window", "number", "required", "s"),
        ("sigma_Pa", config_doc.NO_DESCRIPTION, "number or null", "`null`", "Pa"),
        ("box", "prior box [lower, upper] in SI units", "object", '`{"a": 1.5}`', "SI"),
        ("box.inner", "one \\| two", "one of `x`, `null`", '`"x"`', "SI"),
        ("width", "the half width [m]", "one of `loo` or number", '`"loo"`', "m")]


def test_config_doc_check_fails_on_a_stale_readme(tmp_path, monkeypatch):
    stale = tmp_path / "README.md"
    stale.write_text("# hand-edited\n")
    monkeypatch.setattr(config_doc, "README", stale)
    monkeypatch.setattr(config_doc, "REPO", tmp_path)
    assert config_doc.main(["--check"]) == 1
    assert config_doc.main([]) == 0 and config_doc.main(["--check"]) == 0


# --------------------------------------------------------------------------------------------------
# threads, .test, CI
# --------------------------------------------------------------------------------------------------
def test_every_job_gets_one_thread_whatever_the_caller_sets(tmp_path):
    """One real job (the Latin hypercube of the CI config) started with 3 threads in the caller's
    environment: the job's log says it ran with 1 of each (calibration.job_log writes what it saw)."""
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text((REPO / ".test" / "config" / "config.yaml").read_text())
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(tmp_path),
           "--workflow-profile", "none", "--cores", "1", "results/tiny/iter_0/params.csv"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         env={**os.environ, **dict.fromkeys(THREAD_VARIABLES, "3")})
    assert out.returncode == 0, out.stderr[-3000:]
    log = (tmp_path / "results" / "tiny" / "logs" / "lhs.log").read_text()
    assert log.splitlines()[0] == "threads: " + " ".join(f"{v}=1" for v in THREAD_VARIABLES)
    assert (tmp_path / "results" / "tiny" / "iter_0" / "params.csv").is_file()


def test_ci_runs_lint_format_and_the_test_config_before_the_suite():
    text = "\n".join(ln for ln in (REPO / ".ci" / "run").read_text().splitlines() if not ln.startswith("#"))
    order = [text.index(s) for s in ('pip install -e ".[test]"', "snakemake --lint", "snakefmt --check Snakefile rules/",
                                      "--directory .test", "CI: .test run took", "pytest -q")]
    assert order == sorted(order)
    cfg = yaml.safe_load((REPO / ".test" / "config" / "config.yaml").read_text())
    assert cfg["run"] == ["tiny"] and cfg["experiments"]["tiny"]["kind"] == "twin"
