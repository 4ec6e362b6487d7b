"""forecast/<record>/: the best-estimate simulation with the posterior-mean parameters, with fracture
snapshots (a failed run gets a picture saying so instead of the damage maps)."""
from pathlib import Path

from calibration.workflow_io import failure_card, read_json, run_member, simulator_command

sim = snakemake.params.sim
run = run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **read_json(snakemake.input.params)["params"]},
           record=snakemake.params.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
           curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
           attempt=snakemake.resources.attempt, time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           extra_run={"forecast": True, "record": snakemake.wildcards.record},
           snapshots=snakemake.params.snapshots)
for png in (snakemake.output.damage_peak, snakemake.output.damage_end, snakemake.output.overview):
    if not Path(png).is_file():
        why = (f"the forecast run failed: {run.get('reason', '')}" if run.get("status") != "ok"
               else f"the simulator ({sim['command']}) wrote no fracture snapshots")
        failure_card(png, f"No fracture snapshot: {why}")
