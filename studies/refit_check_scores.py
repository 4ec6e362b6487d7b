"""The refit check's interval scores (benchmarks/planted_plan.json, ``seeds.refit_check``): per series of
``bench_planted.py --cases face_gap --seeds 5311,5312,5313`` that re-fitted its shipped model, each planted
parameter's 90 % interval from the refit (with its verify round) against the selection's surrogate fit the
walk tested, both scored against the planted value by the interval score (a proper score, lower is
better) and whether each holds it.

Run after the benchmark, from the folder its series ran in (``results/<experiment>/diagnosis/refit.json``
and the series' ``truth.json`` under ``--work``):
``python studies/refit_check_scores.py --bench benchmarks/results/bench_planted_refit_check.json
--results results --work <work> --out studies/results/refit_check_scores.json``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from enkf.scores import interval_score  # noqa: E402
from studies.sigma_t_bias import write  # noqa: E402

#: The level of the reported intervals (q05-q95).
ALPHA = 0.1


def planted_values(truth: dict, names) -> dict[str, float]:
    """Each fitted name's planted value: the base parameters', each record's copy of a planted effect's."""
    out = {n: float(v) for n, v in (truth.get("params") or {}).items() if n in names}
    for t in truth.get("tests", []):
        for p, v in (t.get("planted") or {}).items():
            if f"{p}@{t['name']}" in names:
                out[f"{p}@{t['name']}"] = float(v)
    return out


def score_refit(refit: dict, truth: dict) -> dict:
    """Per planted name the refit's and the selection's 90 % intervals, their interval scores and whether
    each holds the planted value."""
    post, sel = refit["posterior"], refit["selection_posterior"]
    out = {}
    for n, v in planted_values(truth, list(post)).items():
        row = {"planted": v}
        for label, q in (("refit", post[n]), ("selection", sel[n])):
            row[label] = {"mean": q["mean"], "q05": q["q05"], "q95": q["q95"],
                          "inside": bool(q["q05"] <= v <= q["q95"]),
                          "interval_score": float(interval_score(q["q05"], q["q95"], v, ALPHA))}
        out[n] = row
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bench", required=True)
    ap.add_argument("--results", required=True, help="the results/ folder the series ran into")
    ap.add_argument("--work", required=True, help="bench_planted.py's --work folder (each series' truth.json)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    bench = json.loads(Path(args.bench).read_text())
    out = {"study": "refit_check_scores", "what": __doc__.split("\n\n")[0].replace("\n", " "), "bench": args.bench,
           "alpha": ALPHA, "series": {}}
    for s in bench["series"]:
        exp = s["experiment"]
        path = Path(args.results) / exp / "diagnosis" / "refit.json"
        refit = json.loads(path.read_text()) if path.is_file() else None
        entry = {"named": s["named"], "correct": s["correct"]}
        if not refit or not refit.get("posterior"):
            entry["refit"] = None
        else:
            truth = json.loads((Path(args.work) / exp / "series" / "truth.json").read_text())
            verify = next((h for h in refit["history"] if h["phase"] == "verify"), {})
            entry.update({"model": refit["model"], "runs": refit["runs"], "verify": verify,
                          "params": score_refit(refit, truth)})
        out["series"][exp] = entry
    rows = [r for e in out["series"].values() for r in (e.get("params") or {}).values()]
    out["totals"] = {label: {"inside": sum(r[label]["inside"] for r in rows), "of": len(rows),
                             "mean_interval_score_over_planted": (
                                 sum(r[label]["interval_score"] / abs(r["planted"]) for r in rows) / len(rows)
                                 if rows else None)}
                     for label in ("refit", "selection")}
    return write(out, args.out)


if __name__ == "__main__":
    main()
