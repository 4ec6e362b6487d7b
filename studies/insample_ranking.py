"""The in-sample test on real runs for every candidate of the catalogue: a ranking with power where the
emulated cross-validation cannot tell candidates apart (issue 53, item 2; after ``insample_test.py``,
which ran it for one shared effect).

For a finished series (its ``diagnosis/selection.pkl``, ``check_runs.json`` and the check's runs), on the
calibration records only:

* the base ``(sigma_t, E_t)`` and, per candidate, base + candidate (a per-record candidate with one copy
  per record) fitted to all calibration records by least squares on the selection's surrogate, each time
  weighted as the comparison below weights it (so the nested model never fits worse in sample);
* both points run on each calibration record's check meshes (the base model's cross-validation runs'
  meshes, so every model of a record is compared on common realizations), through the candidate's
  measurement chain, and compared in pairs by their squared errors weighted per time by
  ``1 / (noise^2 + mesh scatter^2)``, as the walk compares (``compare_replicated``);
* the chance gain of the larger model in sample, simulated on the surrogate under the base fit (the
  calibration's noise and mesh scatter added, both models re-fitted to each draw), with the same draws
  for every candidate: each candidate's real gain is read against its own chance quantiles, and the
  maximum over candidates of ``gain / q99`` against the same maximum over the draws (a level over the
  whole catalogue, not per test); and ``z_over_chance``: the real gain less the chance gain's mean over
  the real gain's paired sd and the chance gain's sd together (Bonferroni over the catalogue at 0.05:
  above 2.576 with ten candidates).

What is not in the null: the surrogate's departure from the real runs at the two fitted points. On a
null series that shows as real gains above the simulated chance; this study measures it there.

Development data only (series on the development seeds). Run with the series' own code first on the path
(the pickles are that code's objects)::

    PYTHONPATH=<series clone> python studies/insample_ranking.py --series <clone>/results/planted_null_5391 \
        --out studies/results/insample_ranking_null_5391.json
"""
from __future__ import annotations

import argparse
import hashlib
import json
import pickle
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

from calibration.diagnose import measured_curve, record_params  # noqa: E402
from calibration.protocol import protocol_model  # noqa: E402
from enkf.diagnosis import RecordErrors, walk_weights  # noqa: E402
from enkf.diagnosis.crossval import ModelSpec, compare_replicated  # noqa: E402
from enkf.diagnosis.weights import Weighted  # noqa: E402
from shpb import effects as fx  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from studies.anchored_interactions import run_point  # noqa: E402
from studies.point_alternatives import least_squares  # noqa: E402


def load(series: Path) -> dict:
    """The selection's state, the calibration records' data and their check meshes (step 0's cv runs)."""
    diag = series / "diagnosis"
    st = pickle.loads((diag / "selection.pkl").read_bytes())
    sel = st["selection"]
    calib = list(sel.calib_records)
    obs = pd.read_csv(series / "observations" / "obs.csv")
    rows = json.loads((diag / "check_runs.json").read_text())["rows"]
    w = walk_weights(st["noise"], st.get("simulator") or {}, calib)
    meshes = {}
    for j in calib:
        idx = sorted((r["replicate"], i) for i, r in enumerate(rows)
                     if r["step"] == 0 and r["role"] == "cv" and r["record"] == j)
        meshes[j] = [(json.loads((diag / "check" / str(i) / "run.json").read_text()),
                      float(np.median(np.diff(pd.read_csv(diag / "check" / str(i) / "curve.csv").time_s))))
                     for _, i in idx]
    report = json.loads((diag / "report.json").read_text())
    return {"sel": sel, "model": st["model"], "noise": st["noise"], "sim": st.get("simulator") or {},
            "calib": calib, "y": {j: obs[obs.record == j].stress_Pa.to_numpy() for j in calib},
            # the fits read the data as the comparison does: each time by 1 / (noise^2 + mesh scatter^2)
            "sig": 1.0 / np.sqrt(np.concatenate([w[j] for j in calib])),
            "meshes": meshes, "report": report}


