"""How much can a twin's curve say about each parameter at all? The score of a posterior that knows the
other parameter and the simulator's own scatter exactly (issue 52's bars on information).

The one-posterior benchmark's bars ask the reported intervals to score at most 0.25 (``sigma_t``) and
0.55 (``E_t``) of the prior box's weighted interval score. Development twins' curves (data, runs at
nearly the truth) show why ``E_t`` is hard: it acts after the first damage, where runs at the same
parameters on other mesh realizations part by a large fraction of the peak, and a quarter of the twins'
windows end before the post-peak. This study measures the ceiling that scatter sets, per twin, with
nothing estimated that the product has to estimate:

* one parameter on a grid of ``CELLS`` cell centres over its box, the other held at its truth (an oracle:
  the product must learn both at once, so its marginal can only be wider);
* at each grid point ``--meshes`` runs on fresh mesh realizations: their mean curve and their scatter
  (:func:`enkf.variability.simulator_variability`, the product's model of it: smoothed per-time sd, one
  AR(1) correlation time), the synthetic likelihood
  ``N(d; mean_k, R + (1 + 1 / M) S_k)`` (Wood 2010; ``S_k / M`` the mean's own error), log-determinant
  included;
* the twin's data exactly as the benchmark made them (``studies.sigma_t_bias.twin_data``); the
  log-likelihood interpolated linearly between the grid points on a fine grid, a uniform prior over the
  box;
* per parameter, the weighted interval score of the resulting 50 % and 90 % intervals and median over
  the prior's, the bars' statistic, and the same for the reported posterior of the same twins (their
  ``bench_coverage.py`` records, ``--records``).

If the oracle's mean score over the prior's is above a bar, no Gaussian likelihood built on this
simulator's scatter meets that bar on these twins at ``fast`` and this window: the bar asks for more
than the curves hold.

Run: ``python studies/identification_ceiling.py --seed 70 --twins 16 --cores 2 --records
/work/dev70/ws.json --out studies/results/identification_ceiling_dev70.json`` (16 x 2 x 12 x 6 = 2304
`fast` disc runs, 16 min on 2 cores; development twins only; ``ws.json`` is that seed's
``bench_coverage.py --seed 70 --twins 16 --misspecified 0`` output).

What it found on development seed 70 (16 well-specified twins; no benchmark twin read): **no ceiling**.
The oracle is far too sure: its 90 % intervals hold the truth in 5 of 16 twins for ``sigma_t`` and 4
of 16 for ``E_t`` (50 %: 2 and 3), many of them a few per cent of the box wide and off the truth by
10-60 % (the two box-top twins, whose curves still rise at the window's end, at 0.36 and 0.73 of the
truth), so it scores 0.60 (``sigma_t``) and 1.20 (``E_t``) of the prior's WIS, worse than the shipped
posterior on the same twins (0.249 and 0.733, knowing neither parameter). Its log-likelihood moves by
tens to hundreds between neighbouring grid points: the mesh scatter after the first damage is not a
Gaussian about the realizations' mean (a realization holds the plateau or drops, at its own time), so
a Gaussian likelihood of it, even one measured at every parameter point with no emulator, is too sure
by far. That is what ``enkf.selfcal``'s ``lambda`` corrects in the shipped posterior; it cannot be
replaced by measuring the scatter better, and this study cannot say how far below the prior's score a
right likelihood could go. Whether the bars are reachable at ``fast`` over this window stays open.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import linalg

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import _simulate, twin_task  # noqa: E402
from benchmarks.scores import weighted_interval_score as record_wis  # noqa: E402
from calibration.experiment import mesh_seed  # noqa: E402
from enkf.scores import QUANTILES, prior_expected_wis, weighted_interval_score  # noqa: E402
from enkf.variability import simulator_variability  # noqa: E402
from studies.pit_recalibration import cdf_at, quantile_at  # noqa: E402
from studies.sigma_t_bias import each_twin, twin_data, write  # noqa: E402

CELLS = 12
FINE = 481
NAMES = ("sigma_t", "E_t")
# the replicate runs' mesh realizations: a stage and iteration index of this study's own
MESH_STAGE, MESH_K = "replicate", 97


def box(exp) -> tuple[np.ndarray, np.ndarray]:
    p = exp["parameters"]
    return np.array([float(p[n][0]) for n in NAMES]), np.array([float(p[n][1]) for n in NAMES])


def synthetic_loglik(y, curves, grid_t, noise_sd: float) -> float:
    """``log N(y; mean, R + (1 + 1/M) S)`` of replicate ``curves`` (M, m) at one parameter point."""
    ok = np.all(np.isfinite(curves), axis=1)
    c = curves[ok]
    S, _ = simulator_variability(c, grid_t)
    C = noise_sd ** 2 * np.eye(grid_t.size) + (0.0 if S is None else (1.0 + 1.0 / len(c)) * S.dense())
    L = linalg.cholesky(C, lower=True)
    w = linalg.solve_triangular(L, y - c.mean(axis=0), lower=True)
    return float(-0.5 * (w @ w) - np.sum(np.log(np.diag(L))))


def oracle_posterior(loglik: np.ndarray, centres: np.ndarray, lo: float, hi: float, truth: float) -> dict:
    """The 1D posterior on the fine grid (log-likelihood linear between the centres, flat beyond them, a
    uniform prior over the box): its quantiles, the truth's PIT and the WIS over the box width."""
    x = np.linspace(lo, hi, FINE)
    lp = np.interp(x, centres, loglik)
    w = np.exp(lp - lp.max())
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(x))])
    cdf /= cdf[-1]
    q = {k: quantile_at(cdf, x, level) for k, level in QUANTILES.items()}
    return {**q, "pit": cdf_at(cdf, x, truth), "wis_over_width": float(weighted_interval_score(q, truth)) / (hi - lo)}


