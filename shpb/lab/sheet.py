"""Test sheets: one small YAML file per SHPB test that says everything the reduction and the model
need (docs/own-data.md): the signals file and its format, the bars, the specimen, the rock, metadata.

:func:`load_sheet` validates a sheet against ``sheet_schema.json`` (shipped beside this module) and
then checks what a schema cannot say: every number finite and within its field's plausible range (a
unit slip is named, :mod:`shpb.lab.checks`), the signals file exists, the specimen fits the bar, the rock
is known, the volts have their bridge constants; :func:`shpb.lab.sheet_readers.check_sheet` adds the
signals themselves (columns present, a uniform time axis, no NaN). Every problem is one line of a :class:`SheetError`
naming the sheet file, the field and what was expected, so a workflow can refuse a bad sheet before
any job runs. :func:`shpb.lab.sheet_readers.read_sheet_record` turns a valid sheet's signals into a
:class:`~shpb.lab.records.RawRecord` with the sheet's bars and specimen.

Units SI throughout (m, Pa, kg/m^3, s).
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from .bars import BarSetup, bridge_strain_per_volt
from .checks import nonfinite_problems, range_problems

__all__ = ["Sheet", "SheetError", "load_sheet", "is_sheet", "lithology_table", "SHEET_SCHEMA", "WILDCARD_SAFE",
           "FORMATS"]

SHEET_SCHEMA = Path(__file__).with_name("sheet_schema.json")
LITHOLOGY_TABLE = Path(__file__).with_name("lithologies.csv")
#: Names that are safe as Snakemake wildcards and folder names (rules/common.smk's record constraint).
WILDCARD_SAFE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
FORMATS = ("freiburg", "lanl_raw", "lanl_minikolsky", "yao", "csv")
#: Sign of a compressive strain in each format's files, where the format fixes it (csv: the sheet says).
DEFAULT_COMPRESSION_SIGN = {"freiburg": 1, "lanl_raw": 1, "lanl_minikolsky": -1, "yao": -1}
_CSV_ONLY = ("time", "incident", "transmitted")


class SheetError(ValueError):
    """A test sheet is invalid; ``problems`` holds one line per problem (sheet file: field: expected)."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


@dataclass(frozen=True)
class Sheet:
    """A validated test sheet (SI units).

    ``bar``: the :class:`BarSetup` of the reduction; its volts-to-strain factors are the sheet's, or
    1.0 where the sheet gives none (strain signals, or a LANL file that carries its own: the reader
    then uses the file's, ``strain_per_volt_given`` is False). ``bar_nu``: the bars' Poisson ratio
    (the model needs it). ``specimen``: ``geometry`` plus ``length``, ``diameter`` (cylinder) or
    ``diameter``, ``thickness``, ``flat_angle_deg`` (disc). ``rock``: ``E``, ``nu``, ``rho`` and where
    they came from (``source``).
    """

    path: Path
    name: str
    format: str
    signals_file: Path
    signals: dict
    bar: BarSetup
    bar_nu: float
    bar_material: str
    strain_per_volt_given: bool
    specimen: dict
    rock: dict
    reduction: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    @property
    def geometry(self) -> str:
        return self.specimen["geometry"]

    @property
    def specimen_diameter(self) -> float:
        return float(self.specimen["diameter"])

    @property
    def specimen_length(self) -> float | None:
        """Cylinder length [m]; None for a disc."""
        v = self.specimen.get("length")
        return None if v is None else float(v)

    def bars_summary(self) -> dict:
        """The bars as the model takes them (JSON-ready)."""
        return {"material": self.bar_material, "E": self.bar.E, "rho": self.bar.rho, "nu": self.bar_nu,
                "diameter_m": self.bar.diameter,
                "gauge_distance_m": [self.bar.gauge_distance_incident, self.bar.gauge_distance_transmitted]}


def is_sheet(path: str | Path) -> bool:
    """A record path names a test sheet when it ends in ``.yaml`` or ``.yml``."""
    return Path(path).suffix.lower() in (".yaml", ".yml")


# --------------------------------------------------------------------------------------------------
# Schema messages
# --------------------------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def _schema() -> dict:
    return json.loads(SHEET_SCHEMA.read_text())


def _field(path) -> str:
    return ".".join(str(p) for p in path) if path else "<top level>"


