"""sensitivity/report.json, indices_time.csv, indices_features.csv, plots/sensitivity_indices.png: the
design's curves on the experiment's observation grid -> calibration.sensitivity.analyze."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import numpy as np
import pandas as pd

from calibration import sensitivity as sa
from calibration.observations import curve_on_grid, observation_grid, read_curve, reduce_measured_record
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json

exp, e = snakemake.wildcards.exp, snakemake.params.exp
spec = sa.SensitivitySpec.from_config(exp, e)
o = e["observations"]
dt = o["dt"]
if dt is None:  # the observations' own default: 1 us for a twin, the record's sampling for a measured one
    dt = 1.0e-6 if e["kind"] == "twin" else reduce_measured_record(snakemake.input.record[0])[0].dt
grid = observation_grid(o["t_start"], o["t_end"], dt)

X = pd.read_csv(snakemake.input.design)[list(spec.names)].to_numpy(float)
Y = np.full((len(X), grid.size), np.nan)
reasons = {}
for i, (curve, run) in enumerate(zip(snakemake.params.curves, snakemake.params.runs)):
    status = read_json(run)
    df = read_curve(curve)
    if status.get("status") == "ok" and len(df) >= 2:
        Y[i] = curve_on_grid(df["time_s"].to_numpy(float), df["stress_Pa"].to_numpy(float), grid)
    if status.get("status") != "ok":
        reasons[i] = status.get("reason") or "failed"
    elif not np.all(np.isfinite(Y[i])):
        reasons[i] = "the curve does not cover the observation window"
indices = sa.analyze(spec, X, Y, grid, failed_reasons=reasons)  # refuses, naming the rows, if any failed
wall = [read_json(r).get("wall_s") or 0.0 for r in snakemake.params.runs]
atomic_write_json(snakemake.output.report, sa.report(spec, indices, simulation_wall_s=float(np.sum(wall)),
                                                     grid={"t_start_s": grid[0], "t_end_s": grid[-1], "dt_s": dt}))
table_time, table_features = sa.tables(indices)
atomic_write_csv(table_time, snakemake.output.time)
atomic_write_csv(table_features, snakemake.output.features)
sa.plot_sensitivity_indices(snakemake.output.png, grid, indices,
                            title=f"{exp}: {spec.method}, N = {spec.samples}, {spec.n_simulations} simulations")
