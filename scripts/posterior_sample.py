"""posterior/samples.csv + sampler.json: the emulator MCMC posterior (calibration.posterior, posterior: emulator_mcmc)."""
import pandas as pd

from calibration.experiment import ExperimentSpec
from calibration.observations import read_observations
from calibration.posterior import refine_record, sample_posterior, samples_frame
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json, read_responses

inp = snakemake.input
spec = ExperimentSpec.from_config(snakemake.wildcards.exp, snakemake.params.exp)
refine = None
if "refine_params" in inp.keys():  # emulated.refine_runs: the refinement batch, the latest runs
    status, Y_ref = read_responses(inp.refine_responses)
    Y_ref[status["status"].to_numpy(str) != "ok"] = float("nan")  # a failed run is no design point
    refine = (pd.read_csv(inp.refine_params), Y_ref)
post = sample_posterior(spec, [pd.read_csv(p) for p in inp.params], [read_responses(p)[1] for p in inp.responses],
                        read_json(inp.analyses[-1]), read_observations(inp.obs, inp.obs_meta), refine)
if refine is not None:
    post.diagnostics["refine"] = refine_record(spec, status, Y_ref)
atomic_write_csv(samples_frame(post), snakemake.output.samples)
atomic_write_json(snakemake.output.sampler, post.to_dict())
