"""Compare two results trees of the same config and seed, file by file.

    python tools/compare_runs.py BEFORE/results AFTER/results [--out JSON]

Every file present in both trees is compared: CSV files as tables (exactly, without columns of wall
times), JSON files as data without timings (keys containing "wall", and speeds: "per_s"), log files
(.log) not at all (they hold timings; listed apart), everything else byte for byte. A JSON
file whose only differences are keys present in one tree alone is reported with those keys. Prints
(or writes) one JSON report: identical files, files identical but for timings, files that differ
(with the first differing key or column), and files found in one tree only.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd


def _timing(key: str) -> bool:
    return "wall" in key or "per_s" in key


def _strip(obj, path=""):
    if isinstance(obj, dict):
        return {k: _strip(v, f"{path}.{k}") for k, v in obj.items() if not _timing(k)}
    if isinstance(obj, list):
        return [_strip(v, path) for v in obj]
    return obj


def _first_diff(a, b, path=""):
    """(the first key path where two JSON values differ, or None; the key paths only one side has)."""
    if isinstance(a, dict) and isinstance(b, dict):
        only = [f"{path}.{k}" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            d, o = _first_diff(a[k], b[k], f"{path}.{k}")
            only += o
            if d:
                return d, only
        return None, only
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{path} (length {len(a)} vs {len(b)})", []
        only = []
        for i, (x, y) in enumerate(zip(a, b)):
            d, o = _first_diff(x, y, f"{path}[{i}]")
            only += o
            if d:
                return d, only
        return None, only
    return (None, []) if a == b else (path or "(value)", [])


def compare_file(a: Path, b: Path) -> tuple[str, str]:
    """(status, detail): identical, identical_but_timings, one_sided_keys, differ, log."""
    if a.suffix == ".log":
        return "log", ""
    if a.suffix == ".csv":
        x, y = pd.read_csv(a), pd.read_csv(b)
        if x.equals(y):
            return "identical", ""
        x, y = x[[c for c in x.columns if not _timing(c)]], y[[c for c in y.columns if not _timing(c)]]
        if x.equals(y):
            return "identical_but_timings", ""
        cols = [c for c in x.columns if c not in y.columns or not x[c].equals(y[c])]
        return "differ", f"columns {cols[:5]}" if cols else "shape"
    if a.suffix == ".json":
        x, y = json.loads(a.read_text()), json.loads(b.read_text())
        if x == y:
            return "identical", ""
        d, only = _first_diff(_strip(x), _strip(y))
        if d:
            return "differ", d
        return ("one_sided_keys", ", ".join(only)) if only else ("identical_but_timings", "")
    return ("identical", "") if a.read_bytes() == b.read_bytes() else ("differ", "bytes")


def compare(before: Path, after: Path) -> dict:
    fa = {p.relative_to(before) for p in before.rglob("*") if p.is_file()}
    fb = {p.relative_to(after) for p in after.rglob("*") if p.is_file()}
    out = {"before": str(before), "after": str(after), "identical": [], "identical_but_timings": [],
           "one_sided_keys": {}, "differ": {}, "logs_not_compared": [], "only_before": sorted(map(str, fa - fb)),
           "only_after": sorted(map(str, fb - fa))}
    for rel in sorted(fa & fb):
        status, detail = compare_file(before / rel, after / rel)
        if status in ("identical", "identical_but_timings"):
            out[status].append(str(rel))
        elif status == "log":
            out["logs_not_compared"].append(str(rel))
        else:
            out[status][str(rel)] = detail
    out["counts"] = {k: len(out[k]) for k in ("identical", "identical_but_timings", "one_sided_keys", "differ",
                                             "logs_not_compared", "only_before", "only_after")}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    rep = compare(a.before, a.after)
    text = json.dumps(rep, indent=1)
    if a.out:
        a.out.write_text(text + "\n")
    print(json.dumps(rep["counts"]))
    return 0 if not rep["differ"] else 1


if __name__ == "__main__":
    sys.exit(main())
