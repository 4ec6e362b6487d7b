"""Where does the emulated likelihood put a twin's truth? A development check of issue 30's E_t
under-coverage (run on development seeds, never the coverage benchmark's 40 and 41).

For each twin (``bench_coverage``'s twin, seed ``1000 * seed + i`` with the ``i``-th truth of the
seed's Latin hypercube, so a twin here is the same run as that seed's ``bench_coverage`` twin) the loop
runs as the workflow's; then, on the emulator of every run with the last analysis's error terms
(``R + D`` and the emulator's leave-one-out AR(1) error ``C_em``, which holds the runs' variability
``S``: what the emulated analysis and ``posterior: emulator_mcmc`` use):

* the emulated posterior on a grid of the box (uniform prior; exact for the emulated likelihood, no
  sampler): its 90 % marginal intervals and whether they hold the truth, and ``delta_chi2_truth``,
  ``chi2(truth) - min chi2`` (for a right likelihood a chi-square with 2 degrees of freedom: above 4.6 in
  10 % of twins);
* the candidate fix as the workflow runs it (:func:`enkf.selfcal.self_calibration`: no truth, the last
  runs as pseudo-data of known parameters), its ``lambda`` and the grid posterior at ``lambda``;
* ``replicates_at_truth`` runs at the truth, each on its own mesh: their mean estimates the simulator's
  mean curve there, so the emulator's own error at the truth, ``em(truth) - mean``, can be set against
  ``C_em`` (``emulator_error_chi2_per_obs``; about 1 if ``C_em`` holds it, below 1 if ``C_em`` is too wide
  where the truth is, well above 1 if too narrow), and the data's departure from that mean against
  ``R + S`` (``data_chi2_per_obs``, ``S`` from those replicates).

Run: ``python studies/bench_emulated_likelihood.py --seed 50 --twins 40 --which 3,12,14,22,25,27,0,1,2,5
--out benchmarks/results/bench_emulated_likelihood_<date>.json`` (about 2 min per twin on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import time
from dataclasses import replace

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
from multiprocessing import get_context
import sys
from pathlib import Path

import numpy as np
from scipy import linalg, stats

from calibration.experiment import all_runs, mesh_seed, reported_ensemble
from calibration.model_error import stored_error
from calibration.posterior import sample_posterior
from enkf import prediction_interval_dict
from enkf.emulated import emulator_error_model
from enkf.emulator import smoothed_emulator
from enkf.selfcal import self_calibration
from shpb.atomic import emit_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_coverage import _simulate, simulate_twin, truths, twin_experiment, twin_task  # noqa: E402

GRID = 121          # per parameter: 121 x 121 points of the box
REPLICATES = 8      # runs at the truth


def _marginals(axes, c2: np.ndarray, scale: float, truth, names, level: float = 0.90) -> dict:
    """Per parameter, the central ``level`` interval of the grid posterior ``exp(-(chi2 - min) / 2 scale)``
    (uniform prior), its mean, and whether it holds the truth."""
    w = np.exp(-0.5 * (c2 - c2.min()) / scale).reshape([len(a) for a in axes])
    q = 0.5 * (1 - level)
    out = {}
    for j, p in enumerate(names):
        marg = w.sum(axis=tuple(k for k in range(len(names)) if k != j))
        c = np.cumsum(marg) / marg.sum()
        a, b = float(np.interp(q, c, axes[j])), float(np.interp(1 - q, c, axes[j]))
        out[p] = {"q05": a, "q95": b, "covers": bool(a <= truth[j] <= b),
                  "mean": float(np.sum(axes[j] * marg) / marg.sum())}
    return out


def _mcmc_marginals(spec, params, responses, analyses, obs, truth) -> dict:
    """The 90 % intervals of ``posterior: emulator_mcmc`` with ``emulated.self_calibrate`` on the twin's
    runs (:func:`calibration.posterior.sample_posterior`, the workflow's sampler and seed)."""
    K = len(analyses) - 1
    post = sample_posterior(replace(spec, self_calibrate=True), params[:K + 1], responses[:K + 1], analyses[K], obs)
    s = post.summary
    out = {p: {"q05": s[p]["q05"], "q95": s[p]["q95"], "mean": s[p]["mean"],
               "covers": bool(s[p]["q05"] <= truth[j] <= s[p]["q95"])} for j, p in enumerate(spec.names)}
    out["converged_chain"] = bool(post.diagnostics.get("converged_chain"))
    out["lambda"] = post.diagnostics["emulator_error"]["self_calibration"]["lambda"]
    return out


def replicates_at_truth(pool, exp, names, truth, seed) -> np.ndarray:
    tasks = [twin_task(exp, names, truth, exp["preset"], mesh_seed(seed, "replicate", 99, r))  # k = 99: no loop's
             for r in range(REPLICATES)]
    return np.array(pool.map(_simulate, tasks))


def emulated_check(reps, spec, params, responses, analyses, obs, truth, seed) -> dict:
    names = list(spec.names)
    K = len(analyses) - 1
    X, Y, latest = all_runs(spec, params[:K + 1], responses[:K + 1], np.asarray(analyses[K]["alive"], bool))
    terms = stored_error(obs, analyses[K])
    lo, hi = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
    em, info = smoothed_emulator(X, Y, lo, hi, names, latest, spec.smoothing, terms.likelihood().std)
    c_em, _ = emulator_error_model(em.loo_residuals()[latest], obs.time, obs.frame["record"].to_numpy(str))
    C = terms.emulated().dense() + c_em.dense()
    L = linalg.cholesky(C, lower=True)
    d = obs.values

    def chi2(P):
        w = linalg.solve_triangular(L, (em(np.atleast_2d(P)) - d).T, lower=True)
        return np.sum(w * w, axis=0)

    axes = [np.linspace(lo[j], hi[j], GRID) for j in range(len(names))]
    G = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(names), -1).T
    c2 = np.concatenate([chi2(G[i:i + 2000]) for i in range(0, G.shape[0], 2000)])
    c_truth = float(chi2(truth)[0])
    best = G[int(np.argmin(c2))]
    # where the truth loses: the whitened residual's squares (sequential innovations of the Cholesky
    # factor, so a time's term depends on the past only) summed before and after the observed peak
    wt = linalg.solve_triangular(L, em(truth[None, :])[0] - d, lower=True)
    wb = linalg.solve_triangular(L, em(best[None, :])[0] - d, lower=True)
    peak = int(np.argmax(d))
    scale = max(1.0, float(c2.min()) / d.size)  # the variance inflated until the best fit's chi2/obs is 1
    out = {"smoothing": info["smoothing"], "runs": int(X.shape[0]), "min_chi2_per_obs": float(c2.min() / d.size),
           "chi2_truth_per_obs": c_truth / d.size, "delta_chi2_truth": c_truth - float(c2.min()),
           "best_fit": dict(zip(names, map(float, best))),
           "delta_chi2_truth_before_peak": float(np.sum(wt[:peak + 1] ** 2) - np.sum(wb[:peak + 1] ** 2)),
           "delta_chi2_truth_after_peak": float(np.sum(wt[peak + 1:] ** 2) - np.sum(wb[peak + 1:] ** 2)),
           "inflation": scale, "grid": _marginals(axes, c2, 1.0, truth, names),
           "grid_inflated": _marginals(axes, c2, scale, truth, names)}
    # the candidate fix, as the workflow would run it (enkf.selfcal: no truth, the last runs as pseudo-data)
    groups = obs.frame["record"].to_numpy(str)
    out["self_calibration"] = self_calibration(X, Y, latest, terms.emulated(), lower=lo, upper=hi,
                                               smoothing=info["smoothing"], rng=np.random.default_rng(seed),
                                               error_model=lambda r: emulator_error_model(r, obs.time, groups)[0])
    out["self_calibration"]["truth_inside_90_at_lambda"] = bool(
        out["delta_chi2_truth"] / out["self_calibration"]["lambda"] <= stats.chi2.ppf(0.90, len(names)))
    out["self_calibration"]["grid"] = _marginals(axes, c2, out["self_calibration"]["lambda"], truth, names)
    # the same fix as the workflow reports it: posterior: emulator_mcmc with emulated.self_calibrate
    out["self_calibration"]["mcmc"] = _mcmc_marginals(spec, params, responses, analyses, obs, truth)
    # the simulator's mean curve at the truth, from replicates on meshes of their own
    reps = reps[np.all(np.isfinite(reps), axis=1)]
    mean = reps.mean(axis=0)
    S = np.cov(reps.T) if reps.shape[0] > 1 else np.zeros((d.size, d.size))
    e = em(truth[None, :])[0] - mean
    # the emulator's error at the truth against C_em, the replicate mean's own scatter S/n beside it
    Ce = c_em.dense() + S / reps.shape[0] + 1e-12 * np.eye(d.size) * np.trace(c_em.dense()) / d.size
    out["emulator_error_chi2_per_obs"] = float(e @ linalg.solve(Ce, e, assume_a="pos")) / d.size
    out["emulator_error_rms_Pa"] = float(np.sqrt(np.mean(e ** 2)))
    out["c_em_rms_Pa"] = float(np.sqrt(np.mean(np.diag(c_em.dense()))))
    out["s_rms_Pa"] = float(np.sqrt(np.mean(np.diag(S))))
    # the data against the mean at the truth, R and the replicates' S (diagonal: a guide, S is rank n-1)
    Rd = np.diag(terms.R) + np.diag(S)
    out["data_chi2_per_obs_diag"] = float(np.mean((d - mean) ** 2 / Rd))
    out["replicates"] = int(reps.shape[0])
    return out


