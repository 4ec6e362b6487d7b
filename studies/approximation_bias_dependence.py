"""Does the approximation error's bias depend on the parameters? (Development diagnostic.)

    python studies/approximation_bias_dependence.py benchmarks/cache/coverage_v3/approx-24/pairs_*.json \
        > studies/results/approximation_bias_dependence.json

The approximation error (:mod:`enkf.approximation`) subtracts the pairs' mean difference ``fine -
coarse`` and carries their scatter about it as a covariance averaged over the prior. An *enhanced*
error model would instead predict the difference at each parameter point, e.g. ``a + B (log theta -
mean)``, and carry only what that leaves. It is worth having only if the parameters predict the
difference on pairs the fit has not seen. This script answers with leave-one-pair-out prediction
errors on the cached pairs (the model's training runs, no twin's truth or data read), per seed and
pooled: the constant offset against a linear and a quadratic model in ``log theta``, next to the part
of the scatter that is the two meshes' own variability, the ``(1 + 1/k)`` times the coarse runs' own
scatter that :func:`enkf.approximation.approximation_error` takes off (``coarse_variability:
subtracted``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from enkf.approximation import approximation_error  # noqa: E402


def load_pairs(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(design (n, p), fine (n, m), coarse (n, k, m))`` of a cached pairs file, failed pairs left out."""
    cached = json.loads(Path(path).read_text())
    design = np.array(cached["design"], float)
    Y = np.array(cached["curves"], float).reshape(design.shape[0], -1, len(cached["curves"][0]))
    ok = np.all(np.isfinite(Y), axis=(1, 2))
    return design[ok], Y[ok, 0], Y[ok, 1:]


def features(design: np.ndarray, order: int) -> np.ndarray:
    """Regressors in ``log theta`` centred on the pairs' mean: constant (0), linear (1), quadratic (2)."""
    z = np.log(design) - np.log(design).mean(axis=0)
    z = z / z.std(axis=0)
    cols = [np.ones(len(z))]
    if order >= 1:
        cols += list(z.T)
    if order >= 2:
        p = z.shape[1]
        cols += [z[:, i] * z[:, j] for i in range(p) for j in range(i, p)]
    return np.column_stack(cols)


def loo_rms(X: np.ndarray, E: np.ndarray) -> float:
    """RMS over pairs and times of the leave-one-pair-out prediction error of ``E`` by least squares on ``X``
    (the hat matrix's closed form: ``e_i / (1 - h_ii)``)."""
    H = X @ np.linalg.pinv(X)
    resid = E - H @ E
    loo = resid / (1.0 - np.diag(H))[:, None]
    return float(np.sqrt(np.mean(loo ** 2)))


def diagnose(design: np.ndarray, fine: np.ndarray, coarse: np.ndarray, times: np.ndarray) -> dict:
    """The leave-one-pair-out errors of the three models on pairs ``(fine (n, m), coarse (n, k, m))`` on ``times``."""
    k = coarse.shape[1]
    E = fine - coarse.mean(axis=1)
    info = approximation_error(fine, coarse, times, coarse_variability="subtracted")[2]
    out = {"n_pairs": int(E.shape[0]), "coarse_realizations": int(k),
           "meshes_own_rms_Pa": float(np.sqrt(1 + 1 / k) * info["coarse_variability_rms_Pa"])}
    for name, order in (("constant", 0), ("linear", 1), ("quadratic", 2)):
        out[f"loo_rms_{name}_Pa"] = loo_rms(features(design, order), E)
    out["linear_over_constant"] = out["loo_rms_linear_Pa"] / out["loo_rms_constant_Pa"]
    out["quadratic_over_constant"] = out["loo_rms_quadratic_Pa"] / out["loo_rms_constant_Pa"]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pairs", nargs="+", type=Path)
    args = ap.parse_args(argv)
    from benchmarks.bench_coverage import twin_experiment
    from calibration.observations import observation_grid

    o = twin_experiment()["observations"]
    t = observation_grid(o["t_start"], o["t_end"], o["dt"])
    sets = {p.stem: load_pairs(p) for p in sorted(args.pairs)}
    report = {"benchmark": "approximation_bias_dependence",
              "sources": [str(p.resolve().relative_to(ROOT)) if p.resolve().is_relative_to(ROOT) else str(p)
                          for p in sorted(args.pairs)],
              "cores": os.cpu_count(),
              "per_file": {name: diagnose(*s, t) for name, s in sets.items()}}
    report["pooled"] = diagnose(*(np.concatenate(parts) for parts in zip(*sets.values())), t)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
