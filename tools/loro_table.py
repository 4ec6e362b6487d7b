"""The leave-one-record-out table of docs/closing-the-loop.md, generated from the series' committed
``loro/summary.json`` (one source for the numbers).

    python tools/loro_table.py benchmarks/results/loro_seen/marble_loro.json [more series] [--docs]
    python tools/loro_table.py --add-risk <series summary.json> <its folds' report.json ...>
    python tools/loro_table.py --figure <series summary.json> <folds.png>   # the series' figure, re-made

The block sits between ``<!-- loro-table:start -->`` and ``<!-- loro-table:end -->`` in
docs/closing-the-loop.md;
``tests/test_docs_tables.py`` checks that it equals what this tool makes from the JSON files named in it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
START, END = "<!-- loro-table:start -->", "<!-- loro-table:end -->"


def _mpa(v) -> str:
    return "-" if v is None else f"{v / 1e6:.1f}"


def _pct(e) -> str:
    return "-" if e is None else f"{100 * e:+.0f} %"


def _cov(c) -> str:
    return "-" if c is None else f"{c:.2f}"


def _coverage(r: dict) -> str:
    """The held-out record's 90 % predictive band coverage before -> after ("-" for a fold run before the
    check reported it)."""
    b, a = r.get("predictive_coverage_90_before"), r.get("predictive_coverage_90_after")
    return ("-" if b is None and a is None else f"{_cov(b)} -> {_cov(a)}") + _over_box(
        r.get("interval_score_over_box_before"), r.get("interval_score_over_box_after"))


def _over_box(b, a) -> str:
    """The band's interval score over the design box's band, before -> after ("" for a fold run before the
    check scored it)."""
    return "" if b is None and a is None else f"; score/box {_cov(b)} -> {_cov(a)}"


def _mean_coverage(series: dict) -> str:
    vals = {}
    for w in ("before", "after"):
        got = [r[f"predictive_coverage_90_{w}"] for r in series["rows"] if r.get(f"predictive_coverage_90_{w}") is not None]
        vals[w] = (sum(got) / len(got), len(got)) if got else None
    if vals["before"] is None and vals["after"] is None:
        return "-"
    n = max(v[1] for v in vals.values() if v is not None)
    t = series["totals"]
    return (f"**{_cov(vals['before'] and vals['before'][0])} -> {_cov(vals['after'] and vals['after'][0])}**"
            f" ({n} of {len(series['rows'])} folds)" + _over_box(t.get("mean_interval_score_over_box_before"),
                                                                 t.get("mean_interval_score_over_box_after")))


#: Committed folders of series run again, and how the table marks them: ``loro_rerun_*`` the same records
#: and config through later code, ``loro_anchored_*`` that, with the shipped default selection
#: (``selection_model: anchored``) instead of the emulator of the first runs, ``loro_gated_*`` that, with
#: each fold re-fitted and gated as a held-out experiment is.
MARKS = {"loro_rerun": " (re-run)", "loro_anchored": " (re-run, anchored)", "loro_gated": " (re-run, folds gated)"}


def _label(series: dict, path: str) -> str:
    """The series' name, marked where the committed folder holds a re-run of a series run before
    (:data:`MARKS`)."""
    folder = Path(path).parent.name
    return series["experiment"] + next((m for k, m in MARKS.items() if folder.startswith(k)), "")


def rows(series: dict, label: str | None = None) -> list[str]:
    label = label or series["experiment"]
    out = []
    for r in series["rows"]:
        rate = r.get("strain_rate_per_s")
        out.append(
            f"| {label} | {r['heldout']}" + (f" ({rate:.0f} 1/s)" if rate else "")
            + f" | {', '.join(r['effects']) or 'none (base kept)'} "
            f"| {_mpa(r['rmse_before'])} -> {_mpa(r['rmse_after'])} "
            f"| {_pct(r.get('peak_rel_error_before'))} -> {_pct(r.get('peak_rel_error_after'))} "
            f"| {r['time_to_peak_error_before'] * 1e6:+.0f} -> {r['time_to_peak_error_after'] * 1e6:+.0f} "
            f"| {_coverage(r)} |")
    t = series["totals"]
    sd = t.get("sd_rmse_change")
    out.append(f"| {label} | **mean over {t['folds']} folds** | "
               + ", ".join(f"{e} {n}/{t['folds']}" for e, n in t["effects_kept"].items())
               + f" | **{_mpa(t['mean_rmse_before'])} -> {_mpa(t['mean_rmse_after'])}** (change "
               f"{t['mean_rmse_change'] / 1e6:+.1f}" + (f", sd {sd / 1e6:.1f}" if sd is not None else "")
               + f"; {t['folds_worse']} fold(s) worse)" + _risk(t.get("cv_risk_worse_than_base"))
               + f" | | | {_mean_coverage(series)} |")
    return out


def _risk(r) -> str:
    """The calibration records' real cross-validation runs predicted worse than the base (the chance that a
    new record is), and what that rate gives for 'no fold worse' in a series of this length."""
    if not r or not r.get("records"):
        return ""
    lo, hi = r["ci90"]
    plo, phi = r["p_no_fold_worse_ci90"]
    return (f"; CV records worse than base {r['worse']}/{r['records']} (90 % [{lo:.2f}, {hi:.2f}]), "
            f"P(no fold worse) {r['p_no_fold_worse']:.2f} [{plo:.2f}, {phi:.2f}]")


def add_risk(summary_path: Path, reports) -> None:
    """Add ``totals.cv_risk_worse_than_base`` to a series' committed summary from its folds' committed
    ``report.json`` files, with the function the workflow's loro rule uses (for summaries written before
    the rule reported it; the rows are left as the run wrote them)."""
    from calibration.closing import pooled_risk, cv_risk
    from calibration.contracts import atomic_write_json

    summary = json.loads(summary_path.read_text())
    reps = [json.loads(Path(p).read_text()) for p in reports]
    if len(reps) != summary["totals"]["folds"]:
        raise SystemExit(f"{summary_path}: {summary['totals']['folds']} folds, {len(reps)} report(s) given")
    summary["totals"]["cv_risk_worse_than_base"] = pooled_risk(
        [cv_risk(r.get("errors_per_record") or {}, int(r["shipped_step"])) for r in reps], len(reps))
    atomic_write_json(summary_path, summary)


def block(paths) -> str:
    lines = ["| series | held-out record | effects kept | held-out RMSE, real FDEM [MPa] | peak error | "
             "time-to-peak error [us] | held-out 90 % band coverage |", "|---|---|---|---|---|---|---|"]
    for p in paths:
        series = json.loads((ROOT / p).read_text())
        lines += rows(series, _label(series, p))
    head = "From " + ", ".join(f"`{p}`" for p in paths) + " (before: base model; after: the model the fold kept):"
    foot = ("The band coverage is the fraction of the held-out curve inside its 90 % predictive band "
            "(check.json's `predictive_coverage_90`); \"-\": the fold was run before the check reported it. "
            "Score/box: the band's interval score over that of the same band with the posterior's draws replaced "
            "by draws uniform over the emulator's design box (the base posterior's neighbourhood and the "
            "candidates' ranges; `interval_score_over_box`): 1, knowing the parameters better than that box "
            "does not improve the prediction; below 0.55, it does. "
            "These records are development data: they were read while the method was built, so a coverage "
            "here is not a test on unseen records.")
    return f"{START}\n{head}\n\n" + "\n".join(lines) + f"\n\n{foot}\n{END}"


DOC = ROOT / "docs" / "closing-the-loop.md"


def doc_block_sources(text: str) -> list[str]:
    inner = text.split(START, 1)[1].split(END, 1)[0]
    head = inner.strip().split("\n", 1)[0]
    return head.split("`")[1::2][: head.count("`") // 2]


def main(argv) -> int:
    paths = [a for a in argv[1:] if not a.startswith("--")]
    if "--add-risk" in argv:  # tools/loro_table.py --add-risk <summary.json> <fold report.json>...
        add_risk(ROOT / paths[0], paths[1:])
        return 0
    if "--figure" in argv:  # tools/loro_table.py --figure <summary.json> <folds.png>: the loro rule's figure
        from calibration.plots import plot_loro

        plot_loro(paths[1], json.loads(Path(paths[0]).read_text()))
        return 0
    text = block(paths)
    if "--docs" in argv:
        old = DOC.read_text()
        a, b = old.index(START), old.index(END) + len(END)
        DOC.write_text(old[:a] + text + old[b:])
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
