"""Cluster jobs worth scheduling (issue 33, item 4): on Slurm, the simulations of one ensemble iteration
run in jobs of `simulations_per_cluster_job` simulations instead of one job of a few seconds each.

How (docs/cluster.md): the simulations of a stage run in batches of `simulations_per_job` (one job of
rule simulate each, rules/inputs.smk, stage_batches); the batch jobs carry a `group:` id per experiment,
stage (ensemble iteration, sensitivity or diagnosis design, diagnosis check) and block of simulations
(batch_group); profiles/slurm lets a group span those disconnected jobs
(`group-components: [simulations=1000]`) and gives every Slurm job one simulation slot, so that a group
job is sized for its simulations in series.

Checked here without a cluster: the dry run of profiles/slurm prints every group job with its jobs; a run
whose `sbatch` is a stand-in that records its arguments and refuses the job shows what a group job asks
Slurm for; a local run does not group. A few seconds each; the runs that execute jobs use one core.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest
import yaml

from calibration.workflow_io import ConfigError, validate_config

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"
SLURM_PROFILE = REPO / "profiles" / "slurm"
DEFAULT_PROFILE = REPO / "profiles" / "default"


def twin(seed: int, ensemble_size: int) -> dict:
    return {
        "kind": "twin", "geometry": "brazilian_disc", "preset": "fast", "seed": seed,
        "ensemble_size": ensemble_size, "method": "esmda", "esmda": {"steps": 2}, "posterior": "ensemble",
        "parameters": {"sigma_t": [4.0e6, 60.0e6], "E_t": [200.0, 2400.0]},
        "simulation": {"t_end": 1.2e-4, "sample_dt": 1.0e-6},
        "observations": {"t_end": 1.0e-4, "dt": 1.0e-6, "truth": {"sigma_t": 45.0e6, "E_t": 500.0},
                         "noise": {"relative_sigma": 0.01}},
    }


def write_config(workdir: Path, **top) -> None:
    """Two fast twins: `big` with 25 members, `small` with 8."""
    cfg = {"run": ["big", "small"], **top, "experiments": {"big": twin(3, 25), "small": twin(4, 8)}}
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


def snakemake(workdir: Path, *args: str, profile: Path | None = SLURM_PROFILE, env: dict | None = None,
              timeout: float = 120.0) -> subprocess.CompletedProcess:
    """Snakemake as on the command line: --profile profiles/slurm, and profiles/default as the workflow
    profile (which Snakemake reads from the repository root in every run)."""
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(workdir),
           "--configfile", str(workdir / "config.yaml"), "--workflow-profile", str(DEFAULT_PROFILE)]
    if profile is not None:
        cmd += ["--profile", str(profile)]
    return subprocess.run(cmd + list(args), capture_output=True, text=True, timeout=timeout, cwd=workdir,
                          env={**os.environ, **(env or {})})


def group_jobs(plan: str) -> list[tuple[str, list[tuple[str, dict]]]]:
    """The group jobs of a dry run's plan, each as (group id, [(rule, wildcards)]): Snakemake prints a
    group job as `Group job <id> (jobs in lexicogr. order):` followed by its jobs, indented."""
    groups, current, rule = [], None, None
    for line in plan.splitlines():
        m = re.search(r"Group job (\S+) \(jobs in lexicogr\. order\):", line)
        if m:
            current = []
            groups.append((m.group(1), current))
            continue
        if re.match(r"(rule|localrule|checkpoint) \w+:|Job stats:", line):  # a job outside any group
            current = None
            continue
        if current is None:
            continue
        m = re.match(r"\s+(?:rule|checkpoint) (\w+):", line)
        if m:
            rule = m.group(1)
            continue
        m = re.match(r"\s+wildcards: (.*)", line)
        if m:
            current.append((rule, dict(kv.split("=", 1) for kv in m.group(1).split(", "))))
    return groups


def batch_sizes(n: int, k: int = 8) -> list[int]:
    """The runs per batch of a stage of n runs (rules/inputs.smk, stage_batches; fast: at most 8 per
    job, an even count of batches)."""
    nb = min(n, 2 * -(-n // (2 * k)))
    return [(b + 1) * n // nb - b * n // nb for b in range(nb)]


def job_count(plan: str, rule: str) -> int:
    m = re.search(rf"^{rule}\s+(\d+)$", plan, re.M)
    return int(m.group(1)) if m else 0


def runs_of(w: dict) -> int:
    """The runs of one batch job of the plan (its stage: the experiment's members or replicates)."""
    n = {"big": 25, "small": 8}[w["exp"]] if w["stage"] == "member" else 6
    return batch_sizes(n)[int(w["batch"])]


def sizes_per_iteration(groups) -> dict[tuple[str, str], list[int]]:
    """Runs per group job, per experiment and iteration."""
    out = defaultdict(list)
    for _, jobs in groups:
        out[(jobs[0][1]["exp"], jobs[0][1]["key"])].append(sum(runs_of(w) for _, w in jobs))
    return {k: sorted(v, reverse=True) for k, v in out.items()}


# Targets: big's iteration 1 (which brings its iteration 0 along: propose <- analysis <- iteration 0)
# and small's iteration 0, so the plan holds member batches of two iterations and two experiments.
TARGETS = ["results/big/iter_1/responses.csv", "results/small/iter_0/responses.csv"]
N_MEMBERS = 25 + 25 + 8
#: batch jobs of at most 8 fast runs (simulations_per_job), an even count: 25 -> 4, 8 -> 2, 6 replicates -> 2
N_BATCHES = 4 + 4 + 2 + 3 * 2


@pytest.mark.parametrize("size, expected", [
    # the default (fast: 12): a stage of n simulations -> n // 12 groups of whole batches (6, 6, 6 | 7)
    (None, {("big", "iter_0"): [18, 7], ("big", "iter_1"): [18, 7], ("small", "iter_0"): [8]}),
    (5, {("big", "iter_0"): [7, 6, 6, 6], ("big", "iter_1"): [7, 6, 6, 6], ("small", "iter_0"): [8]}),
])
def test_the_slurm_dry_run_groups_the_batches_of_each_iteration_into_jobs_of_the_configured_size(
        tmp_path, size, expected):
    write_config(tmp_path, **({"simulations_per_cluster_job": {"fast": size}} if size else {}))
    out = snakemake(tmp_path, "-n", *TARGETS)
    plan = out.stdout + out.stderr
    assert out.returncode == 0, plan[-3000:]
    # every simulation is declared by its own rule and run by a batch job; the aggregation takes the batch
    # files, so the declaring rules are no jobs (rules/inputs.smk, stage_batch_files)
    assert job_count(plan, "member") == 0 and job_count(plan, "replicate") == 0
    assert job_count(plan, "aggregate") == 3
    # the member and replicate batches, and each twin's truth run (a batch of its own)
    assert job_count(plan, "simulate") == N_BATCHES + 2
    groups = [g for g in group_jobs(plan) if g[1][0][1]["stage"] != "truth"]
    batches = [(w["exp"], w["stage"], w["key"], w["batch"]) for _, jobs in groups for _, w in jobs]
    assert sorted(batches) == sorted(set(batches)) and len(batches) == N_BATCHES, \
        "every batch job in exactly one group job"
    assert {rule for _, jobs in groups for rule, _ in jobs} == {"simulate"}
    assert sum(runs_of(w) for _, jobs in groups for _, w in jobs if w["stage"] == "member") == N_MEMBERS
    # the replicates at an iteration's mean form group jobs of their own (one per iteration, 6 < 12)
    replicate_groups = [(gid, jobs) for gid, jobs in groups if {w["stage"] for _, w in jobs} == {"replicate"}]
    groups = [g for g in groups if g not in replicate_groups]
    for gid, jobs in groups + replicate_groups:
        assert len({(w["exp"], w["stage"], w["key"]) for _, w in jobs}) == 1, \
            f"{gid} mixes stages, iterations or experiments"
        numbers = sorted(int(w["batch"]) for _, w in jobs)
        assert numbers == list(range(numbers[0], numbers[-1] + 1)), f"{gid}: not a block of batches"
    assert sizes_per_iteration(groups) == expected
    assert sizes_per_iteration(replicate_groups) == {("big", "iter_0"): [6], ("big", "iter_1"): [6],
                                                     ("small", "iter_0"): [6]}


def test_without_the_profiles_group_components_every_batch_is_its_own_job(tmp_path):
    # The profile's `group-components` is what makes a group span its disconnected batch jobs: given
    # as 1 (the command line replaces the profile's list), the plan is one cluster job per batch.
    write_config(tmp_path)
    out = snakemake(tmp_path, "-n", *TARGETS, "--group-components", "simulations=1")
    plan = out.stdout + out.stderr
    assert out.returncode == 0, plan[-3000:]
    groups = group_jobs(plan)
    assert len(groups) == N_BATCHES + 2 and {len(jobs) for _, jobs in groups} == {1}


FAKE_SLURM = """#!/bin/sh
# Stand-in for the Slurm client commands (tests/test_slurm_grouping.py): record the call; sbatch refuses.
echo "$(basename "$0") $*" >> "$FAKE_SLURM_LOG"
if [ "$(basename "$0")" = sbatch ]; then echo "sbatch: error: stand-in sbatch" >&2; exit 1; fi
exit 0
"""


def test_a_group_job_asks_slurm_for_one_cpu_the_memory_of_one_simulation_and_the_sum_of_runtimes(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name in ("sbatch", "squeue", "sacct", "scontrol", "sinfo", "sacctmgr", "sshare", "scancel", "srun"):
        (bin_dir / name).write_text(FAKE_SLURM)
        (bin_dir / name).chmod(0o755)
    log = tmp_path / "slurm_calls.log"
    work = tmp_path / "run"
    write_config(work)
    # Executes the Latin hypercube (a local rule, one core); every submission is refused, --keep-going
    # submits every ready group job once per attempt (member_retries 1: twice).
    out = snakemake(work, "results/big/iter_0/responses.csv", "--keep-going", "--local-cores", "1",
                    "--slurm-no-account", env={"PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
                                                "FAKE_SLURM_LOG": str(log)})
    calls = log.read_text().splitlines() if log.exists() else []
    submissions = [c for c in calls if c.startswith("sbatch ") and "'simulate:exp=big,stage=member,key=iter_0," in c]
    assert submissions, (out.stdout + out.stderr)[-3000:]
    asked = set()
    for call in submissions:
        found = re.findall(r"'simulate:exp=big,stage=member,key=iter_0,batch=(\d+)'", call)
        n = sum(batch_sizes(25)[int(b)] for b in found)
        runtime = int(re.search(r" -t (\d+) ", call).group(1))
        mem = int(re.search(r" --mem (\d+) ", call).group(1))
        cpus = int(re.search(r" --cpus-per-task=(\d+) ", call).group(1))
        asked.add((n, cpus, mem, runtime))
    # a batch of r fast runs asks for r x 10 min (member_time_limit_s 600 s) + 5 min, a group job for the
    # sum over its batches (6, 6, 6 runs | 7); mem_mb 1000 (profile)
    assert asked == {(18, 1, 1000, 3 * 65), (7, 1, 1000, 75)}


def test_a_local_run_does_not_group_and_the_default_profile_has_no_cluster_settings(tmp_path):
    from test_workflow import write_stand_in

    p = yaml.safe_load((DEFAULT_PROFILE / "config.yaml").read_text())
    assert not {"group-components", "groups", "resources", "set-resource-scopes"} & set(p)
    write_config(tmp_path, simulator=write_stand_in(tmp_path))
    targets = [f"results/small/iter_0/members/00{i}/synthetic/run.json" for i in (0, 1)]
    out = snakemake(tmp_path, "--cores", "1", *targets, profile=None)
    log = out.stdout + out.stderr
    assert out.returncode == 0, log[-3000:]
    assert all((tmp_path / t).exists() for t in targets)
    assert "Group job" not in log
    # the declared files written by their batch before their rule is reached: expected, not warned about
    assert "were not present when the DAG was created" not in log
    # one batch job ran the two members (and the other two of its batch of four: 8 runs, two batches)
    assert len(re.findall(r"Finished jobid: \d+ \(Rule: simulate\)", log)) == 1
    assert len(re.findall(r"Finished jobid: \d+ \(Rule: member\)", log)) == 2


def test_the_group_size_is_a_validated_config_key_with_per_preset_defaults():
    cfg = {"experiments": {"big": twin(3, 25)}}
    assert validate_config(cfg, SCHEMA)["simulations_per_job"] == {"fast": 8, "standard": 4, "paper": 1}
    with pytest.raises(ConfigError, match="simulations_per_job"):
        validate_config({**cfg, "simulations_per_job": {"fast": 0}}, SCHEMA)
    assert validate_config(cfg, SCHEMA)["simulations_per_cluster_job"] == {"fast": 12, "standard": 6, "paper": 2}
    with pytest.raises(ConfigError, match="simulations_per_cluster_job"):
        validate_config({**cfg, "simulations_per_cluster_job": {"fast": 0}}, SCHEMA)
    with pytest.raises(ConfigError, match="simulations_per_cluster_job"):
        validate_config({**cfg, "simulations_per_cluster_job": {"fastest": 3}}, SCHEMA)


def test_docs_cluster_prints_what_the_default_configs_dry_run_groups():
    # docs/cluster.md's example: group jobs of the default config's first iteration, batches per group
    # -F: the plan of a fresh run whatever this checkout holds under results/
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "-F", "--profile", str(SLURM_PROFILE)], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    printed = {f"{gid} {len(jobs)}" for gid, jobs in group_jobs(out.stdout + out.stderr)}
    doc = (REPO / "docs" / "cluster.md").read_text()
    block = doc[doc.index("prints, for the default config"):]
    block = block[block.index("```\n") + 4:]
    assert set(block[:block.index("```")].splitlines()) == printed
