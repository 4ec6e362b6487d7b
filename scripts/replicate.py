"""One replicate run at the iteration's ensemble mean on its own mesh realization (calibration.model_error)."""
import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.workflow_io import run_member, simulator_command

sim, wc = snakemake.params.sim, snakemake.wildcards
spec = ExperimentSpec.from_config(wc.exp, snakemake.config["experiments"][wc.exp])
P = pd.read_csv(snakemake.input.params)[list(spec.names)].to_numpy(float)
# the mean in the unbounded space of the analysis: for a box over orders of magnitude (E_t 100-50,000
# J/m^2) the arithmetic mean of a prior Latin hypercube sits far from where the members are
mean = spec.transform.to_bounded(spec.transform.to_unbounded(P).mean(axis=0)[None, :])[0]
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **dict(zip(spec.names, map(float, mean)))},
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, mesh_seed=snakemake.params.mesh_seed,
           time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           extra_run={"replicate": int(wc.member), "iteration": int(wc.it), "record": wc.record})
