# The ensemble: the LHS prior (iteration 0), the analysis ensemble of the previous iteration
# (iterations >= 1), and one simulation job per member and record.


rule lhs:
    """`parameters: auto`: the sensitivity report decides which parameters the prior spans."""
    input:
        unpack(
            lambda wc: (
                {"sensitivity": f"results/{wc.exp}/sensitivity/report.json"}
                if EXPERIMENTS[wc.exp]["parameters"] == "auto"
                else {}
            )
        ),
    output:
        params="results/{exp}/iter_0/params.csv",
    log:
        "results/{exp}/logs/lhs.log",
    conda:
        CONDA_ENV
    params:
        prior=lambda wc: {
            k: EXPERIMENTS[wc.exp][k] for k in ("parameters", "ensemble_size", "seed")
        },
    script:
        "../scripts/lhs.py"


rule propose:
    input:
        analysis=lambda wc: f"results/{wc.exp}/iter_{int(wc.it) - 1}/analysis.json",
    output:
        params="results/{exp}/iter_{it}/params.csv",
    log:
        "results/{exp}/logs/iter_{it}/propose.log",
    wildcard_constraints:
        it="[1-9][0-9]*",
    conda:
        CONDA_ENV
    script:
        "../scripts/propose.py"


rule member:
    """One FDEM simulation. A numerical failure (exit code 3) or the time limit leave a failed run.json
    and an empty curve (the analysis drops the member with that reason); rejected arguments or a missing
    input (exit code 2) fail the job with the simulator's message and leave nothing, so a re-run after
    the fix simulates the member; a crash is retried (`member_retries`) and recorded as failed on the
    last attempt."""
    input:
        unpack(member_inputs),
    output:
        curve="results/{exp}/iter_{it}/members/{member}/{record}/curve.csv",
        run="results/{exp}/iter_{it}/members/{member}/{record}/run.json",
    log:
        "results/{exp}/iter_{it}/members/{member}/{record}/simulate.log",
    retries: config["member_retries"]
    group:
        lambda wc: simulation_group(
            wc.exp,
            f"iter_{wc.it}",
            wc.member,
            EXPERIMENTS[wc.exp]["ensemble_size"],
            wc.record,
            records(wc.exp),
        )
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, None),
        runtime=lambda wc: runtime_min(wc.exp, None),
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "member", wc.it, wc.member, wc.record),
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/member.py"


rule replicate:
    """One replicate run at the iteration's ensemble mean on its own mesh realization: the replicates of
    an iteration differ only in the mesh and measure the simulator's own variability S
    (calibration.model_error; observations.model_error.simulator_replicates)."""
    input:
        unpack(member_inputs),
    output:
        curve="results/{exp}/iter_{it}/replicates/{member}/{record}/curve.csv",
        run="results/{exp}/iter_{it}/replicates/{member}/{record}/run.json",
    log:
        "results/{exp}/iter_{it}/replicates/{member}/{record}/simulate.log",
    retries: config["member_retries"]
    group:
        lambda wc: simulation_group(
            wc.exp,
            f"rep_{wc.it}",
            wc.member,
            len(replicate_ids(wc.exp)),
            wc.record,
            records(wc.exp),
        )
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, None),
        runtime=lambda wc: runtime_min(wc.exp, None),
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: mesh_seed_of(
            wc.exp, "replicate", wc.it, wc.member, wc.record
        ),
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/replicate.py"
