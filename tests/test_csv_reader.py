"""The csv reader of test sheets (shpb.lab.sheet_readers) on a scope's export: header lines of the scope's
own before the column names are skipped with signals.skip_rows or dropped with signals.comment, and the
record then reduces exactly as the plain file does; six malformed cases each stop with the sheet, the
file, the line or field and the fix."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from shpb.lab.lab_reduce import reduce_sheet
from shpb.lab.sheet import SheetError, load_sheet
from shpb.lab.sheet_readers import check_sheet

REPO = Path(__file__).resolve().parents[1]
DISC = REPO / "data" / "examples" / "granite_disc"
#: A scope's own header: ten lines of one or two fields before the column names (a DSO's csv export).
SCOPE_HEADER = ["Model,DSO-X 3024A", "Serial,MY00000000", "Record Length,698", "Sample Interval,5e-07",
                "Trigger Point,200", "Vertical Units,strain", "Horizontal Units,s", "Probe Attenuation,1",
                "Acquisition,Normal", "Notes"]


def _sheet(tmp_path: Path, header: list[str], name: str = "scope", **signals) -> Path:
    (tmp_path / f"{name}.csv").write_text("\n".join(header + (DISC / "signals.csv").read_text().splitlines()) + "\n")
    doc = yaml.safe_load((DISC / "granite_disc.yaml").read_text())
    doc["name"] = name
    doc["signals"].update({"file": f"{name}.csv", **signals})
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _problems(path) -> str:
    with pytest.raises(SheetError) as err:
        check_sheet(path)
    return str(err.value)


@pytest.fixture(scope="module")
def plain():
    return reduce_sheet(*check_sheet(DISC / "granite_disc.yaml"))


@pytest.mark.parametrize("header, signals", [
    (SCOPE_HEADER, {"skip_rows": 10}),
    (["# " + ln for ln in SCOPE_HEADER], {"comment": "#"}),
    (["# exported by the scope"] + SCOPE_HEADER, {"skip_rows": 11, "comment": "#"}),   # counts every line
], ids=["skip_rows", "comment", "both"])
def test_a_scope_export_reads_and_reduces_as_the_plain_file(tmp_path, plain, header, signals):
    sheet, raw = check_sheet(_sheet(tmp_path, header, **signals))
    assert raw.n_samples == 1692 and raw.time[0] == -1.0e-4        # every data row of signals.csv, no header line
    red = reduce_sheet(sheet, raw)
    np.testing.assert_array_equal(red.stress, plain.stress)
    assert red.peak_stress == pytest.approx(33.37e6, abs=0.01e6)


def test_a_scope_header_without_skip_rows_names_the_line_and_the_fix(tmp_path):
    # pandas alone: "Error tokenizing data. C error: Expected 2 fields in line 11, saw 3"
    msg = _problems(_sheet(tmp_path, SCOPE_HEADER))
    assert "scope.yaml: signals.file:" in msg and "scope.csv: line 11 has 3 fields" in msg
    assert "set signals.skip_rows: 10" in msg and "line 11 of scope.csv" in msg


def test_a_header_of_one_field_lines_names_the_skip_rows_fix(tmp_path):
    # the user's case: lines without a comma ("Expected 1 fields in line 11, saw 3")
    msg = _problems(_sheet(tmp_path, [f"scope line {i}" for i in range(10)]))
    assert "line 11 has 3 fields where the header row (after signals.skip_rows: 0) has 1" in msg
    assert "set signals.skip_rows: 10" in msg


def test_a_wrong_skip_rows_that_parses_names_the_right_one(tmp_path):
    # three-field lines before the header: pandas reads them as a header and data, the columns are missing
    msg = _problems(_sheet(tmp_path, ["a,b,c", "1,2,3", "4,5,6"], skip_rows=1))
    assert "scope.yaml: signals.time.column: expected a column of scope.csv" in msg and "'time_s' not found" in msg
    assert "the columns are named on line 4 of scope.csv: set signals.skip_rows: 3" in msg


def test_no_header_row_at_all_says_how_to_skip(tmp_path):
    path = _sheet(tmp_path, SCOPE_HEADER, skip_rows=10)
    csv = tmp_path / "scope.csv"
    csv.write_text("\n".join(csv.read_text().splitlines()[11:]) + "\n")   # the column names gone too
    msg = _problems(path)
    assert "signals.time.column: expected a column of scope.csv" in msg
    assert "set signals.skip_rows to their number, or signals.comment" in msg


def test_skip_rows_on_a_format_with_its_own_reader_is_refused(tmp_path):
    doc = yaml.safe_load((REPO / "data/examples/sheets/CaMa_SHPB_004.yaml").read_text())
    doc["signals"]["file"] = str((REPO / "data/examples/sheets" / doc["signals"]["file"]).resolve())
    doc["signals"]["skip_rows"] = 3
    (tmp_path / "fb.yaml").write_text(yaml.safe_dump(doc))
    msg = _problems(tmp_path / "fb.yaml")
    assert "fb.yaml: signals.skip_rows: only format csv takes it (format 'freiburg'" in msg and "got 3" in msg


@pytest.mark.parametrize("signals, field", [({"skip_rows": -1}, "signals.skip_rows"),
                                            ({"comment": "##"}, "signals.comment")])
def test_the_schema_bounds_the_new_fields(tmp_path, signals, field):
    path = _sheet(tmp_path, [], **signals)
    with pytest.raises(SheetError) as err:
        load_sheet(path)
    assert f"scope.yaml: {field}:" in str(err.value)
