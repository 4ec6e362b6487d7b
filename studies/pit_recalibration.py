"""Can a twin's own runs correct the reported posterior's shift? Quantile recalibration from the
pseudo-runs (issue 52).

The reported posterior (the power-tempered emulated likelihood, ``lambda`` from :mod:`enkf.selfcal`)
puts ``sigma_t``'s median a few per cent above the truth on well-specified twins, and its SBC ranks fail
(``studies/tempering_forms.py``: the deviance rises faster towards low ``sigma_t`` than towards high, and
dividing it by ``lambda`` turns that into a long upper tail). ``lambda`` calibrates the posterior's
*scale* on the simulator's own runs taken as data (each last-iteration run, its curve plus a noise draw,
on the emulator of the other runs). The same pseudo-runs can calibrate its *location*: the
probability integral transform (PIT) of run ``i``'s known parameters under its own tempered posterior,
``u_ij = F_j^(i)(theta_ij)``, is uniform when the posterior is calibrated. With
``z_ij = Phi^-1(u_ij)`` and their mean ``mu_j`` and standard deviation ``s_j`` over the runs, the
recalibrated quantile at level ``q`` is the tempered posterior's quantile at level
``Phi(mu_j + s_j Phi^-1(q))`` (Kuleshov et al. 2018's quantile recalibration, here per experiment on its
own runs; ``location``: ``s_j = 1``).

This study reads each development twin's density exactly on a grid over the box (the kept runs and
refinement batch of ``benchmarks/bench_coverage.py --keep-runs``; the emulator, AR(1) error and
``lambda`` as :mod:`enkf.ces` builds them), computes every pseudo-run's PIT on the same grid, and scores
the twins' truths under the grid posterior as it is (``power``) and recalibrated (``location``,
``location_scale``): coverage of the 50 % and 90 % intervals, the KS p-value of the truths' PITs (SBC's
rank test in the limit of many draws), the WIS over the prior's, the median's ratio to the truth.

Two more forms read the same grid. ``randomized``: the power posterior at the data moved by one draw of
``(lambda - 1) C`` noise, data whose error is the ``lambda C`` the tempered likelihood assumes (its
credible sets then cover under that model, at the price of a location jitter); ``bagged``: the mixture
of 16 such posteriors. ``untempered`` is the likelihood with ``lambda`` = 1, for reference.

Run: ``python studies/pit_recalibration.py --kept KEEP --seed S --twins N --out studies/results/...``
(about 1 min per twin on one core; the kept runs are not in the repository:
``bench_coverage.py --seed S --twins N --misspecified M --keep-runs KEEP`` makes them).

What it found on development seeds 70 and 72 (16 well-specified twins each, 11 of them below 40 MPa;
no benchmark twin re-scored): the grid reads the shipped posterior (its quantiles a median 1.6 % and
1.2 % of the 90 % width from emcee's). Below 40 MPa the power form's median sits above the truth in 9
of 11 twins on both seeds (the one-posterior benchmark: 53 of 64); untempered, 7 and 8 of 11, so the
tempering makes part of the shift and the rest is the likelihood's own. The pseudo-runs' PITs are
noisy (their mean probit ``mu`` spans -0.57 to 0.35 over the twins, 25 runs each) and recalibrating by
them brings the share to 7 and 8 of 11 without changing the score: ``sigma_t``'s WIS over the prior's
0.249 -> 0.242 and 0.234 -> 0.238 (location), 0.243 and 0.231 (location and scale), ``E_t``'s 0.734 ->
0.771 and 0.698 -> 0.674. The randomized data and their mixture score worse (``sigma_t`` 0.288 / 0.355
randomized, 0.277 / 0.290 bagged): the location jitter they add costs more than the shift. Nothing
adopted: none of these moves ``sigma_t``'s WIS by more than the seeds' difference, so none is worth a
fresh benchmark run.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import truths, twin_experiment  # noqa: E402
from calibration.experiment import ExperimentSpec  # noqa: E402
from enkf.scores import QUANTILES, prior_expected_wis, weighted_interval_score  # noqa: E402
from enkf.selfcal import pseudo_runs  # noqa: E402
from studies.sigma_t_bias import write  # noqa: E402
from studies.tempering_forms import deviance, kept_posterior, whitener  # noqa: E402

GRID = 121
FORMS = ("power", "location", "location_scale", "randomized", "bagged", "untempered")
# where the one-posterior benchmark's sigma_t median sits high (README): truths below this
LOW_SIGMA_T = 40e6
# the randomized form's mixture size
BAGS = 16
# PITs are clipped away from 0 and 1 before the probit: a run at the box's edge has a PIT of 0 or 1 on
# the grid, which would put an infinite z into the mean
PIT_CLIP = 0.005
# the pseudo-runs' noise draws: a stream of the twin's seed of this study's own
PIT_STREAM = 52


def kept_twin(keep: Path, kind: str, i: int, seed: int):
    """``(whiten, d, lambda, lo, hi, pseudo)`` of a kept twin: ``whiten(P, y)`` the residuals on the full
    emulator whitened by its covariance (the untempered deviance is their squared norm), ``pseudo`` a list of ``(theta_i, chi2_i, y_i)``,
    each pseudo-run's parameters, deviance on the emulator of the other runs and data (its curve plus a
    noise draw)."""
    k = kept_posterior(keep, i, seed, kind)
    C = k.terms.emulated().dense() + k.error_model(k.em.loo_residuals()[k.latest]).dense()
    whiten = whitener(k.em, C)
    pseudo = [(k.X[j], deviance(em_j, C_j), y_j)
              for j, em_j, C_j, y_j in pseudo_runs(k.X, k.Y, k.latest, k.terms.emulated(), lower=k.lo, upper=k.hi,
                                                     smoothing=k.smoothing, error_model=k.error_model,
                                                     rng=np.random.default_rng([int(k.spec.seed), PIT_STREAM]))]
    return whiten, k.d, k.lam, k.lo, k.hi, pseudo


def grid_weights(chi2_grid: np.ndarray, lam: float) -> np.ndarray:
    """The power-tempered posterior's cell probabilities, the density taken constant over each cell (a
    uniform prior on the box)."""
    logp = -0.5 * chi2_grid / lam
    w = np.exp(logp - logp.max())
    return w / w.sum()


def cdfs_of(w: np.ndarray):
    """The marginal CDFs of cell probabilities ``w`` on the grid's cell edges: ``(cdf_0, cdf_1)``."""
    return tuple(np.concatenate([[0.0], np.cumsum(w.sum(axis=1 - a))]) for a in (0, 1))


