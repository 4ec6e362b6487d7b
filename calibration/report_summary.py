"""The summary an experiment's HTML report opens on (``results/<exp>/summary.html``, the report's
"0 Summary" category, shown on the report's first page): the verdict; where the diagnosis ran, a short
answer (what to quote: the shipped model, the calibrated sigma_t and E_t beside their re-fit under it, the
held-out errors); the parameters with their 90 % intervals, the misfit per iteration, each record's error
before and after the calibration, and where the diagnosis ran its FDEM check the calibration and held-out
errors before and after the loop.

Read from ``summary.json`` (:func:`calibration.experiment.summary`) and, for an experiment with a
``diagnosis`` block, ``diagnosis/check.json``. The HTML is a fragment with inline styles and ASCII
text only, so that the report can show it both as a result of its own and inside the workflow
description (``report/workflow.rst``). A value missing from the files is shown as ``?``; the page
never fails the run that writes it.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from html import escape

from enkf.scores import INFORMATIVE_RATIO
from shpb import effects as fx
from shpb.lab.init_config_yaml import APPROXIMATION_ERROR
from .scored import approximation_form, learned_holds, misspecified_90

__all__ = ["summary_html"]

#: Display units of the calibrated parameters (SI value x factor); other names are shown in SI.
DISPLAY = {"Pa": (1e-6, "MPa"), "J/m^2": (1.0, "J/m^2"), "m": (1e6, "um"), "s": (1e6, "us")}
#: SI units of parameter names (the last part of a dotted effect parameter, e.g. ``face_gap.gap_m``).
UNITS = {"sigma_n": "Pa", "sigma_t": "Pa", "E_n": "J/m^2", "E_t": "J/m^2", "E": "Pa"}

_TABLE = 'style="border-collapse:collapse;font-size:0.85em;margin:0.3em 0 0.8em 0"'
_CELL = 'style="border:1px solid #ccc;padding:2px 6px;text-align:{align}"'


def _num(x, scale: float = 1.0, fmt: str = ".4g") -> str:
    try:
        x = float(x) * scale
    except (TypeError, ValueError):
        return "?"
    return format(x, fmt) if math.isfinite(x) else str(x)


def _unit(name: str) -> tuple[float, str]:
    """(factor, display unit) of a parameter name."""
    last = str(name).split(".")[-1]
    si = UNITS.get(last)
    if si is None:
        for suffix, unit in (("_Pa", "Pa"), ("_m", "m"), ("_s", "s")):
            if last.endswith(suffix):
                si = unit
    return DISPLAY.get(si, (1.0, si or ""))


def _table(header: list[str], rows: list[list[str]]) -> str:
    """A small HTML table (cells already escaped); the first column left-aligned, the others right."""
    def cells(tag, values):
        return "".join(f"<{tag} {_CELL.format(align='left' if j == 0 else 'right')}>{v}</{tag}>"
                       for j, v in enumerate(values))
    body = "".join(f"<tr>{cells('td', r)}</tr>" for r in rows)
    return f"<table {_TABLE}><tr>{cells('th', header)}</tr>{body}</table>"


def _get(d, *keys):
    for k in keys:
        d = d.get(k) if isinstance(d, Mapping) else None
    return d


def _headline(name: str, s: Mapping) -> list[str]:
    v = s.get("verdict") if isinstance(s.get("verdict"), Mapping) else {"verdict": s.get("verdict")}
    flags = ", ".join(str(f) for f in v.get("flags") or []) or "none"
    what = ", ".join(escape(str(s[k])) for k in ("kind", "geometry", "preset", "method") if s.get(k))
    n = f", N = {escape(str(s['ensemble_size']))}" if s.get("ensemble_size") else ""
    stop = (f"{escape(str(s.get('stop_reason') or '?'))} after {escape(str(s.get('iterations', '?')))} analyses"
            f" ({'converged' if s.get('converged') else 'not converged'}), "
            f"{escape(str(s.get('n_simulations', '?')))} simulations")
    out = [f'<h3 style="margin:0.8em 0 0.2em 0">{escape(name)}</h3>',
           f"<p style=\"margin:0.2em 0\">{what}{n}; stop: {stop}.</p>",
           f"<p style=\"margin:0.2em 0\"><b>Verdict: {escape(str(v.get('verdict') or '?'))}</b> "
           f"(flags: {escape(flags)})</p>"]
    if v.get("next_step"):
        out.append(f"<p style=\"margin:0.2em 0\">Next step: {escape(str(v['next_step']))}</p>")
    return out


#: The rock's own parameters, quoted first in the short answer (an effect's parameters follow in the tables)
ROCK = ("sigma_t", "E_t")


def _box_end(q: Mapping, box: Mapping) -> str:
    """Where a 90 % interval runs into an end of the prior box (within EDGE_FRACTION of its width), in words."""
    lo, hi = _get(box, "lower"), _get(box, "upper")
    if not all(isinstance(v, (int, float)) for v in (lo, hi, q.get("q05"), q.get("q95"))):
        return ""
    low = fx.box_end(q["q05"], lo, hi, EDGE_FRACTION) == "lower"
    high = fx.box_end(q["q95"], lo, hi, EDGE_FRACTION) == "upper"
    if low and high:
        return "; the whole prior box: not constrained"
    if high:
        return "; it runs to the prior box's upper end: read it as a lower bound"
    if low:
        return "; it runs to the prior box's lower end: read it as an upper bound"
    return ""


def _caveat(q: Mapping, holds: bool | None) -> str:
    """:func:`_reading` of a parameter's interval, short: only where it is not simply learned."""
    ratio = q.get("score_over_prior")
    reading = _reading(ratio, holds) if isinstance(ratio, (int, float)) else None
    return {"prior": "; not constrained: mostly the prior", "narrowed": "; read it as the prior narrowed"}.get(reading, "")


