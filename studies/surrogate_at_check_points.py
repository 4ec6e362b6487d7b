"""Where the emulator's choice meets the real simulator (issue 53, item 2): at each step's cross-validation
points, how far the selection model's curve (the anchored surrogate the choice was made on) lies from the
real FDEM runs there (the mean of the check's mesh realizations, through the same measurement chain),
against the surrogate's own error (pooled leave-one-out rms) and the runs' mesh scatter; and the emulated
against the real cross-validated gain. No runs: a finished experiment's diagnosis folder is read.

    python studies/surrogate_at_check_points.py --runs RESULTS/planted_seating_5302 ... --out OUT.json
"""
from __future__ import annotations

import argparse
import json
import pickle
from pathlib import Path

import numpy as np

from calibration.observations import read_observations
from calibration.walk import check_runs_of
from calibration.protocol import emulator_errors, real_curves
from shpb.atomic import emit_json


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def one_run(run: Path) -> dict:
    d = run / "diagnosis"
    state = pickle.loads((d / "selection.pkl").read_bytes())
    sel, model = state["selection"], state["model"]
    rows, runs = check_runs_of(d)
    real = real_curves(rows, runs, model)["cv"]
    o = read_observations(run / "observations" / "obs.csv", run / "observations" / "obs.json")
    own = emulator_errors(model, sel.calib_records)
    report = json.loads((d / "report.json").read_text())
    walked = {s["step"]: s for s in report["confirmation"]["steps"]}
    steps = []
    for st in (*sel.steps, *getattr(sel, "alternatives", [])):  # a selection pickled before alternatives has none
        per = {}
        for j, point in st.cv.points().items():
            Y = real.get(st.index, {}).get(j)
            if Y is None:
                continue
            Y = np.atleast_2d(np.asarray(Y, float))
            names = list(point)
            emu = model.forward(names, [j])(np.array([point[n] for n in names]))[0]
            y = o.values[o.record_slice(j)]
            per[j] = {"surrogate_minus_real_rms_Pa": _rms(emu - Y.mean(axis=0)),
                      "own_error_rms_Pa": _rms(np.sqrt(np.diag(own[j].dense()))),
                      "mesh_scatter_rms_Pa": _rms(Y.std(axis=0, ddof=1)) if Y.shape[0] > 1 else None,
                      "emulated_cv_rmse_Pa": _rms(y - emu), "real_cv_rmse_Pa": float(np.sqrt(np.mean((y - Y) ** 2)))}
        steps.append({"step": st.index, "model": st.spec.label(), "alternative_to": st.alternative_to,
                      "emulated_cv_rmse_Pa": st.cv.rmse, "walked": walked.get(st.index, {}).get("confirmed"),
                      "z": walked.get(st.index, {}).get("z"), "records": per})
    return {"verdict": report["verdict"], "steps": steps}


def main(argv=None, one=None, doc: str | None = None) -> dict:
    """Read each of ``--runs`` (finished experiments' results folders) with ``one`` (default this study's
    :func:`one_run`) and write ``--out``; ``doc``: the study's docstring (its first paragraph is ``what``)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", nargs="+", required=True, help="experiments' results folders (finished diagnosis)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    one = one or one_run
    out = {"what": (doc or __doc__).split("\n\n")[0], "runs": {Path(r).name: one(Path(r)) for r in a.runs}}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
