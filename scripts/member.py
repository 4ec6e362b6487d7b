"""One ensemble member: `python -m shpb simulate` with the member's parameters (calibration.workflow_io.run_member)."""
from calibration.workflow_io import member_params, run_member, simulator_command

sim = snakemake.params.sim
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params=member_params(snakemake.input.params, snakemake.wildcards.member, sim["fixed"]),
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, mesh_seed=snakemake.params.mesh_seed, time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           # the refinement batch's runs (rule refine_member) have no loop iteration
           extra_run={"member": int(snakemake.wildcards.member),
                      "iteration": snakemake.params.get("iteration") or int(snakemake.wildcards.it),
                      "record": snakemake.wildcards.record})