def _rock_values(post: Mapping, prior: Mapping, holds: Mapping | None = None) -> str:
    out = []
    for p in ROCK:
        q = post.get(p)
        if not isinstance(q, Mapping):
            continue
        f, unit = _unit(p)
        if unit == "J/m^2" and isinstance(q.get("mean"), (int, float)) and abs(q["mean"]) >= 1e3:
            f, unit = 1e-3, "kJ/m^2"
        note = _box_end(q, _get(prior, p) or {}) or _caveat(q, (holds or {}).get(p))
        out.append(f"{p} {_num(q.get('mean'), f, '.3g')} {escape(unit)} (90 %: {_num(q.get('q05'), f, '.3g')} to "
                   f"{_num(q.get('q95'), f, '.3g')}{note})")
    return ", ".join(out) or "?"


def _heldout_text(check: Mapping, refitted: bool) -> str:
    held = check.get("heldout") if isinstance(check.get("heldout"), Mapping) else {}
    bands = _get(check, "predictive_band", "records") or {}
    if not held:
        return ("No record was held out: the errors below are the calibration records' cross-validated ones, "
                "so no record the fit never saw tests the model.")
    each = [f"{escape(str(r))} {_num(_get(e, 'before', 'rmse'), 1e-6, '.3g')} -> "
            f"{_num(_get(e, 'after', 'rmse'), 1e-6, '.3g')} MPa, its 90 % band holding "
            f"{_num(_get(bands, r, 'after', 'predictive_coverage_90'), 1.0, '.2f')} of its curve" for r, e in held.items()]
    at = " at the selection's fit (the re-fitted values were not run on them)" if refitted else ""
    return (f"On the record(s) the fit never saw, the RMSE of real FDEM runs before -> after the loop{at}: "
            + "; ".join(each) + ".")


def _in_short(summary: Mapping, check: Mapping, refit) -> list[str]:
    """The answer a lab quotes, first: the model the run ships; the rock's parameters from the calibration's
    posterior (the form the coverage harness scored) and, where the loop added effects and re-fitted them on
    real runs, under the shipped model too (a fit no benchmark has scored for the rock's parameters), with
    where their intervals run into the prior box; how the model did on the records the fit never saw."""
    added = [str(a) for a in check.get("added") or []]
    model = "base + " + " + ".join(added) if added else "the base model"
    post = refit.get("posterior") if isinstance(refit, Mapping) else None
    prior = summary.get("prior") if isinstance(summary.get("prior"), Mapping) else {}
    calibrated = _rock_values(summary.get("posterior") or {}, prior, learned_holds(summary.get("posterior_form")))
    refitted = bool(added and isinstance(post, Mapping) and post)
    why = ("each effect confirmed on real FDEM runs; which effect of its group it is, and whether it sits at the "
           "end of its catalogue range, is said below" if added else
           "no effect the loop tried made real FDEM runs predict better")
    text = (f"<b>In short.</b> This run ships {escape(model)} ({why}). The rock's parameters, calibrated "
            f"(the posterior below, the form the coverage harness scored on twins): {calibrated}.")
    if refitted:
        text += (f" Under the shipped model, re-fitted on real FDEM runs (diagnosis/refit.json; no benchmark has "
                 f"scored these intervals for the rock's parameters): {_rock_values(post, prior)}. Quote the "
                 "calibrated intervals; the shipped model's values say how far the effects the loop found move them.")
    return ['<p style="margin:0.4em 0;padding:0.3em 0.5em;border-left:3px solid #48a">'
            f"{text} {_heldout_text(check, refitted)}</p>"]


