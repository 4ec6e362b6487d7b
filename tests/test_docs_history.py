"""README.md and docs/*.md state the current state for users: no commit hashes, dates or seed histories
(those belong in CHANGELOG.md and studies/README.md), no path to a file that is not in the repository,
and a README short enough to read, whose test command is the one CI runs."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# a commit-like token: 7-40 hex characters with at least one digit and one letter, standing alone
# (an underscore or a dot around it does not make it part of a word: file names carry hashes too)
HEX = re.compile(r"(?<![0-9A-Za-z])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![0-9A-Za-z])")
ISO_DATE = re.compile(r"(?<!\d)(?:19|20)\d\d-[01]\d-[0-3]\d(?!\d)")
# "seed 64", "seeds (45, 49)", "_seed64" in a file name; `mesh_seed 3`, a config key, is not a history
SEED = re.compile(r"(?<![A-Za-z])(?<!mesh_)seeds?[ _]?\(?\d+", re.IGNORECASE)
PATTERNS = {"commit hash": HEX, "ISO date": ISO_DATE, "seed number": SEED}
# Tokens that match a pattern and are not history; none is needed today. Add (pattern name, token)
# pairs only with the reason beside them.
WHITELIST: set = set()
# repository paths cited in prose; placeholders (<exp>, {a,b}, *) are not checked
PATH = re.compile(r"(?<![\w/.])((?:benchmarks|studies|tools|docs|config|data|tests|calibration|enkf|shpb|fdem"
                  r"|scripts|rules|profiles|report)/[\w./{},*<>-]*[\w/])")


def _docs() -> list:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def history_tokens(text: str) -> list:
    """``[(line number, pattern name, token)]`` of every hash, date or seed number in ``text``."""
    out = []
    for i, line in enumerate(text.splitlines(), 1):
        for name, rx in PATTERNS.items():
            out += [(i, name, m.group(0)) for m in rx.finditer(line) if (name, m.group(0)) not in WHITELIST]
    return out


def missing_paths(text: str, base: Path) -> list:
    """Paths cited in ``text`` that exist neither from the repository root nor from ``base``."""
    out = []
    for m in PATH.finditer(text):
        p = m.group(1)
        if not any(c in p for c in "{}*<>") and not (ROOT / p).exists() and not (base / p).exists():
            out.append(p)
    return out


@pytest.mark.parametrize("text, found", [
    ("a fresh clone of 860f5e5 in an empty folder", [(1, "commit hash", "860f5e5")]),
    ("`benchmarks/results/default_run_2026-11-29_860f5e5/`",
     [(1, "commit hash", "860f5e5"), (1, "ISO date", "2026-11-29")]),
    ("measured 2026-11-24, JSON in", [(1, "ISO date", "2026-11-24")]),
    ("development seed 62 chose it", [(1, "seed number", "seed 62")]),
    ("on four fresh seeds (45, 49)", [(1, "seed number", "seeds (45")]),
    ("Seeds 45, 49", [(1, "seed number", "Seeds 45")]),
    ("`bench_coverage_seed64_heteroscedastic.json`", [(1, "seed number", "seed64")]),
    ("line one\nthe commit 3b80388a12", [(2, "commit hash", "3b80388a12")]),
    # not history: numbers, words of hex letters, a config key, a paper's year, a range of sizes
    ("1,100 s in 5656 moves; a decade; `mesh_seed` 1-8; mesh_seed 3; Godinez & Rougier (2021); 2021-2024 runs; 0x1f", []),
    ("deadbeef 1234567 abcdefa", []),
])
def test_the_history_patterns_find_hashes_dates_and_seeds_and_nothing_else(text, found):
    assert history_tokens(text) == found


@pytest.mark.parametrize("path", _docs(), ids=lambda p: p.name)
def test_readme_and_docs_carry_no_commit_hashes_dates_or_seed_histories(path):
    assert history_tokens(path.read_text()) == [], f"{path.name}: move the history to CHANGELOG.md"


@pytest.mark.parametrize("path", _docs(), ids=lambda p: p.name)
def test_every_repository_path_cited_in_readme_and_docs_exists(path):
    assert missing_paths(path.read_text(), path.parent) == []


def test_a_missing_path_is_found_and_a_placeholder_is_not_checked():
    text = "see `studies/no_such_study.py`, `results/<exp>/`, `tools/{a,b}.py` and `studies/README.md`"
    assert missing_paths(text, ROOT) == ["studies/no_such_study.py"]


def test_the_readme_explains_every_verdict_the_code_can_give():
    from calibration.verdict import FLAG_ORDER

    text = (ROOT / "README.md").read_text()
    rows = {line.split("|")[1].strip() for line in text.splitlines() if line.startswith("| `")}
    assert {f"`{v}`" for v in (*FLAG_ORDER, "ok")} <= rows
    assert "`confirmed`" in text and "`base_kept`" in text


def test_the_readme_is_short_and_runs_the_ci_test_command():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    assert 'pip install -e ".[test]" && pytest -q\n' in text
    assert "pip install -e . && snakemake --cores 2\n" in text