def summarise(rows: list, lower, upper) -> dict:
    """Coverage of the 90 % intervals per parameter (reported ensemble; emulated posterior on the grid; the
    same with the variance inflated to the best fit's chi2/obs; with the runs' self-calibrated lambda), and
    the medians of what locates the truth's loss."""
    from scipy import stats

    names = list(rows[0]["truth"]) if rows else []
    kinds = {"ensemble": lambda r: r["ensemble"], "grid": lambda r: r["grid"],
             "grid_inflated": lambda r: r["grid_inflated"], "self_calibrated": lambda r: r["self_calibration"]["grid"],
             "self_calibrated_mcmc": lambda r: r["self_calibration"]["mcmc"]}
    cov = {k: {p: int(sum(get(r)[p]["covers"] for r in rows)) for p in names} for k, get in kinds.items()}
    med = lambda key: float(np.median([r[key] for r in rows]))  # noqa: E731
    return {"twins": len(rows), "covered_90": cov,
            "median_width_90_over_box": {
                k: {p: float(np.median([(kinds[k](r)[p]["q95"] - kinds[k](r)[p]["q05"]) / (upper[j] - lower[j])
                                        for r in rows])) for j, p in enumerate(names)}
                for k in ("ensemble", "grid", "self_calibrated", "self_calibrated_mcmc")},
            "self_calibrated_mcmc_chains_converged": int(sum(r["self_calibration"]["mcmc"]["converged_chain"]
                                                             for r in rows)),
            "truth_outside_emulated_90_region": int(sum(r["delta_chi2_truth"] > stats.chi2.ppf(0.9, len(names)) for r in rows)),
            "median": {k: med(k) for k in ("delta_chi2_truth", "delta_chi2_truth_before_peak", "delta_chi2_truth_after_peak",
                                           "min_chi2_per_obs", "emulator_error_chi2_per_obs", "data_chi2_per_obs_diag")},
            "self_calibration": {"median_lambda": float(np.median([r["self_calibration"]["lambda"] for r in rows])),
                                 "median_fraction_of_runs_inside_90": float(np.median(
                                     [r["self_calibration"]["fraction_inside_90"] for r in rows])),
                                 "truth_inside_90_at_lambda": int(sum(r["self_calibration"]["truth_inside_90_at_lambda"]
                                                                      for r in rows))}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=50)
    ap.add_argument("--twins", type=int, default=40, help="size of the seed's Latin hypercube of truths")
    ap.add_argument("--which", default="0,1,2,3", help="comma-separated twin indices")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", default=None)
    ap.add_argument("--keep", default=None, help="folder to keep each twin's runs in (re-analysis without simulating)")
    args = ap.parse_args(argv)
    if args.seed in (40, 41):
        raise SystemExit("seeds 40 and 41 are the coverage benchmark's: use a development seed")
    exp = twin_experiment()
    from calibration.experiment import ExperimentSpec
    spec0 = ExperimentSpec.from_config("twin_ref", exp)
    T = truths(args.twins, spec0.lower, spec0.upper, args.seed)
    started, rows = time.time(), []
    with get_context("spawn").Pool(max(1, args.cores)) as pool:
        for i in (int(v) for v in args.which.split(",")):
            seed = 1000 * args.seed + i
            saved = Path(args.keep) / f"twin_{seed}.pkl" if args.keep else None
            if saved is not None and saved.is_file():  # a development re-analysis without re-simulating
                spec, params, responses, analyses, obs, reps = pickle.loads(saved.read_bytes())
            else:
                spec, params, responses, analyses, obs = simulate_twin(pool, exp, T[i], seed, "fast")
                reps = replicates_at_truth(pool, exp, list(spec.names), T[i], seed)
                if saved is not None:
                    saved.parent.mkdir(parents=True, exist_ok=True)
                    saved.write_bytes(pickle.dumps((spec, params, responses, analyses, obs, reps)))
            Rr, P, alive = reported_ensemble(spec, analyses, params)
            ints = prediction_interval_dict(P[list(spec.names)].to_numpy(float)[alive], list(spec.names),
                                            transform=spec.transform)
            row = {"twin": i, "seed": seed, "truth": dict(zip(spec.names, map(float, T[i]))),
                   "ensemble": {p: {"q05": ints[p]["q05"], "q95": ints[p]["q95"],
                                    "covers": bool(ints[p]["q05"] <= T[i][j] <= ints[p]["q95"])}
                                for j, p in enumerate(spec.names)},
                   "stop_reason": analyses[-1]["decision"]["reason"],
                   **emulated_check(reps, spec, params, responses, analyses, obs, T[i], seed)}
            rows.append(row)
            print(json.dumps({k: row[k] for k in ("twin", "delta_chi2_truth", "emulator_error_chi2_per_obs",
                                                    "data_chi2_per_obs_diag")}), flush=True)
    out = {"benchmark": "bench_emulated_likelihood", "seed": args.seed, "cores": os.cpu_count(),
           "wall_s": time.time() - started, "grid": GRID, "replicates_at_truth": REPLICATES,
           "summary": summarise(rows, spec0.lower, spec0.upper), "twins": rows}
    return emit_json(out, args.out)


if __name__ == "__main__":
    main()
