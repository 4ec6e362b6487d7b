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


# One FDEM simulation of the refinement batch, on its own mesh realization; the failure policy of
# `rule member` (a failed run is left out of the emulator).
rule refine_member:
    input:
        batch=lambda wc: batch_file("refine_member", wc),
    output:
        curve="results/{exp}/refine/members/{member}/{record}/curve.csv",
        run="results/{exp}/refine/members/{member}/{record}/run.json",
    params:
        parameters=lambda wc: {"row": wc.member},
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "refine", 0, wc.member, wc.record),
        # the refinement batch's runs have no loop iteration
        run=lambda wc: {
            "member": int(wc.member),
            "iteration": "refine",
            "record": wc.record,
        },


rule refine_aggregate:
    input:
        params="results/{exp}/refine/params.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        batches=lambda wc: stage_batch_files(wc.exp, "refine_member"),
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


# The best-estimate simulation with the posterior-mean parameters, with fracture snapshots (a failed run
# gets a picture saying so instead of the damage maps).
rule forecast:
    input:
        batch=lambda wc: batch_file("forecast", wc),
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
    params:
        parameters={"key": "params"},
        snapshots=4,
        run=lambda wc: {"forecast": True, "record": wc.record},
