"""posterior/samples.csv + sampler.json: the emulator MCMC posterior (calibration.posterior, posterior: emulator_mcmc)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.observations import read_observations
from calibration.posterior import refine_batch, sample_posterior, samples_frame
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json, read_responses

inp = snakemake.input
spec = ExperimentSpec.from_config(snakemake.wildcards.exp, snakemake.params.exp)
refine, record = None, None
if "refine_params" in inp.keys():  # emulated.refine_runs: the refinement batch, the latest runs
    refine, record = refine_batch(spec, pd.read_csv(inp.refine_params), *read_responses(inp.refine_responses))
post = sample_posterior(spec, [pd.read_csv(p) for p in inp.params], [read_responses(p)[1] for p in inp.responses],
                        read_json(inp.analyses[-1]), read_observations(inp.obs, inp.obs_meta), refine)
if record is not None:
    post.diagnostics["refine"] = record
atomic_write_csv(samples_frame(post), snakemake.output.samples)
atomic_write_json(snakemake.output.sampler, post.to_dict())
