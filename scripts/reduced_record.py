"""observations/<record>/{record.json, incident.csv, curves.csv}: one measured record reduced once
(calibration.observations.write_reduced_record; the files: shpb.lab.reduced_store)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from pathlib import Path

from calibration.observations import write_reduced_record

write_reduced_record(snakemake.input[0], Path(snakemake.output.record).parent)
