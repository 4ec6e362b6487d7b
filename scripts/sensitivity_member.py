"""One simulation of the sensitivity design: calibration.workflow_io.run_member with the row's parameters, the
experiment's fixed parameters and its other estimated parameters held at their prior-box centres."""
from calibration.workflow_io import member_params, run_member, simulator_command

sim = snakemake.params.sim
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params=member_params(snakemake.input.params, snakemake.wildcards.sample,
                                {**sim["fixed"], **snakemake.params.held}),
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, time_limit_s=snakemake.resources.time_limit_s,
           max_attempts=snakemake.params.max_attempts,
           extra_run={"sensitivity_sample": int(snakemake.wildcards.sample), "record": snakemake.wildcards.record})
