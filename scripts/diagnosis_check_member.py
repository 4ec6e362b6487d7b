"""One real FDEM run of the loop's check (check_runs.json, row `row`; rules/diagnosis.smk)."""
from calibration.workflow_io import read_json, run_member, simulator_command

sim, wc = snakemake.params.sim, snakemake.wildcards
row = read_json(snakemake.input.rows)["rows"][int(wc.row)]
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **row["simulator"]}, record=snakemake.params.record_file or None,
           t_end=sim["t_end"], sample_dt=sim["sample_dt"], curve_path=snakemake.output.curve,
           run_path=snakemake.output.run, log_path=snakemake.log[0], attempt=snakemake.resources.attempt,
           time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           mesh_seed=snakemake.params.mesh_seed,
           extra_run={"check_row": int(wc.row), "step": row["step"], "role": row["role"], "record": row["record"]})
