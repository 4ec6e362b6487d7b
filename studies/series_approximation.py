"""A leave-one-record-out series of measured records with the approximation error (issue 52): what the
term does to each fold's intervals and held-out band on real records, and what it costs now that a
series runs each record's pairs once.

Plan, fixed before the run: `config/validation_marble.yaml` (`marble_unseen`: four Carrara-marble records,
each held out once) run from a fresh clone of main with

    snakemake --cores 2 --configfile config/validation_marble.yaml term.yaml

(`term.yaml`: ``experiments.marble_unseen.observations.model_error.approximation_error: {preset: standard,
pairs: 24}``, what `init-config` writes), against the committed run of the same series without the term
(`benchmarks/results/loro_rerun_marble/`). Reported per fold: the held-out record, the loop's verdict and
effects, the held-out RMSE before and after the loop, its 90 % band's coverage and score over the design
box's, the fold's `sigma_t` and `E_t` quantiles, and the held-out record's own mesh offset; over the
series, the means the series table reports; the runs made (each record's pairs once, under the series'
folder, none under a fold's) and the wall time. These records are development data (read before); nothing
is chosen from this run.

Usage: python studies/series_approximation.py --run <clone>/results --wall-s <seconds>
           --out studies/results/series_approximation.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

from shpb.atomic import emit_json  # noqa: E402

SERIES = "marble_unseen"
COMMITTED = ROOT / "benchmarks" / "results" / "loro_rerun_marble"
QUANTILES = ("q05", "q50", "q95")
TOTALS = ("mean_rmse_before", "mean_rmse_after", "folds_better", "folds_worse", "effects_kept",
          "mean_predictive_coverage_90_before", "mean_predictive_coverage_90_after",
          "mean_interval_score_over_box_before", "mean_interval_score_over_box_after")


def _fold(summary: dict, check: dict, held: str, heldout_meta: dict | None) -> dict:
    h = check["heldout"][held]
    band = (check.get("predictive_band") or {}).get("records", {}).get(held, {})
    out = {"verdict": check.get("verdict"), "added": check.get("added"),
           **{f"rmse_{s}": h[s]["rmse"] for s in ("before", "after")},
           **{f"predictive_coverage_90_{s}": (band.get(s) or {}).get("predictive_coverage_90")
              for s in ("before", "after")},
           **{f"interval_score_over_box_{s}": (band.get(s) or {}).get("interval_score_over_box")
              for s in ("before", "after")},
           "posterior": {p: {q: summary["posterior"][p][q] for q in QUANTILES} for p in ("sigma_t", "E_t")}}
    approx = (heldout_meta or {}).get("approximation_error")
    if approx:  # the held-out record's own correction (none without the term)
        out["heldout_offset_rms_Pa"] = approx["offset_rms_Pa"]
        out["heldout_offset_max_abs_Pa"] = approx["offset_max_abs_Pa"]
    return out


def _series(table: dict, fold_files) -> dict:
    """Each fold's figures (``fold_files(held)``: its summary, check and held-out obs.json) and the totals."""
    folds = {}
    for row in table["rows"]:
        summary, check, meta = fold_files(row["heldout"])
        folds[row["heldout"]] = _fold(summary, check, row["heldout"], meta)
    return {"folds": folds, "totals": {k: table["totals"].get(k) for k in TOTALS}}


def _read_json(path: Path):
    return json.loads(path.read_text()) if path.is_file() else None


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="the results folder of the series run with the term")
    ap.add_argument("--wall-s", type=float, required=True, help="the run's wall time (snakemake, 2 cores)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    res = Path(a.run)

    def run_files(held):
        fold = res / f"{SERIES}__{held}"
        return tuple(_read_json(fold / f) for f in ("summary.json", "diagnosis/check.json",
                                                     "diagnosis/heldout/obs.json"))

    def committed_files(held):
        return _read_json(COMMITTED / f"{held}_summary.json"), _read_json(COMMITTED / f"{held}_check.json"), None

    with_term = _series(json.loads((res / SERIES / "loro" / "summary.json").read_text()), run_files)
    without = _series(json.loads((COMMITTED / f"{SERIES}.json").read_text()), committed_files)
    runs = {"series": len(list((res / SERIES / "approximation").glob("*/*/run.json"))),
            "folds": len(list(res.glob(f"{SERIES}__*/approximation/*/*/run.json")))}
    out = {"what": __doc__.split("\n")[0], "cores": 2, "wall_s_with_term": a.wall_s,
           "wall_s_without_term": _read_json(COMMITTED / "run.json")["wall_s"],
           "committed_without_term": str(COMMITTED.relative_to(ROOT)), "approximation_runs": runs,
           "with_term": with_term, "without_term": without}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
