"""One FDEM run at the loop's posterior mean, before or after (rules/diagnosis.smk, diagnosis_check_member)."""
from calibration.diagnose import heldout_fill, simulator_params
from calibration.workflow_io import read_json, run_member, simulator_command

sim, wc = snakemake.params.sim, snakemake.wildcards
rep = read_json(snakemake.input.report)
post = rep[f"params_{wc.which}"]  # per-record parameters: the record's own, a held-out record's fill
run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
           params={**sim["fixed"], **simulator_params(post, wc.record, heldout_fill(rep, wc.record))},
           record=snakemake.params.record_file or None,
           t_end=sim["t_end"], sample_dt=sim["sample_dt"], curve_path=snakemake.output.curve,
           run_path=snakemake.output.run, log_path=snakemake.log[0], attempt=snakemake.resources.attempt,
           time_limit_s=snakemake.resources.time_limit_s, max_attempts=snakemake.params.max_attempts,
           extra_run={"check": wc.which, "record": wc.record})
