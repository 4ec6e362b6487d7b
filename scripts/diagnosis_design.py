"""diagnosis/design/params.csv + design.json: the selection model's design around the calibrated posterior
(diagnosis.selection_model: the anchored one-at-a-time runs, or the emulator's space-filling design)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import numpy as np
import pandas as pd

from calibration.experiment import ExperimentSpec, diagnosis_settings
from calibration.closing import candidate_effects
from calibration.diagnose import (anchored_design, base_design_box, design_points, physical_design_ranges,
                                  workflow_sample)
from calibration.diagnosis_config import design_size, selection_model
from calibration.workflow_io import atomic_write_csv, atomic_write_json

e, exp = snakemake.params.exp, snakemake.wildcards.exp
d = diagnosis_settings(e)
spec = ExperimentSpec.from_config(exp, e)
post = pd.read_csv(snakemake.input.posterior)
sample = workflow_sample(post, spec.names)  # the draws summary.json's posterior summarises
blo, bhi = base_design_box(post, spec.names, spec.lower, spec.upper, width_sd=d["base_width_sd"],
                           min_rel_width=d["base_min_rel_width"])
pnames, plo, phi = physical_design_ranges(candidate_effects(d), d["physical_upper"])
model = selection_model(d)
axis = pair = None
if model == "anchored":
    X, axis, pair = anchored_design(sample.mean(axis=0), blo, bhi, plo, phi,
                                    base_step=float(d.get("anchor_step", 0.25)), sweep=int(d.get("sweep_points", 3)),
                                    cross=[list(spec.names).index(n) for n in d.get("interactions") or []])
else:
    X = design_points(blo, bhi, plo, phi, d["design_points"], seed=d["seed"], null_fraction=d["null_fraction"])
if X.shape[0] != design_size(e):  # the Snakefile declared design_size(e) runs per record
    raise RuntimeError(f"the {model} design of {exp} has {X.shape[0]} points, the workflow declared {design_size(e)}")
names = list(spec.names) + pnames
frame = pd.DataFrame(X, columns=names)
frame.insert(0, "member", np.arange(len(frame)))
atomic_write_csv(frame, snakemake.output.design)
atomic_write_json(snakemake.output.meta, {"names": names, "base_names": list(spec.names), "physical_names": pnames,
                                          "selection_model": model,
                                          "axis": None if axis is None else axis.tolist(),
                                          "pair": None if pair is None else pair.tolist(),
                                          "lower": np.concatenate([blo, plo]).tolist(),
                                          "upper": np.concatenate([bhi, phi]).tolist(),
                                          "posterior_mean": dict(zip(spec.names, sample.mean(axis=0).tolist())),
                                          "posterior_std": dict(zip(spec.names, sample.std(axis=0, ddof=1).tolist()))})
