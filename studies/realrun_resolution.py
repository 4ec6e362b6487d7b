"""The selection on real runs' resolution round (calibration.realrun, module docstring item 6), on finished
development series: the reported fit run at the finer preset and at the experiment's, linearised again,
corrected (calibration.realrun.resolution_corrected), and each 90 % interval, before and after, against
the planted truth (series/truth.json: the base parameters and the planted effect, a per-record one per
record). Why: on the development friction series of seed 5393 the uncorrected intervals missed the
planted friction, sigma_t and E_t alike.

    python studies/realrun_resolution.py --run results/<exp> --config <config.yaml> --exp <exp> \\
        --fit <realrun.json or an output of studies/realrun_selection.py> --effect interface_friction \\
        --truth <series>/truth.json --out studies/results/realrun_resolution_<case>_<seed>.json
    python studies/realrun_resolution.py --pool studies/results/realrun_interval_forms.json <outputs>

The weights are the workflow's (its round state, ``--state``) or, for a series the study script
selected on, the study's (the base at its start on the first three check meshes). The calibration
records only; the held-out record is neither read nor run.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from multiprocessing import Pool
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from calibration import realrun as rr  # noqa: E402
from calibration.realrun_files import series_of  # noqa: E402
from calibration.observations import curve_on_grid, read_observations  # noqa: E402

MESHES = {"fit": 3101, "check": 3201, "coarse": 3301, "fine": 3401}   # first mesh seed of each kind of run
_OBS = {}


def _init(run, geometry, preset, t_end, sample_dt):
    _OBS.update(run=run, geometry=geometry, preset=preset, t_end=t_end, sample_dt=sample_dt,
                obs=read_observations(Path(run) / "observations/obs.csv", Path(run) / "observations/obs.json"))


def _run(row):
    from shpb.simulate import simulate
    o = _OBS
    sim = simulate(o["geometry"], row.get("preset") or o["preset"], params=dict(row["simulator"]),
                   record=str(Path(o["run"]) / "observations" / row["record"]), t_end=o["t_end"],
                   sample_dt=o["sample_dt"], mesh_seed=MESHES[row["kind"]] + int(row["mesh"]))
    if sim.run["status"] != "ok":
        return None
    t = o["obs"].time[o["obs"].record_slice(row["record"])]
    f = curve_on_grid(np.asarray(sim.columns["time_s"]), np.asarray(sim.columns["stress_Pa"]), t)
    return f if np.all(np.isfinite(f)) else None


def _fit_of(doc: dict, effect: str | None) -> dict:
    """The fit to correct: realrun.json's or the study's candidate (or base) entry."""
    entry = doc["base"] if effect is None else doc["candidates"][effect]
    return {k: float(v) for k, v in entry["fit"].items()}


def _interval_rows(fit, interval, truth_of) -> list[dict]:
    out = []
    for n in interval["q05"]:
        t = truth_of(n)
        out.append({"name": n, "fit": fit[n], "q05": interval["q05"][n], "q95": interval["q95"][n], "truth": t,
                    "inside": None if t is None else bool(interval["q05"][n] <= t <= interval["q95"][n])})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--exp", required=True)
    ap.add_argument("--fit", required=True)
    ap.add_argument("--effect", default=None, help="the track to correct (default: the base)")
    ap.add_argument("--state", help="the workflow's last realrun round (its weights)")
    ap.add_argument("--truth", required=True)
    ap.add_argument("--preset", default="standard")
    ap.add_argument("--meshes", type=int, default=4)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    exp = yaml.safe_load(Path(a.config).read_text())["experiments"][a.exp]
    obs = read_observations(Path(a.run) / "observations/obs.csv", Path(a.run) / "observations/obs.json")
    s = series_of(obs, exp)
    records = list(obs.records)
    shared, own = rr.names_of(a.effect, records)
    theta = _fit_of(json.loads(Path(a.fit).read_text()), a.effect)
    truth = json.loads(Path(a.truth).read_text())
    planted = {t["name"]: t.get("planted") or {} for t in truth["tests"]}

    def truth_of(name):
        stem, _, rec = name.partition("@")
        if stem in truth["params"]:
            return float(truth["params"][stem])
        return float(planted.get(rec, {}).get(stem, (truth.get("plant") or {}).get(stem, np.nan)))

    track = {"shared": shared, "own": own, "theta": theta, "stage": "resolution"}
    rows = rr._track_rows("named", track, records, s["box"], 0, {"preset": a.preset, "meshes": a.meshes})
    state = json.loads(Path(a.state).read_text()) if a.state else None
    if state is None:   # the study selected without keeping its check runs: the fit on eight meshes of its own
        rows += [{"record": r, "simulator": rr._sim_params(theta, r, shared, own), "kind": "check", "mesh": m,
                  "name": None, "h": 0.0, "preset": None} for r in records for m in range(8)]
    init = (a.run, exp["geometry"], exp["preset"], float(exp["simulation"]["t_end"]),
            float(exp["simulation"]["sample_dt"]))
    with Pool(2, initializer=_init, initargs=init) as pool:
        if state is not None:
            w = {r: np.asarray(v) for r, v in state["weights"].items()}
            weights_from = a.state
        else:   # the study's weights: the base at its start on the first three check meshes
            doc = json.loads(Path(a.fit).read_text())
            sh0, own0 = rr.names_of(None, records)
            wrows = [{"record": r, "simulator": rr._sim_params(doc["start"], r, sh0, own0), "kind": "check",
                      "mesh": m} for r in records for m in range(rr.WEIGHT_MESHES)]
            wc = pool.map(_run, wrows)
            w = rr._weights(wrows, wc, records, s["noise"])
            weights_from = "the base at the study's start, three meshes"
        curves = pool.map(_run, rows)
    if state is not None:
        checks = state["tracks"][a.effect or "base"]["check_runs"]
        checks = {r: [None if c is None else np.asarray(c, float) for c in v] for r, v in checks.items()}
        checks_from = "the workflow's check runs (the cross-validation points)"
    else:
        checks = {r: [c for row, c in zip(rows, curves) if row["kind"] == "check" and row["record"] == r]
                  for r in records}
        checks_from = "eight meshes at the fit"
    mesh = rr.mesh_term(checks, records)
    args = (w, s["y"], records, s["box"], s["noise"], s["times"])
    at = _at_theta(rows, curves, shared, own, records)
    forms = {"per_sample": rr.fit_interval(theta, theta, *at, *args),
             "before": rr.fit_interval(theta, theta, *at, *args, mesh=mesh)}
    after = rr.resolution_corrected(theta, rows, curves, shared, own, *args, mesh=mesh)
    doc = {"study": "realrun_resolution", "run": a.run, "exp": a.exp, "effect": a.effect, "cores": 2,
           "preset": a.preset, "meshes": a.meshes, "weights_from": weights_from, "runs": len(rows),
           "failed": sum(c is None for c in curves),
           "checks_from": checks_from,
           "per_sample": {"intervals": _interval_rows(theta, forms["per_sample"], truth_of),
                          "misfit_scale": forms["per_sample"]["misfit_scale"],
                          "what": "the mesh scatter as independent per sample (the form before this study)"},
           "before": {"intervals": _interval_rows(theta, forms["before"], truth_of),
                      "misfit_scale": forms["before"]["misfit_scale"],
                      "what": "the mesh covariance over time, no resolution round"},
           "after": {"what": "the resolution round (calibration.realrun.resolution_corrected)",
                     "intervals": _interval_rows(after["fit"], after["interval_90"], truth_of),
                     "misfit_scale": after["interval_90"]["misfit_scale"], "bias_rms_Pa": after["bias_rms"]},
           "wall_s": round(time.perf_counter() - t0, 1)}
    Path(a.out).write_text(json.dumps(doc, indent=1) + "\n")
    for k in ("per_sample", "before", "after"):
        print(k, [(i["name"], round(i["fit"], 6 if i["fit"] < 1 else 1), i["inside"]) for i in doc[k]["intervals"]])


def pooled(paths) -> dict:
    """The forms' tallies over several of this script's outputs: per form, the series whose planted
    parameters (every per-record copy) all lie inside their 90 % intervals, and every reported parameter
    inside; ``sigma_t``'s relative error of the uncorrected fit."""
    docs = [json.loads(Path(p).read_text()) for p in paths]
    out = {"study": "realrun_resolution (pooled)", "series": [d["exp"] for d in docs], "forms": {}}
    for form in ("per_sample", "before", "after"):
        planted = [all(i["inside"] for i in d[form]["intervals"] if i["name"].split("@")[0] not in rr.BASE)
                   for d in docs]
        every = [i["inside"] for d in docs for i in d[form]["intervals"]]
        out["forms"][form] = {"what": docs[0][form]["what"], "planted_inside": sum(planted), "series": len(docs),
                              "parameters_inside": sum(every), "parameters": len(every)}
    errs = [next(i for i in d["before"]["intervals"] if i["name"] == "sigma_t") for d in docs]
    out["sigma_t_rel_error"] = [(i["fit"] - i["truth"]) / i["truth"] for i in errs]
    return out


def _at_theta(rows, curves, shared, own, records):
    """``(base, jac, allnames)`` at the fit, from the round's coarse runs and its linearisation: the
    uncorrected interval on the same runs."""
    lin = [(row, c) for row, c in zip(rows, curves) if row["kind"] == "fit"]
    _, jac, alln = rr._linearised([r for r, _ in lin], [c for _, c in lin], shared, own, records)
    at = {r: np.mean([c for row, c in zip(rows, curves) if row["record"] == r and row["kind"] in ("coarse", "fit")
                      and row["name"] is None and c is not None], axis=0) for r in records}
    return at, jac, alln


if __name__ == "__main__":
    if sys.argv[1:2] == ["--pool"]:     # --pool OUT IN...: the tallies of several outputs
        Path(sys.argv[2]).write_text(json.dumps(pooled(sys.argv[3:]), indent=1) + "\n")
    else:
        main()
