"""diagnosis/realrun.json: what the selection on real runs names (calibration.realrun)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.realrun import summary_of
from calibration.workflow_io import atomic_write_json, read_json

atomic_write_json(snakemake.output.realrun, summary_of(read_json(snakemake.input.last)))
