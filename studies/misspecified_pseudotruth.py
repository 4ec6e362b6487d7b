"""What the misspecified coverage twins' posteriors cover: the standard mesh's parameters, or the `fast`
model's best fit to the standard mesh's curve?

For each misspecified twin of the given ``bench_coverage`` JSONs (data from the ``standard`` mesh at the
truth T, model at ``fast``): the twin's noise-free data curve is simulated again (its own truth mesh
realization, as the benchmark made it), and the *pseudo-truth* theta* is the parameter point whose `fast`
curve, averaged over two mesh realizations held fixed for the search (common random numbers), is
closest to it in least squares over the twin's observation window: Nelder-Mead in the unit box,
started **at the truth T** (so that a flat or rugged misfit leaves theta* near T, never drawn toward the
posterior by the start). Reported per twin and pooled: theta* / T, the chi^2 per observation at T and at
theta* against the data's 1 % noise, and whether the twin's reported 90 % interval (the emulator MCMC's
5-95 %) holds T and theta*.

A development diagnostic of the benchmark's misspecified sets after they were scored: no setting is
chosen on it. Prints one JSON object (and writes it with ``--out``); 2 cores, about 1 min per twin.

    python studies/misspecified_pseudotruth.py benchmarks/results/bench_coverage_mcmc_2026-11-27.json \\
        benchmarks/results/bench_coverage_misspecified_seed43_2026-11-27.json --out <json>
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import _simulate, twin_experiment, twin_task  # noqa: E402
from calibration.experiment import ExperimentSpec, mesh_seed  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

#: Mesh realizations of the `fast` search, per twin (the "check" stage: no run of the twin itself uses it).
SEARCH_MESHES = 2


def pseudo_truth(pool, exp: dict, names, lower, upper, truth: np.ndarray, data: np.ndarray, seed: int,
                 maxfev: int) -> dict:
    """theta*: the `fast` curve (mean of SEARCH_MESHES fixed realizations) nearest ``data`` in least squares."""
    meshes = [mesh_seed(seed, "check", 90, r) for r in range(SEARCH_MESHES)]
    sigma = 0.01 * float(np.max(data))  # the twin's noise: 1 % of its reference peak
    span = upper - lower

    def curve(theta):
        return np.mean(pool.map(_simulate, [twin_task(exp, names, theta, exp["preset"], ms) for ms in meshes]), axis=0)

    def chi2(theta):
        y = curve(theta)
        return float(np.mean(((y - data) / sigma) ** 2)) if np.all(np.isfinite(y)) else 1e12

    def objective(u):
        inside = np.clip(u, 0.0, 1.0)
        return chi2(lower + inside * span) + 1e3 * float(np.sum((u - inside) ** 2))

    u0 = (truth - lower) / span
    simplex = np.array([u0, u0 + [0.08, 0.0], u0 + [0.0, 0.08]])
    simplex = np.where(simplex > 1.0, simplex - 0.16, simplex)  # stay in the box at its upper ends
    res = minimize(objective, u0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "maxfev": maxfev, "xatol": 0.004, "fatol": 1e-3})
    theta = lower + np.clip(res.x, 0.0, 1.0) * span
    return {"theta_star": dict(zip(names, map(float, theta))), "chi2_per_obs_at_truth": chi2(truth),
            "chi2_per_obs_at_theta_star": float(res.fun), "evaluations": int(res.nfev)}


def pooled_summary(rows: list, names) -> dict:
    """Over the twins: how many reported 90 % intervals hold T and theta*, the median ratios, and how far
    the `fast` curve stays from the data at T and at theta* (chi^2 per observation against the 1 % noise)."""
    chi_t = [r["chi2_per_obs_at_truth"] for r in rows]
    chi_s = [r["chi2_per_obs_at_theta_star"] for r in rows]
    out = {p: {"covers_truth": sum(r["covers"][p]["truth"] for r in rows),
               "covers_theta_star": sum(r["covers"][p]["theta_star"] for r in rows),
               "theta_star_over_truth_median": float(np.median([r["covers"][p]["theta_star_over_truth"] for r in rows])),
               "posterior_mean_over_theta_star_median": float(np.median(
                   [r["covers"][p]["posterior_mean_over_theta_star"] for r in rows]))} for p in names}
    out["chi2_per_obs_at_truth"] = {"median": float(np.median(chi_t)), "min": min(chi_t), "max": max(chi_t)}
    out["chi2_per_obs_at_theta_star"] = {"median": float(np.median(chi_s)), "min": min(chi_s), "max": max(chi_s)}
    out["searches_at_their_budget"] = sum(r["evaluations"] >= r["maxfev"] for r in rows)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("jsons", nargs="+")
    ap.add_argument("--maxfev", type=int, default=30)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--limit", type=int, default=None, help="the first N twins only (a trial)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    exp = twin_experiment()
    spec = ExperimentSpec.from_config("twin_ref", exp)
    names, lower, upper = list(spec.names), spec.lower, spec.upper
    twins = [r for p in a.jsons for r in json.loads(Path(p).read_text())["misspecified"]["twins"]][:a.limit]
    started, rows = time.time(), []
    with get_context("spawn").Pool(max(1, a.cores)) as pool:
        tasks = [twin_task({**exp, "seed": r["seed"]}, names, [r["truth"][p] for p in names], r["data_preset"],
                           mesh_seed(r["seed"], "truth")) for r in twins]
        data = pool.map(_simulate, tasks)
        for r, y in zip(twins, data):
            truth = np.array([r["truth"][p] for p in names])
            found = pseudo_truth(pool, {**exp, "seed": r["seed"]}, names, lower, upper, truth, np.asarray(y), r["seed"],
                                 a.maxfev)
            post = r["emulator_mcmc"]["params"]
            row = {"seed": r["seed"], "truth": r["truth"], **found, "maxfev": a.maxfev, "covers": {}}
            for p in names:
                lo, hi = post[p]["q05"], post[p]["q95"]
                row["covers"][p] = {"truth": bool(lo <= r["truth"][p] <= hi),
                                    "theta_star": bool(lo <= found["theta_star"][p] <= hi),
                                    "theta_star_over_truth": found["theta_star"][p] / r["truth"][p],
                                    "posterior_mean_over_theta_star": post[p]["mean"] / found["theta_star"][p]}
            rows.append(row)
            print(f"{r['seed']}: theta*/T " + ", ".join(f"{p} {row['covers'][p]['theta_star_over_truth']:.3f}"
                                                       for p in names), file=sys.stderr, flush=True)
    pooled = pooled_summary(rows, names)
    out = {"benchmark": "misspecified_pseudotruth", "sources": a.jsons, "twins": len(rows),
           "search": {"method": "Nelder-Mead in the unit box from the truth", "maxfev": a.maxfev,
                      "meshes_per_point": SEARCH_MESHES, "misfit": "mean squared error over the twin's window / (1 % of the data's peak)^2"},
           "pooled": pooled, "cores": os.cpu_count(), "pool_workers": a.cores,
           "wall_s": time.time() - started, "per_twin": rows}
    return emit_json(out, a.out)


if __name__ == "__main__":
    main()
