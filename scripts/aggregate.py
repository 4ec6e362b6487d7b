"""iter_<k>/responses.csv and replicates.csv: every member's and replicate's curves on the observation grid,
with its status."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from pathlib import Path

import pandas as pd

from calibration.observations import read_curve, read_observations, response_matrix
from calibration.workflow_io import combine_member_runs, member_ids, read_json, write_responses

obs = read_observations(snakemake.input.obs, snakemake.input.obs_meta)


def collect(out, folder_name, ids, numbers):
    curves, status = [], []
    for mid in ids:
        folder = {rec: Path(out).parent / folder_name / mid / rec for rec in snakemake.params.records}
        curves.append({rec: read_curve(f / "curve.csv") for rec, f in folder.items()})
        status.append(combine_member_runs({rec: read_json(f / "run.json") for rec, f in folder.items()}))
    write_responses(out, numbers, status, response_matrix(curves, obs))


members = pd.read_csv(snakemake.input.params)["member"].tolist()
collect(snakemake.output.responses, "members", member_ids(len(members)), members)
reps = list(snakemake.params.replicates)
if "replicates" in snakemake.output.keys():  # the refinement batch (rule refine_aggregate) has none
    collect(snakemake.output.replicates, "replicates", reps, list(range(len(reps))))