def marginal_cdfs(chi2_grid: np.ndarray, lam: float):
    return cdfs_of(grid_weights(chi2_grid, lam))


def randomized_weights(W: np.ndarray, lam: float, z: np.ndarray) -> np.ndarray:
    """The power posterior at data moved by ``(lambda - 1) C``-distributed noise (``z`` standard normal,
    one row per draw; several rows: the mixture of their posteriors): data whose error is the ``lambda C``
    the tempered likelihood assumes, so that its credible sets cover under that error model."""
    out = 0.0
    for zb in np.atleast_2d(z):
        V = W - np.sqrt(max(lam - 1.0, 0.0)) * zb
        out = out + grid_weights(np.einsum("ij,ij->i", V, V).reshape(GRID, GRID), lam)
    return out / np.atleast_2d(z).shape[0]


def cdf_at(cdf: np.ndarray, edges: np.ndarray, x: float) -> float:
    return float(np.interp(x, edges, cdf))


def quantile_at(cdf: np.ndarray, edges: np.ndarray, q: float) -> float:
    # the CDF is non-decreasing; cells of zero mass make flat stretches, which interp resolves leftmost
    return float(np.interp(q, cdf, edges))


def recalibration(pits: np.ndarray) -> dict:
    """``{form: (mu, s)}`` from the pseudo-runs' PITs of one parameter."""
    z = stats.norm.ppf(np.clip(pits, PIT_CLIP, 1.0 - PIT_CLIP))
    mu, s = float(np.mean(z)), float(np.std(z, ddof=1))
    return {"power": (0.0, 1.0), "location": (mu, 1.0), "location_scale": (mu, s)}