def candidate_names(state: dict) -> list[str]:
    """The candidates the selection offered (its first round), in the catalogue's order."""
    names = list(state["sel"].rounds[0]["tried"])
    return [e.name for e in fx.effects() if e.name in names]


def fits(state: dict, cands: list[str], data: np.ndarray, starts: int, seed: int, at: dict | None = None) -> dict:
    """Least-squares points of the base and of base + each candidate on ``data`` (the calibration records'
    concatenated curves); ``at``: earlier points to start from as well."""
    pm, calib, base = protocol_model(state["model"]), state["calib"], list(state["sel"].steps[0].spec.base)
    out = {}
    for name in [None, *cands]:
        spec = ModelSpec.of(base, [fx.get_effect(name)]) if name else ModelSpec.of(base)
        names = spec.names(calib)
        lo, hi = (np.asarray(v, float) for v in pm.box(names))
        f = pm.forward(names, calib)
        x0 = [at[name]["x"]] if at else []
        if name:
            # the base's fit with the effect at its null: the nested model never fits worse than the base
            b = dict(zip(out[None]["names"], out[None]["x"]))
            plain = [fx.split_record(n)[0] for n in names]
            nulls = fx.null_values([p for n, p in zip(names, plain) if n not in b])
            x0.append([b[n] if n in b else nulls[p] for n, p in zip(names, plain)])
        x = least_squares(f, data, state["sig"], lo, hi, starts=starts, seed=seed, x0=x0 or None)
        out[name] = {"names": names, "x": x, "curve": f(x)[0]}
    return out


def real_curves(state: dict, series: Path, point: dict, work: Path, pool: ThreadPoolExecutor) -> dict:
    """Per calibration record the ``(K, m)`` curves of ``point`` on its K check meshes, through the
    point's measurement chain, at the record's observation times."""
    model, jobs = state["model"], {}
    for j in state["calib"]:
        plain = record_params(point, j)
        base, phys, _ = fx.split_params(plain)
        sim_params = {**base, **phys}
        for k, (run0, dt) in enumerate(state["meshes"][j]):
            # each run on its own output times, as the check's (a disc's time step moves with its parameters)
            key = hashlib.sha1(json.dumps([j, k, sorted(sim_params.items())]).encode()).hexdigest()[:16]
            jobs[(j, k)] = pool.submit(run_point, series, j, sim_params, run0, work / j / key, dt)
    post = {n: {"mean": v} for n, v in point.items()}
    out = {}
    for j in state["calib"]:
        rows = []
        for k in range(len(state["meshes"][j])):
            c = jobs[(j, k)].result()
            rows.append(measured_curve(c, model.model_times, post, model.obs_times[j], record=j))
        out[j] = np.vstack(rows)
    return out


def null_gains(state: dict, cands: list[str], at: dict, draws: int, seed: int, w: np.ndarray) -> dict:
    """Per candidate the chance gains of the larger model in sample over ``draws`` data sets drawn on the
    surrogate under the base fit, the same draws for every candidate."""
    rng = np.random.default_rng([seed, 53])
    calib, noise, sim = state["calib"], state["noise"], state["sim"]
    mean0 = at[None]["curve"]
    gains = {c: [] for c in cands}
    for _ in range(draws):
        e = np.concatenate([noise[j].sample(rng, 1)[0] + (sim[j].sample(rng, 1)[0] if j in sim else 0.0)
                            for j in calib])
        d = mean0 + e
        fd = fits(state, cands, d, starts=3, seed=int(rng.integers(1 << 30)), at=at)
        s0 = float(np.sum(w * (d - fd[None]["curve"]) ** 2))
        for c in cands:
            gains[c].append(s0 - float(np.sum(w * (d - fd[c]["curve"]) ** 2)))
    return {c: np.array(g) for c, g in gains.items()}


