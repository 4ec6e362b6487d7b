"""What the coverage benchmark's twins whose 90 % interval misses the truth have in common.

    python studies/coverage_misses.py > benchmarks/results/coverage_misses_<date>.json

Reads the cached well-specified twin records of ``benchmarks/bench_coverage.py``
(default ``benchmarks/cache/coverage_v2/well_specified_40_*.json``) and prints one JSON object: per parameter,
every miss (truth, its place in the prior box, the 90 % interval, the side the truth is on, the
interval's relative half-width, the stop, the chi^2 and the estimated discrepancy) and misses against
covers (medians with Mann-Whitney p, Fisher exact tests, a binomial test of the side, the posterior
mean's error) and the coverage a calibrated posterior would give to the intervals: 0.90 for the
prediction intervals of one more draw the workflow reports now (``--intervals prediction``), 0.90 (n - 1)
/ (n + 1) for the members' sample 5-95 % quantiles it reported until 2026-11-25 (``--intervals
sample_quantiles``, the ``coverage`` cache).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / "cache" / "coverage_v2"
#: What a calibrated posterior's interval covers: ``--intervals``.
INTERVALS = ("prediction", "sample_quantiles")

def _benchmark():
    """benchmarks/bench_coverage.py, whose twins these are (imported from the checkout)."""
    import sys
    sys.path.insert(0, str(ROOT))
    from benchmarks import bench_coverage
    return bench_coverage


def _box() -> dict:
    """The twins' prior box: the twin_ref experiment of config/config.yaml, as the benchmark reads it."""
    from calibration.experiment import ExperimentSpec
    bc = _benchmark()
    spec = ExperimentSpec.from_config(bc.EXPERIMENT, bc.twin_experiment())
    return {p: (float(lo), float(hi)) for p, lo, hi in zip(spec.names, spec.lower, spec.upper)}


NUMERIC = ("truth_box_fraction", "distance_to_bound", "other_truth_box_fraction", "sigma_t_truth", "E_t_truth",
           "half_width_rel", "width_over_box", "reported_iteration", "stop_chi2_per_obs", "median_chi2_per_obs",
           "disc_sigma_over_noise", "disc_sigma_pre_over_noise", "disc_sigma_post_over_noise", "disc_corr_time_us")


def load_records(cache: Path = CACHE, pattern: str = "well_specified_40_*.json") -> list:
    return [json.loads(f.read_text()) for f in sorted(Path(cache).glob(pattern))]


def _discrepancy(rec: dict) -> dict:
    recs = (rec.get("discrepancy") or {}).get("records") or {}
    d = next(iter(recs.values()), None)
    if not d:
        return {k: np.nan for k in ("disc_sigma_over_noise", "disc_sigma_pre_over_noise",
                                    "disc_sigma_post_over_noise", "disc_corr_time_us")}
    noise = d["noise_sigma"]
    return {"disc_sigma_over_noise": d["sigma_over_noise"], "disc_sigma_pre_over_noise": d["sigma_pre"] / noise,
            "disc_sigma_post_over_noise": d["sigma_post"] / noise, "disc_corr_time_us": d["corr_time_s"] * 1e6}


