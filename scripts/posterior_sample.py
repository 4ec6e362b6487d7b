"""posterior/samples.csv + sampler.json: the emulator MCMC posterior (calibration.posterior, posterior: emulator_mcmc)."""
import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.observations import read_observations
from calibration.posterior import sample_posterior, samples_frame
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json, read_responses

inp = snakemake.input
spec = ExperimentSpec.from_config(snakemake.wildcards.exp, snakemake.params.exp)
post = sample_posterior(spec, [pd.read_csv(p) for p in inp.params], [read_responses(p)[1] for p in inp.responses],
                        read_json(inp.analyses[-1]), read_observations(inp.obs, inp.obs_meta))
atomic_write_csv(samples_frame(post), snakemake.output.samples)
atomic_write_json(snakemake.output.sampler, post.to_dict())
