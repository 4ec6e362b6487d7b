# Plots (Figs. 4-7 of the paper and diagnostics), posterior table and summary.json, and the summary the
# HTML report opens on (summary.html: verdict, intervals, misfit per iteration, diagnosis errors).

localrules: report_summary


def final_inputs(wc):
    exp = wc.exp
    recs = list(records(exp))
    files = {
        "params": iteration_files(exp, "params.csv"),
        "responses": iteration_files(exp, "responses.csv"),
        "analyses": iteration_files(exp, "analysis.json"),
        "obs": f"results/{exp}/observations/obs.csv",
        "obs_meta": f"results/{exp}/observations/obs.json",
        "forecast_curves": expand("results/{exp}/forecast/{record}/curve.csv", exp=exp, record=recs),
        "forecast_runs": expand("results/{exp}/forecast/{record}/run.json", exp=exp, record=recs),
        "forecast_params": f"results/{exp}/forecast/params.json",
    }
    files.update(posterior_sample_files(exp))
    if EXPERIMENTS[exp]["kind"] == "twin":
        files["truth_run"] = f"results/{exp}/truth/synthetic/run.json"
    return files


rule plots:
    input:
        unpack(final_inputs),
    output:
        parameters=report("results/{exp}/plots/parameters.png", category="{exp}",
                          caption="../report/parameters.rst"),
        ensemble_curves=report("results/{exp}/plots/ensemble_curves.png", category="{exp}",
                               caption="../report/ensemble_curves.rst"),
        forecast=report("results/{exp}/plots/forecast.png", category="{exp}", caption="../report/forecast.rst"),
        misfit=report("results/{exp}/plots/misfit.png", category="{exp}", caption="../report/misfit.rst"),
        sensitivity=report("results/{exp}/plots/sensitivity.png", category="{exp}",
                           caption="../report/sensitivity.rst"),
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
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        records=lambda wc: records(wc.exp),
    script:
        "../scripts/summary.py"


def report_summary_inputs(wc):
    files = {"summary": f"results/{wc.exp}/summary.json"}
    if diagnosis_cfg(wc.exp):  # the diagnosis's FDEM check: errors before and after, held-out records too
        files["check"] = f"results/{wc.exp}/diagnosis/check.json"
    return files


rule report_summary:
    input:
        unpack(report_summary_inputs),
    output:
        html=report("results/{exp}/summary.html", category="0 Summary", caption="../report/summary.rst",
                    labels={"experiment": "{exp}"}),
    script:
        "../scripts/report_summary.py"
