"""Cluster execution: the Snakemake profiles, the one-node test cluster script, the comparison logic,
and -- opt-in -- the real thing.

The cheap tests always run. The real-cluster test (marker ``slurm``) stands up Slurm on localhost as
root, runs the ``fast`` workflow through ``profiles/slurm`` and compares it with a local run; the
default ``pytest`` run deselects it (``addopts = -m "not slurm"`` in pyproject.toml). Run it with

    RUN_SLURM_TESTS=1 pytest -q -m slurm tests/test_slurm.py
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from _rules_text import rule_texts

REPO = Path(__file__).resolve().parents[1]
CLUSTER = REPO / "tools" / "slurm" / "slurm_local_cluster.sh"
PROFILES = REPO / "profiles"
#: The rule that runs FDEM simulations (a batch of one stage per job, rules/simulate.smk): the only one a
#: cluster run submits as Slurm jobs. The rules that declare each simulation (member, replicate, truth,
#: ...) run no job of their own.
SIMULATION_RULES = {"simulate"}

sys.path.insert(0, str(REPO / "tools" / "slurm"))
import slurm_compare  # noqa: E402


def load_profile(name: str) -> dict:
    return yaml.safe_load((PROFILES / name / "config.yaml").read_text())


# --------------------------------------------------------------------------------------------------
# Profiles
# --------------------------------------------------------------------------------------------------
def snakemake_options() -> set[str]:
    from snakemake.cli import get_argument_parser

    return {s for a in get_argument_parser()._actions for s in a.option_strings}


#: Options of snakemake-executor-plugin-slurm 2.8.0 used by profiles/slurm (checked against the
#: installed plugin when it is there, see test_every_profile_key_is_a_snakemake_option).
SLURM_PLUGIN_OPTIONS = {"slurm-status-command", "slurm-init-seconds-before-status-checks"}


@pytest.mark.parametrize("name", ["default", "slurm"])
def test_every_profile_key_is_a_snakemake_option(name):
    options = snakemake_options()
    plugin_installed = any(o.startswith("--slurm-") for o in options)
    for key in load_profile(name):
        if key.startswith("slurm-") and not plugin_installed:
            assert key in SLURM_PLUGIN_OPTIONS, f"{name}: {key} is not an option of the Slurm plugin 2.8.0"
        else:
            assert f"--{key}" in options, f"profiles/{name}: {key} is not a snakemake option"


def test_slurm_profile_uses_the_executor_with_a_status_command_that_works_without_accounting():
    p = load_profile("slurm")
    assert p["executor"] == "slurm"
    # sacct (the plugin's default when the binary exists) fails without slurmdbd and the run waits
    # forever; squeue works with and without accounting.
    assert p["slurm-status-command"] == "squeue"
    assert 1 <= p["slurm-init-seconds-before-status-checks"] <= 10
    assert p["rerun-incomplete"] is True
    assert int(p["jobs"]) >= 10


def test_test_cluster_keeps_finished_jobs_long_enough_for_squeue_status():
    # The plugin falls back from squeue to sacct when MinJobAge < 3 x the first-poll delay.
    init = load_profile("slurm")["slurm-init-seconds-before-status-checks"]
    text = CLUSTER.read_text()
    assert re.search(r"^MinJobAge=\$min_job_age$", text, re.M)
    m = re.search(r'min_job_age="\$\{SLURM_LOCAL_MINJOBAGE:-(\d+)\}"', text)
    assert m and int(m.group(1)) >= 3 * init


def test_slurm_profile_gives_every_job_memory_and_runtime():
    res = load_profile("slurm")["default-resources"]
    assert res["mem_mb"] >= 1000 and res["runtime"] >= 10
    # partition/account are left to the user (documented, not guessed)
    assert "slurm_partition" not in res and "slurm_account" not in res
    text = (PROFILES / "slurm" / "config.yaml").read_text()
    assert "# slurm_partition:" in text and "# slurm_account:" in text


def test_default_profile_is_for_one_machine():
    p = load_profile("default")
    assert "executor" not in p
    assert p["rerun-incomplete"] is True
    assert p["scheduler"] == "greedy"
    assert p["cores"] == "all" or int(p["cores"]) >= 1


# --------------------------------------------------------------------------------------------------
# Workflow rules: cheap stages are localrules, simulations are cluster jobs of one CPU
# --------------------------------------------------------------------------------------------------
def workflow_rules() -> tuple[dict[str, str], set[str]]:
    """{rule name: body} and the localrules of Snakefile + rules/*.smk."""
    return rule_texts([REPO / "Snakefile", *sorted((REPO / "rules").glob("*.smk"))])


def has_action(body: str) -> bool:
    return bool(re.search(r"^\s+(shell|script|run|notebook|wrapper):", body, re.M))


def test_localrules_name_existing_rules_and_cover_every_cheap_stage():
    rules, local = workflow_rules()
    if not (SIMULATION_RULES & set(rules)):
        pytest.fail("the workflow's simulation rules (member, truth, forecast) are not in the Snakefile yet")
    assert local <= set(rules), f"localrules name unknown rules: {sorted(local - set(rules))}"
    cheap = {n for n, b in rules.items() if has_action(b)} - SIMULATION_RULES
    assert cheap <= local, f"cheap stages that a cluster run would submit as jobs: {sorted(cheap - local)}"
    assert not (SIMULATION_RULES & local)


def test_simulation_rules_ask_for_one_cpu():
    rules, _ = workflow_rules()
    for name in SIMULATION_RULES & set(rules):
        assert re.search(r"^\s+threads:\s*1\s*$", rules[name], re.M), f"rule {name} must declare threads: 1"


# --------------------------------------------------------------------------------------------------
# The test-cluster script
# --------------------------------------------------------------------------------------------------
def test_cluster_script_is_valid_bash():
    subprocess.run(["bash", "-n", str(CLUSTER)], check=True)
    if shutil.which("shellcheck"):
        subprocess.run(["shellcheck", str(CLUSTER)], check=True)


def test_cluster_script_tears_down_by_recorded_pids_on_every_exit():
    text = CLUSTER.read_text()
    assert "trap with_cluster_exit EXIT" in text
    code = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    assert not re.search(r"\b(pkill|killall)\b", code), "never stop processes by name"


def test_down_stops_exactly_the_recorded_pids(tmp_path):
    # Two processes of ours; only the one recorded under its real name may be stopped.
    recorded = subprocess.Popen(["sleep", "300"])
    other = subprocess.Popen(["sleep", "300"])
    try:
        (tmp_path / "pids").write_text(f"{recorded.pid} sleep\n{other.pid} slurmd\n")
        out = subprocess.run(["bash", str(CLUSTER), "down", str(tmp_path)], capture_output=True, text=True,
                             timeout=30)
        assert out.returncode == 0, out.stderr
        assert recorded.wait(timeout=5) is not None
        time.sleep(0.2)
        assert other.poll() is None, "a PID recorded under another program's name must not be killed"
        assert not (tmp_path / "pids").exists()
    finally:
        for p in (recorded, other):
            if p.poll() is None:
                p.kill()
                p.wait()


def test_cluster_script_refuses_to_reuse_a_directory_with_a_running_cluster(tmp_path):
    (tmp_path / "pids").write_text("")
    out = subprocess.run(["bash", str(CLUSTER), "up", str(tmp_path)], capture_output=True, text=True, timeout=30)
    assert out.returncode != 0


# --------------------------------------------------------------------------------------------------
# Comparison logic of tools/slurm/slurm_compare.py
# --------------------------------------------------------------------------------------------------
def test_summary_comparison_ignores_wall_times_only():
    a = {"experiment": "x", "wall_s": 10.0, "misfit": [{"rmse_Pa": 1.5, "wall_s": 3}], "posterior": {"E": {"mean": 2.0}}}
    b = {"experiment": "x", "wall_s": 99.0, "misfit": [{"rmse_Pa": 1.5, "wall_s": 7}], "posterior": {"E": {"mean": 2.0}}}
    assert slurm_compare.numbers_equal(a, b) == []
    b["posterior"]["E"]["mean"] = 2.0000000001
    assert slurm_compare.numbers_equal(a, b) == ["/posterior/E/mean: 2.0 vs 2.0000000001"]
    assert slurm_compare.numbers_equal({"x": float("nan")}, {"x": float("nan")}) == []


def test_parameter_tables_must_match_exactly(tmp_path):
    for run in ("a", "b"):
        d = tmp_path / run / "results" / "e" / "iter_0"
        d.mkdir(parents=True)
        (d / "params.csv").write_text("member,E\n0,1.0e10\n1,2.0e10\n")
    assert slurm_compare.compare_tables(tmp_path / "a", tmp_path / "b", "results/*/iter_*/params.csv") == 1
    (tmp_path / "b" / "results" / "e" / "iter_0" / "params.csv").write_text("member,E\n0,1.0e10\n1,2.0000001e10\n")
    with pytest.raises(slurm_compare.CheckFailed, match="column E differs"):
        slurm_compare.compare_tables(tmp_path / "a", tmp_path / "b", "results/*/iter_*/params.csv")


