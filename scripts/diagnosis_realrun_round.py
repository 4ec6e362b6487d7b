"""diagnosis/realrun/round_<r>.json: round r of the selection on real runs (calibration.realrun): round 0
the weights' runs and every model's first linearisation, each later round what the runs before it give
and the next runs, or the result. The held-out records are neither read nor run."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from pathlib import Path

from calibration.observations import read_curve, read_observations
from calibration.realrun import first_round, next_round
from calibration.realrun_files import on_grid, series_of
from calibration.workflow_io import atomic_write_json, read_json

inp, e = snakemake.input, snakemake.params.exp
obs = read_observations(inp.obs, inp.obs_meta)
s = series_of(obs, e)
cfg = e["diagnosis"]["realrun_selection"]
if int(snakemake.wildcards.r) == 0:
    # from the workflow's reported posterior mean, every effect at its null
    post = read_json(inp.summary)["posterior"]
    state = first_round({n: float(post[n]["mean"]) for n in ("sigma_t", "E_t")}, cfg["candidates"], list(obs.records),
                        s["box"], profile=int(cfg["profile"]), check_meshes=int(cfg["check_meshes"]),
                        resolution=cfg.get("resolution"))
else:
    last = read_json(inp.rounds[-1])
    folder = Path(inp.rounds[0]).parent / f"iter_{len(inp.rounds) - 1}"
    curves = [on_grid(read_curve(folder / str(i) / "curve.csv"), s["times"][row["record"]])
              for i, row in enumerate(last["rows"])]
    state = next_round(last, curves, s["y"], s["noise"], s["times"])
atomic_write_json(snakemake.output.state, state)
