"""diagnosis/report.json, check.json, check.png: the confirmation walk on the real cross-validation runs,
then the held-out records' errors before and after (calibration.closing.assemble)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pickle
from pathlib import Path

from calibration.closing import assemble
from calibration.observations import read_observations
from calibration.plots import plot_diagnosis_check
from calibration.walk import check_runs_of
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json

inp, out = snakemake.input, snakemake.output
state = pickle.loads(open(inp.selection, "rb").read())
if "discrepancy" not in state:  # written before the bands needed the calibration's discrepancy
    raise RuntimeError(f"{inp.selection} holds no discrepancy: re-run rule diagnosis_select for it")
# row i's run, written by the check's batches (rules/inputs.smk, diagnosis_check_inputs)
rows, runs = check_runs_of(Path(inp.rows).parent)
obs = read_observations(inp.obs, inp.obs_meta)
held = read_observations(inp.heldout, inp.heldout_meta) if "heldout" in inp.keys() else None
# the refit's identification gate can ship an earlier step of the walk (calibration.walk.gated)
refit = read_json(inp.refit) if "refit" in inp.keys() else None
report, check, curves, bands = assemble(state["selection"], rows, runs, state["model"], obs, held, state["noise"],
                                        state["simulator"], state["discrepancy"], refit)
atomic_write_json(out.report, report)
atomic_write_json(out.check, check)
atomic_write_csv(bands, out.band)
plot_diagnosis_check(out.png, curves, check["errors_per_record"], check["added"], check["fdem_confirmation"]["text"],
                     bands, check["predictive_band"]["records"])