def study_twin(exp, truth, seed, pool, meshes: int) -> dict:
    grid_t, _, y, noise_sd = twin_data(exp, list(NAMES), truth, seed, pool)
    lo, hi = box(exp)
    out = {"seed": int(seed), "truth": dict(zip(NAMES, map(float, truth))), "noise_sd_Pa": noise_sd}
    for a, name in enumerate(NAMES):
        centres = lo[a] + (np.arange(CELLS) + 0.5) * (hi[a] - lo[a]) / CELLS
        tasks = []
        for j, v in enumerate(centres):
            p = np.array(truth, float)
            p[a] = v
            tasks += [twin_task(exp, list(NAMES), p, "fast", mesh_seed(seed, MESH_STAGE, MESH_K, m, 1 + a * CELLS + j))
                      for m in range(meshes)]
        curves = np.array(pool.map(_simulate, tasks)).reshape(CELLS, meshes, grid_t.size)
        ll = np.array([synthetic_loglik(y, curves[j], grid_t, noise_sd) for j in range(CELLS)])
        out[name] = {**oracle_posterior(ll, centres, lo[a], hi[a], float(truth[a])), "loglik": ll.tolist(),
                     "failed_runs": int(np.sum(~np.all(np.isfinite(curves), axis=2)))}
    return out


def reported(records: Path | None, lo, hi) -> dict:
    """The reported posterior's WIS over the box width per twin seed and parameter (bench_coverage.py's
    records of the same twins: their emulator-MCMC intervals and median)."""
    if records is None:
        return {}
    twins = json.loads(records.read_text())["well_specified"]["twins"]
    return {int(t["seed"]): {n: record_wis(t["emulator_mcmc"]["params"][n], t["truth"][n]) / (hi[a] - lo[a])
                             for a, n in enumerate(NAMES)} for t in twins}


def summarise(rows: list[dict], shipped: dict) -> dict:
    prior = prior_expected_wis(0.0, 1.0)
    out = {}
    for n in NAMES:
        oracle = np.array([r[n]["wis_over_width"] for r in rows])
        t = np.array([r["truth"][n] for r in rows])
        q = {k: np.array([r[n][k] for r in rows]) for k in ("q05", "q95", "q25", "q75")}
        entry = {"oracle_wis_over_prior": float(oracle.mean() / prior),
                 "oracle_coverage_90": float(np.mean((q["q05"] <= t) & (t <= q["q95"]))),
                 "oracle_coverage_50": float(np.mean((q["q25"] <= t) & (t <= q["q75"])))}
        mine = [shipped[r["seed"]][n] for r in rows if r["seed"] in shipped]
        if len(mine) == len(rows):
            entry["reported_wis_over_prior"] = float(np.mean(mine) / prior)
        out[n] = entry
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=70)
    ap.add_argument("--twins", type=int, default=16)
    ap.add_argument("--meshes", type=int, default=6)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--records", default=None, help="bench_coverage.py's JSON of the same development twins")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    t0, rows, lo, hi = time.time(), [], None, None
    for i, seed, exp, _, truth, pool in each_twin(args):
        lo, hi = box(exp)
        rows.append(study_twin(exp, truth, seed, pool, args.meshes))
        print(f"{i + 1}/{args.twins}: " + ", ".join(f"{n} {rows[-1][n]['q50'] / rows[-1]['truth'][n]:.3f} "
                                                    f"wis {rows[-1][n]['wis_over_width']:.3f}" for n in NAMES),
              file=sys.stderr, flush=True)
    shipped = reported(Path(args.records) if args.records else None, lo, hi)
    out = {"study": "identification_ceiling", "what": __doc__.split("\n\n")[0].replace("\n", " "), "seed": args.seed,
           "cells": CELLS, "meshes": args.meshes, "cores": args.cores, "wall_s": time.time() - t0,
           "summary": summarise(rows, shipped), "twins": rows}
    return write(out, args.out)


if __name__ == "__main__":
    main()
