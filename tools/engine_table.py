"""The engine's speed tables in docs/engine.md, generated from the committed benchmark JSON.

    python tools/engine_table.py benchmarks/results/bench_engine.json \
        studies/results/profile_engine.json [--docs]

prints (or with --docs writes between the markers of docs/engine.md) the before/after table of
benchmarks/bench_engine.py and the profile of studies/profile_engine.py, so the numbers are quoted
from one source (tests/test_docs_tables.py checks it).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "engine.md"
START, END = "<!-- engine-table:start -->", "<!-- engine-table:end -->"
PART_NAMES = {"node_update": "node update", "contact_refresh": "contact list", "triangles": "triangles",
              "joints": "joints", "damage_bookkeeping": "damage bookkeeping",
              "contact_forces": "contact forces", "rest_of_step": "rest (tractions, kick)"}


def _speed(bench: dict) -> list[str]:
    rows = ["| member | steps | solver before [s] | solver after [s] | speed-up | member wall after [s] | updates/s after | curves | max diff to the peak | peak diff |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for label, r in bench["cases"].items():
        a, b = r["baseline"], r["new"]
        ag = r["agreement"]
        same = "bit-identical" if ag["bit_identical"] else "differ"
        rows.append(f"| {label} | {b['steps']:,} | {a['solver_wall_s']:.2f} | {b['solver_wall_s']:.2f} | "
                    f"{r['speedup_solver']:.1f}x | {b['wall_s']:.2f} | {b['element_updates_per_s'] / 1e6:.0f}e6 | {same} | "
                    f"{100 * ag['max_diff_to_peak_over_peak']:.2g} % | {100 * ag['peak_rel_diff']:.2g} % |")
    return rows


def _profile(prof: dict) -> list[str]:
    cases = prof["cases"]
    head = "| part of the step | " + " | ".join(c["case"] for c in cases) + " |"
    rows = [head, "|---|" + "---|" * len(cases)]
    for key, name in PART_NAMES.items():
        rows.append(f"| {name} | " + " | ".join(
            f"{c['parts_s'][key]:.2f} s ({100 * c['parts_share'][key]:.0f} %)" for c in cases) + " |")
    rows.append("| sum of parts / solver time | " + " | ".join(f"{c['parts_sum_over_solver']:.2f}" for c in cases) + " |")
    return rows


def table(bench: dict, prof: dict, bench_path: str, prof_path: str) -> str:
    # the revisions compared are in the JSON (and the CHANGELOG); the docs state the current engine only
    lines = [f"Before and after the engine's speed work (`{bench_path}`: {bench['cores_on_machine']} cores, one process at a time on one core; solver time, warm JIT):",
             "", *_speed(bench), "",
             f"Where a step's time goes now (`{prof_path}`, timers inside the step loop):", "", *_profile(prof)]
    return "\n".join(lines)


def block(bench_path: str, prof_path: str) -> str:
    bench = json.loads((ROOT / bench_path).read_text())
    prof = json.loads((ROOT / prof_path).read_text())
    return f"{START}\n{table(bench, prof, bench_path, prof_path)}\n{END}"


def doc_block_sources(text: str) -> tuple[str, str]:
    """The two JSON paths named in the block of docs/engine.md."""
    inner = text.split(START, 1)[1].split(END, 1)[0]
    parts = inner.split("`")
    return parts[1], [p for p in parts[3::2] if p.endswith(".json")][0]


def main(argv) -> int:
    bench_path, prof_path = argv[1], argv[2]
    if "--docs" in argv:
        text = DOC.read_text()
        a, b = text.index(START), text.index(END) + len(END)
        DOC.write_text(text[:a] + block(bench_path, prof_path) + text[b:])
    else:
        print(block(bench_path, prof_path))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
