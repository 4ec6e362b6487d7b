"""Malformed measured records, each built in tmp_path from a shipped example with one change, are refused
before any simulation with a message naming the file, the field (or channel and line) and what was
expected: test sheets through ``check_record`` (what the Snakefile calls for every record) and through
``python -m shpb reduce``, Freiburg raw records through ``check_record``."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from calibration.observations import ObservationFileError, check_record
from shpb.__main__ import main

REPO = Path(__file__).resolve().parents[1]
CAMA_SHEET = REPO / "data/examples/sheets/CaMa_SHPB_004.yaml"
GRANITE = REPO / "data/examples/granite_disc/granite_disc.yaml"
RAE2021 = REPO / "data/freiburg-rae-rock-shpb/Rae2021"
RAW004 = RAE2021 / "SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
RAW014 = RAE2021 / "SHPBdata/CaMa/CaMa_SHPB_014_Ti25_55b_Al12b_0_001.txt"


# --------------------------------------------------------------------------------------------------
# Builders: each writes one malformed record into tmp_path and returns (record to check, file named)
# --------------------------------------------------------------------------------------------------
def _set(doc: dict, dotted: str, value) -> None:
    *head, last = dotted.split(".")
    for k in head:
        doc = doc.setdefault(k, {})
    doc[last] = value


def _sheet_doc(base: Path) -> dict:
    doc = yaml.safe_load(base.read_text())
    doc["signals"]["file"] = str((base.parent / doc["signals"]["file"]).resolve())
    return doc


def _write_sheet(tmp: Path, doc: dict, text_edit=None) -> Path:
    path = tmp / "bad.yaml"
    text = yaml.safe_dump(doc, sort_keys=False)
    path.write_text(text_edit(text) if text_edit else text)
    return path


def sheet(base: Path, field: str, value):
    """The shipped sheet ``base`` with ``field`` set to ``value`` (a YAML scalar, written as text: .nan)."""
    def build(tmp: Path):
        doc = _sheet_doc(base)
        _set(doc, field, "__VALUE__")
        path = _write_sheet(tmp, doc, lambda t: t.replace("__VALUE__", str(value)))
        return path, path
    return build


def sheet_edit(base: Path, edit):
    """The shipped sheet with ``edit(doc)`` applied."""
    def build(tmp: Path):
        doc = _sheet_doc(base)
        edit(doc)
        path = _write_sheet(tmp, doc)
        return path, path
    return build


def _freiburg_lines() -> list[str]:
    return RAW004.read_bytes().decode("latin-1").splitlines()


def _set_cell(lines: list[str], lineno: int, col: int, text: str) -> list[str]:
    fields = lines[lineno - 1].split(";")
    fields[col] = text
    lines[lineno - 1] = ";".join(fields)
    return lines


def _negated(lines: list[str]) -> list[str]:
    out = lines[:11]
    for ln in lines[11:]:
        f = ln.split(";")
        out.append(";".join([f[0]] + [str(-float(v)) for v in f[1:]]) if ln.strip() else ln)
    return out


def signals_freiburg(lines_edit):
    """The CaMa_SHPB_004 sheet over a copy of its Freiburg signals file edited by ``lines_edit(lines)``."""
    def build(tmp: Path):
        sig = tmp / RAW004.name
        sig.write_text("\n".join(lines_edit(_freiburg_lines())) + "\n", encoding="latin-1")
        doc = _sheet_doc(CAMA_SHEET)
        doc["signals"]["file"] = str(sig)
        return _write_sheet(tmp, doc), sig
    return build


def signals_csv(frame_edit, sheet_edit_=None):
    """The granite-disc sheet over a copy of its csv signals edited by ``frame_edit(df)`` (returns text or df)."""
    def build(tmp: Path):
        import pandas as pd

        df = pd.read_csv(GRANITE.parent / "signals.csv")
        out = frame_edit(df)
        sig = tmp / "signals.csv"
        sig.write_text(out if isinstance(out, str) else out.to_csv(index=False))
        doc = _sheet_doc(GRANITE)
        doc["signals"]["file"] = str(sig)
        if sheet_edit_:
            sheet_edit_(doc)
        return _write_sheet(tmp, doc), sig.name
    return build


def empty_sheet(tmp: Path):
    path = tmp / "bad.yaml"
    path.write_text("")
    return path, path


def _freiburg_tree(tmp: Path, lith: str = "CaMa", lines=None, cells=None, raw: Path = RAW004) -> Path:
    """A Rae2021 folder in tmp with one raw record (its lines edited) and its spreadsheet (cells edited)."""
    folder = tmp / "Rae2021" / "SHPBdata" / lith
    folder.mkdir(parents=True)
    dst = folder / raw.name
    text = raw.read_bytes().decode("latin-1").splitlines()
    dst.write_text("\n".join(lines(text) if lines else text) + "\n", encoding="latin-1")
    xlsx = tmp / "Rae2021" / f"{lith}.xlsx"
    if not cells:
        shutil.copy(RAE2021 / "CaMa.xlsx", xlsx)
        return dst
    from openpyxl import load_workbook

    wb = load_workbook(RAE2021 / "CaMa.xlsx")
    ws = wb.worksheets[0]
    rows = list(ws.iter_rows())
    head = [c.value for c in rows[0]]
    row = next(r for r in rows if r[0].value == raw.stem)
    for column, value in cells.items():
        row[head.index(column)].value = value
    wb.save(xlsx)
    return dst


def raw_record(lith: str = "CaMa", lines=None, cells=None, raw: Path = RAW004):
    def build(tmp: Path):
        path = _freiburg_tree(tmp, lith, lines, cells, raw)
        return path, path
    return build


def _raw_text(text: str):
    def build(tmp: Path):
        path = _freiburg_tree(tmp)
        path.write_text(text, encoding="latin-1")
        return path, path
    return build


# --------------------------------------------------------------------------------------------------
# The cases: (id, builder, fragments the message must hold beside the file)
# --------------------------------------------------------------------------------------------------
C, G = CAMA_SHEET, GRANITE
CASES = [
    # NaN / inf in a sheet's numbers
    ("nan bars.rho", sheet(C, "bars.rho", ".nan"), ["bars.rho", "expected a finite number"]),
    ("inf bars.E", sheet(C, "bars.E", ".inf"), ["bars.E", "expected a finite number"]),
    ("nan rock.nu", sheet(C, "rock.nu", ".nan"), ["rock.nu", "expected a finite number"]),
    ("nan bridge gain", sheet(C, "signals.bridge.gain", ".nan"), ["signals.bridge.gain", "finite number"]),
    ("nan stated rate", sheet(C, "metadata.strain_rate_per_s", ".nan"), ["metadata.strain_rate_per_s", "finite"]),
    ("-inf disc thickness", sheet(G, "specimen.thickness", "-.inf"), ["specimen.thickness", "finite number"]),
    # unit slips, one per dimensional field
    ("length in mm", sheet(C, "specimen.length", 40), ["specimen.length = 40 m", "did you mean 40 mm"]),
    ("diameter in mm", sheet(C, "specimen.diameter", 38.94), ["specimen.diameter = 38.94 m", "38.94 mm"]),
    ("rock E in GPa", sheet(C, "rock.E", 44.8), ["rock.E = 44.8 Pa", "did you mean 44.8 GPa"]),
    ("rock rho in g/cc", sheet(C, "rock.rho", 2.711), ["rock.rho = 2.711 kg/m^3", "2.711 g/cm^3"]),
    ("bar E in GPa", sheet(C, "bars.E", 110), ["bars.E = 110 Pa", "did you mean 110 GPa"]),
    ("bar rho in g/cc", sheet(C, "bars.rho", 4.43), ["bars.rho = 4.43 kg/m^3", "4.43 g/cm^3"]),
    ("bar diameter in mm", sheet(C, "bars.diameter", 50), ["bars.diameter = 50 m", "did you mean 50 mm"]),
    ("gauge x_I in mm", sheet(C, "bars.gauge_distance_incident", 1250),
     ["bars.gauge_distance_incident = 1250 m", "1250 mm"]),
    ("gauge x_T in cm", sheet(C, "bars.gauge_distance_transmitted", 100),
     ["bars.gauge_distance_transmitted = 100 m", "100 cm"]),
    ("disc thickness in mm", sheet(G, "specimen.thickness", 25), ["specimen.thickness = 25 m", "25 mm"]),
    ("disc diameter in cm", sheet(G, "specimen.diameter", 5.0), ["specimen.diameter = 5 m", "5 cm"]),
    ("gauge factor x1000", sheet(C, "signals.bridge.gauge_factor", 1990),
     ["signals.bridge.gauge_factor = 1990", "expected 0.5 to 250"]),
    ("excitation in mV", sheet(C, "signals.bridge.excitation_V", 5000),
     ["signals.bridge.excitation_V = 5000 V", "expected 0.1 V to 50 V"]),
    ("steel bar rho in g/cc", sheet(G, "bars.rho", 7.85), ["bars.rho = 7.85 kg/m^3", "g/cm^3"]),
    ("strain_per_volt per mV", sheet(REPO / "data/examples/sheets/Yao_epoxy_01.yaml", "signals.strain_per_volt", 0.501),
     ["signals.strain_per_volt = 0.501 1/V", "expected 1e-07 1/V to 0.1 1/V"]),
    ("window in us", sheet(C, "reduction.window_s", 200), ["reduction.window_s = 200 s", "did you mean 200 us"]),
    ("stated stress in MPa", sheet(C, "metadata.reference_stress_Pa", 174.1),
     ["metadata.reference_stress_Pa = 174.1 Pa", "did you mean 174.1 MPa"]),
    ("striker velocity in mm/s", sheet(C, "bars.striker.velocity", 12000), ["bars.striker.velocity = 12000 m/s"]),
    # geometry and rock
    ("specimen wider than the bar", sheet(C, "specimen.diameter", 0.06),
     ["specimen.diameter", "expected at most the bar diameter 0.05 m"]),
    ("disc thicker than the bar", sheet(G, "specimen.thickness", 0.06),
     ["specimen.thickness", "expected at most the bar diameter"]),
    ("unknown lithology", sheet_edit(C, lambda d: d.__setitem__("rock", {"lithology": "GrGr"})),
     ["rock.lithology", "expected a name or code of lithologies.csv", "'GrGr'"]),
    ("length missing", sheet_edit(C, lambda d: d["specimen"].pop("length")), ["specimen.length", "missing"]),
    ("signals file missing", sheet(C, "signals.file", "nowhere.txt"), ["signals.file", "expected an existing file"]),
    # sheet against data
    ("stated stress contradicts", sheet(C, "metadata.reference_stress_Pa", 1.2e8),
     ["metadata.reference_stress_Pa", "states 120 MPa", "172.2 MPa", "expected agreement within 25%"]),
    ("stated rate contradicts", sheet(C, "metadata.strain_rate_per_s", 152),
     ["metadata.strain_rate_per_s", "states 152 1/s", "expected agreement within 25%"]),
    ("sheet over another test's record", sheet(C, "signals.file", str(RAW014)),
     ["metadata.strain_rate_per_s", "states 91.9 1/s", "expected agreement within 25%"]),
    # window and sign: the message names the fields that set them
    ("bar E 100x low: window", sheet(C, "bars.E", 1.1e9),
     ["bars.gauge_distance_incident", "bars.E", "bars.rho", "record too short", "expected at least 10 samples"]),
    ("gauge x_I 9 m: window", sheet(C, "bars.gauge_distance_incident", 9.0),
     ["bars.gauge_distance_incident", "record too short", "2 x_I / c0"]),
    ("flipped sign csv", sheet(G, "signals.compression_sign", -1),
     ["signals.compression_sign", "record too short", "flipped compression sign"]),
    ("flipped sign freiburg", signals_freiburg(_negated),
     ["signals.format (freiburg: its sign)", "expected a quiet pre-trigger", "flipped compression sign"]),
    ("record without its pulse", signals_csv(lambda df: df.head(150)),
     ["signals.compression_sign", "no incident pulse found", "quiet pre-trigger"]),
    # time unit and sampling
    ("time unit us for s", sheet(G, "signals.time.unit", "us"),
     ["signals.time.unit: sampling interval of signals.csv = 5e-13 s", "expected 1e-09 s to 2e-05 s"]),
    ("time unit ms for s", sheet(G, "signals.time.unit", "ms"), ["signals.time.unit: sampling interval of signals.csv = 5e-10 s"]),
    ("time column in us", signals_csv(lambda df: df.assign(time_s=df["time_s"] * 1e6)),
     ["signals.time.unit: sampling interval of signals.csv = 0.5 s", "did you mean 0.5 us"]),
    # finiteness of every channel, csv and Freiburg
    ("nan incident csv", signals_csv(lambda df: df.astype({"incident_strain": float}).assign(
        incident_strain=df["incident_strain"].where(df.index != 300))),
     ["signals.incident.columns", "'incident_strain'", "data row(s) [301]"]),
    ("nan transmitted csv", signals_csv(lambda df: df.assign(
        transmitted_strain=df["transmitted_strain"].where(df.index != 500))),
     ["signals.transmitted.columns", "'transmitted_strain'", "[501]"]),
    ("nan time csv", signals_csv(lambda df: df.assign(time_s=df["time_s"].where(df.index != 7))),
     ["signals.time.column", "[8]"]),
    ("nan incident A1", signals_freiburg(lambda ls: _set_cell(ls, 400, 1, "nan")),
     ["line 400", "channel A1 (incident bar gauge 1)", "expected a finite number"]),
    ("nan reflected A2", signals_freiburg(lambda ls: _set_cell(ls, 1500, 2, "nan")),
     ["line 1500", "channel A2 (incident bar gauge 2)", "expected a finite number"]),
    ("nan transmitted A3", signals_freiburg(lambda ls: _set_cell(ls, 1200, 3, "NaN")),
     ["line 1200", "channel A3 (transmission bar gauge 1)"]),
    ("inf transmitted A4", signals_freiburg(lambda ls: _set_cell(ls, 1300, 4, "inf")),
     ["line 1300", "channel A4 (transmission bar gauge 2)"]),
    # broken files
    ("truncated freiburg signals", signals_freiburg(lambda ls: ls[:1500]), ["Blocklength", "truncated"]),
    ("empty freiburg signals", signals_freiburg(lambda ls: []), ["signals.file", "expected 11 header lines"]),
    ("empty sheet", empty_sheet, ["<top level>", "expected a mapping"]),
    ("sheet without fields", sheet_edit(C, lambda d: d.clear()), ["bars: missing", "specimen: missing"]),
    ("truncated csv", signals_csv(lambda df: df.head(10)), ["signals.time.column", "at least 20 samples"]),
    ("wrong csv columns", signals_csv(lambda df: df.rename(columns={"incident_strain": "ch1"})),
     ["signals.incident.columns", "'incident_strain' not found"]),
    ("csv not a table", signals_csv(lambda df: ""), ["signals.file", "expected a CSV file with a header row"]),
    ("freiburg row of 4 fields", signals_freiburg(lambda ls: ls[:600] + [";".join(ls[600].split(";")[:4])] + ls[601:]),
     ["line 601", "expected 5 ';'-separated numbers"]),
    # Freiburg raw records as the default config lists them
    ("raw: nan A1", raw_record(lines=lambda ls: _set_cell(ls, 400, 1, "nan")),
     ["line 400", "channel A1 (incident bar gauge 1)", "expected a finite number"]),
    ("raw: nan A2 reflected", raw_record(lines=lambda ls: _set_cell(ls, 1500, 2, "nan")),
     ["line 1500", "channel A2"]),
    ("raw: nan A3", raw_record(lines=lambda ls: _set_cell(ls, 1200, 3, "nan")), ["line 1200", "channel A3"]),
    ("raw: inf time", raw_record(lines=lambda ls: _set_cell(ls, 900, 0, "inf")), ["line 900", "time [s]"]),
    ("raw: unknown lithology", raw_record(lith="GrGr"),
     ["lithology 'GrGr'", "expected a lithology of PetrophysicalProperties.xlsx", "Carrara Marble"]),
    ("raw: specimen wider than the bar", raw_record(cells={"Sample Diameter (mm)": 70}),
     ["diameter_m = 0.07 m", "expected at most the bar diameter 0.05 m"]),
    ("raw: length in m", raw_record(cells={"Sample Length (mm)": 0.04225}),
     ["length_m (specimen.length) = 4.225e-05 m", "expected 0.0002 m to 0.2 m"]),
    ("raw: no length", raw_record(cells={"Sample Length (mm)": None}),
     ["length_m (specimen.length)", "expected a finite number"]),
    ("raw: strength contradicts", raw_record(cells={"Strength (MPa)": 120.0}),
     ["spreadsheet reference_stress_Pa", "states 120 MPa", "expected agreement within 25%"]),
    ("raw: flipped sign", raw_record(lines=_negated), ["expected a quiet pre-trigger", "flipped compression sign"]),
    ("raw: truncated", raw_record(lines=lambda ls: ls[:2000]), ["Blocklength", "truncated"]),
    ("raw: empty file", _raw_text(""), ["expected 11 header lines"]),
    ("raw: wrong columns", raw_record(lines=lambda ls: ls[:11] + [ln + ";1.0" for ln in ls[11:]]),
     ["line 12", "expected 5 ';'-separated numbers"]),
]


@pytest.mark.parametrize("builder,fragments", [pytest.param(b, f, id=i) for i, b, f in CASES])
def test_check_record_refuses_a_malformed_record(tmp_path, builder, fragments):
    record, named = builder(tmp_path)
    with pytest.raises(ObservationFileError) as err:
        check_record(record, 3.0e-4)
    msg = str(err.value)
    assert str(named) in msg, msg
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in: {msg}"


SHEET_CASES = [c for c in CASES if not c[0].startswith("raw:")]


@pytest.mark.parametrize("case", ["nan bars.rho", "length in mm", "bar E 100x low: window", "flipped sign csv",
                                  "sheet over another test's record", "nan incident A1", "time unit us for s"])
def test_reduce_names_the_sheet_and_exits_2(tmp_path, capsys, case):
    _, builder, fragments = next(c for c in SHEET_CASES if c[0] == case)
    record, named = builder(tmp_path)
    assert main(["reduce", str(record), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert str(record) in err and str(named) in err, err
    assert all(f in err for f in fragments), err
    assert not (tmp_path / "out").exists()


def test_there_are_at_least_45_distinct_cases():
    assert len({i for i, _, _ in CASES}) == len(CASES) >= 45
