"""A self-calibration factor per parameter, tried on development twins (issue 52).

``studies/selfcal_axes.py`` found that the one factor ``lambda`` of the reported posterior (the emulated
log-likelihood divided by it, :mod:`enkf.selfcal`) widens ``sigma_t`` more and ``E_t`` less than each axis'
own pseudo-runs ask for. Here each axis gets its own factor from the same pseudo-runs: ``lambda_p`` is the
median over the runs of the profile likelihood ratio at the run's own value of parameter ``p`` (the other
parameter profiled out), over chi-square(1)'s median, at least 1. Two forms read it:

* ``axes_marginal``: parameter ``p``'s interval is the marginal of the likelihood divided by ``lambda_p``
  (each marginal from its own generalized posterior, the box's uniform prior kept);
* ``axes_stretch``: the reported (power) posterior's marginal quantiles stretched about its median by
  ``sqrt(lambda_p / lambda)``, kept inside the box.

Every form is read on an exact grid over the box from the kept runs of ``benchmarks/bench_coverage.py
--keep-runs`` (``studies/pit_recalibration.py``'s reading, which matches the sampler), scored against the
truths as the harness scores (coverage, the truths' PIT KS p-value, WIS over the prior's) and split by the
product's ``uninformative`` flag (:func:`benchmarks.scores.product_flag_split`).

Run: ``python studies/axes_forms.py --kept KEEP --seed S --twins N --out studies/results/axes_forms_devS.json``
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import truths, twin_experiment  # noqa: E402
from benchmarks.scores import product_flag_split  # noqa: E402
from calibration.experiment import ExperimentSpec  # noqa: E402
from enkf.scores import QUANTILES, prior_expected_wis, weighted_interval_score  # noqa: E402
from studies.pit_recalibration import (GRID, cdf_at, cdfs_of, grid_of, grid_weights, kept_twin,  # noqa: E402
                                       quantile_at)
from studies.sigma_t_bias import write  # noqa: E402

FORMS = ("power", "axes_marginal", "axes_stretch")
NAMES = ("sigma_t", "E_t")


def axis_lambdas(pseudo, P: np.ndarray) -> list[float]:
    """Each axis' factor from the pseudo-runs, on the grid: the profile over the other axis at the run's own
    value of this one (its nearest grid column) against the grid's least deviance."""
    deltas = [[], []]
    mids = [np.unique(P[:, a]) for a in (0, 1)]
    for theta, chi2, y in pseudo:
        g = chi2(P, y).reshape(GRID, GRID)
        least = g.min()
        for a in (0, 1):
            k = int(np.argmin(np.abs(mids[a] - theta[a])))
            line = g[k, :] if a == 0 else g[:, k]
            deltas[a].append(max(0.0, float(line.min()) - least))
    return [max(1.0, float(np.median(d) / stats.chi2.median(1))) for d in deltas]


def study_twin(keep: Path, kind: str, i: int, seed: int, truth: np.ndarray) -> dict:
    whiten, d, lam, lo, hi, pseudo = kept_twin(keep, kind, i, seed)
    edges, P = grid_of(lo, hi)
    W = whiten(P, d)
    chi2 = np.einsum("ij,ij->i", W, W).reshape(GRID, GRID)
    lam_axes = axis_lambdas(pseudo, P)
    power = grid_weights(chi2, lam)
    out = {"seed": 1000 * seed + i, "kind": kind, "lambda": lam, "lambda_axes": dict(zip(NAMES, lam_axes)),
           "truth": dict(zip(NAMES, map(float, truth))), "forms": {f: {} for f in FORMS}}
    for a, name in enumerate(NAMES):
        c_power = cdfs_of(power)[a]
        c_axis = cdfs_of(grid_weights(chi2, lam_axes[a]))[a]
        q_power = {k: quantile_at(c_power, edges[a], lv) for k, lv in QUANTILES.items()}
        f = np.sqrt(lam_axes[a] / lam)
        stretched = {k: float(np.clip(q_power["q50"] + f * (v - q_power["q50"]), lo[a], hi[a]))
                     for k, v in q_power.items()}
        for form, q, pit in (
                ("power", q_power, cdf_at(c_power, edges[a], truth[a])),
                ("axes_marginal", {k: quantile_at(c_axis, edges[a], lv) for k, lv in QUANTILES.items()},
                 cdf_at(c_axis, edges[a], truth[a])),
                ("axes_stretch", stretched, None)):
            out["forms"][form][name] = {**q, "pit": pit,
                                        "wis_over_width": float(weighted_interval_score(q, truth[a])) / (hi[a] - lo[a])}
    return out


def summarise(rows: list[dict], lo, hi) -> dict:
    out = {}
    for form in FORMS:
        out[form] = {}
        for a, n in enumerate(NAMES):
            r = [row["forms"][form][n] for row in rows]
            t = np.array([row["truth"][n] for row in rows])
            pit = [x["pit"] for x in r if x["pit"] is not None]
            split = product_flag_split(r, t, float(lo[a]), float(hi[a]))
            out[form][n] = {
                "coverage_90": float(np.mean([x["q05"] <= y <= x["q95"] for x, y in zip(r, t)])),
                "coverage_50": float(np.mean([x["q25"] <= y <= x["q75"] for x, y in zip(r, t)])),
                "pit_ks_p": float(stats.kstest(pit, "uniform").pvalue) if len(pit) == len(r) else None,
                "wis_over_prior": float(np.mean([x["wis_over_width"] for x in r]) / prior_expected_wis(0.0, 1.0)),
                "informative": {"covered": split["informative"].get("coverage_90", {}).get("covered"),
                                "n": split["informative"]["n"]}}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kept", required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--twins", type=int, default=16)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    spec = ExperimentSpec.from_config("twin_ref", twin_experiment())
    keep = Path(args.kept)
    rows = []
    for i, truth in enumerate(truths(args.twins, spec.lower, spec.upper, args.seed)):
        if not (keep / f"well_specified_{args.seed}_{i:03d}.refine.pkl").exists():
            continue
        rows.append(study_twin(keep, "well_specified", i, args.seed, truth))
        print(f"twin {i}: lambda {rows[-1]['lambda']:.2f} axes {rows[-1]['lambda_axes']}", file=sys.stderr, flush=True)
    out = {"study": "axes_forms", "what": __doc__.split("\n\n")[1].replace("\n", " "), "seed": args.seed,
           "grid": GRID, "twins": len(rows), "summary": summarise(rows, spec.lower, spec.upper), "rows": rows}
    return write(out, args.out)


if __name__ == "__main__":
    main()
