"""diagnosis/realrun_heldout.json: the held-out records' errors before and after, at the fits the selection
on real runs reports (calibration.realrun_files.heldout_errors). The first script that reads the held-out
records' curves for it; the fits were made without them."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from pathlib import Path

from calibration.observations import read_curve, read_observations
from calibration.realrun_files import heldout_errors, on_grid
from calibration.workflow_io import atomic_write_json, read_json

inp = snakemake.input
held = read_observations(inp.obs, inp.obs_meta)
rows = read_json(inp.rows)["rows"]
y = {h: held.values[held.record_slice(h)] for h in held.records}
times = {h: held.time[held.record_slice(h)] for h in held.records}
folder = Path(inp.rows).parent / "realrun_heldout"
curves = [on_grid(read_curve(folder / str(i) / "curve.csv"), times[row["record"]]) for i, row in enumerate(rows)]
atomic_write_json(snakemake.output.heldout, {
    "records": heldout_errors(rows, curves, y, times), "runs": len(rows), "failed": sum(c is None for c in curves),
    "note": ("each held-out record run at the base's fit (before) and the named effect's (after) on every check mesh, "
             "a per-record parameter at the calibration records' mean; rmse: of one run on a random mesh")})
