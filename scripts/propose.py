"""iter_<k>/params.csv: the analysis ensemble stored by iteration k-1's analysis."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.experiment import params_frame
from calibration.workflow_io import atomic_write_csv, read_json

nxt = read_json(snakemake.input.analysis)["next_params"]
if nxt is None:
    raise RuntimeError(f"{snakemake.input.analysis} holds no analysis ensemble (the ES-MDA schedule is complete)")
atomic_write_csv(params_frame(nxt["values"], nxt["names"]), snakemake.output.params)