def _parameters(s: Mapping) -> list[str]:
    post = s.get("posterior")
    if not isinstance(post, Mapping) or not post:
        return ["<p>No posterior in summary.json.</p>"]
    truth = s.get("truth") if isinstance(s.get("truth"), Mapping) else {}
    which = (f"{s['posterior_method']} sample" if s.get("posterior_method") not in (None, "ensemble")
             else f"ensemble of iteration {escape(str(s.get('posterior_iteration', '?')))}")
    scored = any(isinstance(q, Mapping) and q.get("score_over_prior") is not None for q in post.values())
    header = (["parameter", "posterior mean", "90 % interval", "unit"] + (["expected score / prior's"] if scored else [])
              + (["truth"] if truth else []))
    rows = []
    holds = learned_holds(s.get("posterior_form"))
    for p, q in post.items():
        q = q if isinstance(q, Mapping) else {}
        f, unit = _unit(p)
        row = [escape(str(p)), _num(q.get("mean"), f), f"[{_num(q.get('q05'), f)}, {_num(q.get('q95'), f)}]",
               escape(unit)]
        if scored:
            row.append(_learned(q.get("score_over_prior"), holds.get(p)))
        if truth:
            t = truth.get(p)
            inside = (t is not None and _num(q.get("q05")) != "?" and _num(q.get("q95")) != "?"
                      and float(q["q05"]) <= float(t) <= float(q["q95"]))
            row.append("-" if t is None else f"{_num(t, f)} ({'inside' if inside else 'outside'})")
        rows.append(row)
    # a twin's data are the model's own; a measured record's never are
    mis = "" if truth else _misspecified(s.get("posterior_form"))
    return ([f"<p style=\"margin:0.4em 0 0 0\">Parameters (posterior: {which}; {_scored(s)}):</p>",
             _table(header, rows)] + ([f"<p style=\"margin:0.4em 0 0 0\">{mis}</p>"] if mis else []))


def _reading(ratio, holds: bool | None = None) -> str | None:
    """How a parameter's interval reads from the score its posterior expects over the prior box's
    (calibration.verdict's ``uninformative``) and ``holds`` (False: the coverage harness found this form's
    intervals of the parameter too sure where it counts as learned, calibration.scored.learned_holds):
    ``"prior"``, ``"narrowed"``, ``"learned"``, or None without a score."""
    if ratio is None:
        return None
    if float(ratio) > INFORMATIVE_RATIO:
        return "prior"
    return "narrowed" if holds is False else "learned"


def _learned(ratio, holds: bool | None = None) -> str:
    """The score over the prior's and its reading (:func:`_reading`), for the parameters' table."""
    words = {"prior": "not constrained: mostly the prior",
             "narrowed": ("learned, but on the coverage harness's twins this form's intervals of it held the truth "
                          "less often than stated where it counts as learned: read it as the prior narrowed"),
             "learned": "learned"}
    reading = _reading(ratio, holds)
    return "-" if reading is None else f"{float(ratio):.2f} ({words[reading]})"


def _scored(s: Mapping) -> str:
    """Whether the coverage harness scored the reported posterior's form on this loop (summary.json's
    ``posterior_form``, calibration.posterior.posterior_form)."""
    form = s.get("posterior_form")
    if not isinstance(form, Mapping):
        return "its form is not recorded"
    if form.get("scored_by"):
        return f"this form and loop are scored by the coverage harness, {escape(str(form['scored_by']))}"
    other = form.get("form_scored_on")
    where = (f" (the same form is scored on another loop's twins, {escape(str(other.get('benchmark')))})"
             if isinstance(other, Mapping) else "")
    return ("no coverage benchmark has scored this form on this loop" + where
            + ": read the intervals with the verdict and the predictive coverage")


