"""The planted-effect benchmark's score in docs/closing-the-loop.md, generated from its committed JSON.

    python tools/planted_table.py benchmarks/results/bench_planted.json [--docs]

prints (or with --docs writes between the markers of docs/closing-the-loop.md) one row per planted
case (what each seed's loop named, the planted effect's place in the selection's first ranking, the
planted parameter inside the shipped model's 90 % interval, the held-out record's RMSE before and after)
and the plan's bars against the measured shares, so the numbers are quoted from one source
(tests/test_docs_tables.py checks it).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_planted import bar_counts  # noqa: E402

DOC = ROOT / "docs" / "closing-the-loop.md"
START, END = "<!-- planted-table:start -->", "<!-- planted-table:end -->"
# the plan's case classes, in the order the table shows them
CLASSES = ("physical", "measurement", "null", "out_of_catalogue")
CLASS_NAMES = {"physical": "physical", "measurement": "measurement", "null": "null",
               "out_of_catalogue": "outside the catalogue"}


def _named(r: dict) -> str:
    mark = " (right)" if r.get("correct") else ""
    return f"`{r['named']}`{mark}" if not r.get("error") else "did not finish"


def _rank(r: dict) -> str:
    p = r.get("proposals")
    return "-" if not p or p.get("planted_rank") is None else str(p["planted_rank"])


def _heldout(r: dict) -> str:
    h = list((r.get("heldout") or {}).values())
    if not h:
        return "-"
    return ", ".join(f"{x['rmse_before_Pa'] / 1e6:.1f} -> {x['rmse_after_Pa'] / 1e6:.1f}" for x in h)


def _covered(r: dict) -> str:
    checks = (r.get("coverage") or {}).get("checks") or []
    if not checks or not r.get("correct"):
        return "-"
    return f"{sum(bool(c['inside']) for c in checks)} of {len(checks)}"


def _scatter(rows: list[dict]) -> str:
    vals = {r.get("above_scatter") for r in rows}
    return "yes" if vals == {True} else "no" if vals == {False} else "-" if vals == {None} else "mixed"


def case_rows(doc: dict) -> list[str]:
    by_case: dict[str, list[dict]] = {}
    for r in sorted(doc["series"], key=lambda r: r["seed"]):
        by_case.setdefault(r["case"]["case"], []).append(r)
    order = sorted(by_case, key=lambda c: (CLASSES.index(by_case[c][0]["case"]["class"]), c))
    out = ["| planted | kind | beyond the mesh scatter | named, per seed (ascending) | planted effect's rank in the first round | "
           "planted values inside their 90 % intervals (where named) | held-out RMSE before -> after [MPa] |",
           "|---|---|---|---|---|---|---|"]
    for c in order:
        rows = by_case[c]
        out.append(f"| `{c}` | {CLASS_NAMES[rows[0]['case']['class']]} | {_scatter(rows)} | "
                   + "; ".join(_named(r) for r in rows) + " | " + ", ".join(_rank(r) for r in rows) + " | "
                   + "; ".join(_covered(r) for r in rows) + " | " + "; ".join(_heldout(r) for r in rows) + " |")
    return out


def _share(x) -> str:
    return "-" if x is None else f"{x:.2f}"


def bar_rows(doc: dict, plan: dict) -> list[str]:
    s, a, bars = doc["scores"], doc["acceptance"], plan["acceptance"]
    n = {k: f"{hits} of {series}" for k, (hits, series) in bar_counts(doc["series"]).items()}
    fp = s["null_false_positive_rate"]
    yes = {True: "yes", False: "**no**", None: "-"}
    return ["| the plan's bar | measured | share | bar | met |", "|---|---|---|---|---|",
            f"| a physical effect beyond the scatter named first | {n['physical_named_top']} | "
            f"{_share(s['physical_named_top_share'])} | >= {bars['physical_named_top_share_min']:.2f} | {yes[a['physical_named']]} |",
            f"| its parameter inside the 90 % interval (named series) | {n['parameter_in_90']} | "
            f"{_share(s['parameter_in_90_share'])} | >= {bars['parameter_in_90_interval_share_min']:.2f} | {yes[a['parameter_in_90']]} |",
            f"| a null adds nothing | {n['null_adds_nothing']} | {_share(None if fp is None else 1 - fp)} | "
            f">= {bars['null_adds_nothing_share_min']:.2f} | {yes[a['null_adds_nothing']]} |",
            f"| outside the catalogue ends `base_kept` or `unexplained` | {n['out_of_catalogue_ok']} | "
            f"{_share(s['out_of_catalogue_ok_share'])} | >= {bars['out_of_catalogue_unexplained_or_base_kept_share_min']:.2f} | "
            f"{yes[a['out_of_catalogue']]} |"]


def block(path: str) -> str:
    doc = json.loads((ROOT / path).read_text())
    plan = json.loads((ROOT / "benchmarks" / "planted_plan.json").read_text())
    s = doc["scores"]
    head = (f"From `{path}` ({s['finished']} series of {s['series']}, {doc['cores']} cores, "
            f"{doc['wall_s'] / 3600:.1f} h of series in all):")
    return "\n".join([START, head, "", *bar_rows(doc, plan), "", *case_rows(doc), END])


def main(argv=None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    write = "--docs" in args
    args = [a for a in args if a != "--docs"]
    text = block(args[0])
    if not write:
        print(text)
        return
    doc = DOC.read_text()
    start, end = doc.index(START), doc.index(END) + len(END)
    DOC.write_text(doc[:start] + text + doc[end:])


if __name__ == "__main__":
    main()
