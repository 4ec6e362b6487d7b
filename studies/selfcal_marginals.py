"""Is the self-calibrated posterior's miscalibration a matter of size or of direction? A development
check of issue 30 (kept runs of development seeds; the coverage benchmark's 40 and 41 are refused).

``enkf.selfcal`` scales the emulated likelihood's covariance by one ``lambda``. On the coverage benchmark
the reported 90 % intervals cover ``sigma_t`` at 0.92 and ``E_t`` at 0.80: one factor cannot fix both
if the likelihood is too sure in one direction only. The runs can tell, without any truth: every run of
a twin's last iteration, plus an instrument-noise draw, is data of known parameters. For each such run
``i`` (the emulator of the other runs, its ``C_em`` from that emulator's leave-one-out residuals, as
``enkf.selfcal`` does) the grid posterior over the box (uniform prior, ``GRID`` x ``GRID``) at ``lambda``
times a multiplier gives each parameter's 90 % marginal interval and whether run ``i``'s own value lies
in it; ``lambda`` is the median rule's from the other runs of the twin (leave one run out). A calibrated
likelihood covers both parameters at 0.90 with the multiplier 1; a direction-wise miscalibration shows
as one parameter needing a larger multiplier than the other. Also: the covariance scaled separately
before and after the curve's peak (``PHASE_SCALES``, ``lambda`` re-fitted on top: does the post-peak, where
``E_t`` acts, need more than the rise?), the misses by side, and the coverage per quarter of the box in
which the run's value lies; and the credible levels recalibrated per parameter from each twin's own
runs' ranks or from every other twin's (:func:`recalibrated`).

    python studies/bench_emulated_likelihood.py --seed 50 --twins 40 --which 0,1,2,3,4,5,6,7,8,9,10,11 \
        --keep <folder>        # the 12 development twins' runs (about 22 min on 2 cores), once
    python studies/selfcal_marginals.py --keep <folder> [<folder of another seed> ...]

Prints one JSON object; about 5 s per twin on one core.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
from scipy import linalg, stats

from calibration.experiment import all_runs
from calibration.model_error import stored_error
from enkf.emulated import emulator_error_model
from enkf.emulator import smoothed_emulator
from enkf.selfcal import pseudo_runs

GRID = 81
MULTIPLIERS = (1.0, 1.5, 2.0, 3.0)
#: (before the peak, after it): the covariance's scale per phase, then lambda re-fitted by the median rule
PHASE_SCALES = ((1.0, 1.0), (1.0, 2.0), (1.0, 4.0), (2.0, 1.0), (4.0, 1.0))


def twin_runs(spec, params, responses, analyses, obs, seed: int) -> list[dict]:
    """Per run of the last iteration: its parameters and, per pair of ``PHASE_SCALES``, the grid's chi2 and
    the run's delta chi2 (``lambda`` and the intervals are left to :func:`score`)."""
    K = len(analyses) - 1
    X, Y, latest = all_runs(spec, params[:K + 1], responses[:K + 1], np.asarray(analyses[K]["alive"], bool))
    terms = stored_error(obs, analyses[K])
    lo, hi = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
    _, info = smoothed_emulator(X, Y, lo, hi, list(spec.names), latest, spec.smoothing, terms.likelihood().std)
    groups = obs.frame["record"].to_numpy(str)
    axes = [np.linspace(lo[j], hi[j], GRID) for j in range(lo.size)]
    G = np.array(np.meshgrid(*axes, indexing="ij")).reshape(lo.size, -1).T
    rows = []
    # the runs as enkf.selfcal makes them data of known parameters
    for i, em, C, y in pseudo_runs(X, Y, latest, terms.emulated(), lower=lo, upper=hi, smoothing=info["smoothing"],
                                   error_model=lambda r: emulator_error_model(r, obs.time, groups)[0],
                                   rng=np.random.default_rng(seed)):
        E, e_i = em(G) - y, em(X[i][None, :])[0] - y
        after = np.arange(y.size) > int(np.argmax(y))
        row = {"theta": X[i], "c2": {}, "delta": {}}
        for pair in PHASE_SCALES:
            s_ = np.where(after, np.sqrt(pair[1]), np.sqrt(pair[0]))
            L = linalg.cholesky(C * s_[:, None] * s_[None, :], lower=True)
            W = linalg.solve_triangular(L, E.T, lower=True)
            c2 = np.sum(W * W, axis=0)
            w_i = linalg.solve_triangular(L, e_i, lower=True)
            row["c2"][pair], row["delta"][pair] = c2, max(0.0, float(w_i @ w_i) - float(c2.min()))
        rows.append(row)
    for r in rows:
        r["axes"] = axes
    return rows