def twin_table(records: list, p: str, bounds: dict) -> pd.DataFrame:
    """One row per twin: parameter ``p``'s interval against its truth, and the twin's run features."""
    lo, hi = bounds[p]
    other = next(q for q in bounds if q != p)
    rows = []
    for r in records:
        t, q = r["truth"][p], r["params"][p]
        u = (t - lo) / (hi - lo)
        side = "above" if t > q["q95"] else "below" if t < q["q05"] else "inside"
        ou = (r["truth"][other] - bounds[other][0]) / (bounds[other][1] - bounds[other][0])
        rows.append({"seed": r["seed"], "truth": t, "truth_box_fraction": u, "distance_to_bound": min(u, 1 - u),
                     "other_truth_box_fraction": ou, "sigma_t_truth": r["truth"]["sigma_t"],
                     "E_t_truth": r["truth"]["E_t"], "q05": q["q05"], "q95": q["q95"], "mean": q["mean"],
                     "n_members": q["n"], "side": side, "miss": side != "inside",
                     "half_width_rel": 0.5 * (q["q95"] - q["q05"]) / t,
                     "width_over_box": (q["q95"] - q["q05"]) / (hi - lo),
                     "mean_rel_error": q["mean"] / t - 1, "mean_error_box": (q["mean"] - t) / (hi - lo),
                     "toward_centre": bool(np.sign(q["mean"] - t) == np.sign(0.5 - u)),
                     "reported_iteration": r["reported_iteration"], "stop_reason": r["stop_reason"],
                     "converged": bool(r["converged"]), "stop_chi2_per_obs": r["stop_chi2_per_obs"],
                     "median_chi2_per_obs": r["median_chi2_per_obs"], **_discrepancy(r)})
    return pd.DataFrame(rows)