def test_member_jobs_are_read_from_the_head_log(tmp_path):
    log = tmp_path / "snakemake.log"
    log.write_text(
        "rule member:\n    input: x\n    wildcards: exp=fast, it=0, member=3, record=synthetic\n"
        "localrule aggregate:\n    wildcards: exp=fast, it=0\n"
        "SLURM-job '12' failed, SLURM status is: 'FAILED'. Detailed failure reason unavailable\n")
    assert slurm_compare.jobs_in_log(log, "member") == [{"exp": "fast", "it": "0", "member": "3", "record": "synthetic"}]
    assert slurm_compare.failed_slurm_jobs(log) == [("12", "FAILED")]


def test_fault_wrapper_crashes_one_member_and_hangs_another(tmp_path):
    cmd = slurm_compare.fault_wrapper(tmp_path, crash=1, hang=2).split()

    def call(member, timeout=10):
        return subprocess.run(cmd + ["--help-me", "--out", f"results/e/iter_0/members/{member}/synthetic/.sim-x"],
                              capture_output=True, timeout=timeout)

    for _ in range(2):
        crash = call("001")
        assert crash.returncode == 1 and b"injected crash" in crash.stderr
        with pytest.raises(subprocess.TimeoutExpired):  # member 2 hangs on every attempt
            call("002", timeout=2)
    # every other member reaches the real simulator (here: its argument parser, which rejects --help-me)
    other = call("011")
    assert other.returncode != 0 and b"injected" not in other.stderr