def grid_of(lo, hi):
    """``(edges, P)``: the grid's cell edges per parameter and its cell centres (GRID^2, 2)."""
    edges = [np.linspace(lo[a], hi[a], GRID + 1) for a in (0, 1)]
    mids = [0.5 * (e[1:] + e[:-1]) for e in edges]
    return edges, np.column_stack([g.ravel() for g in np.meshgrid(*mids, indexing="ij")])


def study_twin(keep: Path, kind: str, i: int, seed: int, truth: np.ndarray) -> dict:
    whiten, d, lam, lo, hi, pseudo = kept_twin(keep, kind, i, seed)
    edges, P = grid_of(lo, hi)
    W = whiten(P, d)
    cdfs = marginal_cdfs(np.einsum("ij,ij->i", W, W).reshape(GRID, GRID), lam)
    z_rng = np.random.default_rng([seed, i, PIT_STREAM])
    extra = {"untempered": marginal_cdfs(np.einsum("ij,ij->i", W, W).reshape(GRID, GRID), 1.0),
             "randomized": cdfs_of(randomized_weights(W, lam, z_rng.standard_normal((1, W.shape[1])))),
             "bagged": cdfs_of(randomized_weights(W, lam, z_rng.standard_normal((BAGS, W.shape[1]))))}
    pits_runs = np.array([[cdf_at(c, edges[a], th[a]) for a, c in enumerate(marginal_cdfs(chi2(P, y).reshape(GRID, GRID), lam))]
                          for th, chi2, y in pseudo])
    names = ("sigma_t", "E_t")
    out = {"seed": 1000 * seed + i, "kind": kind, "lambda": lam, "truth": dict(zip(names, map(float, truth))),
           "pseudo_runs": len(pseudo), "forms": {}}
    for a, name in enumerate(names):
        maps = recalibration(pits_runs[:, a])
        pit = cdf_at(cdfs[a], edges[a], truth[a])
        width = hi[a] - lo[a]
        for form, (mu, s) in maps.items():
            q = {k: quantile_at(cdfs[a], edges[a], stats.norm.cdf(mu + s * stats.norm.ppf(level)))
                 for k, level in QUANTILES.items()}
            u = float(stats.norm.cdf((stats.norm.ppf(np.clip(pit, 1e-12, 1 - 1e-12)) - mu) / s))
            out["forms"].setdefault(form, {})[name] = {
                "pit": u, "mu": mu, "s": s, **q,
                "wis_over_width": float(weighted_interval_score(q, truth[a])) / width,
                "median_over_truth": q["q50"] / float(truth[a])}
        for form, c in extra.items():
            q = {k: quantile_at(c[a], edges[a], level) for k, level in QUANTILES.items()}
            out["forms"].setdefault(form, {})[name] = {
                "pit": cdf_at(c[a], edges[a], truth[a]), **q,
                "wis_over_width": float(weighted_interval_score(q, truth[a])) / width,
                "median_over_truth": q["q50"] / float(truth[a])}
        out["forms"]["power"][name]["pseudo_pit_mean"] = float(np.mean(pits_runs[:, a]))
    return out