def _misspecified(form) -> str:
    """How this form's 90 % intervals fared on the harness's misspecified twins (``posterior_form``'s
    ``misspecified_90``): what a measured record's intervals can expect, and the form that did better where
    this one held under 90 %; "" for a form never scored on such twins."""
    if not isinstance(form, Mapping):
        return ""
    # a summary written before the key carries its form, and the form finds its scores
    mis = form.get("misspecified_90") or misspecified_90(form)
    if not isinstance(mis, Mapping):
        return ""
    text = ("On the coverage harness's misspecified twins (data the model cannot reproduce: made on a finer mesh, "
            "or with a rate dependence the calibration does not declare) this form's 90 % intervals held the truth "
            "in " + _held(mis))
    short = any(isinstance(q, Mapping) and "covered" in q and q["covered"] < 0.9 * q["n"] for q in mis.values())
    if short and not form.get("approximation_error"):
        with_term = misspecified_90({**form, "approximation_error": approximation_form(APPROXIMATION_ERROR)})
        text += (": expect measured records' intervals to be too narrow. With the approximation error "
                 "(observations.model_error.approximation_error, what init-config writes) such twins' intervals held "
                 + (_held(with_term) if with_term else "more often"))
    return text + "."


def _held(mis: Mapping) -> str:
    held = [f"{escape(p)} {int(q['covered'])} of {int(q['n'])}" for p, q in mis.items()
            if isinstance(q, Mapping) and "covered" in q]
    return ", ".join(held) + f" ({escape(', '.join(map(str, mis.get('benchmarks', []))))})"


def _misfit(s: Mapping) -> list[str]:
    misfit = s.get("misfit") or []
    if not misfit:
        return []
    reported = s.get("posterior_iteration")
    target = _get(s, "verdict", "chi2_per_obs", "stop_target")
    rows = []
    for m in misfit:
        m = m if isinstance(m, Mapping) else {}
        it = m.get("iteration", "?")
        rows.append([escape(str(it)) + (" (reported)" if it == reported else ""), escape(str(m.get("n_alive", "?"))),
                     _num(m.get("median_chi2_per_obs", m.get("chi2_per_obs"))),
                     _num(m.get("stop_chi2_per_obs")), _num(m.get("rmse_Pa"), 1e-6)])
    header = ["iteration", "members ok", "median member chi2/obs (noise)",
              "same, noise + discrepancy (stop test)", "RMSE of the mean curve [MPa]"]
    return [f"<p style=\"margin:0.4em 0 0 0\">Misfit per iteration (0 = prior; the stop test's target "
            f"{_num(target)}):</p>", _table(header, rows)]


def _records(s: Mapping) -> list[str]:
    per = s.get("misfit_per_record")
    if not isinstance(per, Mapping) or not per:
        return []
    rows = [[escape(str(rec)), _num(_get(v, "before", "rmse_Pa"), 1e-6), _num(_get(v, "after", "rmse_Pa"), 1e-6)]
            for rec, v in per.items()]
    return ["<p style=\"margin:0.4em 0 0 0\">RMSE per record [MPa]: before = prior ensemble mean, after = "
            "the forecast run at the posterior mean:</p>", _table(["record", "before", "after"], rows)]


def _corrected(summary: Mapping) -> str:
    """What the diagnosis's records are compared with where the data model carries the approximation
    error: the data less the coarse mesh's mean error, the held-out records' from pairs of their own."""
    approx = summary.get("approximation_error")
    if not isinstance(approx, Mapping):
        return ""
    return (f" Each record's data here, the held-out records' too, are the observed stress less the "
            f"{escape(str(approx.get('coarse_preset', '?')))} mesh's mean error against "
            f"{escape(str(approx.get('fine_preset', '?')))} (the approximation pairs run on that record's own "
            "incident wave): the errors are the model's, not its mesh's.")