def _f(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _mw(a, b):
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    return _f(stats.mannwhitneyu(a, b).pvalue) if len(a) and len(b) else None


def _fisher(flag: pd.Series, miss: pd.Series) -> dict:
    """2 x 2 table flag x miss: counts, miss fraction with and without the flag, two-sided p."""
    t = [[int((flag & miss).sum()), int((flag & ~miss).sum())], [int((~flag & miss).sum()), int((~flag & ~miss).sum())]]
    res = stats.fisher_exact(t)
    return {"misses_with": t[0][0], "n_with": sum(t[0]), "misses_without": t[1][0], "n_without": sum(t[1]),
            "odds_ratio": _f(res.statistic), "p": _f(res.pvalue)}


def compare(df: pd.DataFrame, intervals: str = "prediction") -> dict:
    """Misses against covers for one parameter's table."""
    m, c = df[df["miss"]], df[~df["miss"]]
    n, k, n_mem = len(df), int(df["miss"].sum()), int(df["n_members"].median())
    above, below = int((df["side"] == "above").sum()), int((df["side"] == "below").sum())
    expected = 0.90 if intervals == "prediction" else _benchmark().reference_coverage(df["n_members"], 0.05, 0.95)
    out = {"n": n, "misses": k, "covers": n - k, "coverage_90": (n - k) / n,
           "coverage_vs_nominal_0.90_p": _f(stats.binomtest(n - k, n, 0.9).pvalue),
           "expected_coverage": {"intervals": intervals, "n_members": n_mem, "expected": expected,
                                 "p": _f(stats.binomtest(n - k, n, expected).pvalue)},
           "direction": {"above": above, "below": below,
                         "binomial_p": _f(stats.binomtest(above, k).pvalue) if k else None},
           "misses_mean_toward_box_centre": int(m["toward_centre"].sum()),
           "medians_misses_vs_covers": {}, "fisher": {}}
    for col in NUMERIC:
        a, b = m[col].to_numpy(float), c[col].to_numpy(float)
        out["medians_misses_vs_covers"][col] = {"misses": _f(np.nanmedian(a)) if len(a) else None,
                                                "covers": _f(np.nanmedian(b)) if len(b) else None,
                                                "mann_whitney_p": _mw(a, b)}
    u = df["truth_box_fraction"]
    for name, flag in (("truth_within_0.1_of_box_from_a_bound", df["distance_to_bound"] < 0.1),
                       ("truth_within_0.2_of_box_from_a_bound", df["distance_to_bound"] < 0.2),
                       ("truth_in_lowest_fifth_of_box", u < 0.2), ("truth_in_highest_fifth_of_box", u > 0.8)):
        out["fisher"][name] = _fisher(flag, df["miss"])
    out["fisher"]["converged"] = _fisher(df["converged"], df["miss"])
    out["fisher"]["mean_displaced_toward_box_centre"] = _fisher(df["toward_centre"], df["miss"])
    out["stop_reasons"] = {"misses": m["stop_reason"].value_counts().to_dict(),
                           "covers": c["stop_reason"].value_counts().to_dict()}
    out["bias"] = bias(df)
    return out


def bias(df: pd.DataFrame) -> dict:
    """The posterior mean's error over all twins: a systematic sign, and a pull toward the box centre."""
    rel, box = df["mean_rel_error"].to_numpy(float), df["mean_error_box"].to_numpy(float)
    slope = stats.spearmanr(df["truth_box_fraction"], box)
    width = stats.spearmanr(df["truth_box_fraction"], df["width_over_box"])
    return {"mean_rel_error_median": _f(np.median(rel)),
            "mean_rel_error_quartiles": np.quantile(rel, [0.25, 0.75]).tolist(),
            "mean_rel_error_median_abs": _f(np.median(np.abs(rel))),
            "fraction_positive": float(np.mean(rel > 0)), "wilcoxon_p": _f(stats.wilcoxon(rel).pvalue),
            "mean_error_box_median": _f(np.median(box)),
            "spearman_error_box_vs_truth_fraction": {"rho": _f(slope.statistic), "p": _f(slope.pvalue)},
            "spearman_width_over_box_vs_truth_fraction": {"rho": _f(width.statistic), "p": _f(width.pvalue)},
            "mean_toward_box_centre": int(df["toward_centre"].sum())}


def miss_rows(df: pd.DataFrame) -> list:
    cols = ["seed", "sigma_t_truth", "E_t_truth", "truth_box_fraction", "q05", "q95", "mean", "side",
            "half_width_rel", "mean_rel_error", "reported_iteration", "stop_reason", "converged",
            "stop_chi2_per_obs", "median_chi2_per_obs", "disc_sigma_over_noise", "disc_sigma_pre_over_noise",
            "disc_sigma_post_over_noise", "disc_corr_time_us"]
    rows = df.loc[df["miss"], cols].to_dict("records")
    return [{k: (v.item() if hasattr(v, "item") else v) for k, v in r.items()} for r in rows]


def coverage_by_fifth(df: pd.DataFrame, column: str = "truth_box_fraction") -> dict:
    """Covers per fifth of the prior box that the truth falls in (the truths are a Latin hypercube), of
    this parameter (``truth_box_fraction``) or of the other one (``other_truth_box_fraction``), with the
    median over those twins of the median member's chi^2 per observation against ``R``."""
    fifth = np.clip((df[column] * 5).astype(int), 0, 4)
    g = df.groupby(fifth)
    return {f"{k / 5:.1f}-{(k + 1) / 5:.1f}": {"n": int(len(x)), "covers": int(len(x) - x["miss"].sum()),
                                             "median_member_chi2_per_obs": _f(float(np.median(x["median_chi2_per_obs"])))}
            for k, x in g}


def analyse(records: list, bounds: dict | None = None, intervals: str = "prediction") -> dict:
    """The analysis of each parameter; bounds default to the twins' prior box (_box)."""
    bounds = _box() if bounds is None else bounds
    out = {"n_twins": len(records), "intervals": intervals, "bounds": {p: list(b) for p, b in bounds.items()},
           "params": {}}
    for p in bounds:
        df = twin_table(records, p, bounds)
        out["params"][p] = {"summary": compare(df, intervals), "coverage_by_box_fifth": coverage_by_fifth(df),
                            "coverage_by_other_parameter_fifth": coverage_by_fifth(df, "other_truth_box_fraction"),
                            "misses": miss_rows(df)}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", default=str(CACHE))
    ap.add_argument("--pattern", default="well_specified_40_*.json")
    ap.add_argument("--intervals", choices=INTERVALS, default="prediction")
    args = ap.parse_args(argv)
    records = load_records(Path(args.cache), args.pattern)
    out = {"source": f"{Path(args.cache).relative_to(ROOT) if Path(args.cache).is_relative_to(ROOT) else args.cache}"
                     f"/{args.pattern}", **analyse(records, intervals=args.intervals)}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
