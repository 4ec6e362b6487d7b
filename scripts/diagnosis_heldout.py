"""diagnosis/heldout/obs.csv + obs.json: the held-out records reduced like the calibration records."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.observations import measured_observations

o = snakemake.params.obs
obs, _ = measured_observations(snakemake.params.records, t_start=o["t_start"], t_end=o["t_end"], dt=o["dt"],
                               error_kind=o["error"]["kind"], sigma_scale=o["error"]["sigma_scale"])
obs.write(snakemake.output.csv, snakemake.output.meta)