def _marginal_cdfs(axes, c2, scale) -> list[np.ndarray]:
    """Per parameter, the grid posterior ``exp(-(chi2 - min) / 2 scale)``'s marginal CDF on its axis."""
    w = np.exp(-0.5 * (c2 - c2.min()) / scale).reshape([len(a) for a in axes])
    margs = [w.sum(axis=tuple(k for k in range(len(axes)) if k != j)) for j in range(len(axes))]
    return [np.cumsum(m) / m.sum() for m in margs]


def _ranks(axes, c2, scale, theta) -> list[float]:
    """Per parameter, the marginal CDF at ``theta``: below 0.05 the value lies below the central 90 %
    interval, above 0.95 above it."""
    return [float(np.interp(theta[j], axes[j], c)) for j, c in enumerate(_marginal_cdfs(axes, c2, scale))]


def _beta_levels(u: np.ndarray, level: float = 0.90) -> tuple[float, float]:
    """The posterior CDF levels whose interval holds ``level`` of values with ranks ``u``: the quantiles of
    a Beta distribution fitted to ``u`` by moments (Rodrigues, Prangle & Sisson 2018's recalibration,
    smoothed because one twin has only 24 runs to estimate it from)."""
    u = np.clip(np.asarray(u, float), 1e-3, 1 - 1e-3)
    m, v = u.mean(), min(u.var(), 0.999 * u.mean() * (1 - u.mean()))
    k = m * (1 - m) / v - 1
    q = 0.5 * (1 - level)
    return float(stats.beta.ppf(q, m * k, (1 - m) * k)), float(stats.beta.ppf(1 - q, m * k, (1 - m) * k))


def recalibrated(twins: list[list[dict]], names, across: bool = False) -> dict:
    """The fraction of runs inside their recalibrated 90 % interval, the credible levels per parameter from
    the ranks (:func:`_beta_levels`) of the twin's other runs (``across`` False: leave one run out) or of
    every other twin's runs (``across`` True: leave one twin out, a correction learnt across twins)."""
    n, c50, base = len(names), stats.chi2.median(len(names)), PHASE_SCALES[0]
    per_twin = []
    for rows in twins:
        deltas = np.array([q["delta"][base] for q in rows])
        lams = [max(1.0, float(np.median(np.delete(deltas, i)) / c50)) for i in range(len(rows))]
        U = np.array([_ranks(r["axes"], r["c2"][base], lams[i], r["theta"]) for i, r in enumerate(rows)])
        per_twin.append((rows, lams, U))
    inside, total = np.zeros(n), 0
    for t, (rows, lams, U) in enumerate(per_twin):
        pooled = np.vstack([u for k, (_, _, u) in enumerate(per_twin) if k != t]) if across else None
        for i, r in enumerate(rows):
            for j, c in enumerate(_marginal_cdfs(r["axes"], r["c2"][base], lams[i])):
                a, b = _beta_levels(pooled[:, j] if across else np.delete(U[:, j], i))
                inside[j] += np.interp(a, c, r["axes"][j]) <= r["theta"][j] <= np.interp(b, c, r["axes"][j])
            total += 1
    return {p: round(float(inside[j]) / total, 3) for j, p in enumerate(names)}


def run_ranks(rows: list[dict]) -> list[list[float]]:
    """Per run of a twin, each parameter's marginal CDF at the run's value (``lambda`` of the other runs):
    what a correction learnt across twins is fitted to."""
    c50, base = stats.chi2.median(rows[0]["theta"].size), PHASE_SCALES[0]
    deltas = np.array([q["delta"][base] for q in rows])
    return [[round(u, 4) for u in _ranks(r["axes"], r["c2"][base],
                                          max(1.0, float(np.median(np.delete(deltas, i)) / c50)), r["theta"])]
            for i, r in enumerate(rows)]


