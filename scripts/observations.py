"""observations/obs.csv + obs.json: twin (truth + noise) or measured records (calibration.observations)."""
import pandas as pd

from calibration.experiment import rng_for
from calibration.observations import measured_observations, observation_grid, twin_observations

e = snakemake.params.exp
o = e["observations"]
if e["kind"] == "twin":
    grid = observation_grid(o["t_start"], o["t_end"], o["dt"] or 1.0e-6)
    obs = twin_observations(pd.read_csv(snakemake.input.truth), grid, rng=rng_for(e["seed"], "noise"),
                            relative_sigma=o["noise"]["relative_sigma"], sigma_Pa=o["noise"]["sigma_Pa"],
                            corr_time=o["noise"]["corr_time"], meta={"truth": o["truth"]})
else:
    obs, _ = measured_observations(snakemake.params.records, t_start=o["t_start"], t_end=o["t_end"], dt=o["dt"],
                                   error_kind=o["error"]["kind"], sigma_scale=o["error"]["sigma_scale"])
obs.write(snakemake.output.csv, snakemake.output.meta)
