"""The diagnosis report: JSON, tables and plots for ``results/<experiment>/diagnosis/``
(:mod:`enkf.diagnosis`, step 5)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..diagnostics import jsonable


# ----------------------------------------------------------------------------------------------
# 5. Report
# ----------------------------------------------------------------------------------------------

def report_to_json(report: dict, *, curves: bool = False) -> dict:
    """Strict-JSON version of a :func:`diagnose_loop` report (DataFrames as lists of records; the
    ``curves`` arrays only if asked)."""
    def conv(obj):
        if isinstance(obj, pd.DataFrame):
            return obj.to_dict(orient="records")
        if isinstance(obj, dict):
            return {k: conv(v) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return [conv(v) for v in obj]
        return obj
    out = {k: v for k, v in report.items() if curves or k != "curves"}
    return jsonable(conv(out))


def _split_records(t, y):
    """``(t, y)`` with a NaN gap wherever the time runs backwards (the next record of a concatenated
    vector starts), so a plotted line does not join the end of one record to the start of the next."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    cut = np.nonzero(np.diff(t) < 0)[0] + 1
    return np.insert(t, cut, np.nan), np.insert(y, cut, np.nan)


def write_report(report: dict, directory, *, time_scale: float = 1e6, value_scale: float = 1e-6,
                 time_label: str = "time [us]", value_label: str = "stress [MPa]") -> list[Path]:
    """Write a :func:`diagnose_loop` report to ``directory`` (e.g. ``results/<experiment>/diagnosis/``):

    ``report.json`` (everything but the curves), ``candidates.csv`` (every round's ranking with a
    ``round`` column), ``params.csv`` (posterior before/after), ``errors.csv`` (RMSE, peak and
    time-to-peak errors before/after on calibration and held-out data), and the plots ``fit.png``
    (data and fits before/after, whitened residuals) and ``candidates.png`` (score-test significance and
    collinearity per candidate). Returns the paths written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = []

    p = out / "report.json"
    p.write_text(json.dumps(report_to_json(report), indent=2, allow_nan=False))
    paths.append(p)

    tables = [it["candidates"].assign(round=it["round"]) for it in report["iterations"]
              if it["candidates"] is not None]
    p = out / "candidates.csv"
    (pd.concat(tables, ignore_index=True) if tables else pd.DataFrame(columns=["round", "effect"])).to_csv(p, index=False)
    paths.append(p)

    rows = []
    for when, post in (("before", report["params_before"]), ("after", report["params_after"])):
        for name, s in post.items():
            rows.append({"when": when, "param": name, **s})
    p = out / "params.csv"
    pd.DataFrame(rows).to_csv(p, index=False)
    paths.append(p)

    rows = [{"data": data, "when": when, **vals} for data, d in report["errors"].items() for when, vals in d.items()]
    p = out / "errors.csv"
    pd.DataFrame(rows).to_csv(p, index=False)
    paths.append(p)

    c = report["curves"]
    ho = c.get("heldout_obs") is not None
    fig, axes = plt.subplots(2, 2 if ho else 1, figsize=(11 if ho else 6.5, 6.5), squeeze=False,
                             sharex="col", gridspec_kw={"height_ratios": [2, 1]})
    t = np.asarray(c["times"]) * time_scale
    ax = axes[0, 0]
    ax.plot(*_split_records(t, np.asarray(c["obs"]) * value_scale), ".", ms=2, color="0.5", label="data")
    ax.plot(*_split_records(t, np.asarray(c["fitted_before"]) * value_scale), label="base model")
    ax.plot(*_split_records(t, np.asarray(c["fitted_after"]) * value_scale),
            label="with " + (", ".join(report["added"]) if report["added"] else "nothing added"))
    ax.set_ylabel(value_label)
    ax.set_title(f"calibration data; verdict: {report['verdict']}")
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(*_split_records(t, c["white_before"]), lw=0.8, label="base")
    ax.plot(*_split_records(t, c["white_after"]), lw=0.8, label="after")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylabel("whitened residual")
    ax.set_xlabel(time_label)
    ax.legend(fontsize=8)
    if ho:
        th = np.asarray(c["heldout_times"]) * time_scale
        ax = axes[0, 1]
        ax.plot(*_split_records(th, np.asarray(c["heldout_obs"]) * value_scale), ".", ms=2, color="0.5", label="held-out data")
        ax.plot(*_split_records(th, np.asarray(c["heldout_before"]) * value_scale), label="base model")
        ax.plot(*_split_records(th, np.asarray(c["heldout_after"]) * value_scale), label="after")
        ax.set_title("held-out data")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        ax.plot(*_split_records(th, (np.asarray(c["heldout_obs"]) - np.asarray(c["heldout_before"])) * value_scale), lw=0.8,
                label="base")
        ax.plot(*_split_records(th, (np.asarray(c["heldout_obs"]) - np.asarray(c["heldout_after"])) * value_scale), lw=0.8,
                label="after")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"residual [{value_label.split('[')[-1]}" if "[" in value_label else "residual")
        ax.set_xlabel(time_label)
    fig.tight_layout()
    p = out / "fit.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    if tables:
        tab = tables[0]
        y = np.arange(len(tab))
        axes[0].barh(y, -tab["log10_p"], color=["C2" if ok else "C7" for ok in tab["passes"]])
        axes[0].set_yticks(y, tab["effect"])
        axes[0].invert_yaxis()
        alpha = report["settings"]["alpha_score"]
        axes[0].axvline(-math.log10(alpha), color="k", ls="--", lw=0.8, label=f"p = {alpha:g}")
        axes[0].set_xlabel("-log10 p (score test)")
        axes[0].set_title(f"first ranking; kept: {', '.join(report['added']) or 'none'}", fontsize=9)
        axes[0].set_xscale("symlog", linthresh=1.0)
        axes[0].legend(fontsize=8)
        axes[1].barh(y, tab["collinearity"], color="C1")
        axes[1].set_yticks(y, tab["effect"])
        axes[1].invert_yaxis()
        axes[1].set_xlim(0, 1)
        axes[1].set_xlabel("collinearity with the base parameters")
    else:
        for ax in axes:
            ax.text(0.5, 0.5, "no candidates ranked\n(" + report["verdict"] + ")", ha="center", va="center")
            ax.set_axis_off()
    fig.tight_layout()
    p = out / "candidates.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    return paths