def test_fault_config_sets_the_wrapper_and_a_member_time_limit_below_the_slurm_runtime(tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(json.dumps(slurm_compare.FAST_TWIN))
    from calibration.workflow_io import coerce_yaml_floats

    # (YAML 1.1 reads JSON's 1e-06 as a string; the workflow converts such strings back)
    conf = coerce_yaml_floats(yaml.safe_load(slurm_compare.fault_config(cfg, tmp_path, 1, 2).read_text()))
    assert conf["simulator"].endswith("faulty_simulator.sh")
    assert conf["member_time_limit_s"] == {"fast": slurm_compare.FAIL_TIME_LIMIT_S}
    assert conf["experiments"] == json.loads(json.dumps(slurm_compare.FAST_TWIN))["experiments"]


# --------------------------------------------------------------------------------------------------
# The real cluster (opt-in)
# --------------------------------------------------------------------------------------------------
@pytest.mark.slurm
def test_fast_workflow_on_a_one_node_slurm_cluster_matches_the_local_run(tmp_path):
    if os.environ.get("RUN_SLURM_TESTS") != "1":
        pytest.fail("the real-cluster test starts Slurm daemons as root: run it as "
                    "RUN_SLURM_TESTS=1 pytest -q -m slurm tests/test_slurm.py")
    subprocess.run(["bash", str(CLUSTER), "install"], check=True)
    t0 = time.perf_counter()
    out = subprocess.run(["bash", str(CLUSTER), "run-compare", "--out", str(tmp_path / "runs")],
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    sys.stderr.write(out.stderr[-20000:])
    assert out.returncode == 0, out.stdout + out.stderr[-5000:]
    report = json.loads(out.stdout)
    print(json.dumps(report, indent=2), f"\nrun-compare wall time: {wall:.0f} s")
    assert report["ok"]
    assert report["compare"]["identical"] and report["resume"]["identical"] and report["fail"]["identical"]
    assert report["resume"]["members_finished_before_kill"] >= 1
    assert not any(j.endswith("TIMEOUT") for j in report["fail"]["slurm_failed_jobs"])
    assert report["fail"]["hung_member_slurm_jobs"] == 1
    assert report["fail"]["iteration0_dropped"] == [1, 2]
    # torn down: no link to a test cluster's configuration is left behind
    assert not Path("/run/slurm/conf").exists()
