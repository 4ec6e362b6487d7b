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
