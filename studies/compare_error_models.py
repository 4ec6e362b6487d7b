"""The AR(1) discrepancy against the inflated-noise baseline on a finished experiment (issue 30).

    python studies/compare_error_models.py results/marble_loop [more experiment folders]

For the reported ensemble of each experiment (``summary.json``'s ``posterior_iteration``): per record
the log-likelihood of the member carrying the discrepancy estimate, under ``R + D`` and under ``R``
inflated until that member's chi^2 per observation is 1, and the 90 % posterior-predictive coverage
of the members with either error model; and the Gauss-linear posterior std of each parameter under
either (the members' regression sensitivity): how wide each makes the intervals. Prints JSON.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from calibration.experiment import rng_for
import pandas as pd

from calibration.model_error import compare_with_inflated_noise, linear_posterior_std, stored_error
from calibration.observations import read_observations
from calibration.workflow_io import read_responses


def compare(folder: Path) -> dict:
    summary = json.loads((folder / "summary.json").read_text())
    R = int(summary["posterior_iteration"])
    obs = read_observations(folder / "observations" / "obs.csv", folder / "observations" / "obs.json")
    analysis = json.loads((folder / f"iter_{R}" / "analysis.json").read_text())
    _, Y = read_responses(folder / f"iter_{R}" / "responses.csv")
    alive = np.asarray(analysis["alive"], bool)
    records = compare_with_inflated_noise(obs, Y, alive, analysis, rng_for(summary["seed"], "predictive", 1))
    names = list(summary["posterior"])
    P = pd.read_csv(folder / f"iter_{R}" / "params.csv")[names].to_numpy(float)[alive]
    Cd = stored_error(obs, analysis).likelihood().dense()
    Ci = np.zeros_like(Cd)
    for rec in obs.records:
        sl = obs.record_slice(rec)
        Ci[sl, sl] = records[rec]["inflation_factor"] * obs.of_record(rec).error_model().dense()
    widths = {"ar1_discrepancy": linear_posterior_std(P, Y[alive], Cd),
              "inflated_noise": linear_posterior_std(P, Y[alive], Ci)}
    return {"experiment": summary["experiment"], "iteration": R, "records": records,
            "linear_posterior_std": {k: dict(zip(names, v.tolist())) for k, v in widths.items()}}


if __name__ == "__main__":
    print(json.dumps([compare(Path(p)) for p in sys.argv[1:]], indent=1))
