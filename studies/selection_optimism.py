"""Why the held-out bands of a leave-one-record-out series cover less than the calibration records' do.

A held-out record's band takes its model discrepancy from the calibration records' cross-validated
residuals (calibration.closing.predictive_bands). Those records also chose the effects the loop added (the
walk compares real runs on them), so after the loop their cross-validated errors are the errors of a model
picked to make them small; the held-out record had no say. This study reads the committed series' fold
checks (no runs) and compares, before and after the loop, the held-out records' RMSE with the calibration
records' cross-validated RMSE (root mean square over the series' folds) and the mean coverage of their 90 %
bands. Before the loop no selection has acted, so the two errors should agree; after it, a ratio above 1 is
the selection's optimism, which the calibration records' residuals cannot show.

Paired by record (``paired``): in a leave-one-record-out series each record is held out once and
cross-validated inside every other fold, where it took part in that fold's selection. Its held-out RMSE
and band coverage against the mean of its cross-validated ones: the same record, so the records' own
difficulty cancels; a held-out prediction is made from one more record than a cross-validated one, which
should favour it.

    python studies/selection_optimism.py

Writes ``studies/results/selection_optimism.json``. Development data (every series' records were read
before); nothing is chosen from it.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from shpb.atomic import emit_json  # noqa: E402

SERIES = ("loro_gated_sandstone", "loro_gated_marble", "loro_rerun_sandstone", "loro_rerun_marble",
          "loro_unseen_sandstone", "loro_unseen_marble")


def _rms(values: list[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(values)))) if values else None


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def _rows(folder: Path, step: str):
    """``(record, held out?, RMSE [Pa], band coverage or None)`` of every record of a series' fold checks at
    ``step`` (before or after)."""
    for f in sorted(folder.glob("*_check.json")):
        check = json.loads(f.read_text())
        bands = (check.get("predictive_band") or {}).get("records") or {}
        for rec, e in (check.get("errors_per_record") or {}).items():
            if not isinstance(e, dict) or not isinstance(e.get(step), dict):
                continue
            c = ((bands.get(rec) or {}).get(step) or {}).get("predictive_coverage_90")
            yield rec, e.get("data") == "heldout", float(e[step]["rmse"]), None if c is None else float(c)


def series_errors(folder: Path, step: str) -> dict:
    """RMSE [Pa] of the held-out and the calibration records over a series' folds at ``step`` (before or
    after), and the mean coverage of their 90 % bands where the checks scored them."""
    rmse = {"heldout": [], "calibration": []}
    cover = {"heldout": [], "calibration": []}
    for _, held, r, c in _rows(folder, step):
        role = "heldout" if held else "calibration"
        rmse[role].append(r)
        if c is not None:
            cover[role].append(c)
    h, c = _rms(rmse["heldout"]), _rms(rmse["calibration"])
    return {"records": {k: len(v) for k, v in rmse.items()}, "rmse_heldout_Pa": h, "rmse_calibration_cv_Pa": c,
            "ratio": h / c if h and c else None, "band_coverage_90_heldout": _mean(cover["heldout"]),
            "band_coverage_90_calibration": _mean(cover["calibration"])}


def _by_record(folder: Path, step: str) -> tuple[dict, dict]:
    held, cv = {}, {}
    for rec, is_held, r, c in _rows(folder, step):
        if is_held:
            held[rec] = (r, c)
        else:
            cv.setdefault(rec, []).append((r, c))
    return held, cv


def paired(folder: Path, step: str) -> dict:
    """Per record its held-out RMSE [Pa] and band coverage against the means of its cross-validated ones, and
    the counts of records predicted worse and covered less when held out."""
    held, cv = _by_record(folder, step)
    rows = {}
    for rec, (rmse, cover) in held.items():
        if rec not in cv:
            continue
        covers = [c for _, c in cv[rec] if c is not None]
        rows[rec] = {"rmse_heldout_Pa": rmse, "rmse_cv_mean_Pa": float(np.mean([r for r, _ in cv[rec]])),
                     "coverage_heldout": cover, "coverage_cv_mean": _mean(covers)}
    scored = [v for v in rows.values() if v["coverage_heldout"] is not None and v["coverage_cv_mean"] is not None]
    return {"records": rows, "rmse_worse_heldout": sum(v["rmse_heldout_Pa"] > v["rmse_cv_mean_Pa"] for v in rows.values()),
            "coverage_lower_heldout": sum(v["coverage_heldout"] < v["coverage_cv_mean"] for v in scored),
            "compared": len(rows), "compared_coverage": len(scored)}


def main():
    out = {"what": "held-out RMSE over the calibration records' cross-validated RMSE, before and after the loop, "
                   "and the mean coverage of their 90 % bands, on the committed leave-one-record-out series",
           "source": "benchmarks/results/<series>/*_check.json (errors_per_record, predictive_band)",
           "series": {s: {step: series_errors(ROOT / "benchmarks" / "results" / s, step) for step in ("before", "after")}
                      for s in SERIES}}
    for s in SERIES:
        out["series"][s]["paired"] = {step: paired(ROOT / "benchmarks" / "results" / s, step) for step in ("before", "after")}
    for step in ("before", "after"):
        got = [v["paired"][step] for v in out["series"].values()]
        out[f"paired_{step}"] = {k: int(sum(g[k] for g in got)) for k in
                                 ("rmse_worse_heldout", "coverage_lower_heldout", "compared", "compared_coverage")}
    after = [v["after"]["ratio"] for v in out["series"].values() if v["after"]["ratio"]]
    out["ratio_after_mean"] = float(np.mean(after))
    emit_json(out, ROOT / "studies" / "results" / "selection_optimism.json")


if __name__ == "__main__":
    main()
