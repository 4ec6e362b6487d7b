"""diagnosis/: the discrepancy loop on the emulated FDEM design (calibration.diagnose, enkf.diagnosis)."""
from pathlib import Path

import pandas as pd

from calibration.diagnose import (EmulatedSHPB, covariate_trends, diagnose, emulators_from_design, errors_per_record,
                                  get_effect, model_grid, record_calibrations, record_covariates, record_prior_centres,
                                  report_to_json, write_report)
from calibration.observations import read_curve, read_observations
from calibration.workflow_io import atomic_write_csv, atomic_write_json, read_json

inp, out, e = snakemake.input, snakemake.output, snakemake.params.exp
d = e["diagnosis"]
meta = read_json(inp.design_meta)
names = meta["names"]
X = pd.read_csv(inp.design)[names].to_numpy(float)
model_t = model_grid(e["simulation"])
obs = read_observations(inp.obs, inp.obs_meta)
held = read_observations(inp.heldout, inp.heldout_meta) if "heldout" in inp.keys() else None

root = Path(inp.design).parent
curves = {rec: [read_curve(root / p / rec / "curve.csv") for p in snakemake.params.points]
          for rec in snakemake.params.design_records}
emulators, n_failed = emulators_from_design(X, curves, model_t, meta["lower"], meta["upper"], names,
                                            label=f"diagnosis of {snakemake.wildcards.exp}")
obs_times = {r: obs.grid(r) for r in obs.records}
if held is not None:
    obs_times.update({r: held.grid(r) for r in held.records})
info = {**obs.meta.get("record_info", {}), **(held.meta.get("record_info", {}) if held is not None else {})}
# per-record effects measured by the records' own waves (the face closure before load) centre their priors
model = EmulatedSHPB(emulators, names, model_t, obs_times, record_centres=record_prior_centres(info, d["candidates"]))

report = diagnose(model, base_names=meta["base_names"], candidates=[get_effect(c) for c in d["candidates"]],
                  calib_records=obs.records, obs=obs.values, obs_error=obs.error_model(), times=obs.time,
                  heldout_records=held.records if held is not None else (),
                  heldout_obs=held.values if held is not None else None,
                  heldout_times=held.time if held is not None else None,
                  seed=d["seed"], n_members=d["members"], esmda_steps=d["esmda_steps"],
                  max_additions=d["max_additions"], bic_margin=d["bic_margin"], scopes=d["scopes"])

# per record: errors before/after, and the residual against the strain rate (covariates)
c = report["curves"]
per_record, resid, sigma = errors_per_record([("calibration", obs, c["fitted_before"], c["fitted_after"]),
                                              ("heldout", held, c["heldout_before"], c["heldout_after"])])
cov = record_covariates(info, resid, sigma)
cov["data"] = [per_record[r]["data"] for r in cov["record"]]
# the base parameters fitted to each record alone, against the same covariates
fits = record_calibrations(model, meta["base_names"], [o for o in (obs, held) if o is not None], seed=d["seed"],
                           n_members=d["members"], esmda_steps=d["esmda_steps"])
cov = cov.merge(fits, on="record", how="left")
trend_cols = ["mean_resid_sd", "rms_resid_sd"] + [f"{n}_mean" for n in meta["base_names"]]
trends = covariate_trends(cov, "strain_rate_per_s", trend_cols) if len(cov) >= 3 else None

paths = write_report(report, out.report.rsplit("/", 1)[0])
js = report_to_json(report)
js["errors_per_record"] = per_record
js["covariate_trends"] = trends.reset_index().to_dict(orient="records") if trends is not None else None
js["design"] = {"names": names, "lower": meta["lower"], "upper": meta["upper"], "points": len(X),
                "failed_runs": n_failed}
atomic_write_json(out.report, js)
atomic_write_csv(cov, out.covariates)
