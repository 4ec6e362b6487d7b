"""refine/params.csv: the refinement batch of the reported emulator posterior (calibration.posterior.refine_design)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.observations import read_observations
from calibration.posterior import refine_design
from calibration.workflow_io import atomic_write_csv, read_json, read_responses

inp = snakemake.input
spec = ExperimentSpec.from_config(snakemake.wildcards.exp, snakemake.params.exp)
design = refine_design(spec, [pd.read_csv(p) for p in inp.params], [read_responses(p)[1] for p in inp.responses],
                       read_json(inp.analyses[-1]), read_observations(inp.obs, inp.obs_meta))
atomic_write_csv(design, snakemake.output.params)
