"""One replicate run at the iteration's ensemble mean on its own mesh realization (calibration.model_error)."""
from calibration.workflow_io import ensemble_mean_params, run_member, simulator_command

sim = snakemake.params.sim
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **ensemble_mean_params(snakemake.input.params)},
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, mesh_seed=snakemake.params.mesh_seed,
           time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           extra_run={"replicate": int(snakemake.wildcards.member), "iteration": int(snakemake.wildcards.it),
                      "record": snakemake.wildcards.record})
