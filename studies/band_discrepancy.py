"""Which discrepancy term the check's predictive bands should carry, chosen on calibration records only.

For every fold of the re-run leave-one-record-out series (their run folders, not in the repository:
pass each clone's root), each calibration record's band of its real cross-validation runs is rebuilt
(before: base model, after: the shipped one) with the discrepancy term of each form:

* ``calibration``: the calibration's estimated discrepancy of the *other* calibration records, their
  mean (the shipped form is this with the record's own estimate in the mean);
* ``cv<w>``: the per-time mean square of the other calibration records' cross-validated residuals on
  real FDEM runs at the same step, less the variance the other terms count there, smoothed over ``w``
  samples: the workflow's term (calibration.closing._discrepancy_from) at window ``w``.

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

from calibration.closing import _cv_residuals, _discrepancy_from, _mean_block  # noqa: E402
from calibration.observations import read_observations  # noqa: E402
from calibration.walk import check_runs_of  # noqa: E402
from calibration.protocol import real_curves  # noqa: E402
from enkf.diagnosis.band import replicate_variance, run_band  # noqa: E402

WINDOWS = (5, 11, 21, 41, 81, 161)


def fold_data(fold: Path):
    state = pickle.loads((fold / "diagnosis" / "selection.pkl").read_bytes())
    rows, runs = check_runs_of(fold / "diagnosis")
    obs = read_observations(fold / "observations" / "obs.csv", fold / "observations" / "obs.json")
    return state, real_curves(rows, runs, state["model"]), obs


def score_fold(fold: Path) -> dict:
    """Every calibration record's band at every checked step, one per form; the residuals and the
    variances they are taken against are the workflow's own (calibration.closing._cv_residuals)."""
    state, real, obs = fold_data(fold)
    sel, noise = state["selection"], state["noise"]
    calib = list(obs.records)
    k = max(s for s in real["cv"])  # the last step with real runs is the shipped one or the base
    out = {}
    for step in sorted(real["cv"]):
        cv = _cv_residuals(sel, real, step, obs, noise, {})
        res = {}
        for r in cv:
            others = [o for o in cv if o != r]
            if not others:
                continue
            runs = np.array(real["cv"][step][r], float, ndmin=2)
            pred = sel.steps[step].cv.folds[r]["prediction"]
            S, _ = replicate_variance([c[r] for c in real["cv"].values() if c.get(r) is not None])
            y = obs.values[obs.record_slice(r)]
            base = {"noise": _mean_block([np.diag(noise[o].dense()) for o in calib if o in cv]), "simulator": S}
            forms = {"calibration": _mean_block([np.asarray(state["discrepancy"][o], float) for o in others])}
            for w in WINDOWS:
                forms[f"cv{w}"] = _discrepancy_from(cv, r, w, forms["calibration"])[0]
            res[r] = {}
            for name, D in forms.items():
                band = run_band(pred.draws, pred.curve, runs, {**base, "discrepancy": D},
                                rng=np.random.default_rng(1), level=0.90)
                res[r][name] = {"coverage_90": band.coverage(y), "interval_score_Pa": band.score(y),
                                "width_rms_Pa": band.width_rms()}
        out[str(step)] = res
    return {"steps": out, "shipped_step": k}


def score_series(argv, score) -> tuple[dict, str | None]:
    """``({series: {fold: score(fold folder)}}, --out path)`` from ``<clone root> <series> ... [--out F]``."""
    args = [a for a in argv if not a.startswith("--")]
    out_path = argv[argv.index("--out") + 1] if "--out" in argv else None
    if out_path:
        args.remove(out_path)
    return ({series: {f.name: score(f) for f in sorted(Path(root, "results").glob(f"{series}__*"))}
             for root, series in zip(args[0::2], args[1::2])}, out_path)


def main(argv) -> dict:
    scored, out_path = score_series(argv, score_fold)
    result = {"study": "band_discrepancy", "windows": list(WINDOWS), "series": scored}
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
