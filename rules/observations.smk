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


def observation_inputs(wc):
    e = EXPERIMENTS[wc.exp]
    if e["kind"] == "twin":
        return {"truth": f"results/{wc.exp}/truth/synthetic/curve.csv"}
    return {"records": list(records(wc.exp).values())}


rule observations:
    input:
        unpack(observation_inputs),
    output:
        csv="results/{exp}/observations/obs.csv",
        meta="results/{exp}/observations/obs.json",
    params:
        exp=lambda wc: {k: EXPERIMENTS[wc.exp][k] for k in ("kind", "seed", "observations")},
        records=lambda wc: records(wc.exp),
    script:
        "../scripts/observations.py"
