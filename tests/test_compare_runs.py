"""tools/compare_runs.py tells identical results trees from ones that differ in a number, and leaves
timings and keys one side alone has out of "differ" (it is how same-seed runs are compared)."""
import json
from pathlib import Path

from tools import compare_runs


def _tree(root: Path, stress: float, wall: float, extra: bool):
    (root / "exp/iter_0").mkdir(parents=True)
    (root / "exp/iter_0/curve.csv").write_text(f"time_s,stress_Pa\n0.0,0.0\n1e-6,{stress}\n")
    run = {"status": "ok", "wall_s": wall, "params": {"sigma_t": 4.5e7}}
    if extra:
        run["bars"] = {"E": 2e11}
    (root / "exp/iter_0/run.json").write_text(json.dumps(run))
    (root / "exp/plot.png").write_bytes(b"\x89PNG same")


def test_same_numbers_with_other_timings_are_identical_and_a_changed_number_is_not(tmp_path):
    tool = compare_runs
    _tree(tmp_path / "a", 3.0e7, 1.0, False)
    _tree(tmp_path / "b", 3.0e7, 9.0, True)
    rep = tool.compare(tmp_path / "a", tmp_path / "b")
    assert rep["differ"] == {} and "exp/iter_0/curve.csv" in rep["identical"]
    assert rep["one_sided_keys"] == {"exp/iter_0/run.json": ".bars"}
    _tree(tmp_path / "c", 3.0e7 * (1 + 1e-12), 1.0, False)
    rep = tool.compare(tmp_path / "a", tmp_path / "c")
    assert rep["differ"] == {"exp/iter_0/curve.csv": "columns ['stress_Pa']"}
    assert rep["identical_but_timings"] == [] and "exp/iter_0/run.json" in rep["identical"]
