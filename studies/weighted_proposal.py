"""Would the selection propose the planted effect more often with the walk's weights? (issue 53, item 2)

The walk now compares real runs by squared errors weighted per time by 1 / (noise^2 + mesh scatter^2)
(enkf.diagnosis.walk_weights); the selection still ranks its proposals by the plain sum of the emulated
cross-validated squared errors. This study re-runs each finished series' selection exactly as its job
did (scripts/diagnosis.py: the pickled selection model, the workflow's posterior as the base, the
series' config), records every first-round trial's plain and weighted fall of the error, checks that
the plain ranking is the one the series' report holds, and reports the planted effect's rank under
each. No new FDEM runs. Only the retired benchmark seeds 5302-5304 are read (the plan's seeds 5305-5310
are not).

    python studies/weighted_proposal.py --series RESULTS/planted_x_5302=WORK/planted_x_5302/config.yaml ...
        --out OUT.json
"""
from __future__ import annotations

import argparse
import json
import pickle
from pathlib import Path

import numpy as np
import pandas as pd

import enkf.diagnosis.protocol as protocol
from calibration.closing import blind, select_effects
from calibration.config_check import load_yaml, validate_config
from calibration.diagnosis_config import candidate_effects, diagnosis_settings
from calibration.observations import read_observations
from calibration.protocol import workflow_base
from enkf.diagnosis import walk_weights
from shpb.atomic import emit_json

ROOT = Path(__file__).resolve().parents[1]


def _planted(name: str) -> str | None:
    case = name.removeprefix("planted_").rsplit("_", 1)[0].removeprefix("disc_")
    return None if case == "null" else case


def one_series(run: Path, config: Path) -> dict:
    exp_name = run.name
    e = validate_config(load_yaml(config), ROOT / "config" / "schema.yaml", base_dir=ROOT)["experiments"][exp_name]
    d = run / "diagnosis"
    state = pickle.loads((d / "selection.pkl").read_bytes())
    obs = read_observations(run / "observations" / "obs.csv", run / "observations" / "obs.json")
    held = blind(read_observations(d / "heldout" / "obs.csv", d / "heldout" / "obs.json"))
    meta = json.loads((d / "design" / "design.json").read_text())
    base = workflow_base(state["model"], meta["base_names"], obs.records, pd.read_csv(run / "posterior.csv"),
                         json.loads((run / "summary.json").read_text()), file=str(run / "posterior.csv"))
    w = walk_weights(state["noise"], state["simulator"], list(obs.records))
    calls = []
    plain_compare = protocol.compare_cv

    def recording(y, current, candidate, errors, **kw):
        out = plain_compare(y, current, candidate, errors, **kw)
        weighted = sum(float(((y[j] - current[j]) ** 2 - (y[j] - candidate[j]) ** 2) @ w[j]) for j in current)
        calls.append((out["delta"], weighted))
        return out

    protocol.compare_cv = recording
    try:
        sel = select_effects(state["model"], base_names=meta["base_names"], candidates=candidate_effects(e["diagnosis"]),
                             obs=obs, noise=state["noise"], simulator=state["simulator"], heldout_records=held.records,
                             settings=diagnosis_settings(e), mesh_mode=e["simulation"].get("mesh_realizations") or "per_run",
                             base_fit=base)
    finally:
        protocol.compare_cv = plain_compare
    tried = sel.rounds[0]["tried"] if hasattr(sel, "rounds") else sel.to_dict()["rounds"][0]["tried"]
    first = dict(zip(tried, calls[:len(tried)]))
    plain = sorted(first, key=lambda c: -first[c][0])
    weighted = sorted(first, key=lambda c: -first[c][1])
    kept = [t["effect"] for t in sorted(json.loads((d / "report.json").read_text())["selection"]["rounds"][0]["trials"],
                                        key=lambda t: -t["delta_sq_error"])]
    planted = _planted(exp_name)

    def rank(order):
        return order.index(planted) + 1 if planted in order else None

    return {"planted": planted, "plain_ranking": plain, "weighted_ranking": weighted,
            "plain_matches_report": plain == kept, "planted_rank_plain": rank(plain),
            "planted_rank_weighted": rank(weighted),
            "weighted_gain_over_best_plain": {c: round(first[c][1], 1) for c in weighted[:3]}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--series", nargs="+", required=True, help="RESULTS_FOLDER=CONFIG pairs of finished series")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    pairs = [s.split("=", 1) for s in a.series]
    out = {"what": __doc__.split("\n\n")[0],
           "series": {Path(r).name: one_series(Path(r), Path(c)) for r, c in pairs}}
    ranks = [(v["planted_rank_plain"], v["planted_rank_weighted"]) for v in out["series"].values() if v["planted"]]
    out["planted_first"] = {"plain": sum(p == 1 for p, _ in ranks), "weighted": sum(q == 1 for _, q in ranks),
                            "of": len(ranks)}
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
