"""One definition of the simulator's file contract (shpb.contract), used by both sides: the simulator
that writes curves and the workflow runner that reads them and writes a failed member's header."""

import ast
from pathlib import Path

import calibration.workflow_io as wio
import shpb.contract as contract
import shpb.simulate as sim

ROOT = Path(__file__).resolve().parents[1]


def test_both_sides_use_the_one_definition_of_the_curve_columns():
    assert tuple(sim.CURVE_COLUMNS) == contract.CURVE_COLUMNS == wio.CURVE_COLUMNS
    assert wio.failed_curve_text() == ",".join(contract.CURVE_COLUMNS) + "\n"
    assert "centre_syy_Pa" in wio.failed_curve_text()  # the column the two copies once disagreed on


def test_no_module_spells_the_curve_columns_out_again():
    literal = []
    for pkg in ("shpb", "calibration", "enkf", "scripts"):
        for path in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "CURVE_COLUMNS" for t in node.targets):
                    if isinstance(node.value, (ast.List, ast.Tuple)):
                        literal.append(str(path.relative_to(ROOT)))
    assert literal == ["shpb/contract.py"]


def test_the_cli_exits_with_the_contract_codes(tmp_path):
    from shpb.__main__ import main

    assert main(["simulate", "--geometry", "brazilian_disc", "--preset", "fast", "--param", "no_such=1",
                 "--out", str(tmp_path)]) == contract.EXIT_BAD_INPUT


def test_curve_csv_is_the_text_pandas_writes():
    """curve.csv is written without pandas (a simulation process never imports it); its text is pandas'
    to_csv(index=False, float_format="%.9e") to the byte: missing values empty, negative zero, extremes."""
    import numpy as np
    import pandas as pd

    rng = np.random.default_rng(5)
    cols = {c: rng.normal(size=40) * 10.0 ** rng.uniform(-12, 9, 40) for c in contract.CURVE_COLUMNS}
    cols["force_balance"][[0, 3, 39]] = np.nan
    cols["stress_Pa"][5] = -0.0
    cols["time_s"][7] = 1e-300
    expected = pd.DataFrame(cols)[list(contract.CURVE_COLUMNS)].to_csv(index=False, float_format="%.9e")
    assert sim.curve_csv_text(cols) == expected
    empty = {c: np.array([]) for c in contract.CURVE_COLUMNS}
    assert sim.curve_csv_text(empty) == pd.DataFrame(empty).to_csv(index=False, float_format="%.9e")


def test_a_measured_record_is_read_and_reduced_without_pandas_or_scipy_ndimage():
    """What every member job of a measured record does before the solver starts (the record read, its
    specimen looked up in the spreadsheet, its rock properties, the reduction) leaves pandas, scipy.ndimage
    and scipy.integrate unimported: each costs 0.1-0.3 s per process, and a default run has ~270 of them."""
    import subprocess
    import sys

    from shpb.paths import freiburg_data_dir

    record = sorted((freiburg_data_dir() / "Rae2021" / "SHPBdata" / "CaMa").glob("CaMa_SHPB_004*.txt"))[0]
    code = ("import sys; from shpb.simulate import _measured_incident; "
            f"m = _measured_incident({str(record)!r}); assert m['length'] > 0 and m['rock']['E'] > 0; "
            "print(sorted(x for x in ('pandas', 'scipy.ndimage', 'scipy.integrate') if x in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_the_member_job_wrapper_imports_no_numpy_and_keeps_run_json_types():
    """The rule adapters' imports (calibration.workflow_io, calibration.runner) load neither numpy nor pandas:
    a member job (scripts/simulate.py) loads numpy only with the shipped simulator it forks
    (calibration.runner), and a user's own simulator command not at all; run.json's numbers still come out as
    JSON numbers (numpy scalars included), booleans as booleans and non-finite values as null."""
    import json
    import subprocess
    import sys

    import numpy as np

    from calibration.runner import _jsonable

    code = ("import sys, calibration.workflow_io, calibration.runner; "
            "print(sorted(x for x in ('numpy', 'pandas') if x in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
    run = _jsonable({"steps": np.int64(7), "dt_s": np.float32(0.5), "ok": True, "bad": float("nan"),
                     "list": (np.float64(2.5), 3), 4: "key"})
    assert json.dumps(run) == '{"steps": 7, "dt_s": 0.5, "ok": true, "bad": null, "list": [2.5, 3], "4": "key"}'
