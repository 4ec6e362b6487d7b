"""The decision rule of ``benchmarks/coverage_plan_location.json``, applied to its two scored JSONs.

The plan fixed the rule before any twin ran: the candidate form (``emulated.recalibrate: location``)
becomes every experiment's default only if, on the same twins as the shipped form,

- its well-specified 90 % coverage lies in 0.85-0.95 and its rank tests (chi-square and KS) are not
  rejected at 1 %, for both parameters;
- its weighted interval score over the prior's is at most the shipped form's plus 0.01, per parameter;
- on each misspecified set its 90 % coverage is at least 0.80 or at least the shipped form's, per
  parameter.

Both forms' scores are reported whatever the outcome. A pair of JSONs that does not hold the same
complete twins is refused: the rule compares forms on the same runs.

    python benchmarks/location_decision.py SHIPPED.json CANDIDATE.json --out DECISION.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.scores import COVERAGE_90_BAR, COVERAGE_90_MISSPECIFIED_MIN, SBC_ALPHA, WIS_BAR, verdict  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

SETS = ("well_specified", "misspecified", "misspecified_rate")
WIS_SLACK = 0.01
REPORTED = "summary_emulator_mcmc"


def _scores(block: dict) -> dict:
    """Per parameter, as :func:`benchmarks.scores.verdict` reads them: 90 % coverage (failed samplers as
    misses), the smaller rank-test p, WIS over the prior's; with the 50 % coverage and the median's bias."""
    summ = block[REPORTED]
    bars = verdict(summ)["bars"]
    return {p: {"coverage_90": bars[f"coverage_90 {p}"]["value"], "rank_p": bars[f"sbc {p}"]["value"],
                "wis_over_prior": bars[f"wis_over_prior {p}"]["value"],
                "coverage_50": res["coverage_50"]["fraction"],
                "mean_over_truth_median": res["mean_over_truth_median"]}
            for p, res in summ["params"].items()}


def _check_pair(shipped: dict, candidate: dict) -> None:
    if candidate.get("recalibrate") != "location" or shipped.get("recalibrate") not in (None, "none"):
        raise ValueError(f"location_decision: expected the shipped form (recalibrate none) and the candidate "
                         f"(recalibrate location), got {shipped.get('recalibrate')!r} and {candidate.get('recalibrate')!r}")
    for name in SETS:
        a, b = shipped.get(name), candidate.get(name)
        if not a or not b or not a.get("complete") or not b.get("complete"):
            raise ValueError(f"location_decision: set {name!r} is not complete in both JSONs (the rule is "
                             "applied once, when every planned twin is in)")
        ta = [(r["seed"], r["truth"]) for r in a["twins"]]
        tb = [(r["seed"], r["truth"]) for r in b["twins"]]
        if ta != tb:
            raise ValueError(f"location_decision: set {name!r} holds other twins in the two JSONs")


def decide(shipped: dict, candidate: dict) -> dict:
    """The plan's rule on two bench_coverage JSONs; every condition named with its values."""
    _check_pair(shipped, candidate)
    s = {name: _scores(shipped[name]) for name in SETS}
    c = {name: _scores(candidate[name]) for name in SETS}
    lo, hi = COVERAGE_90_BAR
    conditions = {}
    for p in WIS_BAR:
        cw, sw = c["well_specified"][p], s["well_specified"][p]
        conditions[f"well_specified coverage_90 {p}"] = {
            "candidate": cw["coverage_90"], "bar": f"{lo:.2f}-{hi:.2f}", "met": bool(lo <= cw["coverage_90"] <= hi)}
        conditions[f"well_specified rank tests {p}"] = {
            "candidate": cw["rank_p"], "bar": f"p >= {SBC_ALPHA}", "met": bool(cw["rank_p"] >= SBC_ALPHA)}
        conditions[f"well_specified wis_over_prior {p}"] = {
            "candidate": cw["wis_over_prior"], "shipped": sw["wis_over_prior"],
            "bar": f"<= shipped + {WIS_SLACK}", "met": bool(cw["wis_over_prior"] <= sw["wis_over_prior"] + WIS_SLACK)}
        for name in SETS[1:]:
            cm, sm = c[name][p]["coverage_90"], s[name][p]["coverage_90"]
            conditions[f"{name} coverage_90 {p}"] = {
                "candidate": cm, "shipped": sm, "bar": f">= {COVERAGE_90_MISSPECIFIED_MIN:.2f} or >= shipped",
                "met": bool(cm >= COVERAGE_90_MISSPECIFIED_MIN or cm >= sm)}
    failed = [k for k, v in conditions.items() if not v["met"]]
    return {"plan": "benchmarks/coverage_plan_location.json", "conditions": conditions, "failed": failed,
            "adopt_candidate": not failed, "scores": {"shipped": s, "candidate": c},
            "twins": {name: len(shipped[name]["twins"]) for name in SETS}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shipped")
    ap.add_argument("candidate")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    out = decide(json.loads(Path(args.shipped).read_text()), json.loads(Path(args.candidate).read_text()))
    return emit_json(out, args.out)


if __name__ == "__main__":
    main()
