"""plots/*.png of a finished experiment (calibration.plots)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import numpy as np
import pandas as pd

from calibration import plots
from calibration.experiment import ExperimentSpec, final_iteration, final_verdict, reported_ensemble
from calibration.observations import read_curve, read_observations
from calibration.workflow_io import read_json, read_responses

inp, out, exp = snakemake.input, snakemake.output, snakemake.wildcards.exp
spec = ExperimentSpec.from_config(exp, snakemake.params.exp)
obs = read_observations(inp.obs, inp.obs_meta)
params = [pd.read_csv(p) for p in inp.params]
analyses = [read_json(p) for p in inp.analyses]
Ys = [read_responses(p)[1] for p in inp.responses]
alive = [np.asarray(a["alive"], bool) for a in analyses]
title = f"{exp} ({snakemake.params.exp['kind']}, {spec.method}, N = {spec.ensemble_size})"
plots.plot_parameters(out.parameters, params, alive, spec.names, spec.lower, spec.upper, spec.truth, title)
plots.plot_ensemble_curves(out.ensemble_curves, obs, Ys, title)
K = min(final_iteration(spec, analyses)[0], len(analyses) - 1)
misfits = [{"iteration": a["iteration"], **a["misfit"]} for a in analyses[:K + 1]]
# the summary's verdict on the same posterior (the MCMC sample where the experiment reports one)
verdict = final_verdict(spec, analyses, params, snakemake.params.exp,
                        pd.read_csv(inp.samples) if "samples" in inp.keys() else None,
                        read_json(inp.sampler) if "sampler" in inp.keys() else None)
R = reported_ensemble(spec, analyses, params)[0]  # the ensemble reported as the posterior
forecast = {r: read_curve(p) for r, p in zip(obs.records, inp.forecast_curves)}
plots.plot_forecast(out.forecast, obs, np.nanmean(Ys[0][alive[0]], axis=0), forecast, title,
                    posterior_mean=np.nanmean(Ys[R][alive[R]], axis=0))
plots.plot_misfit(out.misfit, misfits, [a["misfit_per_record"] for a in analyses[:K + 1]],
                  spec.criteria.target(obs.m), title, verdict=verdict)
chi2 = np.array([m["chi2_per_obs"] if m["chi2_per_obs"] is not None else np.nan for m in analyses[0]["members"]])
plots.plot_sensitivity(out.sensitivity, obs, params[0], Ys[0], spec.names, chi2, spec.truth, title)
