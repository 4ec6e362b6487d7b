# Curves on the observation grid, then the checkpoint analysis of iteration k (misfit, failed
# members, stop decision, analysis ensemble for k + 1).


def member_files(wc, name, folder="members"):
    ids = member_ids(EXPERIMENTS[wc.exp]["ensemble_size"]) if folder == "members" else replicate_ids(wc.exp)
    return expand("results/{exp}/iter_{it}/{folder}/{member}/{record}/{name}", exp=wc.exp, it=wc.it,
                  folder=folder, member=ids, record=list(records(wc.exp)), name=name)


rule aggregate:
    input:
        params="results/{exp}/iter_{it}/params.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        curves=lambda wc: member_files(wc, "curve.csv"),
        runs=lambda wc: member_files(wc, "run.json"),
        replicate_curves=lambda wc: member_files(wc, "curve.csv", "replicates"),
        replicate_runs=lambda wc: member_files(wc, "run.json", "replicates"),
    output:
        responses="results/{exp}/iter_{it}/responses.csv",
        replicates="results/{exp}/iter_{it}/replicates.csv",
    params:
        records=lambda wc: list(records(wc.exp)),
        replicates=lambda wc: replicate_ids(wc.exp),
    script:
        "../scripts/aggregate.py"


def earlier_iterations(wc, name):
    """`name` of iterations 0..it-1: the runs an emulated_esmda analysis builds its emulator on."""
    if EXPERIMENTS[wc.exp]["method"] != "emulated_esmda":
        return []
    return [f"results/{wc.exp}/iter_{k}/{name}" for k in range(int(wc.it))]


checkpoint analysis:
    input:
        params="results/{exp}/iter_{it}/params.csv",
        prior="results/{exp}/iter_0/params.csv",
        responses="results/{exp}/iter_{it}/responses.csv",
        replicates="results/{exp}/iter_{it}/replicates.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        history_params=lambda wc: earlier_iterations(wc, "params.csv"),
        history_responses=lambda wc: earlier_iterations(wc, "responses.csv"),
    output:
        analysis="results/{exp}/iter_{it}/analysis.json",
    params:
        inference=lambda wc: inference_settings(wc.exp),
    script:
        "../scripts/analysis.py"
