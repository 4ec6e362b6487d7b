# The forecast (best-estimate) simulation with the posterior-mean parameters
# (calibration.posterior.forecast_parameters): of the reported ensemble, or of the emulator MCMC sample
# (`posterior: emulator_mcmc`, rule posterior_sample).


def posterior_sample_files(exp):
    """The emulator MCMC posterior's files, for `posterior: emulator_mcmc` (calibration.posterior)."""
    if EXPERIMENTS[exp].get("posterior", "ensemble") != "emulator_mcmc":
        return {}
    return {"samples": f"results/{exp}/posterior/samples.csv", "sampler": f"results/{exp}/posterior/sampler.json"}


def refine_runs(exp):
    """How many refinement runs the reported emulator posterior is measured at (emulated.refine_runs)."""
    return int((EXPERIMENTS[exp].get("emulated") or {}).get("refine_runs", 0))


def refine_files(exp):
    """The refinement batch's design and curves (calibration.posterior.refine_design), where it has one."""
    if not posterior_sample_files(exp) or refine_runs(exp) < 1:
        return {}
    return {"refine_params": f"results/{exp}/refine/params.csv", "refine_responses": f"results/{exp}/refine/responses.csv"}


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
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/refine_design.py"


rule refine_member:
    """One FDEM simulation of the refinement batch, on its own mesh realization; the failure policy of
    `rule member` (a failed run is left out of the emulator)."""
    input:
        unpack(lambda wc: {"params": f"results/{wc.exp}/refine/params.csv",
                           "record": [p for p in [records(wc.exp)[wc.record]] if p]}),
    output:
        curve="results/{exp}/refine/members/{member}/{record}/curve.csv",
        run="results/{exp}/refine/members/{member}/{record}/run.json",
    log:
        "results/{exp}/refine/members/{member}/{record}/simulate.log",
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "refine", 0, wc.member, wc.record),
        max_attempts=config["member_retries"] + 1,
        iteration="refine",
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "refine", wc.member, refine_runs(wc.exp), wc.record, records(wc.exp))
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, None),
        runtime=lambda wc: runtime_min(wc.exp, None),
    script:
        "../scripts/member.py"


rule refine_aggregate:
    input:
        params="results/{exp}/refine/params.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        curves=lambda wc: expand("results/{exp}/refine/members/{member}/{record}/curve.csv", exp=wc.exp,
                                 member=member_ids(refine_runs(wc.exp)), record=list(records(wc.exp))),
        runs=lambda wc: expand("results/{exp}/refine/members/{member}/{record}/run.json", exp=wc.exp,
                               member=member_ids(refine_runs(wc.exp)), record=list(records(wc.exp))),
    output:
        responses="results/{exp}/refine/responses.csv",
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
