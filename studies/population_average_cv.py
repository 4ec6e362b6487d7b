"""Does predicting a record as the average over its population's spread beat predicting it at the
population's median? Read on the emulated cross-validation of a finished series (calibration records
only: each prediction is of a calibration record by a calibration without it).

    python studies/population_average_cv.py <results folder of a loro run> > out.json

For every fold's ``diagnosis/selection.pkl`` and every step with a per-record effect, each CV prediction's
RMSE against its record: at the point (per-record values at the population median, what the workflow
runs), as the mean of its draws' curves (posterior members x population draws: the predictive mean, the
curve that minimises the expected squared error if the population is right), and the base model's.
"""

from __future__ import annotations

import glob
import json
import math
import pickle
import sys
from pathlib import Path

import numpy as np

from calibration.observations import read_observations


def rows_of(results: Path) -> list[dict]:
    rows = []
    for f in sorted(glob.glob(str(results / "*__*" / "diagnosis" / "selection.pkl"))):
        fold_dir = Path(f).parents[1]
        sel = pickle.loads(Path(f).read_bytes())["selection"]
        obs = read_observations(fold_dir / "observations" / "obs.csv", fold_dir / "observations" / "obs.json")
        base = sel.steps[0]
        for step in sel.steps[1:]:
            if not step.spec.per_record:
                continue
            for rec, fold in step.cv.folds.items():
                y = obs.values[obs.record_slice(rec)]
                pred = fold["prediction"]
                rmse = lambda c: math.sqrt(float(np.mean((y - c) ** 2)))  # noqa: E731
                rows.append({"fold": fold_dir.name, "model": step.spec.label(), "record": rec,
                             "rmse_base_Pa": rmse(base.cv.folds[rec]["prediction"].curve),
                             "rmse_point_Pa": rmse(pred.curve), "rmse_average_Pa": rmse(pred.draws.mean(0))})
    return rows


def main(argv) -> int:
    rows = rows_of(Path(argv[1]))
    a = np.array([[r["rmse_base_Pa"], r["rmse_point_Pa"], r["rmse_average_Pa"]] for r in rows])
    d = a[:, 2] - a[:, 1]
    out = {"source": argv[1], "predictions": len(rows),
           "mean_rmse_Pa": {"base": a[:, 0].mean(), "point": a[:, 1].mean(), "average": a[:, 2].mean()},
           "average_minus_point_Pa": {"mean": d.mean(), "sd": d.std(ddof=1), "se": d.std(ddof=1) / math.sqrt(d.size),
                                      "average_better": int(np.sum(d < 0))},
           "worse_than_base": {"point": int(np.sum(a[:, 1] > a[:, 0])), "average": int(np.sum(a[:, 2] > a[:, 0]))},
           "rows": rows}
    json.dump(out, sys.stdout, indent=2)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
