"""observations/obs.csv + obs.json: twin (truth + noise) or the stored reduced records (calibration.observations),
corrected by the approximation error of the experiment's preset where it is configured (calibration.approximation)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pandas as pd

from calibration.approximation import apply_stored_approximation_error
from calibration.experiment import rng_for
from calibration.observations import observation_grid, stored_observations, twin_observations

e = snakemake.params.exp
o = e["observations"]
if e["kind"] == "twin":
    grid = observation_grid(o["t_start"], o["t_end"], o["dt"] or 1.0e-6)
    obs = twin_observations(pd.read_csv(snakemake.input.truth), grid, rng=rng_for(e["seed"], "noise"),
                            relative_sigma=o["noise"]["relative_sigma"], sigma_Pa=o["noise"]["sigma_Pa"],
                            corr_time=o["noise"]["corr_time"], meta={"truth": o["truth"]})
else:
    # each record as rule reduced_record stored it (read, not reduced again)
    obs = stored_observations(snakemake.params.records, t_start=o["t_start"], t_end=o["t_end"], dt=o["dt"],
                              error_kind=o["error"]["kind"], sigma_scale=o["error"]["sigma_scale"])
obs = apply_stored_approximation_error(obs, e, snakemake.params.approximation)
obs.write(snakemake.output.csv, snakemake.output.meta)
