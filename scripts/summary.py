"""summary.json and posterior.csv of a finished experiment (calibration.experiment.experiment_outcome)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import os
import time

import pandas as pd

from calibration.experiment import experiment_outcome
from calibration.observations import read_curve, read_observations
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json, read_responses

inp, recs = snakemake.input, list(snakemake.params.records)
responses = [read_responses(p) for p in inp.responses]
summary, posterior = experiment_outcome(
    name=snakemake.wildcards.exp, exp=snakemake.params.exp, params=[pd.read_csv(p) for p in inp.params],
    responses=[Y for _, Y in responses], analyses=[read_json(p) for p in inp.analyses],
    obs=read_observations(inp.obs, inp.obs_meta), n_records=len(recs),
    forecast_curves={r: read_curve(p) for r, p in zip(recs, inp.forecast_curves)},
    forecast_runs={r: read_json(p) for r, p in zip(recs, inp.forecast_runs)},
    started=os.path.getmtime(inp.params[0]), finished=time.time(),
    member_wall_s=sum(float(s["wall_s"].sum()) for s, _ in responses),
    extra_runs=[read_json(inp.truth_run)] if "truth_run" in inp.keys() else [],
    posterior_samples=pd.read_csv(inp.samples) if "samples" in inp.keys() else None,
    posterior_sampler=read_json(inp.sampler) if "sampler" in inp.keys() else None)
summary["forecast_params"] = read_json(inp.forecast_params)["params"]
atomic_write_json(snakemake.output.summary, summary)
atomic_write_csv(posterior, snakemake.output.posterior)
