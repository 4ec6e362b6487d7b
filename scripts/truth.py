"""Twin experiment: the reference simulation with the truth parameters on its own mesh realization (must succeed)."""
from calibration.workflow_io import run_member, simulator_command

sim = snakemake.params.sim
run = run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
                 params={**sim["fixed"], **snakemake.params.truth}, record=snakemake.params.record_file or None,
                 t_end=sim["t_end"], sample_dt=sim["sample_dt"], curve_path=snakemake.output.curve,
                 run_path=snakemake.output.run, log_path=snakemake.log[0], attempt=snakemake.resources.attempt, time_limit_s=snakemake.resources.time_limit_s,
                 max_attempts=snakemake.config["member_retries"] + 1, mesh_seed=snakemake.params.mesh_seed)
if run["status"] != "ok":
    raise RuntimeError(f"the reference simulation of {snakemake.wildcards.exp} failed: {run.get('reason')}")
