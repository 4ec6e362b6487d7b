# Curves on the observation grid, then the checkpoint analysis of iteration k (misfit, failed
# members, stop decision, analysis ensemble for k + 1).


rule aggregate:
    input:
        params="results/{exp}/iter_{it}/params.csv",
        obs="results/{exp}/observations/obs.csv",
        obs_meta="results/{exp}/observations/obs.json",
        # the members' and replicates' files, written by these batches (stage_batch_files)
        batches=lambda wc: iteration_batch_files(wc.exp, wc.it),
    output:
        responses="results/{exp}/iter_{it}/responses.csv",
        replicates="results/{exp}/iter_{it}/replicates.csv",
    log:
        "results/{exp}/logs/iter_{it}/aggregate.log",
    conda:
        CONDA_ENV
    params:
        records=lambda wc: list(records(wc.exp)),
        replicates=lambda wc: replicate_ids(wc.exp),
    script:
        "../scripts/aggregate.py"


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
    log:
        "results/{exp}/logs/iter_{it}/analysis.log",
    conda:
        CONDA_ENV
    params:
        inference=lambda wc: inference_settings(wc.exp),
    script:
        "../scripts/analysis.py"
