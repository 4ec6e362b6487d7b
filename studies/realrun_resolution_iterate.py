"""The resolution correction iterated (studies/realrun_resolution.py): theta_{k+1} = theta_k + one Gauss-Newton
step on y - f_fine(theta_k), the `fast` Jacobian at the fit, four `standard` runs a step; each step's
intervals (the mesh covariance of the check runs, the fine runs' own scatter) against the planted truth.
Whether stepping on at the finer preset reaches the planted values where one step did not.

    python studies/realrun_resolution_iterate.py RUN CONFIG EXP FIT EFFECT TRUTH STATE|- OUT
"""
import json, sys
from multiprocessing import Pool
from pathlib import Path
import numpy as np, yaml
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import studies.realrun_resolution as S
from calibration import realrun as rr
from calibration.observations import read_observations
run, cfgp, exp_name, fitf, effect, truthf, statef, out = sys.argv[1:9]
exp = yaml.safe_load(open(cfgp))["experiments"][exp_name]
obs = read_observations(Path(run)/"observations/obs.csv", Path(run)/"observations/obs.json")
from calibration.realrun_files import series_of
s = series_of(obs, exp); recs = list(obs.records)
shared, own = rr.names_of(effect, recs)
doc = json.load(open(fitf)); theta = {k: float(v) for k, v in doc["candidates"][effect]["fit"].items()}
truth = json.load(open(truthf)); planted = {t["name"]: t.get("planted") or {} for t in truth["tests"]}
def truth_of(n):
    stem, _, rec = n.partition("@")
    return float(truth["params"][stem]) if stem in truth["params"] else float(planted.get(rec, {}).get(stem, truth["plant"].get(stem)))
init = (run, exp["geometry"], exp["preset"], float(exp["simulation"]["t_end"]), float(exp["simulation"]["sample_dt"]))
with Pool(2, initializer=S._init, initargs=init) as pool:
    if statef != "-":
        st = json.load(open(statef)); w = {r: np.asarray(v) for r, v in st["weights"].items()}
        checks = st["tracks"][effect]["check_runs"]
    else:
        sh0, own0 = rr.names_of(None, recs)
        wrows = [{"record": r, "simulator": rr._sim_params(doc["start"], r, sh0, own0), "kind": "check", "mesh": m} for r in recs for m in range(3)]
        w = rr._weights(wrows, pool.map(S._run, wrows), recs, s["noise"])
        crow = [{"record": r, "simulator": rr._sim_params(theta, r, shared, own), "kind": "check", "mesh": m} for r in recs for m in range(8)]
        cc = pool.map(S._run, crow); checks = {r: [c for row, c in zip(crow, cc) if row["record"] == r] for r in recs}
    mesh = rr.mesh_term(checks, recs)
    lrows = rr._lin_rows("x", 0, theta, shared, own, recs, s["box"])
    base, jac, alln = rr._linearised(lrows, pool.map(S._run, lrows), shared, own, recs)
    th = dict(theta); hist = []
    for k in range(3):
        frows = [{"record": r, "simulator": rr._sim_params(th, r, shared, own), "kind": "fine", "mesh": m, "preset": "standard"} for r in recs for m in range(4)]
        fc = pool.map(S._run, frows)
        f = {r: np.mean([c for row, c in zip(frows, fc) if row["record"] == r], axis=0) for r in recs}
        extra = {r: rr.mesh_covariance([c for row, c in zip(frows, fc) if row["record"] == r]) / 4 for r in recs}
        sse = sum(float(np.sum(w[r] * (s["y"][r] - f[r]) ** 2)) for r in recs)
        iv = rr.fit_interval(th, th, f, jac, alln, w, s["y"], recs, s["box"], s["noise"], s["times"], mesh=mesh, extra=extra)
        ins = {n: bool(iv["q05"][n] <= truth_of(n) <= iv["q95"][n]) for n in iv["q05"]}
        hist.append({"k": k, "theta": th, "fine_sse": sse, "interval": iv, "inside": ins})
        print(k, {n: round(v, 8 if v < 1 else 0) for n, v in th.items()}, "fine sse", round(sse, 1), ins, flush=True)
        th = rr.gn_solve(th, f, jac, alln, w, s["y"], recs, s["box"])
json.dump(hist, open(out, "w"), indent=1, default=float)
