"""results/<exp>/summary.html: the summary the HTML report opens on (calibration.report_summary)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.report_summary import summary_html
from calibration.workflow_io import atomic_write_text, read_json

inp = snakemake.input
check = read_json(inp.check) if "check" in inp.keys() else None
refit = read_json(inp.refit) if "refit" in inp.keys() else None
realrun = read_json(inp.realrun) if "realrun" in inp.keys() else None
if "realrun_heldout" in inp.keys():
    realrun = {**realrun, "heldout": read_json(inp.realrun_heldout)}
atomic_write_text(snakemake.output.html, summary_html(snakemake.wildcards.exp, read_json(inp.summary), check, refit,
                                                      realrun))
