# Observations: a twin's reference simulation plus noise, or measured records reduced to the specimen
# stress on the observation grid (calibration.observations).


rule truth:
    """Twin experiments: the reference simulation (truth parameters, possibly a finer preset)."""
    input:
        lambda wc: [p for p in records(wc.exp).values() if p],
    output:
        curve="results/{exp}/truth/{record}/curve.csv",
        run="results/{exp}/truth/{record}/run.json",
    log:
        "results/{exp}/truth/{record}/simulate.log",
    retries: config["member_retries"]
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(
            wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]
        ),
        runtime=lambda wc: runtime_min(
            wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]
        ),
    params:
        sim=lambda wc: sim_settings(
            wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]
        ),
        truth=lambda wc: EXPERIMENTS[wc.exp]["observations"]["truth"],
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "truth", 0, 0, wc.record),
    script:
        "../scripts/truth.py"


rule approximation_run:
    """One run of the approximation error's pairs (calibration.approximation): a design point of the
    prior at the finer preset (fine_<i>) or at the experiment's own (coarse_<i>_<r>), on its own mesh
    realization. A failed run leaves its pair out."""
    input:
        lambda wc: [p for p in [records(wc.exp)[wc.record]] if p],
    output:
        curve="results/{exp}/approximation/{run}/{record}/curve.csv",
        run="results/{exp}/approximation/{run}/{record}/run.json",
    log:
        "results/{exp}/approximation/{run}/{record}/simulate.log",
    wildcard_constraints:
        run="fine_[0-9]+|coarse_[0-9]+_[0-9]+",
    retries: config["member_retries"]
    group:
        lambda wc: simulation_group(
            wc.exp,
            "approximation",
            approximation_run_ids(EXPERIMENTS[wc.exp]).index(wc.run),
            len(approximation_run_ids(EXPERIMENTS[wc.exp])),
            wc.record,
            records(wc.exp),
        )
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(
            wc.exp, approximation_preset(wc.exp, wc.run)
        ),
        runtime=lambda wc: runtime_min(wc.exp, approximation_preset(wc.exp, wc.run)),
    params:
        sim=lambda wc: sim_settings(wc.exp, approximation_preset(wc.exp, wc.run)),
        point=lambda wc: approximation_point(wc.exp, wc.run),
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: approximation_mesh_seed(
            EXPERIMENTS[wc.exp], wc.run, list(records(wc.exp)).index(wc.record)
        ),
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/approximation_run.py"


rule observations:
    input:
        unpack(observation_inputs),
    output:
        csv="results/{exp}/observations/obs.csv",
        meta="results/{exp}/observations/obs.json",
    log:
        "results/{exp}/logs/observations.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: {
            k: EXPERIMENTS[wc.exp][k]
            for k in ("kind", "seed", "preset", "observations")
        },
        records=lambda wc: records(wc.exp),
        approximation_runs=lambda wc: approximation_run_ids(EXPERIMENTS[wc.exp]),
    script:
        "../scripts/observations.py"
