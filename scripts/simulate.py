"""Every simulation job (rules/simulate.smk, `rule simulate` and the rules that use it): `python -m shpb
simulate` through calibration.runner.run_member. What differs between the rules comes in params: where
the parameters are read (calibration.ensemble_files.simulation_params), the record, the mesh seed, the
fracture snapshots, the entries added to run.json and whether a failed run fails the job."""
from pathlib import Path

from calibration.ensemble_files import simulation_params
# the runner's own module, not calibration.workflow_io: that one also loads the config checks, which a
# member job never runs (0.09-0.17 s of every job's start, measured with python -X importtime)
from calibration.runner import failure_card, run_member, simulator_command

sim, p = snakemake.params.sim, snakemake.params
run = run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
                 params=simulation_params(p.parameters, sim["fixed"], snakemake.input.get("params"),
                                          snakemake.config["experiments"]),
                 record=p.record_file or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
                 curve_path=snakemake.output.curve, run_path=snakemake.output.run, log_path=snakemake.log[0],
                 attempt=snakemake.resources.attempt, time_limit_s=snakemake.resources.time_limit_s,
                 max_attempts=p.max_attempts, mesh_seed=p.mesh_seed, extra_run=p.run or None,
                 snapshots=p.snapshots)
if p.must_succeed and run["status"] != "ok":
    raise RuntimeError(f"the {snakemake.rule} simulation of {snakemake.wildcards.exp} failed: {run.get('reason')}")
# the outputs besides the curve and run.json are the snapshots' pictures: a failed run, or a simulator
# that writes none, gets a picture saying so
for name, png in snakemake.output.items():
    if name not in ("curve", "run") and not Path(png).is_file():
        why = (f"the {snakemake.rule} run failed: {run.get('reason', '')}" if run.get("status") != "ok"
               else f"the simulator ({sim['command']}) wrote no fracture snapshots")
        failure_card(png, f"No fracture snapshot: {why}")
