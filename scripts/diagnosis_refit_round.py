"""diagnosis/refit/round_<r>.json: round r of the shipped model's refit on real runs (calibration.refit):
round 0 the design around the selection's fit, each later round the fit of the runs before it and the
next design, the spread over the check's meshes, or the end."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

import pickle
from pathlib import Path

from calibration.model_error import check_replicate_count
from calibration.observations import read_curve, read_observations
from calibration.refit import first_round_after_walk, next_round
from calibration.walk import check_runs_of
from calibration.workflow_io import atomic_write_json, read_json

inp, e = snakemake.input, snakemake.params.exp
saved = pickle.loads(Path(inp.selection).read_bytes())
selection, model = saved["selection"], saved["model"]
obs = read_observations(inp.obs, inp.obs_meta)
if int(snakemake.wildcards.r) == 0:
    # the model the walk ships on the check's runs (the held-out records are not read here)
    rows, runs = check_runs_of(Path(inp.rows).parent)
    state = first_round_after_walk(selection, rows, runs, model, obs, saved["noise"], saved["simulator"],
                                   level=e["diagnosis"]["identified_level"])
else:
    rounds = [read_json(p) for p in inp.rounds]
    folder = Path(inp.rounds[0]).parent

    def curves_of(k):
        # round k's runs (rule diagnosis_refit_member), in its rows' order
        return [read_curve(folder / f"iter_{k}" / str(i) / "curve.csv") for i in range(len(rounds[k]["rows"]))]

    state = next_round(rounds[-1], curves_of, model, {r: obs.values[obs.record_slice(r)] for r in obs.records},
                       saved["noise"], saved["simulator"], selection.settings,
                       rounds=int(e["diagnosis"]["refit_rounds"]), replicates=check_replicate_count(e),
                       selection=selection)
atomic_write_json(snakemake.output.state, state)