def _diagnosis(check: Mapping, summary: Mapping | None = None) -> list[str]:
    added = ", ".join(str(a) for a in check.get("added") or []) or "none"
    conf = _get(check, "fdem_confirmation", "text")
    out = [f"<p style=\"margin:0.4em 0 0 0\"><b>Diagnosis</b>: verdict {escape(str(check.get('verdict') or '?'))}, "
           f"effects kept: {escape(added)}." + (f" {escape(str(conf))}." if conf else "") + "</p>"]
    steps = _get(check, "fdem_confirmation", "steps")
    if isinstance(steps, list) and steps:
        # the walk step by step: a refuted choice and the alternative confirmed after it are both news
        out.append("<p style=\"margin:0.4em 0 0 0\">The walk on real FDEM runs:</p><ol style=\"margin:0.2em 0\">"
                   + "".join(f"<li>{escape(str(_get(st, 'text') or '?'))}</li>" for st in steps) + "</ol>")
    for group in check.get("identification") or []:
        out.append(f"<p style=\"margin:0.4em 0 0 0\">Identification: {escape(str(group.get('text', '')))}.</p>")
    per = check.get("errors_per_record")
    bands = _get(check, "predictive_band", "records") or {}
    if isinstance(per, Mapping) and per:
        rows = []
        for rec, e in sorted(per.items(), key=lambda kv: (_get(kv[1], "data") == "heldout", kv[0])):
            rows.append([escape(str(rec)), escape(str(_get(e, "data") or "?")).replace("heldout", "held out"),
                         _num(_get(e, "before", "rmse"), 1e-6), _num(_get(e, "after", "rmse"), 1e-6),
                         _num(_get(e, "before", "peak_rel_error"), 100.0, "+.1f"),
                         _num(_get(e, "after", "peak_rel_error"), 100.0, "+.1f"),
                         _num(_get(bands, rec, "after", "predictive_coverage_90"), 1.0, ".2f"),
                         _num(_get(bands, rec, "before", "interval_score_over_box"), 1.0, ".2f"),
                         _num(_get(bands, rec, "after", "interval_score_over_box"), 1.0, ".2f")])
        out += ["<p style=\"margin:0.2em 0 0 0\">Errors of real FDEM runs at the posterior means before and "
                "after the loop (diagnosis/check.json), and each record's 90 % predictive band: the share of the "
                "record inside it after the loop, and its interval score (a proper score: lower is better) over "
                "that of the same band with the parameters uniform over the emulator's design box, before and "
                "after (near 1: the model's miss, not the parameters, limits the prediction; '?': a check made "
                "before it was scored). The RMSE weighs every sample alike, so after the failure peak, where "
                "the simulator's own mesh scatter is largest, it can rise while the band's score falls: the "
                "score reads each sample against its own uncertainty, as the walk does." + _corrected(summary or {})
                + "</p>",
                _table(["record", "used for", "RMSE before [MPa]", "RMSE after [MPa]", "peak error before [%]",
                        "peak error after [%]", "band covers", "band score / box before",
                        "band score / box after"], rows)]
    return out + _covariates(check.get("covariate_trends"))


def _refit(refit) -> list[str]:
    """The shipped model's parameters on real FDEM runs (diagnosis/refit.json, calibration.refit) beside the
    selection's surrogate fit the walk tested."""
    post = refit.get("posterior") if isinstance(refit, Mapping) else None
    if not isinstance(post, Mapping) or not post:
        return _gated(refit)
    sel = refit.get("selection_posterior") if isinstance(refit.get("selection_posterior"), Mapping) else {}
    rows = []
    for p, q in post.items():
        f, unit = _unit(str(p).split("@")[0])
        s = sel.get(p) if isinstance(sel.get(p), Mapping) else {}
        rows.append([escape(str(p)), f"{_num(s.get('mean'), f)} [{_num(s.get('q05'), f)}, {_num(s.get('q95'), f)}]",
                     f"{_num(q.get('mean'), f)} [{_num(q.get('q05'), f)}, {_num(q.get('q95'), f)}]", escape(unit)])
    conv = {True: "its last round's means lay within their runs",
            False: "its last round's means still lay outside their runs: read them as a direction, not a value"}
    # its own runs and rounds: a model the identification gate dropped before it had its own (_gated)
    own = refit.get("history") or []
    counted = own and all(isinstance(h, Mapping) and "runs" in h for h in own)
    runs = sum(int(h["runs"]) for h in own) if counted else refit.get("runs", "?")
    return ['<p style="margin:0.4em 0 0 0">' + f"The shipped model ({escape(str(refit.get('model') or '?'))}) re-fitted "
            f"on real FDEM runs around its fit ({escape(str(runs))} runs on the calibration records, "
            f"{escape(str(len(own) or refit.get('rounds', '?')))} rounds; {conv.get(refit.get('converged'), '?')}; "
            f"{_verified(refit)}diagnosis/refit.json). The selection's fit is on its surrogate, which blends the "
            "curves of runs far apart; the held-out errors above are that fit's:</p>",
            _table(["parameter", "selection's surrogate: mean [90 %]", "on real runs: mean [90 %]", "unit"], rows),
            *_at_edge(post), *_earlier(refit), *_gated(refit)]


#: An interval's end within this fraction of its box's width from an edge is on it (draws are clipped there,
#: and a quantile between the edge and the next draw lands a little inside)
EDGE_FRACTION = 0.005


