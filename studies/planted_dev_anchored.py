"""The anchored selection model (diagnosis.selection_model: anchored) on planted development series
(issue 53, item 2): what each round's selection tried and chose, what the real FDEM runs of the walk
said, and the held-out record's error. Development seeds of benchmarks/planted_plan.json only.

    python benchmarks/bench_planted.py --cases rate_strength --seeds 5391 --work W --out O   # then:
    python studies/planted_dev_anchored.py --results RESULTS_DIR --experiment planted_rate_strength_5391 \
        --out studies/results/planted_dev_anchored_rate_strength_5391.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from shpb.atomic import emit_json


def summarise(diagnosis: Path) -> dict:
    report = json.loads((diagnosis / "report.json").read_text())
    check = json.loads((diagnosis / "check.json").read_text())
    rounds = [{"current_cv_rmse_Pa": r["current_cv_rmse"], "chosen": r["chosen"],
               "trials": {t["effect"]: {"cv_rmse_Pa": t["cv_rmse"], "z": t["z"]} for t in r["trials"]}}
              for r in report["selection"].get("rounds", [])]
    walk = [{k: s.get(k) for k in ("effect", "confirmed", "z", "p", "level", "real_cv_rmse_before",
                                    "real_cv_rmse_after")} for s in report["confirmation"]["steps"]]
    held = {h: {w: {"rmse_Pa": v[w]["rmse"], "peak_rel_error": v[w]["peak_rel_error"],
                    "band_coverage": v[w].get("band_coverage")} for w in ("before", "after")}
            for h, v in (check.get("heldout") or {}).items()}
    base = report["selection"]["steps"][0]["posterior"]
    return {"verdict": report.get("verdict"), "added": report.get("added"), "why": report.get("why"),
            "selection_model": json.loads((diagnosis / "design" / "design.json").read_text())["selection_model"],
            "base_posterior": {p: base[p] for p in ("sigma_t", "E_t") if p in base},
            "rounds": rounds, "walk": walk, "heldout": held}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", required=True, help="the run's results/ folder")
    ap.add_argument("--experiment", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    out = {"experiment": a.experiment, **summarise(Path(a.results) / a.experiment / "diagnosis")}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
