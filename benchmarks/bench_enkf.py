"""Benchmark: one ensemble analysis, N = 100 members, m = 2,000 observations, 10 parameters, full
correlated observation error covariance, on one core. Target: under 0.5 s.

Prints one JSON object on stdout. Figures (seconds, median and min over repeats):

* ``esmda_sqexp_cold``: build the dense squared-exponential R (2000 x 2000) and its Cholesky factor,
  then one ES-MDA analysis (the headline figure: nothing cached).
* ``esmda_sqexp_warm``: one ES-MDA analysis with R already factorised (as in an iterative run).
* ``enkf_sqexp_localized_warm``: the paper's EnKF with a localization mask (the masked code path)
  and the spread-floor inflation.
* ``esmda_ar1``: ES-MDA with the AR(1) model (structured, O(m) products).
* ``esmda_sqexp_warm_20pct_dead``: ES-MDA with 20 members failed (replaced by draws).
* ``emulated_esmda_twin``: one analysis of the emulator-assisted ES-MDA at the size of the twin
  experiments' last one (100 runs of a 2-parameter, 101-sample curve; leave-one-out refits, 400 inner
  members, 8 inner steps). Not part of the headline: a different problem size.

Run: ``python benchmarks/bench_enkf.py``.
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, set before NumPy loads its BLAS

import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy  # noqa: E402

import enkf  # noqa: E402

N, M, N_PARAMS = 100, 2000, 10
REPEATS = 7
TARGET_S = 0.5


def _problem():
    rng = np.random.default_rng(0)
    lower, upper = np.full(N_PARAMS, 1.0), np.full(N_PARAMS, 3.0)
    P = enkf.latin_hypercube(lower, upper, N, rng)
    t = np.arange(M) * 0.8e-6
    basis = np.stack([np.sin((j + 1) * np.pi * t / t[-1]) * np.exp(-t / (40e-6 * (j + 1)))
                      for j in range(N_PARAMS)])
    Y = 1e7 * (P**1.5) @ basis + 1e5 * rng.standard_normal((N, M))
    d = 1e7 * (np.full(N_PARAMS, 2.0) ** 1.5) @ basis
    return enkf.BoxTransform(lower, upper), P, Y, d, t


def _emulated_twin_analysis():
    rng = np.random.default_rng(1)
    lower, upper = np.array([4e6, 200.0]), np.array([6e7, 2400.0])
    t = np.linspace(0.0, 1e-4, 101)
    X = enkf.latin_hypercube(lower, upper, 100, rng)
    t_f = 10e-6 + 1.5e-12 * X[:, :1]
    Y = 2.5e-1 * X[:, :1] * np.minimum(t / t_f, 1.0) * 0.5 * (1.0 - np.tanh((t - t_f) / (2e-6 + 6e-9 * X[:, 1:])))
    d = Y[0] + 1e5 * rng.standard_normal(t.size)
    err = enkf.DiagonalError(np.full(t.size, 1e5))
    latest = np.arange(100) >= 75
    return lambda: enkf.emulated_esmda_update(X, Y, latest, d, err, lower=lower, upper=upper, n_members=25,
                                              rng=2, times=t)


def _time(fn):
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"median_s": float(np.median(times)), "min_s": float(np.min(times))}


def main():
    tf, P, Y, d, t = _problem()
    sigma, ell = 2e5, 4e-6
    se = enkf.SquaredExponentialError(sigma, t, ell)
    ar1 = enkf.AR1Error(sigma, t, ell)
    mask = enkf.localization_mask(N_PARAMS, M, {j: slice(0, 200 * j) for j in range(1, N_PARAMS)})
    Y_dead = Y.copy()
    Y_dead[::5] = np.nan

    def cold():
        err = enkf.SquaredExponentialError(sigma, t, ell)
        enkf.esmda_update(P, Y, d, err, alpha=3.5, rng=1, transform=tf)

    figures = {
        "esmda_sqexp_cold": _time(cold),
        "esmda_sqexp_warm": _time(lambda: enkf.esmda_update(P, Y, d, se, alpha=3.5, rng=1, transform=tf)),
        "enkf_sqexp_localized_warm": _time(
            lambda: enkf.enkf_update(P, Y, d, se, rng=1, transform=tf, localization=mask)),
        "esmda_ar1": _time(lambda: enkf.esmda_update(P, Y, d, ar1, alpha=3.5, rng=1, transform=tf)),
        "esmda_sqexp_warm_20pct_dead": _time(
            lambda: enkf.esmda_update(P, Y_dead, d, se, alpha=3.5, rng=1, transform=tf)),
        "emulated_esmda_twin": _time(_emulated_twin_analysis()),
    }
    headline = figures["esmda_sqexp_cold"]["median_s"]
    print(json.dumps({
        "benchmark": "enkf_one_analysis",
        "n_members": N, "n_obs": M, "n_params": N_PARAMS,
        "covariance": "squared exponential, dense 2000 x 2000 (Cholesky), ell = 5 samples",
        "repeats": REPEATS,
        "threads": 1,
        "figures": figures,
        "headline_s": headline,
        "target_s": TARGET_S,
        "meets_target": bool(headline < TARGET_S),
        "machine": {"cpu_count": os.cpu_count(),
                    "affinity_cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
                    "processor": platform.processor() or platform.machine(),
                    "python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__},
    }, indent=2))


if __name__ == "__main__":
    main()