def _at_edge(post: Mapping) -> list[str]:
    """The refit's effect parameters whose 90 % interval reaches an end of the catalogue's range where no
    null lies: the effect is taken as far as the catalogue allows (what it stands in for may be larger)."""
    hits = []
    for name, q in post.items():
        if not isinstance(q, Mapping) or fx.effect_of(str(name)) is None:
            continue
        for end, side, (edge,) in ((q.get("q05"), "lower", fx.bounds([name])[0]),
                                   (q.get("q95"), "upper", fx.bounds([name])[1])):
            if isinstance(end, (int, float)) and fx.catalogue_edge(name, end, EDGE_FRACTION) == side:
                hits.append(f"{escape(str(name))} ({side} end {_num(end, 1.0, '.3g')}, the catalogue's "
                            f"{_num(edge, 1.0, 'g')})")
    if not hits:
        return []
    return ['<p style="margin:0.4em 0 0 0">' + "On real runs these intervals reach an end of their catalogue range, "
            f"away from the effect's null: {'; '.join(hits)}. The effect is taken as far as the catalogue allows: "
            "what it stands in for may be larger, or another effect the catalogue lacks.</p>"]


def _null_intervals(ident: Mapping) -> tuple[str, str]:
    """An identification's intervals against their nulls, in words, and the level of each interval."""
    params = [p for p in ident.get("parameters") or [] if isinstance(p, Mapping)]
    each = _num(1.0 - (1.0 - float(ident.get("level") or 0.9)) / max(1, len(params)), 1.0, ".1%")
    held = "; ".join(f"{escape(str(p.get('name')))} [{_num(p.get('lower'), 1.0, '.3g')}, "
                     f"{_num(p.get('upper'), 1.0, '.3g')}] holds its null {_num(p.get('null'), 1.0, 'g')}"
                     for p in params)
    return held, each


def _earlier(refit: Mapping) -> list[str]:
    """The shipped model's earlier effects that its refit leaves at their nulls (reported, not dropped)."""
    out = []
    for ident in refit.get("earlier_identification") or []:
        if not isinstance(ident, Mapping) or ident.get("identified", True):
            continue
        held, each = _null_intervals(ident)
        name = escape(str(ident.get("effect")))
        out.append('<p style="margin:0.4em 0 0 0">' + f"In this refit none of {name}'s parameters lies away from "
                   f"its null ({held}; each interval at {each}). The walk confirmed {name} before the effect "
                   f"added after it, which may stand in for it; the model without {name} was never walked, so "
                   "it is shipped as walked. Read the two effects as one group.</p>")
    return out


def _gated(refit) -> list[str]:
    """The models the refit's identification gate dropped (calibration.walk.identified), in words."""
    out = []
    for g in (refit.get("gated") or []) if isinstance(refit, Mapping) else []:
        ident = g.get("identification") if isinstance(g, Mapping) else None
        if not isinstance(ident, Mapping):
            continue
        held, each = _null_intervals(ident)
        out.append('<p style="margin:0.4em 0 0 0">' + f"The walk also confirmed {escape(str(ident.get('effect')))} "
                   f"({escape(str(g.get('model')))}), but re-fitted on real runs ({escape(str(g.get('runs', '?')))} "
                   "runs) none of its parameters lies away "
                   f"from its null ({held}; each interval at {each}): not identified, so the model the walk "
                   "confirmed before it is shipped.</p>")
    return out


def _verified(refit: Mapping) -> str:
    """The verify round in words: how far real runs at the refit's mean miss the records, and the factor
    on its intervals (calibration.refit.verify_inflation)."""
    v = next((h for h in refit.get("history") or [] if isinstance(h, Mapping) and h.get("phase") == "verify"), None)
    real = v.get("chi2_per_dof_real_per_mesh") if v else None
    if not real:
        return ""
    return (f"real runs at its mean miss the records by a chi-square per degree of freedom of {min(real):.1f}-"
            f"{max(real):.1f} on its check meshes, against {_num(v.get('fit_misfit_scale'), 1.0, '.1f')} on its "
            f"surrogate, so its intervals are {_num(v.get('inflation'), 1.0, '.2f')} times as wide as the fit's; ")


#: covariate column: (label in the table, display scale, format, the step a trend's slope is quoted per)
COVARIATE_DISPLAY = {"strain_rate_per_s": ("strain rate [1/s]", 1.0, ".0f", (100.0, "100 1/s")),
                     "length_to_diameter": ("L/D", 1.0, ".2f", (0.1, "0.1 of L/D")),
                     "gas_pressure_Pa": ("gas pressure [MPa]", 1e-6, ".3g", (1e5, "0.1 MPa")),
                     "striker_velocity_m_s": ("striker velocity [m/s]", 1.0, ".3g", (1.0, "1 m/s"))}


