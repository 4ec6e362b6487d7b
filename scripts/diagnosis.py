"""diagnosis/selection.pkl + check_runs.json: effects chosen by cross-validation within the calibration
records on the selection model of the FDEM design (anchored or emulator) (calibration.closing; the held-out records' curves are not read)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pickle
from pathlib import Path

import pandas as pd

from calibration.closing import (blind, calibration_discrepancy, check_rows, covariate_table, emulated_model,
                                 protocol_errors, select_effects)
from calibration.diagnose import model_grid
from calibration.experiment import diagnosis_settings
from calibration.model_error import check_replicate_count
from calibration.observations import read_curve, read_observations
from calibration.protocol import workflow_base
from calibration.workflow_io import atomic_write_bytes, atomic_write_csv, atomic_write_json, read_json

inp, out, e = snakemake.input, snakemake.output, snakemake.params.exp
d = diagnosis_settings(e)
meta = read_json(inp.design_meta)
names = meta["names"]
X = pd.read_csv(inp.design)[names].to_numpy(float)
obs = read_observations(inp.obs, inp.obs_meta)
# the held-out records' curves are not read here: their times and noise only (diagnosis_check reads them)
held = blind(read_observations(inp.heldout, inp.heldout_meta)) if "heldout" in inp.keys() else None
summary = read_json(inp.summary)
analysis = read_json(list(inp.analyses)[int(summary["posterior_iteration"])])

root = Path(inp.design).parent
curves = {rec: [read_curve(root / p / rec / "curve.csv") for p in snakemake.params.points]
          for rec in snakemake.params.design_records}
obs_times = {r: obs.grid(r) for r in obs.records}
obs_times.update({r: held.grid(r) for r in (held.records if held is not None else [])})
model, n_failed = emulated_model(X, names, meta["lower"], meta["upper"], curves, model_grid(e["simulation"]),
                                 obs_times, label=f"diagnosis of {snakemake.wildcards.exp}", axis=meta.get("axis"),
                                 pair=meta.get("pair"))
noise, simulator = protocol_errors(obs, analysis, held)
# the base model is the workflow's posterior (posterior.csv, summary.json), not a second fit on the emulator
base = workflow_base(model, meta["base_names"], obs.records, pd.read_csv(inp.posterior), summary, file=inp.posterior)
selection = select_effects(model, base_names=meta["base_names"], candidates=snakemake.params.candidates, obs=obs,
                           noise=noise, simulator=simulator, heldout_records=held.records if held is not None else [],
                           settings=d, mesh_mode=e["simulation"].get("mesh_realizations") or "per_run", base_fit=base)
atomic_write_bytes(out.selection, pickle.dumps({"selection": selection, "model": model, "noise": noise,
                                                "simulator": simulator, "design_failed_runs": n_failed,
                                                "discrepancy": calibration_discrepancy(obs, analysis)}))
# the calibration records' residual at the base model's calibration against every covariate their sheets
# give (strain rate, length-to-diameter ratio, gas pressure): what a rate or geometry effect leaves
table, trends = covariate_table(selection, model, obs)
atomic_write_csv(table, out.covariates)
atomic_write_json(out.rows, {"rows": check_rows(selection, check_replicate_count(e)), "design_failed_runs": n_failed,
                             "covariate_trends": None if trends is None else trends.to_dict(orient="records")})
