"""loro/summary.json, summary.html + folds.png: leave one record out over a series (calibration.closing.loro_table,
calibration.report_series)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.closing import loro_table
from calibration.plots import plot_loro
from calibration.report_series import series_html
from calibration.workflow_io import atomic_write_json, atomic_write_text, read_json

folds = dict(zip(snakemake.params.folds, (read_json(p) for p in snakemake.input.reports)))
info = {}
for p in snakemake.input.obs:
    info.update(read_json(p).get("record_info", {}))
table = loro_table(folds, info)
summary = {"experiment": snakemake.wildcards.exp, **table}
atomic_write_json(snakemake.output.summary, summary)
# the posterior each fold's own page says to quote (its summary.json), beside the table's selection fits
calibrated = {f: read_json(p).get("posterior") or {} for f, p in zip(snakemake.params.folds, snakemake.input.summaries)}
atomic_write_text(snakemake.output.html, series_html(snakemake.wildcards.exp, summary, calibrated))
plot_loro(snakemake.output.png, table)