def _covariates(cov) -> list[str]:
    """The calibration records' real cross-validated peak errors against their test covariates, and the
    trends across them (check.json's ``covariate_trends``, :func:`calibration.covariates.peak_error_trends`)."""
    if not isinstance(cov, Mapping) or not cov.get("records"):
        return []
    recs = cov["records"]
    shown = [c for c in COVARIATE_DISPLAY if any(r.get(c) is not None for r in recs)]
    rows = [[escape(str(r.get("record")))] + [_num(r.get(c), COVARIATE_DISPLAY[c][1], COVARIATE_DISPLAY[c][2])
                                               for c in shown]
            + [_num(r.get(f"peak_rel_error_{w}"), 100.0, "+.1f") for w in ("before", "after")] for r in recs]
    out = ["<p style=\"margin:0.2em 0 0 0\">The calibration records' peak errors (real cross-validated runs) "
           "against what their sheets give: a trend with a test condition points at an effect that depends on it "
           "(a rate law, an end confinement):</p>",
           _table(["record"] + [COVARIATE_DISPLAY[c][0] for c in shown] + ["peak error before [%]",
                                                                            "peak error after [%]"], rows)]
    lines = []
    for t in cov.get("trends") or []:
        if t.get("slope") is None or t.get("covariate") not in COVARIATE_DISPLAY:
            continue
        label, _, _, (step, per) = COVARIATE_DISPLAY[t["covariate"]]
        when = "before" if t.get("column", "").endswith("before") else "after"
        lines.append(f"{when} the loop, against {label.split(' [')[0]}: {_num(t['slope'] * step, 100.0, '+.2f')} % "
                     f"per {per} (Pearson r = {_num(t.get('r'), 1.0, '+.2f')}, p = {_num(t.get('p_pearson'), 1.0, '.2g')}; "
                     f"Spearman p = {_num(t.get('p_spearman'), 1.0, '.2g')}; {t.get('n', '?')} records)")
    if lines:
        out.append("<p style=\"margin:0.2em 0 0 0\">Trends of the peak error across the calibration records:</p>"
                   "<ul style=\"margin:0.2em 0\">" + "".join(f"<li>{escape(x)}</li>" for x in lines) + "</ul>")
    else:
        out.append(f"<p style=\"margin:0.2em 0 0 0\">No trend is tested: that needs three calibration records "
                   f"whose test condition varies; this run has {len(recs)}.</p>")
    return out


def _realrun(real) -> list[str]:
    """What the selection on real runs names (diagnosis/realrun.json, calibration.realrun), beside the walk."""
    if not isinstance(real, Mapping) or not isinstance(real.get("candidates"), Mapping):
        return []
    rows = []
    for e, c in real["candidates"].items():
        own = {k: v for k, v in (c.get("fit") or {}).items() if k not in ("sigma_t", "E_t")}
        iv = c.get("interval_90") if isinstance(c.get("interval_90"), Mapping) else {}

        def value(k, v):
            f, unit = _unit(k.split("@")[0])
            lo, hi = (iv.get("q05") or {}).get(k), (iv.get("q95") or {}).get(k)
            span = f" [{_num(lo, f)}, {_num(hi, f)}]" if lo is not None and hi is not None else ""
            return f"{escape(k)} {_num(v, f)}{span} {escape(unit)}".strip()
        fit = ", ".join(value(k, v) for k, v in own.items())
        rows.append([escape(str(e)), fit, _num(c.get("fit", {}).get("sigma_t"), 1e-6), _num(c.get("z"), fmt=".3g"),
                     _num(c.get("p"), fmt=".2g")])
    name = str(real.get("named"))
    if name == "base_kept":
        said = (f"No candidate's real runs predict the calibration records better than the base model's at "
                f"p &lt; {_num(real.get('level'))}: the base model is kept")
    else:
        group = [escape(str(g)) for g in real.get("group") or [name]]
        said = (f"<b>{escape(name)}</b> is named: its real runs predict the calibration records better than the "
                f"base model's, with the largest z of those below p &lt; {_num(real.get('level'))}"
                + (f"; the records do not tell it apart from {', '.join(group[1:])}" if len(group) > 1 else
                   f"; it beats {', '.join(escape(str(e)) for e in real['versus'])}, which passed too"
                   if real.get("versus") else "; no other candidate passed"))
    return ['<p style="margin:0.4em 0 0 0">' + f"The selection on real runs ({escape(str(real.get('runs', '?')))} FDEM "
            f"runs on the calibration records; diagnosis/realrun.json): each candidate and the base model fitted on "
            f"real runs, each calibration record predicted from the others on "
            f"{escape(str(real.get('check_meshes', '?')))} meshes. {said}. This is beside the walk: the verdict "
            "above is the walk's.</p>",
            _table(["candidate", "its fitted parameters [90 %]", "sigma_t [MPa]", "z against the base", "p"], rows)
            ] + _resolution(real.get("resolution")) + _realrun_heldout(real.get("heldout"))


