"""Where an ES-MDA ensemble's intervals fail on a bounded prior, and where the exact posterior's hold: a
stand-in with a known posterior, no FDEM.

The emulated ES-MDA (``enkf.emulated``) draws each next ensemble from an inner ES-MDA on the emulator:
400 members from a Latin hypercube of the prior box, 8 steps, in the box transform's unbounded space.
ES-MDA is exact for a linear-Gaussian problem; a uniform box prior seen through a logit is neither
Gaussian nor, where the data say little, far from its bounds. This benchmark runs that inner ES-MDA on
the *exact* forward model of a two-parameter stand-in of the disc's curve (a strength-driven rise to a
failure time, then a softening whose duration grows with the fracture energy: the data say little about
the second parameter, as about ``E_t``), and compares its 90 % intervals with those of the exact
posterior (the box prior times the Gaussian likelihood on a 281 x 281 grid, refined over the region that
holds the mass: what a converged MCMC on a perfect emulator gives), over truths drawn uniformly from the whole box. The same noise draw and truth
serve both. Reported per parameter: 90 % coverage with binomial 95 % intervals, separately for truths in
the lowest or highest fifth of the box and in the middle three fifths, and the mean's pull toward the box
centre.

    python studies/bench_box_end_coverage.py --twins 150 --noise 0.05 --transform logit

Prints one JSON object (``--out`` writes it). Seconds to minutes on one core.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from enkf.covariance import DiagonalError  # noqa: E402
from enkf.emulated import esmda_alphas  # noqa: E402
from enkf.loop import assimilate  # noqa: E402
from enkf.sampling import latin_hypercube  # noqa: E402
from enkf.transforms import BoxTransform  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

NAMES = ("sigma_t", "E_t")
LOWER, UPPER = np.array([4e6, 200.0]), np.array([6e7, 2400.0])   # the Table 2 box
TIME = np.linspace(0.0, 160e-6, 161)                              # the default twin's window and grid
MEMBERS, STEPS = 400, 8                                           # enkf.emulated's inner ES-MDA defaults


def forward(P: np.ndarray) -> np.ndarray:
    """(N, 2) -> (N, 161): rise to a failure time that grows with strength, then an exponential softening
    whose time constant grows with the fracture energy (and shrinks with strength)."""
    P = np.atleast_2d(P)
    s, e = P[:, :1], P[:, 1:]
    tp = 40e-6 + 60e-6 * (s / 6e7) ** 0.5
    rise = 0.6 * s * np.clip(TIME / tp, 0.0, 1.0) ** 1.5
    tau = 5e-6 + 40e-6 * (e / 2400.0) ** 0.7 * (2e7 / (s + 1e7))
    post = 0.6 * s * np.exp(-np.clip(TIME - tp, 0.0, None) / tau)
    return np.where(TIME < tp, rise, post)


def _grid(lo, hi, n):
    g = [np.linspace(lo[j], hi[j], n) for j in range(lo.size)]
    return np.array(np.meshgrid(*g, indexing="ij")).reshape(lo.size, -1).T


def _weights(G, d, sigma, F=None):
    ll = -0.5 * np.sum((((forward(G) if F is None else F) - d) / sigma) ** 2, axis=1)
    w = np.exp(ll - ll.max())
    return w / w.sum()


def _grid_quantiles(G, F, d, sigma, qs=(0.05, 0.95), n=281):
    """The exact posterior's quantiles and mean: the box prior times the likelihood on the box's grid,
    then on a grid of the same size over the region that holds its mass (one cell of the first grid
    around every point above 1e-12 of the largest weight), so that a narrow posterior is resolved."""
    w = _weights(G, d, sigma, F)
    keep = G[w > 1e-12 * w.max()]
    cell = (UPPER - LOWER) / (n - 1)
    lo, hi = np.maximum(keep.min(axis=0) - cell, LOWER), np.minimum(keep.max(axis=0) + cell, UPPER)
    G = _grid(lo, hi, n)
    w = _weights(G, d, sigma)
    out = []
    for j in range(G.shape[1]):
        order = np.argsort(G[:, j], kind="stable")
        cw = np.cumsum(w[order])
        out.append([G[order, j][min(np.searchsorted(cw, q), cw.size - 1)] for q in qs] + [float(w @ G[:, j])])
    return np.array(out)   # (n, 3): q05, q95, mean


def _cover(flags: np.ndarray) -> dict:
    k, n = int(flags.sum()), int(flags.size)
    if n == 0:
        return {"n": 0}
    ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
    return {"n": n, "coverage_90": k / n, "ci95": [float(ci.low), float(ci.high)],
            "p_vs_0.90": float(stats.binomtest(k, n, 0.9).pvalue)}


def run(twins: int, noise: float, transform: str, seed: int, members: int = MEMBERS, steps: int = STEPS,
        grid: int = 281) -> dict:
    rng = np.random.default_rng(seed)
    G = _grid(LOWER, UPPER, grid)
    FG = forward(G)
    truths = LOWER + (UPPER - LOWER) * rng.uniform(size=(twins, 2))
    rows = []
    for theta in truths:
        y0 = forward(theta)[0]
        sigma = noise * np.abs(y0).max() * np.ones_like(TIME)
        d = y0 + sigma * rng.standard_normal(TIME.size)
        res = assimilate(forward, latin_hypercube(LOWER, UPPER, members, rng), d, DiagonalError(sigma),
                         rng=rng, method="esmda", alphas=esmda_alphas(steps),
                         transform=BoxTransform(LOWER, UPPER, kind=transform))
        P = res.params[res.alive]
        ens = np.column_stack([np.quantile(P, 0.05, axis=0), np.quantile(P, 0.95, axis=0), P.mean(axis=0)])
        rows.append({"truth": theta, "esmda": ens, "exact": _grid_quantiles(G, FG, d, sigma, n=grid)})
    out = {}
    for j, p in enumerate(NAMES):
        frac = np.array([(r["truth"][j] - LOWER[j]) / (UPPER[j] - LOWER[j]) for r in rows])
        ends = (frac < 0.2) | (frac > 0.8)
        res = {}
        for arm in ("esmda", "exact"):
            lo_, hi_, mean = (np.array([r[arm][j, c] for r in rows]) for c in range(3))
            t = np.array([r["truth"][j] for r in rows])
            inside = (lo_ <= t) & (t <= hi_)
            centre = 0.5 * (LOWER[j] + UPPER[j])
            toward = np.sign(mean - t) == np.sign(centre - t)
            res[arm] = {"all": _cover(inside), "box_ends": _cover(inside[ends]), "middle": _cover(inside[~ends]),
                        "box_end_means_pulled_toward_centre": float(np.mean(toward[ends])),
                        "width_over_box_median": float(np.median((hi_ - lo_) / (UPPER[j] - LOWER[j])))}
        out[p] = res
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--twins", type=int, default=150)
    ap.add_argument("--noise", type=float, default=0.05, help="noise sd over the truth's peak stress")
    ap.add_argument("--transform", choices=["logit", "probit"], default="logit")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    started = time.time()
    result = {"benchmark": "bench_box_end_coverage", "twins": args.twins, "noise_rel_peak": args.noise,
              "transform": args.transform, "seed": args.seed, "inner_members": MEMBERS, "inner_steps": STEPS,
              "params": run(args.twins, args.noise, args.transform, args.seed),
              "wall_s": time.time() - started, "cores": os.cpu_count()}
    return emit_json(result, args.out)


if __name__ == "__main__":
    main()
