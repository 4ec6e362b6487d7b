# The forecast (best-estimate) simulation with the posterior-mean parameters
# (calibration.posterior.forecast_parameters): of the reported ensemble, or of the emulator MCMC sample
# (`posterior: emulator_mcmc`, rule posterior_sample).


rule refine_design:
    """The refinement batch: k-means centroids of the loop's emulator posterior, tempered."""
    input:
        params=lambda wc: iteration_files(wc.exp, "params.csv"),
        responses=lambda wc: iteration_files(wc.exp, "responses.csv"),
        analyses=lambda wc: iteration_files(wc.exp, "analysis.json"),
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
    output:
        params="results/{exp}/refine/params.csv",
    log:
        "results/{exp}/logs/refine_design.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/refine_design.py"


rule refine_member:
    """One FDEM simulation of the refinement batch, on its own mesh realization; the failure policy of
    `rule member` (a failed run is left out of the emulator)."""
    input:
        unpack(
            lambda wc: {
                "params": f"results/{wc.exp}/refine/params.csv",
                "record": [p for p in [records(wc.exp)[wc.record]] if p],
            }
        ),
    output:
        curve="results/{exp}/refine/members/{member}/{record}/curve.csv",
        run="results/{exp}/refine/members/{member}/{record}/run.json",
    log:
        "results/{exp}/refine/members/{member}/{record}/simulate.log",
    retries: config["member_retries"]
    group:
        lambda wc: simulation_group(
            wc.exp,
            "refine",
            wc.member,
            refine_runs(wc.exp),
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
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "refine", 0, wc.member, wc.record),
        max_attempts=config["member_retries"] + 1,
        iteration="refine",
    script:
        "../scripts/member.py"


rule refine_aggregate:
    input:
        params="results/{exp}/refine/params.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        curves=lambda wc: expand(
            "results/{exp}/refine/members/{member}/{record}/curve.csv",
            exp=wc.exp,
            member=member_ids(refine_runs(wc.exp)),
            record=list(records(wc.exp)),
        ),
        runs=lambda wc: expand(
            "results/{exp}/refine/members/{member}/{record}/run.json",
            exp=wc.exp,
            member=member_ids(refine_runs(wc.exp)),
            record=list(records(wc.exp)),
        ),
    output:
        responses="results/{exp}/refine/responses.csv",
    log:
        "results/{exp}/logs/refine_aggregate.log",
    conda:
        CONDA_ENV
    params:
        records=lambda wc: list(records(wc.exp)),
        replicates=[],
    script:
        "../scripts/aggregate.py"


rule posterior_sample:
    input:
        unpack(lambda wc: refine_files(wc.exp)),
        params=lambda wc: iteration_files(wc.exp, "params.csv"),
        responses=lambda wc: iteration_files(wc.exp, "responses.csv"),
        analyses=lambda wc: iteration_files(wc.exp, "analysis.json"),
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
    output:
        samples="results/{exp}/posterior/samples.csv",
        sampler="results/{exp}/posterior/sampler.json",
    log:
        "results/{exp}/logs/posterior_sample.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/posterior_sample.py"


rule forecast_params:
    input:
        unpack(lambda wc: posterior_sample_files(wc.exp)),
        analyses=lambda wc: iteration_files(wc.exp, "analysis.json"),
        params=lambda wc: iteration_files(wc.exp, "params.csv"),
    output:
        params="results/{exp}/forecast/params.json",
    log:
        "results/{exp}/logs/forecast_params.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/forecast_params.py"


rule forecast:
    input:
        unpack(
            lambda wc: {
                "params": f"results/{wc.exp}/forecast/params.json",
                "record": [p for p in [records(wc.exp)[wc.record]] if p],
            }
        ),
    output:
        curve="results/{exp}/forecast/{record}/curve.csv",
        run="results/{exp}/forecast/{record}/run.json",
        # fracture snapshots: VTK of the mesh with joint damage at four times, the failure peak and the
        # window's end, PNG damage maps of the peak and the end, the curve next to both (shpb.snapshots)
        damage_peak=report(
            "results/{exp}/forecast/{record}/snapshots/damage_peak.png",
            category="{exp}",
            caption="../report/damage_map.rst",
        ),
        damage_end=report(
            "results/{exp}/forecast/{record}/snapshots/damage_end.png",
            category="{exp}",
            caption="../report/damage_map.rst",
        ),
        overview=report(
            "results/{exp}/forecast/{record}/snapshots/fracture.png",
            category="{exp}",
            caption="../report/fracture_overview.rst",
        ),
    log:
        "results/{exp}/forecast/{record}/simulate.log",
    retries: config["member_retries"]
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, None),
        runtime=lambda wc: runtime_min(wc.exp, None),
    params:
        snapshots=4,
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/forecast.py"
