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
    params:
        sim=lambda wc: sim_settings(wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]),
        truth=lambda wc: EXPERIMENTS[wc.exp]["observations"]["truth"],
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "truth", 0, 0, wc.record),
    threads: 1
    retries: config["member_retries"]
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]),
        runtime=lambda wc: runtime_min(wc.exp, EXPERIMENTS[wc.exp]["observations"]["preset"]),
    script:
        "../scripts/truth.py"


def approximation_files(exp, name):
    """`name` of every approximation run (none when observations.model_error.approximation_error is off)."""
    return expand("results/{exp}/approximation/{run}/{record}/{name}", exp=exp, run=approximation_run_ids(EXPERIMENTS[exp]),
                  record=list(records(exp)), name=name)


def approximation_point(exp, run):
    """The run's design point {parameter: value} (a param, so that a new box or seed re-runs the pairs)."""
    names = spec(exp).names
    return dict(zip(names, map(float, approximation_design(exp, EXPERIMENTS[exp])[approximation_run(run)[1]])))


def approximation_preset(exp, run):
    return approximation_settings(EXPERIMENTS[exp])["preset"] if run.startswith("fine") else EXPERIMENTS[exp]["preset"]


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
    params:
        sim=lambda wc: sim_settings(wc.exp, approximation_preset(wc.exp, wc.run)),
        point=lambda wc: approximation_point(wc.exp, wc.run),
        record_file=lambda wc: records(wc.exp)[wc.record],
        mesh_seed=lambda wc: approximation_mesh_seed(EXPERIMENTS[wc.exp], wc.run, list(records(wc.exp)).index(wc.record)),
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "approximation", approximation_run_ids(EXPERIMENTS[wc.exp]).index(wc.run), len(approximation_run_ids(EXPERIMENTS[wc.exp])), wc.record, records(wc.exp))
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp, approximation_preset(wc.exp, wc.run)),
        runtime=lambda wc: runtime_min(wc.exp, approximation_preset(wc.exp, wc.run)),
    script:
        "../scripts/approximation_run.py"


def observation_inputs(wc):
    e = EXPERIMENTS[wc.exp]
    out = {"approximation": approximation_files(wc.exp, "curve.csv")}
    if e["kind"] == "twin":
        return {**out, "truth": f"results/{wc.exp}/truth/synthetic/curve.csv"}
    return {**out, "records": list(records(wc.exp).values())}


rule observations:
    input:
        unpack(observation_inputs),
    output:
        csv="results/{exp}/observations/obs.csv",
        meta="results/{exp}/observations/obs.json",
    params:
        exp=lambda wc: {k: EXPERIMENTS[wc.exp][k] for k in ("kind", "seed", "preset", "observations")},
        records=lambda wc: records(wc.exp),
        approximation_runs=lambda wc: approximation_run_ids(EXPERIMENTS[wc.exp]),
    script:
        "../scripts/observations.py"
