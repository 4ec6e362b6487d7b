"""Which discrepancy term the check's predictive bands should carry, chosen on calibration records only.

For every fold of the re-run leave-one-record-out series (their run folders, not in the repository:
pass each clone's root), each calibration record's band of its real cross-validation runs is rebuilt
(before: base model, after: the shipped one) with the discrepancy term of each form:

* ``calibration``: the calibration's estimated discrepancy of the *other* calibration records, their
  mean (the shipped form is this with the record's own estimate in the mean);
* ``cv<w>``: the per-time mean square of the other calibration records' cross-validated residuals on
  real FDEM runs at the same step, less the variance the other terms count there, smoothed over ``w``
  samples (:func:`enkf.diagnosis.band.residual_discrepancy`).

Each calibration record's curve scores its band (coverage of the 90 % band, interval score): the
record's own residual enters neither form. Held-out records are not read. Writes JSON.

    python studies/band_discrepancy.py <clone root> <series> [<clone root> <series> ...] --out F
"""
from __future__ import annotations

import json
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from calibration.closing import _mean_block  # noqa: E402
from calibration.observations import read_curve, read_observations  # noqa: E402
from calibration.protocol import real_curves  # noqa: E402
from enkf.diagnosis.band import interval_score, replicate_variance, residual_discrepancy, run_band  # noqa: E402

WINDOWS = (5, 11, 21, 41, 81, 161)


def fold_data(fold: Path):
    state = pickle.loads((fold / "diagnosis" / "selection.pkl").read_bytes())
    rows = json.loads((fold / "diagnosis" / "check_runs.json").read_text())["rows"]
    runs = [read_curve(fold / "diagnosis" / "check" / str(i) / "curve.csv") for i in range(len(rows))]
    obs = read_observations(fold / "observations" / "obs.csv", fold / "observations" / "obs.json")
    return state, real_curves(rows, runs, state["model"]), obs


def score_fold(fold: Path) -> dict:
    state, real, obs = fold_data(fold)
    sel, noise = state["selection"], state["noise"]
    calib = list(obs.records)
    k = max(s for s in real["cv"])  # the last step with real runs is the shipped one or the base
    steps = sorted(real["cv"])
    out = {}
    for step in steps:
        per = {}
        for r in calib:
            runs = real["cv"][step].get(r)
            if runs is None:
                continue
            pred = sel.steps[step].cv.folds[r]["prediction"]
            S, _ = replicate_variance([c[r] for c in real["cv"].values() if c.get(r) is not None])
            Y = np.array(runs, float, ndmin=2)
            y = obs.values[obs.record_slice(r)]
            per[r] = {"pred": pred, "runs": Y, "y": y, "S": S, "R": np.diag(noise[r].dense()),
                      "P": np.var(np.asarray(pred.draws) - np.asarray(pred.curve), axis=0),
                      "resid": y - Y.mean(axis=0)}
        res = {}
        for r, d in per.items():
            others = [o for o in per if o != r]
            if not others:
                continue
            base = {"noise": _mean_block([per[o]["R"] for o in calib if o in per]), "simulator": d["S"]}
            forms = {"calibration": _mean_block([np.asarray(state["discrepancy"][o], float) for o in others])}
            for w in WINDOWS:
                counted = [per[o]["P"] + per[o]["S"] * (1 + 1 / per[o]["runs"].shape[0]) + per[o]["R"] for o in others]
                forms[f"cv{w}"] = residual_discrepancy([per[o]["resid"] for o in others], counted, window=w)
            res[r] = {}
            for name, D in forms.items():
                band = run_band(d["pred"].draws, d["pred"].curve, d["runs"], {**base, "discrepancy": D},
                                rng=np.random.default_rng(1), level=0.90)
                res[r][name] = {"coverage_90": band.coverage(d["y"]), "interval_score_Pa": band.score(d["y"]),
                                "width_rms_Pa": band.width_rms()}
        out[str(step)] = res
    return {"steps": out, "shipped_step": k}


def main(argv) -> dict:
    args = [a for a in argv if not a.startswith("--")]
    out_path = argv[argv.index("--out") + 1] if "--out" in argv else None
    if out_path:
        args.remove(out_path)
    result = {"study": "band_discrepancy", "windows": list(WINDOWS), "series": {}}
    for root, series in zip(args[0::2], args[1::2]):
        folds = sorted(Path(root, "results").glob(f"{series}__*"))
        result["series"][series] = {f.name: score_fold(f) for f in folds}
    totals = {}
    for series in result["series"].values():
        for fold in series.values():
            for step in fold["steps"].values():
                for r in step.values():
                    for name, v in r.items():
                        t = totals.setdefault(name, {"n": 0, "coverage_90": 0.0, "interval_score_Pa": 0.0,
                                                     "width_rms_Pa": 0.0})
                        t["n"] += 1
                        for key in ("coverage_90", "interval_score_Pa", "width_rms_Pa"):
                            t[key] += v[key]
    for t in totals.values():
        for key in ("coverage_90", "interval_score_Pa", "width_rms_Pa"):
            t[key] /= t["n"]
    result["totals"] = totals
    text = json.dumps(result, indent=1)
    if out_path:
        Path(out_path).write_text(text + "\n")
    print(json.dumps(totals, indent=1))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
