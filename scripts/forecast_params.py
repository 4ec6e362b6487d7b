"""forecast/params.json: the posterior mean the forecast runs at (calibration.posterior.forecast_parameters)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.posterior import forecast_parameters
from calibration.workflow_io import atomic_write_json, read_json

inp = snakemake.input
samples = pd.read_csv(inp.samples) if "samples" in inp.keys() else None
atomic_write_json(snakemake.output.params, forecast_parameters(
    ExperimentSpec.from_config(snakemake.wildcards.exp, snakemake.params.exp),
    [read_json(f) for f in inp.analyses], [pd.read_csv(f) for f in inp.params], samples))