def score(twins: list[list[dict]], names, lower, upper) -> dict:
    n = len(names)
    c50 = stats.chi2.median(n)
    base = PHASE_SCALES[0]
    by_mult = {m: np.zeros(n, int) for m in MULTIPLIERS}
    by_phase = {pair: np.zeros(n, int) for pair in PHASE_SCALES}
    below, above = np.zeros(n, int), np.zeros(n, int)
    quarters = np.zeros((n, 4, 2), int)  # per parameter and quarter of the box: runs, covered
    total = 0
    for rows in twins:
        for i, r in enumerate(rows):
            for pair in PHASE_SCALES:
                deltas = np.array([q["delta"][pair] for k, q in enumerate(rows) if k != i])
                lam = max(1.0, float(np.median(deltas) / c50))
                mults = MULTIPLIERS if pair == base else (1.0,)
                for m in mults:
                    u = np.array(_ranks(r["axes"], r["c2"][pair], lam * m, r["theta"]))
                    inside = (u >= 0.05) & (u <= 0.95)
                    if pair == base:
                        by_mult[m] += inside
                    if m == 1.0:
                        by_phase[pair] += inside
                    if pair == base and m == 1.0:
                        below += u < 0.05  # the run's value lies below its posterior's 90 % interval
                        above += u > 0.95
                        q = np.minimum(((r["theta"] - lower) / (upper - lower) * 4).astype(int), 3)
                        for j in range(n):
                            quarters[j, q[j]] += (1, int(inside[j]))
            total += 1
    frac = lambda c: {p: round(float(c[j]) / total, 3) for j, p in enumerate(names)}  # noqa: E731
    return {"runs": total, "twins": len(twins),
            "marginal_inside_90": {f"x{m:g}": frac(by_mult[m]) for m in MULTIPLIERS},
            "marginal_inside_90_phase_scales": {f"pre x{a:g} / post x{b:g}": frac(by_phase[(a, b)])
                                                for a, b in PHASE_SCALES},
            "marginal_inside_90_recalibrated_per_twin": recalibrated(twins, names),
            "marginal_inside_90_recalibrated_across_twins": recalibrated(twins, names, across=True),
            "misses_at_lambda": {p: {"value_below_interval": int(below[j]), "value_above_interval": int(above[j])}
                                 for j, p in enumerate(names)},
            "inside_90_by_box_quarter": {p: [{"runs": int(quarters[j, k, 0]),
                                              "inside": round(float(quarters[j, k, 1]) / max(1, quarters[j, k, 0]), 3)}
                                             for k in range(4)] for j, p in enumerate(names)}}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", required=True, nargs="+",
                    help="folder(s) of twin_<seed>.pkl from bench_emulated_likelihood --keep")
    args = ap.parse_args(argv)
    files = sorted(f for folder in args.keep for f in Path(folder).glob("twin_*.pkl"))
    if not files:
        raise SystemExit(f"--keep {' '.join(args.keep)}: no twin_*.pkl")
    started, twins, names = time.time(), [], None
    for f in files:
        seed = int(f.stem.split("_")[1])
        if seed // 1000 in (40, 41):
            raise SystemExit(f"{f}: seeds 40 and 41 are the coverage benchmark's: use development runs")
        spec, params, responses, analyses, obs, _reps = pickle.loads(f.read_bytes())
        names, lower, upper = list(spec.names), np.asarray(spec.lower, float), np.asarray(spec.upper, float)
        twins.append(twin_runs(spec, params, responses, analyses, obs, seed))
    print(json.dumps({"benchmark": "selfcal_marginals", "seeds": [int(f.stem.split("_")[1]) for f in files],
                      "grid": GRID, "cores": os.cpu_count(), "wall_s": round(time.time() - started, 1),
                      **score(twins, names, lower, upper),
                      "ranks_at_lambda": {str(int(f.stem.split("_")[1])): run_ranks(rows)
                                          for f, rows in zip(files, twins)}}, indent=1))


if __name__ == "__main__":
    main()