def _realrun_heldout(held) -> list[str]:
    """The held-out records' errors at the selection on real runs' fits (diagnosis/realrun_heldout.json)."""
    if not isinstance(held, Mapping) or not isinstance(held.get("records"), Mapping) or not held["records"]:
        return []
    rows = []
    for h, ev in held["records"].items():
        cells = []
        for model in ("before", "after"):
            e = ev.get(model) if isinstance(ev, Mapping) else None
            cells += ([_num(e.get("rmse"), 1e-6), _num(e.get("peak_rel_error"), 100, "+.1f")] if isinstance(e, Mapping)
                      else ["-", "-"])
        rows.append([escape(str(h))] + cells)
    return ['<p style="margin:0.4em 0 0 0">The held-out records predicted from these fits, made without them '
            "(each run on every check mesh; before: the base model's fit, after: the named effect's, a per-record "
            "value at the calibration records' mean; diagnosis/realrun_heldout.json):</p>",
            _table(["held-out record", "RMSE before [MPa]", "peak before [%]", "RMSE after [MPa]", "peak after [%]"],
                   rows)]


def _resolution(res) -> list[str]:
    """The reported fit corrected for the mesh (calibration.realrun.resolution_corrected), in a sentence."""
    if not isinstance(res, Mapping) or not isinstance(res.get("fit"), Mapping):
        return []
    iv = res.get("interval_90") or {}
    parts = []
    for k, v in res["fit"].items():
        f, unit = _unit(k.split("@")[0])
        lo, hi = (iv.get("q05") or {}).get(k), (iv.get("q95") or {}).get(k)
        span = f" [{_num(lo, f)}, {_num(hi, f)}]" if lo is not None and hi is not None else ""
        parts.append(f"{escape(k)} {_num(v, f)}{span} {escape(unit)}".strip())
    model = "the base model" if res.get("track") == "base" else escape(str(res.get("track")))
    return ['<p style="margin:0.4em 0 0 0">' + f"Corrected for the mesh: {model}'s fit run on "
            f"{escape(str(res.get('meshes', '?')))} meshes at <code>{escape(str(res.get('preset')))}</code> and at the "
            f"experiment's preset, the records less the difference fitted again (90 % intervals, the difference's "
            f"own scatter in them): {'; '.join(parts)}. These are the values to quote.</p>"]


def summary_html(name: str, summary: Mapping, check: Mapping | None = None, refit: Mapping | None = None,
                 realrun: Mapping | None = None) -> str:
    """The summary of experiment ``name`` as an HTML fragment (ASCII, inline styles); ``refit``:
    diagnosis/refit.json where the shipped model was re-fitted on real runs; ``realrun``:
    diagnosis/realrun.json where the selection on real runs ran."""
    try:
        parts = ['<meta charset="utf-8">', '<div class="experiment-summary" style="font-family:sans-serif">']
        parts += _headline(name, summary)
        if isinstance(check, Mapping):
            parts += _in_short(summary, check, refit)
        parts += _parameters(summary) + _misfit(summary) + _records(summary)
        if isinstance(check, Mapping):
            parts += _diagnosis(check, summary) + _refit(refit) + _realrun(realrun)
        parts.append(f"<p style=\"margin:0.2em 0;font-size:0.85em\">From results/{escape(name)}/summary.json"
                     + (f" and results/{escape(name)}/diagnosis/check.json" if isinstance(check, Mapping) else "")
                     + (f" and results/{escape(name)}/diagnosis/refit.json" if isinstance(refit, Mapping) else "")
                     + (f" and results/{escape(name)}/diagnosis/realrun.json" if isinstance(realrun, Mapping) else "")
                     + "; the plots are under the experiment's own category.</p>")
    except Exception as exc:  # noqa: BLE001 - a page of the report must never fail the run
        parts = ['<meta charset="utf-8">', f"<div><p>{escape(name)}: summary not readable "
                                           f"({escape(type(exc).__name__)}: {escape(str(exc))})</p>"]
    return "\n".join(parts + ["</div>"]) + "\n"