def summarise(rows: list[dict]) -> dict:
    prior = {n: prior_expected_wis(0.0, 1.0) for n in ("sigma_t", "E_t")}
    out = {}
    for form in FORMS:
        out[form] = {}
        for n in ("sigma_t", "E_t"):
            r = [row["forms"][form][n] for row in rows]
            truth = np.array([row["truth"][n] for row in rows])
            pit = np.array([x["pit"] for x in r])
            out[form][n] = {
                "coverage_90": float(np.mean([(x["q05"] <= t <= x["q95"]) for x, t in zip(r, truth)])),
                "coverage_50": float(np.mean([(x["q25"] <= t <= x["q75"]) for x, t in zip(r, truth)])),
                "pit_ks_p": float(stats.kstest(pit, "uniform").pvalue),
                "pit_mean": float(pit.mean()),
                "wis_over_prior": float(np.mean([x["wis_over_width"] for x in r]) / prior[n]),
                "median_over_truth_median": float(np.median([x["median_over_truth"] for x in r])),
                "median_above_truth_share": float(np.mean([x["median_over_truth"] > 1.0 for x in r]))}
    return out


def grid_against_sampler(rows: list[dict], cache: Path, kind: str, seed: int) -> dict:
    """How far the grid's power-form quantiles lie from the sampled posterior's (``emcee``, as
    bench_coverage.py recorded it), per twin and parameter the largest quantile difference over the sampled
    90 % interval's width: the grid reads the shipped posterior if this is small."""
    diffs = []
    for r in rows:
        rec = json.loads((cache / f"{kind}_{seed}_{r['seed'] % 1000:03d}.json").read_text())["emulator_mcmc"]["params"]
        for name in ("sigma_t", "E_t"):
            g, e = r["forms"]["power"][name], rec[name]
            diffs.append(max(abs(g[k] - e[k]) for k in QUANTILES) / (e["q95"] - e["q05"]))
    return {"median_of_largest_quantile_difference_over_width": float(np.median(diffs)),
            "largest": float(np.max(diffs))}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kept", required=True, help="bench_coverage.py --keep-runs folder of the seed's twins")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--twins", type=int, default=16)
    ap.add_argument("--misspecified", type=int, default=0)
    ap.add_argument("--cache", default=None,
                    help="bench_coverage.py's cache folder of the same twins: the grid's power-form quantiles are "
                         "compared with the sampled ones it recorded")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    spec = ExperimentSpec.from_config("twin_ref", twin_experiment())
    keep = Path(args.kept)
    out = {"study": "pit_recalibration", "what": __doc__.split("\n\n")[1].replace("\n", " "), "seed": args.seed,
           "grid": GRID, "sets": {}}
    # the misspecified set's truths and seed offset as bench_coverage.py draws them
    for kind, n, seed in (("well_specified", args.twins, args.seed), ("misspecified", args.misspecified, args.seed + 1)):
        rows = []
        for i, truth in enumerate(truths(n, spec.lower, spec.upper, seed) if n else []):
            if not (keep / f"{kind}_{seed}_{i:03d}.refine.pkl").exists():
                continue
            rows.append(study_twin(keep, kind, i, seed, truth))
            f = rows[-1]["forms"]
            print(f"{kind} {i}: " + ", ".join(f"{k} {f[k]['sigma_t']['median_over_truth']:.3f}" for k in FORMS)
                  + f"  mu {f['location']['sigma_t']['mu']:.2f} s {f['location_scale']['sigma_t']['s']:.2f}",
                  file=sys.stderr, flush=True)
        if rows:
            low = [r for r in rows if r["truth"]["sigma_t"] < LOW_SIGMA_T]
            out["sets"][kind] = {"twins": len(rows), "summary": summarise(rows),
                                 "twins_below_40MPa": len(low),
                                 "summary_below_40MPa": summarise(low) if low else None,
                                 "rows": rows}
            if args.cache:
                out["sets"][kind]["grid_against_sampler"] = grid_against_sampler(rows, Path(args.cache), kind, seed)
    return write(out, args.out)


if __name__ == "__main__":
    main()
