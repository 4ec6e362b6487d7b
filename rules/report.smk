# Plots (Figs. 4-7 of the paper and diagnostics), posterior table and summary.json, and the summary the
# HTML report opens on (summary.html: verdict, intervals, misfit per iteration, diagnosis errors).


localrules:
    report_summary,


rule plots:
    input:
        unpack(final_inputs),
    output:
        parameters=report(
            "results/{exp}/plots/parameters.png",
            category="{exp}",
            caption="../report/parameters.rst",
        ),
        ensemble_curves=report(
            "results/{exp}/plots/ensemble_curves.png",
            category="{exp}",
            caption="../report/ensemble_curves.rst",
        ),
        forecast=report(
            "results/{exp}/plots/forecast.png",
            category="{exp}",
            caption="../report/forecast.rst",
        ),
        misfit=report(
            "results/{exp}/plots/misfit.png",
            category="{exp}",
            caption="../report/misfit.rst",
        ),
        sensitivity=report(
            "results/{exp}/plots/sensitivity.png",
            category="{exp}",
            caption="../report/sensitivity.rst",
        ),
    log:
        "results/{exp}/logs/plots.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/plots.py"


rule summary:
    input:
        unpack(final_inputs),
    output:
        summary="results/{exp}/summary.json",
        posterior="results/{exp}/posterior.csv",
    log:
        "results/{exp}/logs/summary.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        records=lambda wc: records(wc.exp),
    script:
        "../scripts/summary.py"


rule report_summary:
    input:
        unpack(report_summary_inputs),
    output:
        html=report(
            "results/{exp}/summary.html",
            category="0 Summary",
            caption="../report/summary.rst",
            labels={"experiment": "{exp}"},
        ),
    log:
        "results/{exp}/logs/report_summary.log",
    conda:
        CONDA_ENV
    script:
        "../scripts/report_summary.py"
