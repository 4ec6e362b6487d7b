"""diagnosis/realrun.json: what the selection on real runs names (calibration.realrun); and the rows of the
held-out records' prediction runs at the fits it reports (calibration.realrun_files.heldout_rows)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.realrun_files import heldout_rows, summary_of
from calibration.workflow_io import atomic_write_json, read_json

summary = summary_of(read_json(snakemake.input.last))
rows = heldout_rows(summary, snakemake.params.heldout, int(snakemake.params.check_meshes))
atomic_write_json(snakemake.output.heldout_rows, {"rows": rows})
atomic_write_json(snakemake.output.realrun, summary)
