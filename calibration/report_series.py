"""The page a leave-one-record-out series opens on (``results/<series>/loro/summary.html``): does the model
reproduce tests it never read, and what did the loop add for that.

Read from the series' table (:func:`calibration.closing.loro_table`, ``loro/summary.json``). Each fold
calibrated and diagnosed the model on every record but one and predicted that one; the page says, first
and in words, what the folds shipped, how the held-out errors of real FDEM runs moved, whether the held-out
90 % bands held their curves as often as stated and whether they beat the same band over the design box,
then one row per fold. HTML fragment, inline styles, ASCII text only (as
:mod:`calibration.report_summary`); a value missing is shown as ``?`` and the page never fails its job.
"""
from __future__ import annotations

from collections.abc import Mapping
from html import escape

from .report_summary import _num, _table

__all__ = ["series_html"]

#: The mean over folds of the held-out bands' coverage that reads as calibrated: a 90 % band of a curve
#: whose samples are correlated holds a fraction that scatters widely about 0.90 from record to record, and
#: the mean over a series' few folds with it (issue 52's range for the shipped series)
BAND_RANGE = (0.80, 0.98)


def _bands(t: Mapping) -> str:
    before, after = t.get("mean_predictive_coverage_90_before"), t.get("mean_predictive_coverage_90_after")
    if after is None:
        return "The folds' checks carry no predictive band."
    lo, hi = BAND_RANGE
    reading = ("too narrow: the predictions are surer than they are right" if after < lo else
               "too wide" if after > hi else "as often as stated, within what a few folds can tell")
    text = (f"The held-out 90 % bands held {_num(before, 1.0, '.2f')} of their curves before the loop and "
            f"{_num(after, 1.0, '.2f')} after ({reading}; a mean of {lo:.2f}-{hi:.2f} reads as calibrated).")
    ratio = t.get("mean_interval_score_over_box_after")
    if isinstance(ratio, (int, float)):
        text += (f" Their interval score after the loop is {ratio:.2f} of the same band's with the parameters "
                 "spread over the design box" + (": no better than not knowing the parameters, the model's miss "
                                                 "limits the prediction." if ratio >= 1.0 else "."))
    return text


def _post(row: Mapping, calibrated: Mapping | None) -> Mapping:
    """A fold's parameters: its calibrated posterior (the fold's summary.json) where given, else the selection's
    fit of the shipped model (the table's ``estimates``)."""
    if calibrated is not None:
        return calibrated.get(row.get("fold")) or {}
    return row.get("estimates") or {}


def _spread(rows, calibrated: Mapping | None, name: str = "sigma_t", scale: float = 1e-6, unit: str = "MPa") -> str:
    """The fitted mean's range over the folds against the widest fold's 90 % interval: a range wider than
    any interval says that leaving one record out moves the estimate more than its interval allows."""
    qs = [_post(r, calibrated).get(name) for r in rows]
    qs = [q for q in qs if isinstance(q, Mapping) and all(isinstance(q.get(k), (int, float))
                                                          for k in ("mean", "q05", "q95"))]
    if len(qs) < 2:
        return ""
    means = [q["mean"] for q in qs]
    width = max(q["q95"] - q["q05"] for q in qs)
    span = max(means) - min(means)
    which = "calibrated" if calibrated is not None else "fitted (the selection's)"
    text = (f" The folds' {which} {name} runs from {_num(min(means), scale, '.3g')} to {_num(max(means), scale, '.3g')} "
            f"{unit}")
    if span > width:
        return text + (f", a spread wider than any fold's 90 % interval ({_num(width, scale, '.2g')} {unit} at the "
                       "widest): which record is left out moves it more than its interval says.")
    return text + f", within the widest fold's 90 % interval ({_num(width, scale, '.2g')} {unit})."


