"""Does a run at the truth pass the stop test? The development check that chose the stop test's
standardised statistic (issue 30, 2026-11-29).

On a benchmark seed's kept twin runs (``bench_coverage.py --keep-runs DIR``), per twin: ``--reruns`` runs
of the twin's truth on mesh realizations of their own (``mesh_seed(twin seed, "truth", 0, 100 + r)``,
never the data's), each scored against the data with the twin's last analysis's stop-test error
model (``R + 2 S``; :func:`calibration.model_error.stored_error`), and the loop's members (last and prior
ensembles) the same way, by two statistics:

* ``whitened``: chi^2 per observation whitened by the model's AR(1) correlations, target ``1 + 2 sqrt(2/m)``
  (the stop test before 2026-11-29);
* ``standardized``: the misfit per observation standardised by the model's variances, target its mean
  plus two sd under the model (:func:`enkf.diagnostics.member_standardized_misfit`).

A stop test whose error model is right passes runs at the truth (at its 2-sd target, about 97 % of
them) and fails the prior ensembles. Rows and rates go to ``--out`` (JSON, with the wall time and cores).

Run: ``python studies/stop_rule_dev.py --seed 62 --runs DIR --out OUT.json`` (the re-runs, 4 per
twin, about 3 min for 50 twins on 2 cores; ``--curves FILE`` caches them).
"""
from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TWINS = 50  # the benchmark's design size (its truths are a Latin hypercube of this many)


def rerun_curves(pool, seed: int, twins: int, reruns: int, cache: Path | None) -> dict:
    """``{i: (reruns, m) curves}`` of each twin's truth on mesh realizations of their own."""
    from benchmarks.bench_coverage import _simulate, truths, twin_experiment, twin_task
    from calibration.experiment import ExperimentSpec
    from calibration.model_error import mesh_seed
    from shpb.atomic import atomic_write_bytes

    exp = twin_experiment()
    spec = ExperimentSpec.from_config("twin_ref", {**exp, "seed": seed})
    T = truths(TWINS, spec.lower, spec.upper, seed)
    curves = pickle.loads(cache.read_bytes()) if cache is not None and cache.is_file() else {}
    for i in range(twins):
        if i in curves:
            continue
        s = 1000 * seed + i
        tasks = [twin_task({**exp, "seed": s}, list(spec.names), T[i], exp["preset"], mesh_seed(s, "truth", 0, 100 + r))
                 for r in range(reruns)]
        curves[i] = np.array(pool.map(_simulate, tasks))
        if cache is not None:
            atomic_write_bytes(cache, pickle.dumps(curves))
    return curves


def statistics(Y: np.ndarray, d: np.ndarray, C) -> dict:
    """Both statistics of the rows ``Y`` against data ``d`` under the error model ``C``."""
    from enkf import StopCriteria
    from enkf.diagnostics import chi2_per_obs, standardized_chi2_per_obs, standardized_target

    ok = np.all(np.isfinite(Y), axis=1)
    return {"whitened": np.atleast_1d(chi2_per_obs(Y[ok], d, C)).tolist(),
            "standardized": np.atleast_1d(standardized_chi2_per_obs(Y[ok], d, C)).tolist(),
            "targets": {"whitened": StopCriteria().target(d.size), "standardized": standardized_target(C)}}


def twin_row(path: Path, curves: np.ndarray) -> dict:
    from calibration.model_error import stored_error

    spec, params, responses, analyses, obs = pickle.loads(path.read_bytes())
    K = len(analyses) - 1
    C_last, C_prior = stored_error(obs, analyses[K]).stop(), stored_error(obs, analyses[0]).stop()
    return {"twin": path.stem, "analyses": K, "truth_reruns": statistics(curves, obs.values, C_last),
            "last_members": statistics(responses[K], obs.values, C_last),
            "prior_members": statistics(responses[0], obs.values, C_prior)}


def rates(rows: list[dict]) -> dict:
    out = {}
    for stat in ("whitened", "standardized"):
        def passes(block, reduce):
            return [reduce(r[block][stat]) <= r[block]["targets"][stat] for r in rows]
        reruns = [v <= r["truth_reruns"]["targets"][stat] for r in rows for v in r["truth_reruns"][stat]]
        last, prior = passes("last_members", np.median), passes("prior_members", np.median)
        out[stat] = {"truth_reruns_pass": float(np.mean(reruns)), "truth_reruns": len(reruns),
                     "median_truth_rerun": float(np.median([v for r in rows for v in r["truth_reruns"][stat]])),
                     "last_ensemble_stops": float(np.mean(last)), "prior_ensemble_passes": float(np.mean(prior)),
                     "twins": len(rows),
                     "median_target": float(np.median([r["last_members"]["targets"][stat] for r in rows]))}
    return out


def main(argv=None) -> dict:
    from multiprocessing import get_context

    from shpb.atomic import emit_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--runs", required=True, help="the folder of bench_coverage.py --keep-runs")
    ap.add_argument("--twins", type=int, default=TWINS)
    ap.add_argument("--reruns", type=int, default=4)
    ap.add_argument("--curves", default=None, help="a pickle caching the re-runs")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    started = time.time()
    with get_context("spawn").Pool(2) as pool:
        curves = rerun_curves(pool, args.seed, args.twins, args.reruns, Path(args.curves) if args.curves else None)
    rows = [twin_row(Path(args.runs) / f"well_specified_{args.seed}_{i:03d}.pkl", curves[i]) for i in range(args.twins)]
    out = {"benchmark": "stop_rule_dev", "seed": args.seed, "reruns_per_twin": args.reruns, "rates": rates(rows),
           "cores": os.cpu_count(), "wall_s": time.time() - started, "rows": rows}
    return emit_json(out, args.out)


if __name__ == "__main__":
    main()
