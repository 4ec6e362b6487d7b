"""The in-sample ranking on real runs with a design per physical candidate: each candidate's runs made again
at a second strength, so the surrogate the points are fitted on carries the ``sigma_t`` x effect term
(issue 53, item 2: "designs per candidate, the base parameters plus one effect").

``insample_ranking.py`` found the in-sample fit's point wrong for a shared effect confounded with
``sigma_t`` (a rate law fitted at k 0.0 for a planted 0.3, an end friction at mu 0.033 for 0.3): the
anchored surrogate is first order around a base fit that absorbed the effect, so each effect's increment
is the one it has at that (too high) strength. ``anchored_interactions.py`` showed the second-order term
from a few cross runs moves the least-squares point most of the way back on two retired series. This
study adds that term to a finished series' selection surrogate and ranks again:

* per calibration record, on its design mesh, each physical candidate's sweep runs again with
  ``sigma_t`` at the design's lower step (what ``diagnosis.interactions: [sigma_t]`` runs: three runs per
  candidate per record);
* the pair terms put into the series' own anchored emulators (nothing else of the surrogate changes);
* then ``insample_ranking.rank`` as it is (``--fit-weights noise``: the fits weighted by the noise alone,
  which do not discount the peak and post-peak where the mesh scatters and an end friction acts): fits of the base and base + candidate on all calibration
  records, both run on the check meshes, the paired real gain, its ``z_over_chance``.

The measurement candidates have no sweep runs (they act on the simulated curve) and are ranked as before.

Development data only (series on the development seeds). Run with the series' own code first on the path::

    PYTHONPATH=<series clone> python studies/insample_interactions.py \\
        --series <clone>/results/planted_interface_friction_5391 \\
        --out studies/results/insample_interactions_interface_friction_5391.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

from calibration.diagnose import curve_on_model_grid  # noqa: E402
from enkf.diagnosis import RecordErrors, walk_weights  # noqa: E402
from enkf.diagnosis.crossval import compare_replicated  # noqa: E402
from enkf.diagnosis.weights import Weighted  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from studies.anchored_interactions import run_point  # noqa: E402
from studies.insample_ranking import candidate_names, fits, load, rank, real_curves  # noqa: E402


def sweeps_at(series: Path, state: dict, work: Path, pool: ThreadPoolExecutor, *, at: str = "step",
              effects: list[str] | None = None, with_null: bool = False) -> tuple[dict, dict]:
    """The design's physical sweeps made again, per calibration record on its design mesh, with ``sigma_t``
    at ``u``: the design's lower step (``at="step"``) or its box's lower bound (``"bound"``). ``effects``:
    only those candidates' sweeps (default every physical one). Returns ``(nulls, sweeps)``: per record
    ``(u, curve)`` of the run with every effect at its null (``with_null``; else empty) and, per parameter
    index ``j``, ``(u, values, curves)`` (curves on ``model_times``). Runs are kept under ``work`` and
    re-used."""
    design = series / "diagnosis" / "design"
    meta = json.loads((design / "design.json").read_text())
    names, axis = meta["names"], np.asarray(meta["axis"], int)
    X = pd.read_csv(design / "params.csv")[names].to_numpy(float)
    js = names.index("sigma_t")
    u = float(min(X[axis == js, js])) if at == "step" else float(meta["lower"][js])
    phys = [names.index(p) for p in meta["physical_names"] if effects is None or p.split(".")[0] in effects]
    jobs = {}
    for rec in state["calib"]:
        d0 = design / "000" / rec
        run0 = json.loads((d0 / "run.json").read_text())
        dt = float(np.median(np.diff(pd.read_csv(d0 / "curve.csv").time_s.to_numpy())))
        if with_null:
            jobs[(rec, None, None)] = pool.submit(run_point, series, rec, {"sigma_t": u}, run0, work / rec / "null", dt)
        for j in phys:
            for r in np.flatnonzero(axis == j):
                # the folder names of the first runs: cross_ at the lower step, sweep_ at the box's bound
                tag = "cross" if at == "step" else "sweep"
                jobs[(rec, j, float(X[r, j]))] = pool.submit(run_point, series, rec, {"sigma_t": u, names[j]: float(X[r, j])},
                                                             run0, work / rec / f"{tag}_{r:03d}", dt)
    nulls, sweeps = {}, {}
    for (rec, j, v), fut in jobs.items():
        y = curve_on_model_grid(fut.result(), state["model"].model_times)
        if y is None:
            raise RuntimeError(f"{rec}: the run at sigma_t {u:g}, {names[j] if j is not None else 'no effect'} "
                               f"= {v} does not cover the model's times")
        if j is None:
            nulls[rec] = (u, y)
        else:
            sweeps.setdefault(rec, {}).setdefault(j, (u, [], []))
            sweeps[rec][j][1].append(v), sweeps[rec][j][2].append(y)
    return nulls, sweeps


def with_pairs(state: dict, cross: dict) -> dict:
    """``state`` with each calibration record's anchored emulator given the ``(sigma_t, effect)`` terms."""
    for rec, per in cross.items():
        em = state["model"].emulators[rec]
        i = em.names.index("sigma_t")
        em._pairs = {**em._pairs, **{(i, j): em._pair_term(i, j, u, v, Y) for j, (u, v, Y) in per.items()}}
    return state