def rank(series: Path, draws: int, seed: int, work: Path, state: dict | None = None) -> dict:
    """The ranking of the module docstring; ``state``: :func:`load`'s, possibly with its surrogate changed
    (``insample_interactions.py``)."""
    t0 = time.perf_counter()
    state = state or load(series)
    calib, y = state["calib"], state["y"]
    cands = candidate_names(state)
    yy = np.concatenate([y[j] for j in calib])
    at = fits(state, cands, yy, starts=12, seed=seed)
    w = walk_weights(state["noise"], state["sim"], calib)
    wcat = np.concatenate([w[j] for j in calib])
    t_fit = time.perf_counter()
    null = null_gains(state, cands, at, draws, seed, wcat)
    t_null = time.perf_counter()
    Wt = Weighted(RecordErrors({j: state["noise"][j] for j in calib}, {}, {}), calib, w)
    with ThreadPoolExecutor(2) as pool:
        pts = {c: dict(zip(at[c]["names"], map(float, at[c]["x"]))) for c in [None, *cands]}
        real = {c: real_curves(state, series, pts[c], work, pool) for c in [None, *cands]}
    t_real = time.perf_counter()
    q99 = {c: float(np.quantile(null[c], 0.99)) for c in cands}
    # the whole catalogue's chance: per draw the largest gain over its candidate's own 99 % quantile
    max_ratio = np.max(np.vstack([null[c] / max(q99[c], 1e-12) for c in cands]), axis=0)
    rows = {}
    for c in cands:
        cmp = compare_replicated(Wt.scale(y), Wt.scale(real[None]), Wt.scale(real[c]), Wt.errors.noise)
        g = float(cmp["delta"])
        # the real gain's own sd (mesh realizations and noise, paired) and the chance gain's spread together:
        # the surrogate-simulated chance alone has no run-to-surrogate departures (too narrow on a null)
        z_chance = (g - float(np.mean(null[c]))) / float(np.hypot(cmp["sd"], np.std(null[c], ddof=1)))
        rows[c] = {"point": pts[c], "real_gain": g, "real_sd": float(cmp["sd"]), "real_z": float(cmp["z"]),
                   "z_over_chance": z_chance, "null_mean": float(np.mean(null[c])),
                   "null_sd": float(np.std(null[c], ddof=1)), "null_gains": null[c].round(3).tolist(),
                   "emulated_gain": float(np.sum(wcat * (yy - at[None]["curve"]) ** 2)
                                          - np.sum(wcat * (yy - at[c]["curve"]) ** 2)),
                   "null_q50": float(np.median(null[c])), "null_q99": q99[c],
                   "null_p": float((1 + np.sum(null[c] >= g)) / (1 + draws)),
                   "ratio_to_q99": g / max(q99[c], 1e-12),
                   "catalogue_p": float((1 + np.sum(max_ratio >= g / max(q99[c], 1e-12))) / (1 + draws)),
                   "rmse_Pa": {j: {"base": float(np.sqrt(np.mean((real[None][j] - y[j]) ** 2))),
                                   "candidate": float(np.sqrt(np.mean((real[c][j] - y[j]) ** 2)))} for j in calib}}
    order = sorted(cands, key=lambda c: -rows[c]["ratio_to_q99"])
    rep = state["report"]
    return {"series": series.name, "calib_records": calib, "candidates": rows, "ranking": order,
            "base_point": pts[None], "walk_named": rep.get("verdict"), "walk_effects": rep.get("added"),
            "draws": draws, "real_runs": sum(len(state["meshes"][j]) for j in calib) * (1 + len(cands)),
            "seconds": {"fits": t_fit - t0, "null": t_null - t_fit, "real_runs": t_real - t_null}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", required=True)
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--work", default=None, help="folder for the new runs (default: <series>/study_insample_ranking)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    series = Path(a.series)
    out = rank(series, a.draws, a.seed, Path(a.work) if a.work else series / "study_insample_ranking")
    out["what"] = __doc__.split("\n")[0]
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
