"""Which model of the emulator's error lets the emulated likelihood cover? A development check of issue
30's ``E_t`` under-coverage (kept runs of development seeds; the coverage benchmark's seeds are refused).

The emulated likelihood ``N(d; em(theta), B + C_em)`` (``B = R + D``) models the emulator's leave-one-out
error at the latest runs as an AR(1) with one correlation time (``ar1``, today's); ``enkf.selfcal`` then
scales the covariance by one ``lambda``. Two alternatives: ``modes``
(:func:`modal_emulator_error`: the residuals' leading whole-curve modes, their number chosen
by leave-one-residual-out likelihood, with an AR(1) remainder) and ``hetero``
(:class:`enkf.hetero.HeteroscedasticError`: ``C_em`` scaled by a local average of every run's own
leave-one-out misfit, so the simulator's scatter may differ across the box). Per kept twin and per error
model, on a ``GRID`` x ``GRID`` grid of the box (uniform prior, exact for the emulated likelihood):

* the runs of the last iteration as data of known parameters (``enkf.selfcal.pseudo_runs``: the emulator
  of the other runs, a draw of the data's error): each parameter's 90 % marginal interval at ``lambda``
  of the other runs (the median rule) and whether the run's own value lies in it: no truth is read;
* the twin's truth in its 90 % marginal intervals at the twin's ``lambda`` (read after the runs' score,
  to see whether what the runs say carries over).

    python studies/bench_emulated_likelihood.py --seed 50 --twins 40 --which 0,...,11 --keep <folder>
    python studies/emulator_error_models.py --keep <folder> [<folder> ...] [--out <json>]
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
from scipy import linalg, stats

from calibration.experiment import all_runs
from calibration.model_error import stored_error
from enkf.covariance import DenseError
from enkf.emulated import emulator_error_model
from enkf.emulator import CurveEmulator, smoothed_emulator
from enkf.hetero import emulated_deviance
from shpb.atomic import emit_json

GRID = 81
BENCHMARK_SEEDS = (40, 41, 43, 45, 49, 53, 55)


def _gauss_logpdf(r: np.ndarray, C: np.ndarray) -> float:
    L = np.linalg.cholesky(C)
    w = np.linalg.solve(L, r)
    return float(-0.5 * w @ w - np.sum(np.log(np.diag(L))) - 0.5 * r.size * math.log(2 * math.pi))


def _modes_plus_ar1(R: np.ndarray, r: int, times, groups) -> np.ndarray:
    """``U diag(s^2 / k) U^T`` of the residuals' ``r`` leading (uncentred) singular directions, plus the
    AR(1) model of what they leave (dense)."""
    if r == 0:
        return emulator_error_model(R, times, groups)[0].dense()
    U, s, _ = np.linalg.svd(R.T, full_matrices=False)
    U, s = U[:, :r], s[:r]
    rest = R - (R @ U) @ U.T
    return (U * (s ** 2 / R.shape[0])) @ U.T + emulator_error_model(rest, times, groups)[0].dense()


def modal_emulator_error(residuals: np.ndarray, times, groups=None, max_modes: int = 6,
                         modes: int | None = None) -> tuple[DenseError, dict]:
    """The emulator's error as a few whole-curve modes plus an AR(1) remainder (the ``modes`` variant).

    Why: an AR(1) with one correlation time counts a departure that moves a whole rise (a mesh
    realization's stiffness) or a whole post-peak as many independent ones. The leading singular
    directions of the leave-one-out residuals carry such departures with their own variance, counted
    once. ``modes`` (default: chosen) is the number kept: the value in ``0 .. max_modes`` (at most
    ``k - 3``) with the highest leave-one-residual-out Gaussian log density.
    """
    R = np.array(residuals, dtype=float, ndmin=2)
    k = R.shape[0]
    top = max(0, min(int(max_modes), k - 3))
    scores = []
    if modes is None:
        for r in range(top + 1):
            scores.append(sum(_gauss_logpdf(R[i], _modes_plus_ar1(np.delete(R, i, axis=0), r, times, groups))
                              for i in range(k)))
        modes = int(np.argmax(scores))
    C = _modes_plus_ar1(R, int(modes), times, groups)
    return DenseError(C, _symmetric=True), {"modes": int(modes), "cv_log_density": scores,
                                            "rms": float(np.sqrt(np.mean(np.diag(C))))}


def _gaussian(C_em_of):
    """A likelihood ``N(d; em, B + C_em)`` with ``C_em = C_em_of(latest residuals)``: the deviance is chi2."""
    def build(em, X, latest, B, lo, hi):
        L = linalg.cholesky(B + C_em_of(em.loo_residuals()[latest]).dense(), lower=True)

        def deviance(P, y):
            w = linalg.solve_triangular(L, (em(np.atleast_2d(P)) - y).T, lower=True)
            return np.sum(w * w, axis=0)
        return deviance, {}
    return build


def _hetero(times, groups):
    """The workflow's heteroscedastic likelihood (:func:`enkf.hetero.emulated_deviance`)."""
    def build(em, X, latest, B, lo, hi):
        C_em = emulator_error_model(em.loo_residuals()[latest], times, groups)[0].dense()
        deviance, h = emulated_deviance(em, B, C_em, X, lo, hi)
        return deviance, {"bandwidth": h.bandwidth, "scale_range": [float(h.q.min()), float(h.q.max())]}
    return build


def _error_models(times, groups):
    return {"ar1": _gaussian(lambda r: emulator_error_model(r, times, groups)[0]),
            "modes": _gaussian(lambda r: modal_emulator_error(r, times, groups)[0]),
            "hetero": _hetero(times, groups)}


def _inside(axes, dev, theta, level=0.90):
    """Per parameter: (whether ``theta`` lies in the grid posterior's central ``level`` interval, its width);
    the posterior is ``exp(-dev / 2)``."""
    w = np.exp(-0.5 * (dev - dev.min())).reshape([len(a) for a in axes])
    q = 0.5 * (1 - level)
    res = []
    for j in range(len(axes)):
        m = w.sum(axis=tuple(k for k in range(len(axes)) if k != j))
        c = np.cumsum(m) / m.sum()
        a, b = np.interp(q, c, axes[j]), np.interp(1 - q, c, axes[j])
        res.append((bool(a <= theta[j] <= b), float(b - a)))
    return res


def twin(spec, params, responses, analyses, obs, truth, seed):
    names = list(spec.names)
    K = len(analyses) - 1
    X, Y, latest = all_runs(spec, params[:K + 1], responses[:K + 1], np.asarray(analyses[K]["alive"], bool))
    terms = stored_error(obs, analyses[K])
    lo, hi = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
    t, g = obs.time, obs.frame["record"].to_numpy(str)
    em, info = smoothed_emulator(X, Y, lo, hi, names, latest, spec.smoothing, terms.likelihood().std)
    axes = [np.linspace(lo[j], hi[j], GRID) for j in range(len(names))]
    G = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(names), -1).T
    c50 = stats.chi2.median(len(names))
    B = terms.emulated().dense()
    L_B = linalg.cholesky(B, lower=True)
    out = {"seed": seed, "truth": dict(zip(names, map(float, truth)))}
    for label, build in _error_models(t, g).items():
        # the runs of the last iteration as data of known parameters, as enkf.selfcal.pseudo_runs draws them
        rng, runs = np.random.default_rng(seed), []
        for i in np.flatnonzero(latest):
            keep = np.arange(X.shape[0]) != i
            em_i = CurveEmulator(X[keep], Y[keep], lo, hi, smoothing=info["smoothing"])
            dev_i, _ = build(em_i, X[keep], latest[keep], B, lo, hi)
            y = Y[i] + L_B @ rng.standard_normal(Y.shape[1])
            dv = dev_i(G, y)
            runs.append((X[i], dv, max(0.0, float(dev_i(X[i], y)[0]) - float(dv.min()))))
        deltas = np.array([r[2] for r in runs])
        # lambda is a learning rate 1 / lambda on the whole log-likelihood (a generalized posterior: the
        # log-determinant's information is over-counted as much as the quadratic form's)
        lams = [max(1.0, float(np.median(np.delete(deltas, i)) / c50)) for i in range(len(runs))]
        inside = [[c for c, _ in _inside(axes, dv / lams[i], theta)] for i, (theta, dv, _) in enumerate(runs)]
        lam = max(1.0, float(np.median(deltas) / c50))
        dev, extra = build(em, X, latest, B, lo, hi)
        tr = _inside(axes, dev(G, obs.values) / lam, truth)
        out[label] = {"lambda": lam, "runs_inside_90": dict(zip(names, np.mean(inside, axis=0).tolist())),
                      "truth_inside_90": {p: tr[j][0] for j, p in enumerate(names)},
                      "width_90_over_box": {p: tr[j][1] / (hi[j] - lo[j]) for j, p in enumerate(names)}, **extra}
        if label == "modes":
            out[label]["modes"] = modal_emulator_error(em.loo_residuals()[latest], t, g)[1]["modes"]
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep", required=True, nargs="+", help="folder(s) of twin_<seed>.pkl")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    files = sorted(f for folder in args.keep for f in Path(folder).glob("twin_*.pkl"))
    if not files:
        raise SystemExit(f"--keep {' '.join(args.keep)}: no twin_*.pkl")
    started, rows = time.time(), []
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.bench_coverage import truths, twin_experiment
    from calibration.experiment import ExperimentSpec
    spec0 = ExperimentSpec.from_config("twin_ref", twin_experiment())
    for f in files:
        seed = int(f.stem.split("_")[1])
        if seed // 1000 in BENCHMARK_SEEDS:
            raise SystemExit(f"{f}: seed {seed // 1000} is the coverage benchmark's: use development runs")
        spec, params, responses, analyses, obs, _reps = pickle.loads(f.read_bytes())
        truth = truths(40, spec0.lower, spec0.upper, seed // 1000)[seed % 1000]
        rows.append(twin(spec, params, responses, analyses, obs, truth, seed))
        print({k: (v if not isinstance(v, dict) else {a: b for a, b in v.items() if a != "truth"})
               for k, v in rows[-1].items() if k != "truth"}, flush=True)
    names = list(rows[0]["truth"])
    summary = {label: {"runs_inside_90": {p: float(np.mean([r[label]["runs_inside_90"][p] for r in rows]))
                                          for p in names},
                       "truth_inside_90": {p: int(sum(r[label]["truth_inside_90"][p] for r in rows)) for p in names},
                       "median_width_90_over_box": {p: float(np.median([r[label]["width_90_over_box"][p]
                                                                        for r in rows])) for p in names},
                       "median_lambda": float(np.median([r[label]["lambda"] for r in rows]))}
               for label in ("ar1", "modes", "hetero")}
    return emit_json({"benchmark": "emulator_error_models", "cores": os.cpu_count(), "grid": GRID,
                      "twins": len(rows), "wall_s": round(time.time() - started, 1), "summary": summary,
                      "rows": rows}, args.out)


if __name__ == "__main__":
    main()
