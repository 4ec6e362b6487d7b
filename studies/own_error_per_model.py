"""The anchored model's own error, pooled or per model (diagnosis.own_error), on the emulator's selection
(issue 53, items 2-3): what each form proposes and which candidates it cannot tell apart. No FDEM runs:
a run's saved selection (diagnosis/selection.pkl: its emulators, noise and base posterior) is selected
again under each form; and the analytic stand-in of tests/test_anchored_selection.py, seeds 3-5.

    python studies/own_error_per_model.py --runs RESULTS/planted_face_gap_5391 RESULTS/marble_loop \\
        --out studies/results/own_error_per_model.json
"""
from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from calibration.observations import read_observations  # noqa: E402
from calibration.protocol import select  # noqa: E402
from shpb import effects as fx  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

FORMS = ("pooled", "per_model")


def _rounds(sel) -> list[dict]:
    return [{"current_cv_rmse_Pa": r["current_cv_rmse"], "chosen": r["chosen"],
             "group": (r.get("group") or {}).get("effects"),
             "trials": {t["effect"]: {"cv_rmse_Pa": t["cv_rmse"], "z": t["z"]} for t in r["trials"]}}
            for r in sel.rounds]


def run_form(run: Path, form: str) -> dict:
    saved = pickle.loads((run / "diagnosis" / "selection.pkl").read_bytes())
    s0, model, st = saved["selection"], saved["model"], saved["selection"].settings
    o = read_observations(run / "observations" / "obs.csv", run / "observations" / "obs.json")
    sel = select(model, base_names=s0.steps[0].spec.base, candidates=[fx.get_effect(t["effect"])
                                                                     for t in s0.rounds[0]["trials"]],
                 calib_records=s0.calib_records, obs={r: o.values[o.record_slice(r)] for r in s0.calib_records},
                 noise=saved["noise"], heldout_records=s0.heldout_records, simulator=saved["simulator"],
                 simulator_correlation=1.0, max_additions=st["max_additions"], alpha=st["alpha"], seed=st["seed"],
                 n_members=st["n_members"], esmda_steps=st["esmda_steps"], gate=st["gate"],
                 base_fit=s0.steps[0].final, per_model=form == "per_model")
    return {"rounds": _rounds(sel)}


def standin() -> dict:
    from test_anchored_selection import ANCHOR, GAP_K, _anchored_standin, _gap_coverage, _select
    from _protocol_standin import record_errors
    from calibration.protocol import emulator_axis_errors, emulator_errors
    from enkf.diagnosis import RecordErrors
    model = _anchored_standin(ANCHOR)
    noise = dict(record_errors(list(GAP_K), model_error=False).noise)
    pooled = emulator_errors(model.emulated, list(GAP_K))
    errors = {"pooled": RecordErrors(noise, pooled),
              "per_model": RecordErrors(noise, pooled, {}, 0.0, 0.0, emulator_axis_errors(model.emulated, list(GAP_K)))}
    out = {}
    for form, err in errors.items():
        seeds = {}
        for seed in (3, 4, 5):
            sel = _select(model, seed, errors=err)
            seeds[str(seed)] = {"rounds": _rounds(sel), "gaps_covered_90": int(sum(_gap_coverage(sel)))
                                if sel.rounds[0]["chosen"] == "face_gap" else None}
        out[form] = seeds
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", nargs="*", default=[], help="experiments' results folders with diagnosis/selection.pkl")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    out = {"what": __doc__.split("\n\n")[0], "standin": standin(),
           "runs": {Path(r).name: {f: run_form(Path(r), f) for f in FORMS} for r in a.runs}}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
