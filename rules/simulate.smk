# The simulation rules' common part: every FDEM simulation job (rules truth, approximation_run, member,
# replicate, refine_member, forecast, diagnosis_member, diagnosis_check_member, sensitivity_member) is
# `use rule simulate as <name> with:`, giving its own input, output, log, group and the params that
# differ (scripts/simulate.py says which). `rule simulate` itself is the template: no other rule asks for
# its outputs.


rule simulate:
    """One FDEM simulation. A numerical failure (exit code 3) or the time limit leave a failed run.json
    and an empty curve (the analysis drops the member with that reason); rejected arguments or a missing
    input (exit code 2) fail the job with the simulator's message and leave nothing, so a re-run after
    the fix simulates the run; a crash is retried (`member_retries`) and recorded as failed on the last
    attempt.

    params: `parameters` where the parameters come from (calibration.ensemble_files.simulation_params),
    `record_file` the reduced record's record.json (rule reduced_record; None: the twin's synthetic one), `mesh_seed` the mesh realization (None:
    the unperturbed mesh), `snapshots` a count of fracture snapshots, `run` the entries added to
    run.json, `must_succeed` a failed run fails the job."""
    output:
        curve="results/{exp}/simulate/{run}/{record}/curve.csv",
        run="results/{exp}/simulate/{run}/{record}/run.json",
    log:
        "results/{exp}/simulate/{run}/{record}/simulate.log",
    retries: config["member_retries"]
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc, rulename: time_limit_s(
            wc.exp, simulation_preset(rulename, wc)
        ),
        runtime=lambda wc, rulename: runtime_min(
            wc.exp, simulation_preset(rulename, wc)
        ),
    params:
        sim=lambda wc: sim_settings(wc.exp),
        parameters={"values": {}},
        record_file=lambda wc: stored_record(wc.exp, wc.record),
        mesh_seed=None,
        snapshots=None,
        run={},
        must_succeed=False,
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/simulate.py"
