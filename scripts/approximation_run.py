"""One run of the approximation error's pairs at its design point and preset (calibration.approximation)."""
from calibration.approximation import approximation_run
from calibration.workflow_io import run_member, simulator_command

sim, wc = snakemake.params.sim, snakemake.wildcards
level, index, realization = approximation_run(wc.run)
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **snakemake.params.point},
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, mesh_seed=snakemake.params.mesh_seed,
           time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           extra_run={"approximation": level, "design_point": index, "realization": realization, "record": wc.record})
