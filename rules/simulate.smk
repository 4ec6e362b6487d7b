# The simulations. Every FDEM run of the workflow is declared by a rule of its stage (truth,
# approximation_run, member, replicate, refine_member, forecast, diagnosis_member,
# diagnosis_check_member, sensitivity_member: SIMULATION_STAGES) that runs nothing itself: it names the
# run's outputs, its batch and the params that differ from the defaults (rules/inputs.smk, batch_runs,
# which states them once: `sim` the experiment's simulation settings, `parameters` where the parameters
# come from (calibration.ensemble_files.simulation_params), `record_file` the reduced record's
# record.json (None: a twin's synthetic record), `mesh_seed` the mesh realization (None: unperturbed),
# `snapshots` a count of fracture snapshots, `run` the entries added to run.json, `must_succeed` a failed
# run fails its batch). The runs of one stage (an ensemble iteration, a design, the check, ...) are cut
# into batches (simulations_per_job per preset; stage_runs, stage_batches), and one job of `rule
# simulate`, the one rule that simulates, runs a batch in one Python process
# (calibration.batch.run_batch: the engine loaded once, each run in a forked child that writes its own
# curve.csv, run.json and manifest.json). Why: a job's start-up and the engine's load cost about as much
# as a `fast` simulation's time loop (benchmarks/results/bench_batch.json). The rules that collect a
# stage's runs (aggregate, refine_aggregate, observations' approximation pairs, the sensitivity analysis,
# the diagnosis) take the stage's batch files as input (stage_batch_files), not the runs' files, so that
# the stage rules never become jobs; the forecast and the truth, one run per record, are still asked for
# by their files (the forecast's snapshots are report items).


rule simulate:
    """One batch of simulations of one stage, in one process (calibration.batch.run_batch). A numerical
    failure (exit code 3) or the time limit leave a failed run.json and an empty curve (the analysis drops
    the member with that reason); rejected arguments or a missing input (exit code 2) fail the batch with
    the simulator's message; a crash is retried (`member_retries`: the job again, the runs that finished
    kept) and recorded as a failed run on the last attempt."""
    input:
        unpack(batch_inputs),
    output:
        batch="results/{exp}/simulate/{stage}/{key}/batch_{batch}.json",
    log:
        "results/{exp}/simulate/{stage}/{key}/batch_{batch}.log",
    wildcard_constraints:
        stage="|".join(SIMULATION_STAGES),
        key="iter_[0-9]+|all",
        batch="[0-9]+",
    retries: config["member_retries"]
    group:
        lambda wc: batch_group(wc)
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        runtime=lambda wc: batch_runtime_min(wc),
    params:
        runs=lambda wc: batch_runs(wc),
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/simulate.py"