def compare(state: dict, y: dict, real0: dict, real1: dict) -> dict:
    """The paired comparison of two points' real runs (per record ``(K, m)``) on the calibration records,
    weighted as the walk weights and unweighted (the plain squared error), with each record's RMSE."""
    calib = state["calib"]
    w = walk_weights(state["noise"], state["sim"], calib)
    out = {}
    for label, ww in (("walk_weights", w), ("plain", {j: np.ones_like(w[j]) for j in calib})):
        Wt = Weighted(RecordErrors({j: state["noise"][j] for j in calib}, {}, {}), calib, ww)
        c = compare_replicated(Wt.scale(y), Wt.scale(real0), Wt.scale(real1), Wt.errors.noise)
        out[label] = {"gain": float(c["delta"]), "sd": float(c["sd"]), "z": float(c["z"])}
    out["rmse_Pa"] = {j: {"base": float(np.sqrt(np.mean((real0[j] - y[j]) ** 2))),
                          "candidate": float(np.sqrt(np.mean((real1[j] - y[j]) ** 2)))} for j in calib}
    return out


def paired(series: Path, state: dict, seed: int, work: Path) -> dict:
    """Every candidate's in-sample point (as ``insample_ranking.rank`` fits it) and the paired comparison of
    its real runs with the base point's (:func:`compare`); no chance draws."""
    cands = candidate_names(state)
    yy = np.concatenate([state["y"][j] for j in state["calib"]])
    at = fits(state, cands, yy, starts=12, seed=seed)
    pts = {c: dict(zip(at[c]["names"], map(float, at[c]["x"]))) for c in [None, *cands]}
    with ThreadPoolExecutor(2) as pool:
        real = {c: real_curves(state, series, pts[c], work, pool) for c in [None, *cands]}
    return {"series": series.name, "base_point": pts[None], "seconds": {},
            "candidates": {c: {"point": pts[c], **compare(state, state["y"], real[None], real[c])} for c in cands}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", required=True)
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--work", default=None,
                    help="folder for the new runs (default: <series>/study_insample_interactions)")
    ap.add_argument("--fit-weights", choices=["walk", "noise"], default="walk",
                    help="the least-squares fits' weights: the walk's 1 / (noise^2 + mesh scatter^2) per time, "
                         "or the noise's alone (the comparison on real runs is weighted as the walk's either way)")
    ap.add_argument("--paired-only", action="store_true",
                    help="no chance draws: every candidate's fitted points and their real runs compared in pairs, "
                         "weighted as the walk and plain (the runs of an earlier call are re-used)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    series = Path(a.series)
    work = Path(a.work) if a.work else series / "study_insample_interactions"
    t0 = time.perf_counter()
    state = load(series)
    if a.fit_weights == "noise":
        obs = pd.read_csv(series / "observations" / "obs.csv")
        state["sig"] = np.concatenate([obs[obs.record == j].sigma_Pa.to_numpy() for j in state["calib"]])
    with ThreadPoolExecutor(2) as pool:
        _, cross = sweeps_at(series, state, work / "cross", pool)
    t_cross = time.perf_counter() - t0
    state = with_pairs(state, cross)
    if a.paired_only:
        out = paired(series, state, a.seed, work / "points")
    else:
        out = rank(series, a.draws, a.seed, work / "points", state=state)
    out["seconds"]["cross_runs"] = t_cross
    out["fit_weights"] = a.fit_weights
    out["cross_runs"] = sum(len(v) for per in cross.values() for _, v, _ in per.values())
    out["what"] = __doc__.split("\n")[0]
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
