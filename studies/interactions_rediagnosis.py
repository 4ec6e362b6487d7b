"""The loop with the anchored model's second-order terms (``diagnosis.interactions: [sigma_t]``) on retired
benchmark series, against the same series' kept reports (issue 53, item 2).

Each series' calibration is kept as it ran; only the diagnosis is made again, by the current code with
``interactions: [sigma_t]``: its design (the sweeps made again at ``sigma_t``'s lower step), the
selection, the real check runs and the walk. The kept report is the series' own, from the retired form
it ran with (a walk that stopped at its first refuted choice on the plain squared-error sum for seeds
5302-5304), so a difference in the walk is not the interactions' alone; the first round's proposals are
(the selection has not changed since those series: ``weighted_proposal.py`` re-selected them exactly).

Run after the re-diagnoses (each: the kept ``results/<series>`` copied into a clone, its
``diagnosis/`` removed, its config given ``interactions: [sigma_t]``, ``snakemake --cores 2
--configfile <cfg> --rerun-triggers mtime``)::

    python studies/interactions_rediagnosis.py --kept /work/bench/results --new /work/ia/results \
        --series planted_interface_friction_5302 ... --out studies/results/interactions_rediagnosis.json
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import pickle  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from benchmarks.bench_planted import heldout_summary, named, parameter_coverage, proposals  # noqa: E402
from calibration.protocol import protocol_model, record_errors  # noqa: E402
from enkf.analysis import esmda_alphas  # noqa: E402
from enkf.covariance import DiagonalError  # noqa: E402
from enkf.diagnosis import RecordErrors  # noqa: E402
from enkf.diagnosis.crossval import seed_for  # noqa: E402
from enkf.loop import assimilate  # noqa: E402
from enkf.sampling import latin_hypercube  # noqa: E402
from enkf.transforms import BoxTransform  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

PLAN = json.loads((ROOT / "benchmarks" / "planted_plan.json").read_text())


def case_of(series: str) -> dict:
    name = re.sub(r"^planted_|_\d+$", "", series)
    return next(c for c in PLAN["cases"] if c["case"] == name)


def summary(folder: Path, case: dict, truth: dict | None) -> dict:
    diag = folder / "diagnosis"
    report = json.loads((diag / "report.json").read_text())
    check = json.loads((diag / "check.json").read_text())
    step = report["selection"]["steps"][int(report["shipped_step"])]
    fitted = {}
    for st in report["selection"]["steps"][1:] + report["selection"].get("alternatives", []):
        for p, v in (st.get("posterior") or {}).items():
            if p not in ("sigma_t", "E_t") and isinstance(v, dict):
                fitted.setdefault(st["model"], {})[p] = [v.get("q05"), v.get("mean"), v.get("q95")]
        fitted.setdefault(st["model"], {})["sigma_t"] = [st["posterior"]["sigma_t"].get(k) for k in ("q05", "mean", "q95")]
    return {"named": named(report), "proposals": proposals(report, case), "why": report.get("why", ""),
            "heldout": heldout_summary(check), "fitted": fitted, "shipped_model": step["model"],
            **({"coverage": parameter_coverage(report, truth)} if truth else {})}


def fit_points(folder: Path, effect_param: str, points: dict, seed: int, members: int = 60, steps: int = 4) -> dict:
    """Where the selection's ES-MDA on the (re-diagnosed) emulator puts ``sigma_t, E_t, effect`` on all
    calibration records under four error models: the selection's own (noise + the emulator's own error +
    mesh scatter, time-correlated), without the emulator's error, the first one's diagonal, and the walk's
    weights (noise^2 + S^2 per time); with each model's misfit at the given ``points`` (e.g. the
    noise-weighted least-squares fit of ``anchored_interactions.py`` and the planted values)."""
    st = pickle.loads((folder / "diagnosis" / "selection.pkl").read_bytes())
    sel, model, noise, sim = st["selection"], st["model"], st["noise"], st.get("simulator") or {}
    calib, names = list(sel.calib_records), ["sigma_t", "E_t", effect_param]
    obs = pd.read_csv(folder / "observations" / "obs.csv")
    y = np.concatenate([obs[obs.record == r].stress_Pa.to_numpy() for r in calib])
    pm = protocol_model(model)
    lo, hi = (np.asarray(v, float) for v in pm.box(names))
    f = pm.forward(names, calib)
    full = record_errors(model, noise, simulator=sim, simulator_correlation=1.0).calibration_error(calib, names)
    no_own = RecordErrors(dict(noise), {}, dict(sim), 0.0, 1.0, {}).calibration_error(calib, names)
    forms = {"selection (noise + own error + mesh scatter, correlated)": full, "without the own error": no_own,
             "diagonal of the selection's": DiagonalError(np.sqrt(np.diag(full.dense()))),
             "the walk's weights (noise^2 + S^2 per time)": DiagonalError(np.sqrt(np.diag(no_own.dense())))}
    out = {}
    for label, err in forms.items():
        rng = np.random.default_rng(seed_for(seed, "calibrate", *calib, *names))
        res = assimilate(f, latin_hypercube(lo, hi, members, rng), y, err, rng=rng, method="esmda",
                         alphas=esmda_alphas(steps), transform=BoxTransform(lo, hi), names=names)
        P = res.params[res.alive]
        m = P.mean(axis=0)
        row = {"fit": dict(zip(names, m.tolist())), "effect_q05_q95": np.quantile(P[:, 2], [0.05, 0.95]).tolist(),
               "emulated_rmse_Pa": float(np.sqrt(np.mean((y - f(m)[0]) ** 2))), "misfit": {}}
        for pl, x in {"fit": m, **{k: np.asarray(v, float) for k, v in points.items()}}.items():
            w = err.whiten(y - f(np.asarray(x))[0])
            row["misfit"][pl] = float(w @ w)
        out[label] = row
    return {"box": {"lower": lo.tolist(), "upper": hi.tolist()}, "forms": out}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kept", required=True, help="folder of the kept results/<series>")
    ap.add_argument("--new", required=True, help="folder of the re-diagnosed results/<series>")
    ap.add_argument("--series", nargs="+", required=True)
    ap.add_argument("--truths", default="/work/benchrun", help="where <w*>/<series>/series/truth.json lie")
    ap.add_argument("--fit-points", help="JSON {series: {effect_param, points: {label: [sigma_t, E_t, value]}}}: "
                                         "where the re-diagnosed emulator's ES-MDA lands (fit_points)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    fits = json.loads(Path(a.fit_points).read_text()) if a.fit_points else {}
    out = {"what": __doc__.split("\n")[0], "interactions": ["sigma_t"], "series": {}}
    for s in a.series:
        case = case_of(s)
        truths = sorted(Path(a.truths).glob(f"w*/{s}/series/truth.json"))
        truth = json.loads(truths[0].read_text()) if truths else None
        row = {"case": case["case"], "plant": case.get("plant") or case.get("artefact")}
        for label, root in (("kept", Path(a.kept)), ("interactions", Path(a.new))):
            try:
                row[label] = summary(root / s, case, truth)
            except (OSError, KeyError) as exc:
                row[label] = {"error": f"{type(exc).__name__}: {exc}"}
        if s in fits:
            row["fit_points"] = fit_points(Path(a.new) / s, fits[s]["effect_param"], fits[s]["points"],
                                           seed=int(fits[s].get("seed", 31)))
        out["series"][s] = row
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
