# Shared names and the input functions that walk the checkpoint loop. No science here: the stop
# decision is calibration.experiment.final_iteration, re-taken from the stored analyses with the current
# stopping rule, so that changing a tolerance never invalidates finished iterations (re-run the final
# targets with `-R summary forecast_params plots` to apply it).
import os

# One BLAS/OpenMP/Numba thread per job, overriding the caller's environment: the analyses are small dense
# solves (tens of members) that more threads do not speed up, the simulations are single-threaded jobs
# (threads: 1) run side by side, so one thread per job is also the fastest with 2 jobs on 2 cores; and a
# threaded BLAS sums in an order that depends on its thread count, so a re-run with another
# OMP_NUM_THREADS would write files that differ in the last digits. Set before any job is spawned: every
# job process inherits it (a cluster job re-reads this file on its node).
from calibration.job_log import THREAD_VARIABLES  # the variables each job's log reports

os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))

# A simulation's files are written by its batch's job (rule simulate) before the stage rule that
# declares them (member, replicate, ...: no job of their own) is reached, which Snakemake reports as a
# warning per simulation, hundreds per run: expected here, so left out of the log.
import logging as _logging
from snakemake.logging import logger as _snakemake_logger


class _BatchWrittenOutputs(_logging.Filter):
    def filter(self, record):
        msg = str(record.msg)
        return not (
            "were not present when the DAG was created" in msg
            and any(f"rule {s} " in msg for s in SIMULATION_STAGES)
        )


_snakemake_logger.addFilter(_BatchWrittenOutputs())

# Only what the DAG's build calls is imported here: calibration.experiment (enkf, SciPy's stats: ~1.5 s
# of every dry run) is imported by spec() and final_k(), which a dry run before the first analysis never
# calls (tests/test_dry_run_imports.py).
from calibration.approximation import (
    approximation_design,
    approximation_mesh_seed,
    approximation_run,
    approximation_run_ids,
    approximation_settings,
)
from calibration.diagnosis_config import series_position
from calibration.model_error import replicate_count, run_mesh_seed
from calibration.workflow_io import experiment_records, member_ids, read_json

# The software of every job, a path relative to rules/. Deployed only on request
# (`--software-deployment-method conda`, envs/workflow.yaml says how); by default each job runs in the
# Python that runs Snakemake.
CONDA_ENV = "../envs/workflow.yaml"

EXPERIMENTS = config["experiments"]
RUN = config["run"] or list(EXPERIMENTS)
PLOTS = ["parameters", "ensemble_curves", "forecast", "misfit", "sensitivity"]


wildcard_constraints:
    exp="[A-Za-z][A-Za-z0-9_-]*",
    it="[0-9]+",
    member="[0-9]+",
    record="[A-Za-z0-9][A-Za-z0-9_.-]*",


localrules:
    lhs,
    propose,
    reduced_record,
    observations,
    aggregate,
    analysis,
    refine_design,
    refine_aggregate,
    posterior_sample,
    forecast_params,
    plots,
    summary,
    diagnosis_design,
    diagnosis_heldout_observations,
    diagnosis_select,
    diagnosis_check,
    diagnosis_refit_round,
    diagnosis_refit,
    diagnosis_realrun_round,
    diagnosis_realrun,
    diagnosis_realrun_heldout,
    loro,


def records(exp):
    """{record name: raw file} ("synthetic" for a twin)."""
    return experiment_records(EXPERIMENTS[exp])


def spec(exp):
    from calibration.experiment import ExperimentSpec

    return ExperimentSpec.from_config(exp, EXPERIMENTS[exp])


def final_k(exp):
    """Walk the checkpoints k = 0, 1, ... until the (current) stop rule says stop; return that k."""
    analyses = []
    k = 0
    while True:
        path = checkpoints.analysis.get(exp=exp, it=k).output.analysis
        analyses.append(read_json(path))
        # imported past the first checkpoint, which a dry run before any analysis does not pass
        from calibration.experiment import final_iteration

        K, decision = final_iteration(spec(exp), analyses)
        if decision is not None:
            return K
        k += 1


