"""The text of each Snakemake rule, read from the workflow files (tests/test_slurm.py,
tests/test_snakemake_conventions.py)."""
from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path


def rule_texts(paths: Iterable[Path]) -> tuple[dict[str, str], set[str]]:
    """({rule name: its text}, the localrules) of the given files. A `use rule <base> as <name> with:` is its
    own text followed by the base's, so that a section it overrides is found first and one it inherits after."""
    rules, local, uses = {}, set(), {}
    for path in paths:
        text = Path(path).read_text()
        # one line (`localrules: a, b`) or snakefmt's one name per indented line
        for m in re.finditer(r"^localrules:((?:(?:[ \t]*|\n[ \t]+)\w+[ \t]*,?)+)", text, re.M):
            local |= {n.strip() for n in m.group(1).replace("\n", ",").split(",") if n.strip()}
        for b in re.split(r"^(?=(?:rule|checkpoint|use rule \w+ as) \w+)", text, flags=re.M):
            m = re.match(r"(?:rule|checkpoint) (\w+):", b)
            if m:
                rules[m.group(1)] = b
            m = re.match(r"use rule (\w+) as (\w+) with:", b)
            if m:
                uses[m.group(2)] = (m.group(1), b)
    return rules | {name: b + rules[base] for name, (base, b) in uses.items()}, local
