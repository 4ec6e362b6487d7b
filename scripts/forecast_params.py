"""forecast/params.json: the posterior mean: of the emulator MCMC sample (posterior: emulator_mcmc) or of the
reported ensemble's alive members (the last iteration's, or the best's when the last made the fit markedly
worse: calibration.verdict.reported_iteration)."""
import numpy as np
import pandas as pd

from calibration.verdict import reported_iteration
from calibration.workflow_io import atomic_write_json, read_json

analyses = [read_json(f) for f in snakemake.input.analyses]
params = list(snakemake.input.params)
k = reported_iteration([a["misfit"]["chi2_per_obs"] for a in analyses])
P = pd.read_csv(params[k])
names = [c for c in P.columns if c != "member"]
if "samples" in snakemake.input.keys():
    S = pd.read_csv(snakemake.input.samples)
    k = len(analyses) - 1
    mean, source = {p: float(S[p].mean()) for p in names}, "emulator_mcmc"
else:
    alive = np.asarray(analyses[k]["alive"], bool)
    mean, source = {p: float(P[p].to_numpy()[alive].mean()) for p in names}, "ensemble"
atomic_write_json(snakemake.output.params, {"iteration": analyses[k]["iteration"], "posterior": source, "params": mean})