def iteration_files(exp, name):
    """`name` of every iteration 0..K of the final loop."""
    return [f"results/{exp}/iter_{k}/{name}" for k in range(final_k(exp) + 1)]


def mesh_seed_of(exp, stage, k=0, index=0, record=None):
    """The mesh realization of one simulation (calibration.experiment.run_mesh_seed; None: unperturbed);
    a fold's record keeps its position in the series (calibration.diagnosis_config.series_position).
    """
    return run_mesh_seed(
        EXPERIMENTS[exp],
        stage,
        int(k),
        int(index),
        series_position(EXPERIMENTS, exp, record),
    )


def replicate_ids(exp):
    """Folder names of the replicate runs per iteration (none when S is not measured)."""
    return (
        member_ids(replicate_count(EXPERIMENTS[exp]))
        if replicate_count(EXPERIMENTS[exp])
        else []
    )


def sim_settings(exp, preset=None):
    """What a simulation of this experiment needs besides its parameters (also the params that make
    Snakemake re-run a member when they change)."""
    e = EXPERIMENTS[exp]
    return {
        "geometry": e["geometry"],
        "preset": preset or e["preset"],
        "fixed": e["fixed"],
        "t_end": e["simulation"]["t_end"],
        "sample_dt": e["simulation"]["sample_dt"],
        "command": config["simulator"],
    }


def inference_settings(exp):
    """Config entries an analysis depends on (a change re-runs the analyses)."""
    e = EXPERIMENTS[exp]
    keys = (
        "method",
        "esmda",
        "emulated",
        "max_iterations",
        "parameters",
        "transform",
        "inflation",
        "truncation",
        "max_rank",
        "min_alive_fraction",
        "localization",
        "seed",
        "ensemble_size",
    )
    return {k: e[k] for k in keys}


def time_limit_s(exp, preset=None):
    """Wall-time limit of one simulation of this experiment (config member_time_limit_s, per preset)."""
    return int(config["member_time_limit_s"][preset or EXPERIMENTS[exp]["preset"]])


def runtime_min(limit_s):
    """Scheduler wall time [min] of a job whose simulations may run `limit_s` seconds in all (their
    own limits in series) plus 5 minutes, so that a simulation stops itself (and is dropped as failed)
    before Slurm would kill the job.
    """
    return -(-int(limit_s) // 60) + 5


#: Parent name of every simulation group id (batch_group in rules/inputs.smk): the Slurm profile's
#: `group-components: [simulations=...]` lets a group span the disconnected batches that share one id
#: (Snakemake's default is one connected component per group job). Snakemake looks a group id up under its parent name
#: (`workflow.parent_groupids`, filled the same way for a group name with wildcards).
SIMULATION_GROUPS = "simulations"


def simulation_preset(rule_name, wc):
    """The preset of one simulation job: the truth at the observations' preset, the approximation
    error's runs at theirs (fine_<i> at the finer preset), a run of the real-run selection's resolution
    round at its row's, every other at the experiment's.
    """
    if rule_name == "truth":
        return EXPERIMENTS[wc.exp]["observations"]["preset"]
    if rule_name == "approximation_run":
        return approximation_preset(wc.exp, wc.run)
    if rule_name == "diagnosis_realrun_member":
        return realrun_row(wc).get("preset") or EXPERIMENTS[wc.exp]["preset"]
    return EXPERIMENTS[wc.exp]["preset"]


def stored_record(exp, record):
    """The record.json of the reduced record a simulation of `record` reads (rule reduced_record in
    rules/observations.smk); None for a twin's synthetic record."""
    if record in records(exp) and not records(exp)[record]:
        return None
    return f"results/{exp}/observations/{record}/record.json"


def record_input(exp, record):
    """The reduced record a simulation reads, its record.json and incident wave (none for a twin)."""
    p = stored_record(exp, record)
    return [p, p[: -len("record.json")] + "incident.csv"] if p else []


include: "inputs.smk"
include: "simulate.smk"
