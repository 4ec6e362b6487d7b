"""diagnosis/heldout/obs.csv + obs.json: the held-out records as rule reduced_record stored them, reduced and
corrected like the calibration records (the mesh offset and scatter of the approximation pairs run on each
held-out record's own incident wave, where the experiment has an approximation error)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.approximation import apply_stored_approximation_error
from calibration.observations import stored_observations

e = snakemake.params.exp
o = e["observations"]
obs = stored_observations(snakemake.params.records, t_start=o["t_start"], t_end=o["t_end"], dt=o["dt"],
                          error_kind=o["error"]["kind"], sigma_scale=o["error"]["sigma_scale"])
obs = apply_stored_approximation_error(obs, e, snakemake.params.approximation)
obs.write(snakemake.output.csv, snakemake.output.meta)
