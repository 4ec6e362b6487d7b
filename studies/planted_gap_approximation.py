"""The default run's planted series with the coarse mesh's approximation error, as the lab's path writes it.

`planted_gap` ships without the approximation error (`init-config --no-approximation-error`), while
`python -m shpb init-config` writes it for a lab's records by default. Its series is made at the `standard`
mesh and calibrated at `fast`, so without the term the coarse mesh's own error is left for the loop's
additions to take up. Does the term keep the walk to the planted face gap? Run the series with it:

    snakemake --cores 2 --configfile studies/planted_gap_approximation.yaml
    python studies/planted_gap_approximation.py results/planted_gap --out studies/results/planted_gap_approximation.json

and this script reads what the run wrote: the verdict, the walk's steps (effect, z, p, level), the held-out
record's errors and band, and the reported parameters (the workflow's posterior, the selection's fit of the
shipped model, the refit on real runs) against the series' truth (data/examples/planted_gap/truth.json).
One run of a development series whose answer without the term had been read: nothing is chosen from it.
Run again with the identification gate (calibration.walk.identified) ->
studies/results/planted_gap_approximation_gated.json, with what the gate dropped (``gated``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from enkf.diagnosis.protocol import step_summary  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402


def _interval(row: dict) -> dict:
    return {"mean": row["mean"], "q05": row["q05"], "q95": row["q95"]}


def _against_truth(post: dict, truth: dict, planted: dict) -> dict:
    """Each reported parameter's interval, and whether it holds its truth (a per-record copy its record's
    planted value; an effect nobody planted its null, 0)."""
    out = {}
    for name, row in post.items():
        base, _, record = name.partition("@")
        true = truth["params"].get(base, planted.get(record) if base == "face_gap.gap_m" else 0.0)
        out[name] = {**_interval(row), "truth": true, "inside": bool(row["q05"] <= true <= row["q95"])}
    return out


def summarize(folder: Path) -> dict:
    truth = json.loads((ROOT / "data/examples/planted_gap/truth.json").read_text())
    planted = {t["name"]: t["planted"]["face_gap.gap_m"] for t in truth["tests"]}
    rep = json.loads((folder / "diagnosis/report.json").read_text())
    chk = json.loads((folder / "diagnosis/check.json").read_text())
    summary = json.loads((folder / "summary.json").read_text())
    held = {r: {"rmse_before_Pa": h["before"]["rmse"], "rmse_after_Pa": h["after"]["rmse"],
                "predictive_coverage_90_after": h["after"].get("predictive_coverage_90")}
            for r, h in chk["heldout"].items()}
    out = {"study": "planted_gap_approximation", "planted": truth["effect"],
           "approximation_error": summary.get("posterior_form", {}).get("approximation_error"),
           "verdict": rep["verdict"], "added": rep["added"],
           "steps": [{k: s[k] for k in ("step", "effect", "confirmed", "z", "p", "level", "alternative_to")}
                     for s in rep["confirmation"]["steps"]],
           "heldout": held,
           "workflow_posterior": _against_truth({k: v for k, v in summary["posterior"].items()}, truth, planted),
           "selection_posterior": _against_truth(step_summary(rep["selection"], rep["shipped_step"])["posterior"],
                                                 truth, planted)}
    refit = folder / "diagnosis/refit.json"
    if refit.exists():
        ref = json.loads(refit.read_text())
        out["refit_posterior"] = _against_truth(ref["posterior"], truth, planted)
        # what the identification gate dropped (calibration.walk.identified), where the code had it
        out["gated"] = [{"model": g["model"], "effect": g["identification"]["effect"],
                         "parameters": g["identification"]["parameters"]} for g in ref.get("gated") or []]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("folder", nargs="?", default="results/planted_gap")
    ap.add_argument("--out")
    ap.add_argument("--wall", type=float, help="the run's wall time [s] on 2 cores, recorded beside its answers")
    a = ap.parse_args()
    out = summarize(Path(a.folder))
    if a.wall is not None:
        out["wall_s_2_cores"] = a.wall
    emit_json(out, a.out)


if __name__ == "__main__":
    main()
