"""forecast/params.json: the posterior mean: of the emulator MCMC sample (posterior: emulator_mcmc) or of the
final ensemble (alive members)."""
import numpy as np
import pandas as pd

from calibration.workflow_io import atomic_write_json, read_json

final = read_json(snakemake.input.analyses[-1])
P = pd.read_csv(snakemake.input.params)
names = [c for c in P.columns if c != "member"]
if "samples" in snakemake.input.keys():
    S = pd.read_csv(snakemake.input.samples)
    mean, source = {p: float(S[p].mean()) for p in names}, "emulator_mcmc"
else:
    alive = np.asarray(final["alive"], bool)
    mean, source = {p: float(P[p].to_numpy()[alive].mean()) for p in names}, "ensemble"
atomic_write_json(snakemake.output.params, {"iteration": final["iteration"], "posterior": source, "params": mean})
