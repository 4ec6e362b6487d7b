"""Coverage of the posterior intervals over many twins (issue 18), at the `fast` preset.

Do the reported intervals mean what they say? ``--twins`` twin experiments of the Brazilian disc
(default 20), each with its own truth and seed: truths on a Latin hypercube of the central 80 % of the
Table 2 box (sigma_t 4-60 MPa, E_t 200-2400 J/m^2), 1 % white noise on the reference curve, N = 25
members, three emulator-assisted ES-MDA analyses as the workflow runs them (tempering 4^(K-1-k)), and the
last ensemble simulated too (the workflow's iterations 0..3). Two posteriors per twin:

* ``ensemble``: the last simulated ensemble (what ``summary.json`` reported before issue 18);
* ``ces``: the emcee sample of the emulator posterior on all 100 runs (:mod:`enkf.ces`).

and the stop tests (chi2 of the ensemble-mean curve against R, the workflow's, and against R + the
emulator's measured error, the candidate) at every iteration: in how many twins each passes.

Prints one JSON object: per twin the truth, the errors of the posterior means and whether the 50 % and
90 % central intervals contain the truth; per posterior the coverage fractions, the share of twins
within 2 % (sigma_t) / 10 % (E_t), and the wall time. The goal (issue 18): 90 % intervals cover in
80-97 % of twins per parameter, 50 % intervals in 35-65 %, mean errors within the bar in >= 90 %.

The simulations of each twin are cached (``--cache``, one ``.npz`` per twin: runs, observations,
truth), so the posterior step can be re-run without simulating again.

Run: ``python benchmarks/bench_coverage.py --twins 20 --cores 2 > benchmarks/results/bench_coverage_<date>.json``
(about 45 min on 2 idle cores: 101 fast simulations per twin).
"""

from __future__ import annotations

import argparse
import json
import time
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import qmc

from bench_twin_seeds import GRID, LOWER, UPPER, _simulate
from enkf import emulated_esmda_update, latin_hypercube
from enkf.ces import emulator_posterior, interval_summary
from calibration.observations import twin_observations

NAMES = ("sigma_t", "E_t")
BAR = {"sigma_t": 0.02, "E_t": 0.10}
INTERVALS = {"50": ("q25", "q75"), "90": ("q05", "q95")}


def truths(n: int, seed: int) -> np.ndarray:
    """``n`` truth points: a scrambled Latin hypercube of the box's central 80 %."""
    lo, hi = LOWER + 0.1 * (UPPER - LOWER), UPPER - 0.1 * (UPPER - LOWER)
    return qmc.scale(qmc.LatinHypercube(d=2, seed=seed).random(n), lo, hi)


def simulate_twin(pool, truth, seed, n_members=25, analyses=3) -> dict:
    """The twin's runs: iterations 0..analyses, each simulated, as the workflow's loop."""
    rng = np.random.default_rng(seed)
    ref = pool.map(_simulate, [truth])[0]
    obs = twin_observations(pd.DataFrame({"time_s": GRID, "stress_Pa": ref}), GRID, rng=rng, relative_sigma=0.01)
    d, err = obs.values, obs.error_model()
    P = latin_hypercube(LOWER, UPPER, n_members, rng)
    X, Y, it = np.empty((0, 2)), np.empty((0, GRID.size)), np.empty(0, int)
    for k in range(analyses + 1):
        Yk = np.array(pool.map(_simulate, list(P)))
        ok = np.all(np.isfinite(Yk), axis=1)
        X, Y, it = np.vstack([X, P[ok]]), np.vstack([Y, Yk[ok]]), np.r_[it, np.full(int(ok.sum()), k)]
        if k < analyses:
            P = emulated_esmda_update(X, Y, it == k, d, err, lower=LOWER, upper=UPPER, n_members=n_members,
                                      rng=rng, times=GRID, temper=4.0 ** (analyses - 1 - k)).params
    return {"X": X, "Y": Y, "iteration": it, "d": d, "sigma": err.std, "truth": np.asarray(truth, float),
            "seed": seed}


def _scores(summary: dict, truth: np.ndarray) -> dict:
    out = {"rel_error": {}, "in_50": {}, "in_90": {}, "interval": {}}
    for j, p in enumerate(NAMES):
        s = summary[p]
        out["rel_error"][p] = s["mean"] / truth[j] - 1.0
        out["interval"][p] = [s["q05"], s["q25"], s["q75"], s["q95"]]
        for level, (a, b) in INTERVALS.items():
            out[f"in_{level}"][p] = bool(s[a] <= truth[j] <= s[b])
    out["within_bar"] = bool(all(abs(out["rel_error"][p]) <= BAR[p] for p in NAMES))
    return out


