# Observations: a twin's reference simulation plus noise, or measured records reduced once (rule
# reduced_record) to the specimen stress on the observation grid (calibration.observations).


# Twin experiments: the reference simulation (truth parameters, possibly a finer preset); it must succeed.
rule truth:
    input:
        batch=lambda wc: batch_file("truth", wc),
    output:
        curve="results/{exp}/truth/{record}/curve.csv",
        run="results/{exp}/truth/{record}/run.json",
    params:
        sim=lambda wc: sim_settings(wc.exp, simulation_preset("truth", wc)),
        parameters=lambda wc: {"values": EXPERIMENTS[wc.exp]["observations"]["truth"]},
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "truth", 0, 0, wc.record),
        must_succeed=True,


# One run of the approximation error's pairs (calibration.approximation): a design point of the prior at
# the finer preset (fine_<i>) or at the experiment's own (coarse_<i>_<r>), on its own mesh realization,
# for a calibration or a held-out record (approximation_records). A failed run leaves its pair out.
rule approximation_run:
    input:
        batch=lambda wc: batch_file("approximation_run", wc),
    output:
        curve="results/{exp}/approximation/{run}/{record}/curve.csv",
        run="results/{exp}/approximation/{run}/{record}/run.json",
    wildcard_constraints:
        run="fine_[0-9]+|coarse_[0-9]+_[0-9]+",
    params:
        sim=lambda wc: sim_settings(wc.exp, simulation_preset("approximation_run", wc)),
        parameters=lambda wc: {"values": approximation_point(wc.exp, wc.run)},
        mesh_seed=lambda wc: approximation_mesh_seed(
            EXPERIMENTS[wc.exp], wc.run, approximation_records(wc.exp).index(wc.record)
        ),
        run=lambda wc: dict(
            zip(
                ("approximation", "design_point", "realization"),
                approximation_run(wc.run),
            ),
            record=wc.record,
        ),


rule reduced_record:
    """A measured record (calibration or held-out) reduced once: its incident wave, set-up, reduced curves,
    noise and checks (calibration.observations.write_reduced_record, shpb.lab.reduced_store); every
    simulation of the record and the observations read these files, not the raw one."""
    input:
        lambda wc: raw_record(wc.exp, wc.record),
    output:
        record="results/{exp}/observations/{record}/record.json",
        incident="results/{exp}/observations/{record}/incident.csv",
        curves="results/{exp}/observations/{record}/curves.csv",
    log:
        "results/{exp}/logs/reduced_record_{record}.log",
    conda:
        CONDA_ENV
    script:
        "../scripts/reduced_record.py"


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
        records=lambda wc: {r: stored_record(wc.exp, r) for r in records(wc.exp)},
        approximation=lambda wc: approximation_folder(wc.exp),
    script:
        "../scripts/observations.py"