def _expected(err) -> str:
    """What a schema violation expected, in words."""
    v, s = err.validator, err.schema
    desc = s.get("description")
    if v == "required":
        name = re.match(r"'([^']+)'", err.message).group(1)
        sub = s.get("properties", {}).get(name, {})
        return f"missing; expected {sub.get('description') or 'this field'}"
    if v == "enum":
        return f"expected one of {s['enum']}, got {err.instance!r}"
    if v in ("exclusiveMinimum", "minimum", "exclusiveMaximum", "maximum"):
        op = {"exclusiveMinimum": ">", "minimum": ">=", "exclusiveMaximum": "<", "maximum": "<="}[v]
        return f"expected a number {op} {err.validator_value}" + (f" ({desc})" if desc else "") + \
            f", got {err.instance!r}"
    if v == "pattern":
        return f"expected {desc or 'a match of ' + err.validator_value}, got {err.instance!r}"
    if v == "type":
        return f"expected {err.validator_value}" + (f" ({desc})" if desc else "") + f", got {err.instance!r}"
    if v == "additionalProperties":
        allowed = sorted(s.get("properties", {}))
        extra = sorted(set(err.instance) - set(allowed))
        return f"unknown field(s) {extra}; expected one of {allowed}"
    return err.message


def _schema_problems(doc, where: str) -> list[str]:
    import jsonschema

    validator = jsonschema.Draft202012Validator(_schema())
    out = []
    for err in sorted(validator.iter_errors(doc), key=lambda e: [str(p) for p in e.absolute_path]):
        path = list(err.absolute_path)
        if err.validator == "required":
            path.append(re.match(r"'([^']+)'", err.message).group(1))
        out.append(f"{where}: {_field(path)}: {_expected(err)}")
    return out


# --------------------------------------------------------------------------------------------------
# Lithologies
# --------------------------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def lithology_table() -> dict[str, dict]:
    """``{key: {name, E, nu, rho, source}}`` of ``lithologies.csv``, keyed by lower-case name and code."""
    import csv

    lines = [ln for ln in LITHOLOGY_TABLE.read_text().splitlines() if ln and not ln.startswith("#")]
    out = {}
    for row in csv.DictReader(lines):
        entry = {"name": row["name"], "E": float(row["E_Pa"]), "nu": float(row["nu"]),
                 "rho": float(row["rho_kg_m3"]), "source": row["source"]}
        out[row["name"].lower()] = entry
        out[row["code"].lower()] = entry
    return out


def _rock(doc: dict, where: str, problems: list[str]) -> dict:
    rock = dict(doc.get("rock") or {})
    out: dict = {}
    lith = rock.get("lithology")
    if lith is not None:
        entry = lithology_table().get(lith.strip().lower().replace(" ", "_"))
        if entry is None:
            names = sorted({e["name"] for e in lithology_table().values()})
            problems.append(f"{where}: rock.lithology: expected a name or code of {LITHOLOGY_TABLE.name} "
                            f"({names}) or the rock's E, nu, rho, got {lith!r}")
            return {}
        out = {"E": entry["E"], "nu": entry["nu"], "rho": entry["rho"], "lithology": entry["name"],
               "source": f"{LITHOLOGY_TABLE.name}: {entry['source']}"}
    missing = [k for k in ("E", "nu", "rho") if k not in rock and k not in out]
    if missing:
        problems.append(f"{where}: rock: expected a lithology or all of E, nu, rho; missing {missing}")
        return {}
    given = {k: float(rock[k]) for k in ("E", "nu", "rho") if k in rock}
    if given:
        out = {**out, **given, "source": "sheet" if len(given) == 3 else f"sheet ({sorted(given)}) and {out['source']}"}
    return out


# --------------------------------------------------------------------------------------------------
# Semantic checks
# --------------------------------------------------------------------------------------------------
def _strain_per_volt(sig: dict, where: str, problems: list[str]) -> tuple[float, float] | None:
    """(incident, transmitted) volts-to-strain factors of the sheet, or None where it gives none."""
    if "strain_per_volt" in sig and "bridge" in sig:
        problems.append(f"{where}: signals.strain_per_volt: expected either strain_per_volt or bridge, not both")
        return None
    if "bridge_transmitted" in sig and "bridge" not in sig:
        problems.append(f"{where}: signals.bridge_transmitted: expected signals.bridge as well (the incident bar's)")
        return None
    if "strain_per_volt" in sig:
        f = float(sig["strain_per_volt"])
        return f, f

    def factor(b):
        return bridge_strain_per_volt(b["excitation_V"], b["gain"], b["gauge_factor"], b.get("active_arms", 1))
    if "bridge" in sig:
        fi = factor(sig["bridge"])
        return fi, factor(sig.get("bridge_transmitted", sig["bridge"]))
    return None


