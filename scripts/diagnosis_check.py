"""diagnosis/check.json + check.png: errors of real FDEM runs at the loop's before/after posterior means."""
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shpb.diagnose import check_errors  # noqa: E402
from shpb.observations import read_curve, read_observations  # noqa: E402
from shpb.workflow_io import atomic_write_json, read_json  # noqa: E402

inp, out, e = snakemake.input, snakemake.output, snakemake.params.exp
rep = read_json(inp.report)
dt = e["simulation"]["sample_dt"] or 5.0e-7
model_t = np.arange(0.0, e["simulation"]["t_end"] + 1e-12, dt)
sets = [("calibration", read_observations(inp.obs, inp.obs_meta))]
if "heldout" in inp.keys():
    sets.append(("heldout", read_observations(inp.heldout, inp.heldout_meta)))
root = Path(inp.report).parent / "check"

runs = {w: {r: read_curve(root / w / r / "curve.csv") for _, o in sets for r in o.records}
        for w in ("before", "after")}
result, curves = check_errors(sets, runs, model_t, {w: rep[f"params_{w}"] for w in ("before", "after")})
atomic_write_json(out.check, {"added": rep["added"], "verdict": rep["verdict"], "errors_per_record": result,
                              "note": "real FDEM runs at the posterior means of diagnosis/report.json "
                                      "(params_before, params_after); None = the run failed"})

fig, axes = plt.subplots(1, len(curves), figsize=(4.2 * len(curves), 3.6), squeeze=False)
after_label = "with " + ", ".join(rep["added"]) if rep["added"] else "after (nothing added)"
for ax, (r, c) in zip(axes[0], curves.items()):
    ax.plot(c["time"] * 1e6, c["obs"] / 1e6, ".", ms=2, color="0.5", label="data")
    for which, name in (("before", "base model"), ("after", after_label)):
        if c[which] is not None:
            rmse = result[r][which]["rmse"] / 1e6
            ax.plot(c["time"] * 1e6, c[which] / 1e6, label=f"FDEM, {name} (RMSE {rmse:.1f} MPa)")
    ax.set_title(f"{r} ({c['data']})", fontsize=9)
    ax.set_xlabel("time [us]")
    ax.legend(fontsize=7)
axes[0][0].set_ylabel("stress [MPa]")
fig.tight_layout()
tmp = Path(out.png).with_suffix(".tmp.png")
fig.savefig(tmp, dpi=110)
tmp.replace(out.png)