def _in_short(t: Mapping, rows=(), calibrated: Mapping | None = None) -> str:
    n = t.get("folds") or 0
    kept = t.get("effects_kept") or {}
    shipped = (", ".join(f"{escape(str(e))} in {k} of {n}" for e, k in kept.items()) if kept
               else "no effect in any fold")
    return ('<p style="margin:0.4em 0;padding:0.3em 0.5em;border-left:3px solid #48a"><b>In short.</b> '
            f"Each of the {n} records was predicted by the model calibrated and diagnosed on the others, which "
            f"never read it. The loop shipped {shipped}. The held-out RMSE of real FDEM runs went from "
            f"{_num(t.get('mean_rmse_before'), 1e-6, '.3g')} to {_num(t.get('mean_rmse_after'), 1e-6, '.3g')} MPa "
            f"on average ({escape(str(t.get('folds_better', '?')))} folds better, "
            f"{escape(str(t.get('folds_worse', '?')))} worse). {_bands(t)}{_spread(rows, calibrated)}</p>")


def _estimate(post: Mapping, name: str, scale: float) -> str:
    q = post.get(name)
    if not isinstance(q, Mapping):
        return "?"
    return f"{_num(q.get('mean'), scale, '.3g')} [{_num(q.get('q05'), scale, '.3g')}, {_num(q.get('q95'), scale, '.3g')}]"


def _rows(rows, calibrated: Mapping | None) -> list[list[str]]:
    out = []
    for r in rows:
        pair = [f"{_num(r.get(f'{k}_before'), s, f)} -> {_num(r.get(f'{k}_after'), s, f)}"
                for k, s, f in (("rmse", 1e-6, ".3g"), ("predictive_coverage_90", 1.0, ".2f"),
                                ("interval_score_over_box", 1.0, ".2f"))]
        out.append([escape(str(r.get("heldout", "?"))), _num(r.get("strain_rate_per_s"), 1.0, ".0f"),
                    escape(", ".join(r.get("effects") or []) or "none (base kept)"),
                    _estimate(_post(r, calibrated), "sigma_t", 1e-6), _estimate(_post(r, calibrated), "E_t", 1e-3),
                    *pair])
    return out


def series_html(name: str, table: Mapping, calibrated: Mapping | None = None) -> str:
    """The series page as an HTML fragment (module docstring); ``table`` is ``loro/summary.json``, ``calibrated``
    ``{fold: posterior}`` of the folds' summary.json (the posterior a lab quotes; without it the page shows the
    selection's fits)."""
    try:
        t = table.get("totals") or {}
        rows = table.get("rows") or []
        source = ("the fold's calibrated posterior, the one its summary.html says to quote" if calibrated is not None
                  else "the selection's fit of the shipped model")
        parts = ['<meta charset="utf-8">', '<div class="series-summary" style="font-family:sans-serif">',
                 f'<h3 style="margin:0.8em 0 0.2em 0">{escape(name)}: leave one record out</h3>', _in_short(t, rows, calibrated),
                 '<p style="margin:0.4em 0 0 0">Per fold: the held-out record and its strain rate, the effects '
                 f"the fold shipped, its sigma_t and E_t (mean [90 %], {source}), and the held-out record's "
                 "RMSE, band coverage and band score over the design box's, before -> after the loop:</p>",
                 _table(["held out", "strain rate [1/s]", "effects shipped", "sigma_t [MPa]", "E_t [kJ/m^2]",
                         "RMSE [MPa]", "band covers", "band score / box"], _rows(rows, calibrated)),
                 f'<p style="margin:0.2em 0;font-size:0.85em">From results/{escape(name)}/loro/summary.json; each '
                 "fold's own page is its experiment's summary.html.</p>"]
    except Exception as exc:  # noqa: BLE001 - a page of the report must never fail the run
        parts = ['<meta charset="utf-8">', f"<div><p>{escape(name)}: series summary not readable "
                                           f"({escape(type(exc).__name__)}: {escape(str(exc))})</p>"]
    return "\n".join(parts + ["</div>"]) + "\n"
