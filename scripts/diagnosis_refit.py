"""diagnosis/refit.json: the shipped model's parameters re-fitted on real runs (calibration.refit)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.refit import refit_summary
from calibration.workflow_io import atomic_write_json, read_json

atomic_write_json(snakemake.output.refit, refit_summary(read_json(snakemake.input.last)))
