import json
from pathlib import Path

import pytest

from studies.refit_check_scores import score_refit

ROOT = Path(__file__).resolve().parents[1]


def test_the_default_run_s_planted_refit_scores_as_the_docs_quote():
    refit = json.loads((ROOT / "benchmarks/results/default_run/planted_gap/diagnosis/refit.json").read_text())
    truth = json.loads((ROOT / "data/examples/planted_gap/truth.json").read_text())
    out = score_refit(refit, truth)
    assert set(out) == {"sigma_t", "E_t", "face_gap.gap_m@PlantGap_01", "face_gap.gap_m@PlantGap_02"}
    g1, g2 = out["face_gap.gap_m@PlantGap_01"], out["face_gap.gap_m@PlantGap_02"]
    assert g1["refit"]["inside"] and g2["refit"]["inside"] and not out["sigma_t"]["refit"]["inside"]
    # inside: the score is the width; outside: the width plus 20 times the miss
    assert g2["refit"]["interval_score"] == pytest.approx(g2["refit"]["q95"] - g2["refit"]["q05"])
    sel = g2["selection"]
    assert sel["interval_score"] == pytest.approx(sel["q95"] - sel["q05"] + 20 * (g2["planted"] - sel["q95"]))
    assert g2["refit"]["interval_score"] * 1e6 == pytest.approx(15.67, abs=0.01)
