"""The development comparison that chose the refinement batch's form (issue 30, 2026-11-29).

Seed 62's kept runs (``bench_coverage.py --seed 62 --twins 50 --misspecified 0 --keep-runs DIR``,
development data, their shipped-form scores already quoted). Per twin: the reported emulator posterior
tempered by 4 (:func:`calibration.posterior.sample_posterior`, ``temper=4``), 25 k-means centroids of
its sample (SciPy ``kmeans2``, k-means++, this script's own random stream), simulated at ``fast`` on
the mesh realizations a next loop iteration would get; then the reported posterior on every run with

* ``A``: the batch as design points only (the emulator's error and the self-calibration still measured
  at the loop's last iteration);
* ``B``: the batch as the latest runs (the error and the self-calibration measured at the batch).

``B`` was adopted (``calibration.posterior``, ``emulated.refine_runs``; the workflow's batch has its own
random stream and mesh stage, so its numbers differ from this script's). The rows go through
``posterior_candidates.py summarise`` beside the shipped form's.

Run: ``python studies/refine_dev.py simulate --runs DIR --batch OUT`` (about 25 s per twin on 2
cores), then ``python studies/refine_dev.py A --runs DIR --batch OUT --out rows_refine_A.json``
(and ``B``).
"""
from __future__ import annotations

import argparse
import json
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

from studies.posterior_candidates import CACHE  # noqa: E402

TEMPER, RUNS = 4.0, 25


def _load(runs: Path, seed: int, i: int):
    return pickle.loads((runs / f"well_specified_{seed}_{i:03d}.pkl").read_bytes())


def simulate(runs: Path, batch: Path, seed: int, twins: int) -> None:
    from multiprocessing import get_context

    from scipy.cluster.vq import kmeans2

    from benchmarks.bench_coverage import _simulate, twin_experiment, twin_task
    from calibration.model_error import mesh_seed
    from calibration.posterior import sample_posterior

    batch.mkdir(parents=True, exist_ok=True)
    with get_context("spawn").Pool(2) as pool:
        for i in range(twins):
            f = batch / f"ref_{seed}_{i:03d}.pkl"
            if f.is_file():
                continue
            spec, params, responses, analyses, obs = _load(runs, seed, i)
            K = len(analyses) - 1
            post = sample_posterior(spec, params[:K + 1], responses[:K + 1], analyses[K], obs, temper=TEMPER)
            lo, hi = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
            U = (post.samples - lo) / (hi - lo)
            rng = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(99,)))
            cent, _ = kmeans2(U[rng.choice(U.shape[0], min(U.shape[0], 4000), replace=False)], RUNS, minit="++", seed=rng)
            P = lo + np.clip(cent, 0, 1) * (hi - lo)
            exp = {**twin_experiment(), "seed": spec.seed}
            Y = np.array(pool.map(_simulate, [twin_task(exp, list(spec.names), p, exp["preset"],
                                                        mesh_seed(spec.seed, "member", K + 1, j)) for j, p in enumerate(P)],
                                  chunksize=1))
            f.write_bytes(pickle.dumps((P, Y, post.summary)))


def score(variant: str, runs: Path, batch: Path, seed: int, twins: int) -> list:
    import pandas as pd

    from calibration.experiment import params_frame
    from calibration.posterior import sample_posterior

    rows = []
    for i in range(twins):
        spec, params, responses, analyses, obs = _load(runs, seed, i)
        P, Y, tempered = pickle.loads((batch / f"ref_{seed}_{i:03d}.pkl").read_bytes())
        truth = json.loads((CACHE / f"well_specified_{seed}_{i:03d}.json").read_text())["truth"]
        K, names = len(analyses) - 1, list(spec.names)
        if variant == "A":  # the batch before the last iteration: latest stays the loop's
            post = sample_posterior(spec, [*params[:K], params_frame(P, names), params[K]],
                                    [*responses[:K], Y, responses[K]], analyses[K], obs)
        else:
            post = sample_posterior(spec, params[:K + 1], responses[:K + 1], analyses[K], obs, refine=(P, Y))
        s = post.summary
        rows.append({"i": i, "truth": truth, **{p: {k: s[p][k] for k in ("q05", "q25", "q75", "q95", "mean")} for p in names},
                     "lam": post.diagnostics["emulator_error"].get("self_calibration", {}).get("lambda"),
                     "tempered": {p: {k: tempered[p][k] for k in ("q05", "q95")} for p in names}})
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cmd", choices=["simulate", "A", "B"])
    ap.add_argument("--runs", required=True)
    ap.add_argument("--batch", required=True)
    ap.add_argument("--seed", type=int, default=62)
    ap.add_argument("--twins", type=int, default=50)
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    if args.cmd == "simulate":
        return simulate(Path(args.runs), Path(args.batch), args.seed, args.twins)
    from shpb.atomic import atomic_write_text

    started = time.time()
    rows = score(args.cmd, Path(args.runs), Path(args.batch), args.seed, args.twins)
    atomic_write_text(Path(args.out), json.dumps({"candidate": f"refine_{args.cmd}", "seed": args.seed,
                                                  "wall_s": time.time() - started, "rows": rows}))


if __name__ == "__main__":
    main()
