"""A selection on real runs alone: each physical candidate fitted to the calibration records by Gauss-Newton
on real FDEM runs and compared with the base model by the walk's paired test (issue 53, item 2).

Why: `studies/oracle_power.py` found the planted end friction and seating confirmable at their truth
(z 18.9 and 76 against the base model's best absorbing fit), while the benchmark's walk never named
them: its proposals and their fitted points come from the anchored surrogate, which cannot follow the
strength a friction or a rate law trades off with. Here no surrogate: the base model and each
candidate (its parameters with `sigma_t` and `E_t`) are fitted by Gauss-Newton steps whose Jacobian is
taken from real runs (finite differences on two meshes, from the workflow's base posterior mean with
every effect at its null); each calibration record is then predicted from the fit on the others
(per-record parameters at the mean of the others' fitted values), run on three check meshes, and
compared with the base model's prediction of it on the same meshes, weighted per time by
1 / (noise^2 + mesh scatter^2) (enkf.diagnosis.crossval.compare_replicated). A candidate is named when
its p is below the walk's level, 0.005; the largest z among those is the name.

Development only: run on development series (seed 5392) whose truths are known; nothing in the
product changes with it. Per series it writes each candidate's fit, each record's z and the name.

    python studies/realrun_selection.py --run results/<exp> --config <config.yaml> --exp <exp> \
        [--candidates rate_strength,interface_friction,seating,face_gap] --out F

``--recheck FIT.json --check-meshes K``: no fitting; the base's and each candidate's cross-validation
points of an earlier run of this script are run on K check meshes (the first three are the earlier run's
own, so its z is reproduced on them first) and compared by the same test, with the same weights (the
earlier run's three meshes). Why: with three meshes a record's realization part of the paired
difference has two degrees of freedom, and the friction series' z 4.88 stayed at p 0.0135; the plan for
K is fixed before the runs (studies/README.md, the row of this mode).

``--versus FIT.json --check-meshes K``: no fitting; the earlier run's named candidate against each other
candidate that passed against the base there, on the same check meshes (z > 0: the named one predicts
better). Why: on two development series a second candidate passed too (a sibling of the planted effect,
or the strength-confounded rate law); the rule of calibration.realrun.grouped says whether the data tell them apart.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from multiprocessing import Pool
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from calibration import realrun as rr  # noqa: E402
from calibration.observations import curve_on_grid, read_observations  # noqa: E402
from shpb import effects as fx  # noqa: E402

FIT_MESHES = (3101, 3102)
CHECK_MESHES = (3201, 3202, 3203)
RECHECK_FIRST = 3201    # --check-meshes K: the comparison on meshes RECHECK_FIRST .. RECHECK_FIRST + K - 1
COMPARE_MESHES = CHECK_MESHES   # the weights always take the first three
GN_STEPS, LEVEL, REL_STEP, EFFECT_STEP = rr.GN_STEPS, rr.LEVEL, rr.REL_STEP, rr.EFFECT_STEP   # the product's
PROFILE_STEPS = 2       # --profile-steps: Gauss-Newton steps of sigma_t and E_t at each grid value
PROFILE_REAL = False    # --profile-real: each grid value's error from real runs at its fit

_OBS = {}


def _init(run):
    _OBS["run"] = run
    _OBS["obs"] = read_observations(Path(run) / "observations/obs.csv", Path(run) / "observations/obs.json")


def _run(job):
    rec, params, mesh, t_end, sample_dt = job
    from shpb.simulate import simulate
    obs = _OBS["obs"]
    sim = simulate("cylinder", "fast", params=dict(params), record=str(Path(_OBS["run"]) / "observations" / rec),
                   t_end=t_end, sample_dt=sample_dt, mesh_seed=mesh)
    t = obs.time[obs.record_slice(rec)]
    if sim.run["status"] != "ok":
        return np.full(t.size, np.nan)
    f = curve_on_grid(np.asarray(sim.columns["time_s"]), np.asarray(sim.columns["stress_Pa"]), t)
    return np.nan_to_num(f, nan=0.0)


class Series:
    def __init__(self, run, config, exp, pool):
        self.run, self.pool = Path(run), pool
        cfg = yaml.safe_load(Path(config).read_text())["experiments"][exp]
        self.t_end, self.sample_dt = float(cfg["simulation"]["t_end"]), float(cfg["simulation"]["sample_dt"])
        self.box = {n: tuple(map(float, v)) for n, v in cfg["parameters"].items()}
        self.upper = {k: float(v) for k, v in (cfg.get("diagnosis", {}).get("physical_upper") or {}).items()}
        self.obs = read_observations(self.run / "observations/obs.csv", self.run / "observations/obs.json")
        self.records = list(self.obs.records)
        info = self.obs.meta["record_info"]
        self.y = {r: self.obs.values[self.obs.record_slice(r)] for r in self.records}
        self.noise = {r: (float(info[r]["noise_estimate"]["sigma"]), float(info[r]["noise_estimate"]["corr_time"]))
                      for r in self.records}
        post = json.loads((self.run / "summary.json").read_text())["posterior"]
        self.start = {n: float(post[n]["mean"]) for n in ("sigma_t", "E_t")}
        self.runs = 0

    def curves(self, jobs):
        keys = [(r, tuple(sorted(p.items())), m, self.t_end, self.sample_dt) for r, p, m in jobs]
        self.runs += len(keys)
        return self.pool.map(_run, keys)

    def bounds(self, name):
        base = name.split("@")[0]
        if base in self.box:
            return self.box[base]
        lo, hi = fx.bounds([base])
        return float(lo[0]), float(min(hi[0], self.upper.get(base, hi[0])))


def _names(effect, records):
    """(shared names, {record: its own names}) of the base model plus ``effect`` (None: the base)."""
    return rr.names_of(effect, records)


def _sim_params(theta, record, shared, own):
    p = {n: theta[n] for n in shared}
    p.update({n.split("@")[0]: theta[n] for n in own[record]})
    return p


def _step_of(s, name, theta):
    if name in REL_STEP:
        return REL_STEP[name] * theta[name]
    lo, hi = s.bounds(name)
    return EFFECT_STEP * (hi - lo)


def linearise(s, theta, shared, own, records, vary=None):
    """Per record its mean curve over the fit meshes at ``theta`` and the Jacobian over every name
    (``vary``: only these names get derivative runs; the others' columns stay zero)."""
    allnames = shared + [n for r in records for n in own[r]]
    jobs, index = [], []
    for r in records:
        for name in [None] + [n for n in shared + own[r] if vary is None or n in vary]:
            th = dict(theta)
            if name is not None:
                lo, hi = s.bounds(name)
                h = _step_of(s, name, theta)
                th[name] = theta[name] + h if theta[name] + h <= hi else theta[name] - h
            for m in FIT_MESHES:
                jobs.append((r, _sim_params(th, r, shared, own), m))
                index.append((r, name, th[name] - theta[name] if name else 0.0))
    out = s.curves(jobs)
    base, jac = {}, {}
    for r in records:
        rows = [(k, i) for k, i in enumerate(index) if i[0] == r]
        at = np.mean([out[k] for k, i in rows if i[1] is None], axis=0)
        J = np.zeros((at.size, len(allnames)))
        for name in shared + own[r]:
            ks = [k for k, i in rows if i[1] == name]
            if not ks:
                continue
            h = index[ks[0]][2]
            J[:, allnames.index(name)] = (np.mean([out[k] for k in ks], axis=0) - at) / h
        base[r], jac[r] = at, J
    return base, jac, allnames


class _Boxes:
    """The series' boxes as calibration.realrun reads them (``box[name]``)."""

    def __init__(self, s):
        self.s = s

    def __getitem__(self, name):
        return self.s.bounds(name)


def gn_solve(s, theta, base, jac, allnames, w, records):
    """One Gauss-Newton update of ``theta`` from the records' data (weighted), each move capped and clipped
    (calibration.realrun.gn_solve)."""
    return rr.gn_solve(theta, base, jac, allnames, w, s.y, records, _Boxes(s))


def weights(s):
    """1 / (noise^2 + mesh scatter^2) per time: the scatter of the base model at the start on the check meshes."""
    runs = s.curves([(r, dict(s.start), m) for r in s.records for m in CHECK_MESHES])
    out, k = {}, 0
    for r in s.records:
        Y = np.array(runs[k:k + len(CHECK_MESHES)])
        k += len(CHECK_MESHES)
        out[r] = rr.smoothed_weights(Y, s.noise[r][0])
    return out


def _predicted_sse(s, theta, last, base, jac, allnames, w):
    d = np.array([theta[n] - last[n] for n in allnames])
    return float(sum(np.sum(w[r] * (s.y[r] - base[r] - jac[r] @ d) ** 2) for r in s.records))


def _profiled_start(s, theta, shared, own, w, profile, path):
    """The shared effect's parameter on ``profile`` interior grid values of its box, ``sigma_t`` and ``E_t``
    fitted at each (two Gauss-Newton steps); the start is the grid value whose fit leaves the least weighted
    squared error (predicted by its last linearisation)."""
    name = shared[2]
    lo, hi = s.bounds(name)
    best = None
    for v in np.linspace(lo, hi, profile + 2)[1:-1]:
        th = {**theta, name: float(v)}
        for _ in range(PROFILE_STEPS):
            base, jac, allnames = linearise(s, th, shared, own, s.records, vary=("sigma_t", "E_t"))
            last, th = dict(th), gn_solve(s, th, base, jac, allnames, w, s.records)
        if PROFILE_REAL:   # the error of real runs at the fitted point, not its linear prediction
            at, _, _ = linearise(s, th, shared, own, s.records, vary=())
            sse = float(sum(np.sum(w[r] * (s.y[r] - at[r]) ** 2) for r in s.records))
        else:
            sse = _predicted_sse(s, th, last, base, jac, allnames, w)
        path.append({**th, "profile_sse": sse})
        if best is None or sse < best[0]:
            best = (sse, th)
    return dict(best[1])


def fit_model(s, effect, w, profile=0):
    """Gauss-Newton fit on every record, then each record's cross-validation point and its check runs."""
    shared, own = _names(effect, s.records)
    theta = dict(s.start)
    for n in shared[2:] + [n for r in s.records for n in own[r]]:
        theta[n] = float(fx.null_values([n.split("@")[0]])[n.split("@")[0]])
    path = [dict(theta)]
    if profile and effect is not None and fx.get_effect(effect).scope == "shared":
        theta = _profiled_start(s, theta, shared, own, w, profile, path)
    for _ in range(GN_STEPS):
        base, jac, allnames = linearise(s, theta, shared, own, s.records)
        last = dict(theta)
        theta = gn_solve(s, theta, base, jac, allnames, w, s.records)
        path.append(dict(theta))
    cv = {}
    for r in s.records:
        others = [o for o in s.records if o != r]
        fit = gn_solve(s, last, base, jac, allnames, w, others)
        point = {n: fit[n] for n in shared}
        for n in own[r]:
            stem = n.split("@")[0]
            point[n] = float(np.mean([fit[f"{stem}@{o}"] for o in others]))
        cv[r] = point
    return {"fit": theta, "path": path, "cv_points": cv}, check_runs(s, effect, cv, COMPARE_MESHES)


def check_runs(s, effect, cv, meshes):
    """Each record's runs at its cross-validation point ``cv[record]`` on ``meshes``: ``{record: (K, m)}``."""
    shared, own = _names(effect, s.records)
    out = s.curves([(r, _sim_params(cv[r], r, shared, own), m) for r in s.records for m in meshes])
    K = len(meshes)
    return {r: np.array(out[i * K:(i + 1) * K]) for i, r in enumerate(s.records)}


def named(z_p: dict) -> str:
    """The rule: among the candidates whose ``(z, p)`` has p below LEVEL, the largest z; else the base."""
    return rr.named(z_p, LEVEL)


def recheck(s, w, earlier: dict) -> dict:
    """The earlier run's fits compared on COMPARE_MESHES, and on its own three first."""
    meshes = COMPARE_MESHES
    base = check_runs(s, None, earlier["base"]["cv_points"], meshes)
    out = {"check_meshes": list(meshes), "candidates": {}}
    for effect, c in earlier["candidates"].items():
        cand = check_runs(s, effect, c["cv_points"], meshes)
        first = compare(s, w, {r: v[:3] for r, v in base.items()}, {r: v[:3] for r, v in cand.items()})
        out["candidates"][effect] = {"on_first_three": first, f"on_{len(meshes)}": compare(s, w, base, cand),
                                     "earlier": {k: c[k] for k in ("z", "p", "dof")}}
        print(effect, out["candidates"][effect], flush=True)
    key = f"on_{len(meshes)}"
    out["named"] = named({e: (v[key]["z"], v[key]["p"]) for e, v in out["candidates"].items()})
    return out


def versus(s, w, earlier: dict) -> dict:
    """The named candidate of an earlier run of this script against every other candidate that passed against
    the base there: both fits' cross-validation points run on COMPARE_MESHES and compared by the same paired
    test, the other candidate as the reference (z > 0: the named one predicts the records better). The rule
    (calibration.realrun.grouped): the named effect stands alone where it beats each of them at LEVEL, else the ones it
    does not beat share its group."""
    name = earlier["named"]
    cands = earlier["candidates"]
    others = [e for e, c in cands.items() if e != name and c["p"] < LEVEL]
    out = {"named": name, "check_meshes": list(COMPARE_MESHES), "versus": {}}
    if name not in cands:
        return {**out, "group": [], "note": "nothing named: nothing to tell apart"}
    mine = check_runs(s, name, cands[name]["cv_points"], COMPARE_MESHES)
    for e in others:
        theirs = check_runs(s, e, cands[e]["cv_points"], COMPARE_MESHES)
        out["versus"][e] = {**compare(s, w, theirs, mine), "against_base": {k: cands[e][k] for k in ("z", "p", "dof")}}
        print(name, "vs", e, out["versus"][e], flush=True)
    out["group"] = rr.grouped(name, {e: (v["z"], v["p"]) for e, v in out["versus"].items()}, LEVEL)
    return out


def compare(s, w, base_runs, cand_runs):
    """The walk's weighted paired test of the candidate's check runs against the base's (calibration.realrun)."""
    times = {r: s.obs.time[s.obs.record_slice(r)] for r in s.records}
    return rr.paired_test(s.y, w, s.noise, times, base_runs, cand_runs, s.records)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--exp", required=True)
    ap.add_argument("--candidates", default="rate_strength,interface_friction,seating,face_gap")
    ap.add_argument("--truth")
    ap.add_argument("--profile", type=int, default=0, help="a shared effect's start: the best of this many "
                    "interior grid values of its box, sigma_t and E_t fitted at each")
    ap.add_argument("--out", required=True)
    ap.add_argument("--profile-steps", type=int, default=2)
    ap.add_argument("--profile-real", action="store_true")
    ap.add_argument("--recheck", help="an earlier output of this script: compare its fits on more check meshes")
    ap.add_argument("--versus", help="an earlier output of this script: its named candidate against the others "
                    "that passed there, on the check meshes")
    ap.add_argument("--check-meshes", type=int, default=len(CHECK_MESHES),
                    help="check meshes of the comparison (the first three also set the weights)")
    a = ap.parse_args(argv)
    global PROFILE_STEPS, PROFILE_REAL, COMPARE_MESHES
    PROFILE_STEPS, PROFILE_REAL = a.profile_steps, a.profile_real
    COMPARE_MESHES = tuple(range(RECHECK_FIRST, RECHECK_FIRST + a.check_meshes))
    t0 = time.perf_counter()
    with Pool(2, initializer=_init, initargs=(a.run,)) as pool:
        s = Series(a.run, a.config, a.exp, pool)
        w = weights(s)
        for mode, run_mode, key in (("versus", versus, "group"), ("recheck", recheck, "named")):
            if getattr(a, mode):
                result = {"study": f"realrun_selection ({mode})", "run": a.run, "exp": a.exp, "cores": 2,
                          "level": LEVEL, "fits_from": getattr(a, mode),
                          **run_mode(s, w, json.loads(Path(getattr(a, mode)).read_text()))}
                result["runs"], result["wall_s"] = s.runs, round(time.perf_counter() - t0, 1)
                Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
                print(f"{key}:", result[key], f"({s.runs} runs, {result['wall_s']} s)")
                return result
        base, base_runs = fit_model(s, None, w)
        result = {"study": "realrun_selection", "run": a.run, "exp": a.exp, "cores": 2, "level": LEVEL,
                  "profile": a.profile, "profile_steps": a.profile_steps, "profile_real": a.profile_real,
                  "check_meshes": list(COMPARE_MESHES),
                  "start": s.start, "base": base, "candidates": {}}
        if a.truth:
            result["truth"] = json.loads(Path(a.truth).read_text()).get("plant")
        for effect in a.candidates.split(","):
            fit, runs = fit_model(s, effect, w, a.profile)
            result["candidates"][effect] = {**fit, **compare(s, w, base_runs, runs)}
            c = result["candidates"][effect]
            print(f"{effect}: z {c['z']:.2f} p {c['p']:.4f}; fit {fit['fit']}", flush=True)
            Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
        result["named"] = named({e: (c["z"], c["p"]) for e, c in result["candidates"].items()})
        result["runs"], result["wall_s"] = s.runs, round(time.perf_counter() - t0, 1)
        Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
        print("named:", result["named"], f"({s.runs} runs, {result['wall_s']} s)")
    return result


if __name__ == "__main__":
    main()
