"""diagnosis/check.json + check.png: errors of real FDEM runs at the loop's before/after posterior means."""
from pathlib import Path


from calibration.diagnose import check_errors, fdem_confirmation, heldout_fill, model_grid
from calibration.observations import read_curve, read_observations
from calibration.plots import plot_diagnosis_check
from calibration.workflow_io import atomic_write_json, read_json

inp, out, e = snakemake.input, snakemake.output, snakemake.params.exp
rep = read_json(inp.report)
model_t = model_grid(e["simulation"])
sets = [("calibration", read_observations(inp.obs, inp.obs_meta))]
if "heldout" in inp.keys():
    sets.append(("heldout", read_observations(inp.heldout, inp.heldout_meta)))
root = Path(inp.report).parent / "check"

runs = {w: {r: read_curve(root / w / r / "curve.csv") for _, o in sets for r in o.records}
        for w in ("before", "after")}
result, curves = check_errors(sets, runs, model_t, {w: rep[f"params_{w}"] for w in ("before", "after")},
                              fills={r: heldout_fill(rep, r) for _, o in sets for r in o.records})
confirmation = fdem_confirmation(result, rep["added"])
atomic_write_json(out.check, {"added": rep["added"], "verdict": rep["verdict"],
                              "fdem_confirmation": confirmation, "errors_per_record": result,
                              "note": "real FDEM runs at the posterior means of diagnosis/report.json "
                                      "(params_before, params_after); None = the run failed"})

plot_diagnosis_check(out.png, curves, result, rep["added"], confirmation["text"])