def _signals_problems(sig: dict, spv, where: str, problems: list[str]) -> None:
    fmt = sig["format"]
    if fmt == "csv":
        for key in (*_CSV_ONLY, "compression_sign"):
            if key not in sig:
                problems.append(f"{where}: signals.{key}: missing; format csv needs it "
                                + ("(1 if compression reads positive, -1 if negative)" if key == "compression_sign"
                                   else "(the column names and unit)"))
        units = {sig[k]["unit"] for k in ("incident", "transmitted") if k in sig}
        if len({"V" if u in ("V", "mV") else "strain" for u in units}) > 1:
            problems.append(f"{where}: signals.transmitted.unit: expected the same kind of unit as "
                            f"signals.incident.unit (both volts or both strain), got {sorted(units)}")
        if units & {"V", "mV"} and spv is None:
            problems.append(f"{where}: signals.bridge: missing; volts need the bridge constants "
                            f"(excitation_V, gain, gauge_factor, active_arms) or signals.strain_per_volt")
    else:
        for key in _CSV_ONLY:
            if key in sig:
                problems.append(f"{where}: signals.{key}: only format csv takes it (format {fmt!r} fixes its columns)")
    if fmt == "freiburg" and spv is None:
        problems.append(f"{where}: signals.bridge: missing; Freiburg records are volts and need the bridge "
                        f"constants (Freiburg: excitation_V 5, gain 400, gauge_factor 1.99, active_arms 1)")


def _specimen_problems(spec: dict, bar_d: float, where: str, problems: list[str]) -> None:
    """The specimen must fit the bar: the bar's face covers a cylinder's face, a disc's thickness and flats."""
    if spec["geometry"] == "cylinder":
        if spec["diameter"] > bar_d:
            problems.append(f"{where}: specimen.diameter: expected at most the bar diameter {bar_d:g} m "
                            f"(bars.diameter: the bar's face must cover the specimen's), got {spec['diameter']:g} m")
        return
    if spec["thickness"] > bar_d:
        problems.append(f"{where}: specimen.thickness: expected at most the bar diameter {bar_d:g} m "
                        f"(the disc lies across the bar's face), got {spec['thickness']:g} m")
    flat = spec["diameter"] * math.sin(math.radians(0.5 * spec["flat_angle_deg"]))
    if flat > bar_d:
        problems.append(f"{where}: specimen.flat_angle_deg: expected flats no wider than the bar diameter "
                        f"{bar_d:g} m, got {flat:g} m (D sin(angle/2))")


# --------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------
def _read_yaml(path: Path) -> object:
    import yaml

    if not path.is_file():
        raise SheetError([f"{path}: test sheet not found"])
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise SheetError([f"{path}: not valid YAML: {exc}"]) from None


def _numbers(obj):
    """YAML 1.1 reads 4.0e9 as a string: turn strings that are exactly a number into floats."""
    if isinstance(obj, dict):
        return {k: _numbers(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_numbers(v) for v in obj]
    if isinstance(obj, str) and re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)", obj.strip()):
        return float(obj)
    return obj


def load_sheet(path: str | Path) -> Sheet:
    """Read and validate a test sheet (its signals are read by :func:`shpb.lab.sheet_readers.check_sheet`,
    which checks them as well: columns present, uniform time, no NaN).

    Raises
    ------
    SheetError
        Listing every problem as ``<sheet file>: <field>: <what was expected>``.
    """
    path = Path(path)
    where = str(path)
    doc = _numbers(_read_yaml(path))
    if not isinstance(doc, dict):
        raise SheetError([f"{where}: <top level>: expected a mapping of name, signals, bars, specimen, rock"])
    # NaN and inf first: JSON schema's "number" takes them, and a NaN passes every bound
    problems = nonfinite_problems(doc, where) or _schema_problems(doc, where)
    problems = problems or range_problems(doc, where)
    if problems:
        raise SheetError(problems)
    sig, bars, spec = doc["signals"], doc["bars"], doc["specimen"]
    signals_file = (path.parent / sig["file"]) if not Path(sig["file"]).is_absolute() else Path(sig["file"])
    if not signals_file.exists():
        problems.append(f"{where}: signals.file: expected an existing file (relative to the sheet), "
                        f"{sig['file']!r} not found (looked at {signals_file})")
    spv = _strain_per_volt(sig, where, problems)
    _signals_problems(sig, spv, where, problems)
    _specimen_problems(spec, float(bars["diameter"]), where, problems)
    rock = _rock(doc, where, problems)
    if problems:
        raise SheetError(problems)
    sign = int(sig.get("compression_sign", DEFAULT_COMPRESSION_SIGN.get(sig["format"], 1)))
    fi, ft = spv if spv is not None else (1.0, 1.0)
    bar = BarSetup(E=float(bars["E"]), rho=float(bars["rho"]), diameter=float(bars["diameter"]),
                   gauge_distance_incident=float(bars["gauge_distance_incident"]),
                   gauge_distance_transmitted=float(bars["gauge_distance_transmitted"]),
                   strain_per_volt_incident=fi, strain_per_volt_transmitted=ft, compression_sign=sign,
                   name=str(bars.get("material", "")))
    sheet = Sheet(path=path, name=doc["name"], format=sig["format"], signals_file=signals_file, signals=dict(sig),
                  bar=bar, bar_nu=float(bars["nu"]), bar_material=str(bars.get("material", "")),
                  strain_per_volt_given=spv is not None, specimen=dict(spec), rock=rock,
                  reduction=dict(doc.get("reduction") or {}), metadata=dict(doc.get("metadata") or {}))
    return sheet
