"""One FDEM run of the diagnosis design (calibration.workflow_io.run_member with the design point's parameters)."""
from calibration.workflow_io import member_params, run_member, simulator_command

sim = snakemake.params.sim
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params=member_params(snakemake.input.params, snakemake.wildcards.point, sim["fixed"]),
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, time_limit_s=snakemake.resources.time_limit_s,
           max_attempts=snakemake.params.max_attempts, mesh_seed=snakemake.params.mesh_seed,
           extra_run={"design_point": int(snakemake.wildcards.point), "record": snakemake.wildcards.record})
