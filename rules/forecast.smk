# The forecast (best-estimate) simulation with the posterior-mean parameters
# (calibration.posterior.forecast_parameters): of the reported ensemble, or of the emulator MCMC sample
# (`posterior: emulator_mcmc`, rule posterior_sample).


def posterior_sample_files(exp):
    """The emulator MCMC posterior's files, for `posterior: emulator_mcmc` (calibration.posterior)."""
    if EXPERIMENTS[exp].get("posterior", "ensemble") != "emulator_mcmc":
        return {}
    return {"samples": f"results/{exp}/posterior/samples.csv", "sampler": f"results/{exp}/posterior/sampler.json"}


rule posterior_sample:
    input:
        params=lambda wc: iteration_files(wc.exp, "params.csv"),
        responses=lambda wc: iteration_files(wc.exp, "responses.csv"),
        analyses=lambda wc: iteration_files(wc.exp, "analysis.json"),
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
    output:
        samples="results/{exp}/posterior/samples.csv",
        sampler="results/{exp}/posterior/sampler.json",
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
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/forecast_params.py"


rule forecast:
    input:
        unpack(lambda wc: {"params": f"results/{wc.exp}/forecast/params.json",
                           "record": [p for p in [records(wc.exp)[wc.record]] if p]}),
    output:
        curve="results/{exp}/forecast/{record}/curve.csv",
        run="results/{exp}/forecast/{record}/run.json",
        # fracture snapshots: VTK of the mesh with joint damage at four times, the failure peak and the
        # window's end, PNG damage maps of the peak and the end, the curve next to both (shpb.snapshots)
        damage_peak=report("results/{exp}/forecast/{record}/snapshots/damage_peak.png", category="{exp}",
                           caption="../report/damage_map.rst"),
        damage_end=report("results/{exp}/forecast/{record}/snapshots/damage_end.png", category="{exp}",
                          caption="../report/damage_map.rst"),
        overview=report("results/{exp}/forecast/{record}/snapshots/fracture.png", category="{exp}",
                        caption="../report/fracture_overview.rst"),
    log:
        "results/{exp}/forecast/{record}/simulate.log",
    params:
        snapshots=4,
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, None),
        runtime=lambda wc: runtime_min(wc.exp, None),
    script:
        "../scripts/forecast.py"
