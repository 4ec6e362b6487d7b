"""An in-sample test on real runs for an effect that cross-validation within three records cannot confirm
(issue 53, item 2; after ``point_alternatives.py``).

The walk confirms an effect when it predicts each calibration record better from the others. With three
records an effect confounded with ``sigma_t`` (an end friction whose increment grows with the strain rate)
is not determined by two of them, so its fold fits scatter and the test has no power, while the fit on
all three predicts the held-out record far better. The alternative measured here: fit the base and the
base + effect on all calibration records (noise-weighted least squares on the surrogate), run both points
on the calibration records' check meshes, and compare the real runs' weighted squared errors (paired over
the meshes, each time weighted by 1 / (noise^2 + mesh scatter^2), as the walk does). In sample the larger
model always gains something by chance; that gain's null distribution is simulated on the surrogate:
data drawn from the base fit's emulated curves plus the calibration's noise and mesh-scatter errors,
both models fitted to each draw the same way, their weighted squared errors compared. The real gain is
read against that distribution's upper quantiles.

Development data only (the re-diagnosed retired series); the level of such a test on FDEM nulls is not
measured here.

Run (cwd: the clone whose ``results/`` holds the re-diagnosed series; 18 runs of 5-7 s)::

    python studies/insample_test.py --series results/planted_interface_friction_5302 \
        --effect interface_friction.mu --out studies/results/insample_test_interface_friction_5302.json
"""
from __future__ import annotations

import argparse
import json
import pickle
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.diagnose import interpolation_matrix  # noqa: E402
from calibration.protocol import protocol_model  # noqa: E402
from enkf.diagnosis import RecordErrors, walk_weights  # noqa: E402
from enkf.diagnosis.crossval import compare_replicated  # noqa: E402
from enkf.diagnosis.weights import Weighted  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from studies.anchored_interactions import run_point  # noqa: E402
from studies.point_alternatives import least_squares  # noqa: E402


def in_sample(series: Path, effect: str, draws: int, seed: int) -> dict:
    """The in-sample test of one shared physical ``effect`` parameter on a finished series (module
    docstring): the two fits, the real gain on the check meshes, the simulated chance gain."""
    diag = series / "diagnosis"
    st = pickle.loads((diag / "selection.pkl").read_bytes())
    sel, model, noise, sim = st["selection"], st["model"], st["noise"], st.get("simulator") or {}
    calib = list(sel.calib_records)
    base_names, names = ["sigma_t", "E_t"], ["sigma_t", "E_t", effect]
    pm = protocol_model(model)
    lo, hi = (np.asarray(v, float) for v in pm.box(names))
    obs = pd.read_csv(series / "observations" / "obs.csv")
    y = {r: obs[obs.record == r].stress_Pa.to_numpy() for r in calib}
    sig = np.concatenate([obs[obs.record == r].sigma_Pa.to_numpy() for r in calib])
    yy = np.concatenate([y[r] for r in calib])
    f0, f1 = pm.forward(base_names, calib), pm.forward(names, calib)
    x0 = least_squares(f0, yy, sig, lo[:2], hi[:2])
    x1 = least_squares(f1, yy, sig, lo, hi)
    w = walk_weights(noise, sim, calib)
    wcat = np.concatenate([w[r] for r in calib])

    def gain(data, a0, a1):
        return float(np.sum(wcat * (data - a0) ** 2) - np.sum(wcat * (data - a1) ** 2))

    # the chance gain of the larger model in sample, on the surrogate under the base fit
    rng = np.random.default_rng([seed, len(effect)])
    mean0 = f0(x0)[0]
    null = []
    for _ in range(draws):
        e = np.concatenate([noise[r].sample(rng, 1)[0] + (sim[r].sample(rng, 1)[0] if r in sim else 0.0)
                            for r in calib])
        d = mean0 + e
        b0 = least_squares(f0, d, sig, lo[:2], hi[:2], starts=6, seed=int(rng.integers(1 << 30)))
        b1 = least_squares(f1, d, sig, lo, hi, starts=6, seed=int(rng.integers(1 << 30)))
        null.append(gain(d, f0(b0)[0], f1(b1)[0]))
    null = np.array(null)
    # the real runs of both in-sample points on the calibration records' check meshes
    rows = json.loads((diag / "check_runs.json").read_text())["rows"]
    real0, real1 = {}, {}
    for j in calib:
        idx = sorted((r["replicate"], i) for i, r in enumerate(rows) if r["step"] == 0 and r["role"] == "cv"
                     and r["record"] == j)
        r0, r1 = [], []
        for k, i in idx:
            d = diag / "check" / str(i)
            run0 = json.loads((d / "run.json").read_text())
            c = pd.read_csv(d / "curve.csv")
            dt = float(np.median(np.diff(c.time_s.to_numpy())))
            for x, nm, out, tag in ((x0, base_names, r0, "base"), (x1, names, r1, effect)):
                cc = run_point(series, j, dict(zip(nm, map(float, x))), run0,
                               series / "study_insample" / j / f"{tag}_{k}", dt)
                # each run on its own output times (a disc's time step moves with its parameters)
                W = interpolation_matrix(cc.time_s.to_numpy(), obs[obs.record == j].time_s.to_numpy())
                out.append(W @ cc.stress_Pa.to_numpy())
        real0[j], real1[j] = np.array(r0), np.array(r1)
    Wt = Weighted(RecordErrors({j: noise[j] for j in calib}, {}, {}), calib, w)
    cmp = compare_replicated(Wt.scale(y), Wt.scale(real0), Wt.scale(real1), Wt.errors.noise)
    q = {f"q{p}": float(np.quantile(null, p / 100)) for p in (50, 95, 99, 99.5)}
    return {"base_point": dict(zip(base_names, x0.tolist())), "effect_point": dict(zip(names, x1.tolist())),
            "real": {"gain_weighted": cmp["delta"], "sd": cmp["sd"], "z_of_gain": cmp["z"],
                     "rmse_Pa": {j: {"base": float(np.sqrt(np.mean((real0[j] - y[j]) ** 2))),
                                     "effect": float(np.sqrt(np.mean((real1[j] - y[j]) ** 2)))} for j in calib}},
            "emulated_gain_at_data": gain(yy, f0(x0)[0], f1(x1)[0]),
            "null_chance_gain": {"draws": draws, "mean": float(null.mean()), **q,
                                 "share_at_or_above_real": float(np.mean(null >= cmp["delta"]))},
            "rejects_at_0.005": bool(cmp["delta"] > q["q99.5"])}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", nargs="+", required=True)
    ap.add_argument("--effects", nargs="+", required=True, help="shared physical parameters, e.g. interface_friction.mu")
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    out = {"what": __doc__.split("\n")[0], "series": {},
           "note": "development data; the null is simulated on the surrogate, the real gain is measured on FDEM "
                   "runs paired over the check meshes: their mesh departures are not in the null"}
    for s in a.series:
        out["series"][Path(s).name] = {e: in_sample(Path(s), e, a.draws, a.seed) for e in a.effects}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
