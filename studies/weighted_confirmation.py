"""Does the confirmation test lose its power to the post-peak's mesh scatter? (issue 53, item 2)

The walk's paired test (enkf.diagnosis.compare_replicated) compares two models by the plain squared-error
sum of their real runs over the whole window. The simulator's mesh scatter is 17x larger after the
failure peak than before it (bench_sim_variability.json: 8.2 % against 0.48 % of the peak on the marble
cylinder), and a change of the failure path between two steps' runs on one mesh does not cancel
in their difference; the plain sum is dominated by those post-peak samples, while the effects of the
catalogue act mostly on the rise. This study re-scores, with no new runs, each walked step of finished
series on the same real runs with each time weighted by the inverse of the variance the workflow gives it
(the record's instrument noise plus the simulator's variability the calibration's replicates measured,
the protocol's ``noise`` and ``simulator``; the Gaussian log score's weights), against the shipped plain
sum: the kept report (the walk as it ran) against the same folder re-assembled by the current
``calibration.closing.assemble`` (the weighted walk: its steps, verdict and held-out errors). Only
development series (seed 5391) and the retired benchmark seeds 5302-5304 are read: the plan's benchmark
seeds 5305-5307 are not re-scored.

    python studies/weighted_confirmation.py --runs RESULTS/planted_seating_5302 ... --out OUT.json
"""
from __future__ import annotations

import json
import pickle
from pathlib import Path

from calibration.closing import assemble
from calibration.observations import read_observations
from calibration.walk import check_runs_of
from surrogate_at_check_points import main as read_runs  # studies/ is the script's own folder


def _outcome(report: dict) -> dict:
    conf = report["confirmation"]
    held = {h: {w: round(v[w]["rmse"] / 1e6, 2) for w in ("before", "after")} for h, v in report["heldout"].items()}
    return {"named": conf["effects"][0] if report["verdict"] == "confirmed" else report["verdict"],
            "walk": [[s["effect"], round(s["z"], 2), s["confirmed"]] for s in conf["steps"]],
            "heldout_rmse_MPa": held}


def one_run(run: Path) -> dict:
    d = run / "diagnosis"
    state = pickle.loads((d / "selection.pkl").read_bytes())
    if not hasattr(state["selection"], "alternatives"):  # pickled before the walk had alternatives
        state["selection"].alternatives = []
    rows, runs = check_runs_of(d)
    obs = read_observations(run / "observations" / "obs.csv", run / "observations" / "obs.json")
    held = read_observations(d / "heldout" / "obs.csv", d / "heldout" / "obs.json")
    report, *_ = assemble(state["selection"], rows, runs, state["model"], obs, held, state["noise"],
                          state["simulator"], state["discrepancy"])
    return {"plain": _outcome(json.loads((d / "report.json").read_text())), "weighted": _outcome(report)}


def main(argv=None) -> dict:
    return read_runs(argv, one_run, __doc__)


if __name__ == "__main__":
    main()
