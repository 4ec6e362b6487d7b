"""iter_<k>/responses.csv: every member's curves on the observation grid, with its status."""
from pathlib import Path

import pandas as pd

from calibration.observations import read_curve, read_observations, response_matrix
from calibration.workflow_io import combine_member_runs, member_ids, read_json, write_responses

obs = read_observations(snakemake.input.obs, snakemake.input.obs_meta)
members = pd.read_csv(snakemake.input.params)["member"].tolist()
curves, status = [], []
for m, mid in zip(members, member_ids(len(members))):
    folder = {rec: Path(snakemake.output.responses).parent / "members" / mid / rec
              for rec in snakemake.params.records}
    curves.append({rec: read_curve(f / "curve.csv") for rec, f in folder.items()})
    status.append(combine_member_runs({rec: read_json(f / "run.json") for rec, f in folder.items()}))
write_responses(snakemake.output.responses, members, status, response_matrix(curves, obs))
