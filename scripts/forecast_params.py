"""forecast/params.json: posterior mean of the final ensemble (alive members)."""
import numpy as np
import pandas as pd

from shpb.workflow_io import atomic_write_json, read_json

final = read_json(snakemake.input.analyses[-1])
P = pd.read_csv(snakemake.input.params)
alive = np.asarray(final["alive"], bool)
names = [c for c in P.columns if c != "member"]
atomic_write_json(snakemake.output.params, {"iteration": final["iteration"],
                                            "params": {p: float(P[p].to_numpy()[alive].mean()) for p in names}})
