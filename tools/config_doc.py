"""config/README.md from config/schema.yaml: every config key with its meaning, type, default and unit.

    python tools/config_doc.py            # rewrite config/README.md
    python tools/config_doc.py --check    # exit 1 if config/README.md is not what the schema gives

The schema is the one source: a key's meaning is its `description`, its type its `type`/`enum`/`anyOf`,
its default its `default` ("required" where the schema requires it), its unit the key's SI suffix
(`_s`, `_Pa`, `_m`), a time key's name (`t_end`, `dt`, ...) or the first `[unit]` its description names. tests/test_snakemake_conventions.py
checks that the committed README is the regenerated one, so a schema change is one command away from
its documentation.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"
README = REPO / "config" / "README.md"

NO_DESCRIPTION = "(no description in the schema)"
#: Units a description may name in brackets, e.g. "end of the simulated window [s]".
UNIT_IN_TEXT = re.compile(r"\[(s|Pa|MPa|m|J/m\^2|1/s|m/Pa|kg/m\^3)\]")
#: SI suffixes of key names (seating.compliance_m_per_Pa, sigma_Pa, member_time_limit_s).
UNIT_SUFFIX = (("_m_per_Pa", "m/Pa"), ("_Pa", "Pa"), ("_s", "s"), ("_m", "m"))
#: Keys that are times by name (the observation and simulation windows, grids and correlation times).
TIME_KEYS = {"t_start", "t_end", "dt", "sample_dt", "corr_time"}

HEADER = """# Workflow configuration

`config/config.yaml` is the default run's configuration; `--configfile FILE` adds or overrides keys
(`config/paper_twins.yaml`, `config/diagnosis.yaml`, `.test/config/config.yaml` are examples). Every
file is validated against `config/schema.yaml` before any job runs: a misspelt key, a value of the
wrong type or outside its range stops the run with a message naming the file, the key and the value.
Units are SI (Pa, J/m^2, s, m); write numbers in scientific notation with a signed exponent (`4.0e+6`).

An experiment is one entry under `experiments:`; `run:` names the ones the default target runs.
The smallest complete example is `.test/config/config.yaml` (CI's fast lane,
`snakemake --cores 2 --directory .test`).

The tables below are generated from the schema's descriptions by `python tools/config_doc.py`
(do not edit them by hand). Nested keys are written with dots: `observations.noise.relative_sigma`
is `relative_sigma` inside `noise` inside `observations`. "required" means the key has no default.
"""


def _type(node: dict) -> str:
    if "const" in node:
        return f"`{node['const']}`"
    if "enum" in node:
        return "one of " + ", ".join(f"`{v}`" if v is not None else "`null`" for v in node["enum"])
    for key in ("anyOf", "oneOf"):
        if key in node:
            return " or ".join(_type(alt) for alt in node[key])
    kind = node.get("type")
    kinds = kind if isinstance(kind, list) else [kind] if kind else []
    names = []
    for k in kinds:
        if k == "array" and isinstance(node.get("items"), dict) and node["items"].get("type"):
            names.append(f"list of {node['items']['type']}")
        elif k == "object" and isinstance(node.get("additionalProperties"), dict) and "properties" not in node:
            names.append(f"mapping to {_type(node['additionalProperties'])}")
        else:
            names.append(str(k))
    return " or ".join(names) if names else "any"


def _default(node: dict, required: bool) -> str:
    if "default" in node:
        return f"`{json.dumps(node['default'])}`"
    return "required" if required else "none"


def _unit(name: str, description: str) -> str:
    if name in TIME_KEYS:
        return "s"
    for suffix, unit in UNIT_SUFFIX:
        if name.endswith(suffix):
            return unit
    m = UNIT_IN_TEXT.search(description)
    if m:
        return m.group(1)
    return "SI" if re.search(r"\bSI\b", description) else ""


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def rows(node: dict, prefix: str = "", unit: str = "") -> list[tuple[str, str, str, str, str]]:
    """(dotted key, meaning, type, default, unit) of every key under `node`'s properties, depth first; a
    key without a unit of its own has its parent's (member_time_limit_s.fast: s)."""
    out = []
    required = set(node.get("required", []))
    for name, child in (node.get("properties") or {}).items():
        path = f"{prefix}{name}"
        description = child.get("description", "")
        own = _unit(name, description) or unit
        out.append((path, _cell(description) or NO_DESCRIPTION, _cell(_type(child)),
                    _default(child, name in required), own))
        out += rows(child, f"{path}.", own)
    return out


def _table(entries) -> str:
    lines = ["| key | meaning | type | default | unit |", "|---|---|---|---|---|"]
    lines += [f"| `{k}` | {m} | {t} | {d} | {u} |" for k, m, t, d, u in entries]
    return "\n".join(lines) + "\n"


def render(schema: dict) -> str:
    top = dict(schema)
    experiments = schema["properties"]["experiments"]["additionalProperties"]
    top_rows = [r for r in rows(top) if r[0] != "experiments"]
    return (HEADER + "\n## Run keys (top level)\n\n" + _table(top_rows)
            + "\n## Experiment keys (`experiments.<name>.<key>`)\n\n" + _table(rows(experiments)))


def undocumented(schema: dict) -> list[str]:
    """Experiment and run keys whose schema entry has no description."""
    experiments = schema["properties"]["experiments"]["additionalProperties"]
    return [r[0] for r in rows(schema) + rows(experiments) if r[1] == NO_DESCRIPTION and r[0] != "experiments"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if config/README.md differs from the schema's")
    ap.add_argument("--undocumented", action="store_true", help="list the keys without a description")
    a = ap.parse_args(argv)
    schema = yaml.safe_load(SCHEMA.read_text())
    if a.undocumented:
        print("\n".join(undocumented(schema)))
        return 0
    text = render(schema)
    if a.check:
        if not README.exists() or README.read_text() != text:
            print(f"{README.relative_to(REPO)} is out of date: run python tools/config_doc.py", file=sys.stderr)
            return 1
        return 0
    README.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