def stopping(run: dict) -> dict:
    """The stop tests at each iteration k: the chi2 per observation of iteration k's ensemble-mean curve
    against R (the workflow's test, taken after the untempered last analysis, k = 3) and against R + the
    emulator's leave-one-out AR(1) error at iteration k's runs (emulator of runs 0..k; the candidate
    rule, recorded in analysis.json as a diagnostic, docs/inference.md)."""
    from enkf import DenseError, DiagonalError
    from enkf.emulated import emulator_error_model
    from enkf.emulator import CurveEmulator

    X, Y, it, d = run["X"], run["Y"], run["iteration"], run["d"]
    R = DiagonalError(run["sigma"])
    target = 1.0 + 2.0 * np.sqrt(2.0 / d.size)
    out = []
    for k in range(1, int(it.max()) + 1):
        upto, latest = it <= k, (it == k)[it <= k]
        em = CurveEmulator(X[upto], Y[upto], LOWER, UPPER)
        emu, _ = emulator_error_model(em.loo_residuals()[latest], GRID)
        r = Y[it == k].mean(axis=0) - d
        C = DenseError(R.dense() + emu.dense(), _symmetric=True)
        out.append({"iteration": k, "chi2_per_obs": float(R.chi2(r) / d.size),
                    "chi2_per_obs_model_error": float(C.chi2(r) / d.size)})
    last = out[-1]
    return {"target": target, "per_iteration": out, "converged": bool(last["chi2_per_obs_model_error"] <= target),
            "converged_without_model_error": bool(last["chi2_per_obs"] <= target),
            "first_passing_iteration": next((o["iteration"] for o in out if o["chi2_per_obs_model_error"] <= target),
                                            None),
            "first_passing_iteration_without_model_error": next(
                (o["iteration"] for o in out if o["chi2_per_obs"] <= target), None)}


def posteriors(run: dict) -> dict:
    from enkf import DiagonalError

    X, Y, it, truth = run["X"], run["Y"], run["iteration"], run["truth"]
    last = it == it.max()
    err = DiagonalError(run["sigma"])
    t0 = time.perf_counter()
    ces = emulator_posterior(X, Y, last, run["d"], err, lower=LOWER, upper=UPPER, times=GRID,
                             rng=np.random.default_rng([int(run["seed"]), 18]), start=X[last], names=NAMES)
    ces_s = time.perf_counter() - t0
    return {"ensemble": _scores(interval_summary(X[last], NAMES), truth),
            "ces": {**_scores(ces.summary, truth), "sampler": {k: ces.diagnostics[k] for k in (
                "steps", "autocorr_time", "acceptance_fraction", "effective_samples", "converged_chain",
                "emulator_error", "emulator", "emulated_mean_chi2_per_obs")}, "wall_s": ces_s},
            "stopping": stopping(run)}


def aggregate(rows: list[dict], method: str) -> dict:
    res = [r[method] for r in rows]
    return {
        "coverage_50": {p: float(np.mean([r["in_50"][p] for r in res])) for p in NAMES},
        "coverage_90": {p: float(np.mean([r["in_90"][p] for r in res])) for p in NAMES},
        "within_bar": float(np.mean([r["within_bar"] for r in res])),
        "mean_abs_rel_error": {p: float(np.mean([abs(r["rel_error"][p]) for r in res])) for p in NAMES},
        "max_abs_rel_error": {p: float(np.max([abs(r["rel_error"][p]) for r in res])) for p in NAMES},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--twins", type=int, default=20)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--seed", type=int, default=18, help="seed of the truth design; twin i uses seed + 1 + i")
    ap.add_argument("--cache", type=Path, default=Path("benchmarks/results/coverage_cache"))
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows, sim_s, cached = [], 0.0, 0
    with get_context("fork").Pool(args.cores) as pool:
        for i, truth in enumerate(truths(args.twins, args.seed)):
            seed = args.seed + 1 + i
            path = args.cache / f"twin_{seed}.npz"
            run = dict(np.load(path)) if path.is_file() else None
            if run is None or not np.allclose(run["truth"], truth, rtol=1e-12):  # a cache of another design
                run = None
            cached += run is not None
            if run is None:
                ts = time.perf_counter()
                run = simulate_twin(pool, truth, seed)
                sim_s += time.perf_counter() - ts
                tmp = path.with_suffix(".tmp.npz")
                np.savez(tmp, **run)
                tmp.replace(path)
            rows.append({"seed": seed, "truth": dict(zip(NAMES, run["truth"].tolist())),
                         "n_runs": int(run["X"].shape[0]), **posteriors(run)})
    print(json.dumps({
        "benchmark": "posterior_interval_coverage", "preset": "fast", "twins": args.twins, "n_members": 25,
        "analyses": 3, "noise": "1 % of the peak, white", "truth_design": "LHS of the central 80 % of the box",
        "goal": {"coverage_90": [0.80, 0.97], "coverage_50": [0.35, 0.65], "within_bar": 0.90},
        "ensemble": aggregate(rows, "ensemble"), "ces": aggregate(rows, "ces"),
        "stopping": {"converged_at_last_iteration": float(np.mean([r["stopping"]["converged"] for r in rows])),
                     "converged_without_model_error": float(np.mean([r["stopping"]["converged_without_model_error"]
                                                                     for r in rows])),
                     "first_passing_iteration": [r["stopping"]["first_passing_iteration"] for r in rows],
                     "first_passing_iteration_without_model_error": [
                         r["stopping"]["first_passing_iteration_without_model_error"] for r in rows]},
        "runs": rows,
        "twins_from_cache": cached, "simulation_wall_s": sim_s, "wall_s": time.perf_counter() - t0, "cores": args.cores,
    }, indent=2))


if __name__ == "__main__":
    main()
