"""What the refuted additions would have done to the held-out records: a check of the confirmation
test's power, read after the run and never used to choose anything.

Every fold of a leave-one-record-out run already holds real FDEM runs of the held-out record at every
step the walk proposed (``diagnosis/check/<i>``, rows of ``check_runs.json`` with role ``heldout``); the
report scores only the base and the shipped step. This tool scores every step, per fold:

    python studies/loro_refuted.py results/marble_loro__CaMa_SHPB_006 [more fold folders] [--json out.json]

A test that refutes additions which lower the held-out error in most folds has too little power; one
that refutes additions which raise it is doing its job.
"""
from __future__ import annotations

import json
import pickle
import sys
from pathlib import Path

from calibration.observations import read_observations
from calibration.walk import check_runs_of
from calibration.protocol import real_curves
from enkf.diagnosis import replicate_curve_errors


def fold_steps(folder: Path) -> dict:
    """``{"fold", "heldout", "steps": [{"step", "model", "confirmed", "rmse", "peak_rel_error"}]}``."""
    d = folder / "diagnosis"
    state = pickle.loads((d / "selection.pkl").read_bytes())
    rows, runs = check_runs_of(d)
    real = real_curves(rows, runs, state["model"])["heldout"]
    held = read_observations(d / "heldout" / "obs.csv", d / "heldout" / "obs.json")
    report = json.loads((d / "report.json").read_text())
    walk = report["confirmation"]["steps"]
    confirmed = {s["step"]: s["confirmed"] for s in walk}
    # the walk's own test per step (calibration records only): what decided, beside what it would have given
    out = {"fold": folder.name, "shipped_step": report["shipped_step"], "why": report["why"],
           "walk": [{k: s.get(k) for k in ("step", "effect", "confirmed", "z", "p", "level")} for s in walk],
           "heldout": {}}
    for h in held.records:
        s = held.record_slice(h)
        steps = []
        for k, step in enumerate(state["selection"].steps):
            curve = real.get(k, {}).get(h)
            if curve is None:
                continue
            e = replicate_curve_errors(held.time[s], curve, held.values[s])  # replicated: their mean errors
            # None: the walk stopped before this step (never tested)
            steps.append({"step": k, "model": step.spec.label(), "confirmed": True if k == 0 else confirmed.get(k),
                          "rmse_Pa": e["rmse"], "peak_rel_error": e["peak_rel_error"]})
        out["heldout"][h] = steps
    return out


def main(argv) -> int:
    args = [a for a in argv[1:] if not a.startswith("--")]
    dest = None
    if "--json" in argv:
        dest = Path(argv[argv.index("--json") + 1])
        args = [a for a in args if a != str(dest)]
    folds = [fold_steps(Path(a)) for a in args]
    for f in folds:
        for h, steps in f["heldout"].items():
            tag = {True: "", False: " (refuted)", None: " (not tested)"}
            cells = ", ".join(f"{s['model']} {s['rmse_Pa'] / 1e6:.1f}{tag[s['confirmed']]}" for s in steps)
            print(f"{f['fold']}: {h} held-out RMSE [MPa]: {cells}")
    if dest is not None:
        dest.write_text(json.dumps(folds, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
