"""The lines the workflow prints to its log: one per analysis as the loop runs (:func:`analysis_line`,
printed by ``scripts/analysis.py``), and when a run ends (the Snakefile's ``onsuccess``) for each
experiment of the run its verdict, stop reason, the posterior mean with the 90 % interval per
parameter, and the path of its ``results/<exp>/summary.json``.

The end-of-run lines are read from the ``summary.json`` files that exist. Neither ever raises: a
missing, unreadable or unexpected value or file gives a line that says so (a log line must not turn
a run into an error).
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

__all__ = ["analysis_line", "experiment_lines", "run_summary", "experiments_of_run"]

#: SI units of the calibrated parameters (other names are printed without a unit).
UNITS = {"sigma_n": "Pa", "sigma_t": "Pa", "E_n": "J/m^2", "E_t": "J/m^2", "E": "Pa", "rho": "kg/m^3"}


def _num(x) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "?"
    return f"{x:.4g}" if math.isfinite(x) else str(x)


def analysis_line(analysis: Mapping) -> str:
    """The log line of one analysis (an ``iter_<k>/analysis.json`` dict), e.g.
    ``twin_ref iteration 2: median member chi2/obs 1.55 (stop at 1.22; 260 against the noise alone),
    25/25 members ok -> continue``.

    The first number is the stop test's statistic (the median member's misfit per observation against
    the stop test's error model, standardised by its variances), with the target the stop rule compares it with;
    the second the same member's against the noise alone; then the members that ran, and the decision
    this analysis took (the final rules re-take it with the current stopping rule).
    """
    try:
        decision = analysis.get("decision") or {}
        values = decision.get("values") or {}
        misfit = analysis.get("misfit") or {}
        stat = values.get("chi2_per_obs", misfit.get("stop_chi2_per_obs", misfit.get("chi2_per_obs")))
        noise = misfit.get("median_chi2_per_obs", misfit.get("chi2_per_obs"))
        failed = analysis.get("failed_members") or []
        what = (f"stop: {decision.get('reason') or '?'}" if decision.get("stop")
                else (decision.get("reason") or "?"))
        line = (f"{analysis.get('experiment', '?')} iteration {analysis.get('iteration', '?')}: "
                f"median member chi2/obs {_num(stat)} (stop at {_num(values.get('chi2_target'))}; "
                f"{_num(noise)} against the noise alone), "
                f"{analysis.get('n_alive', '?')}/{analysis.get('n_members', '?')} members ok")
        if failed:
            line += f" ({len(failed)} failed: see failed_members in analysis.json)"
        return line + f" -> {what}"
    except Exception as exc:  # noqa: BLE001 - a log line must never fail the analysis
        return f"(no misfit line: {type(exc).__name__}: {exc})"


def experiment_lines(name: str, summary: Mapping, path: str | Path) -> list[str]:
    """The lines of one experiment from its ``summary.json`` dict (``path``: where it was read)."""
    verdict = summary.get("verdict")
    if isinstance(verdict, Mapping):
        verdict = verdict.get("verdict")
    lines = [f"{name}: verdict {verdict or '?'}, stop reason {summary.get('stop_reason') or '?'} "
             f"({path})"]
    post = summary.get("posterior")
    if not isinstance(post, Mapping) or not post:
        return lines + ["    no posterior in the summary"]
    method = summary.get("posterior_method")
    lines.append(f"    posterior mean [90 % interval]{f' ({method})' if method else ''}, SI units:")
    width = max(len(str(p)) for p in post)
    for p, s in post.items():
        s = s if isinstance(s, Mapping) else {}
        unit = UNITS.get(str(p).split(".")[-1], "")
        lines.append(f"    {str(p):<{width}}  {_num(s.get('mean'))} [{_num(s.get('q05'))}, {_num(s.get('q95'))}]"
                     f"{' ' + unit if unit else ''}")
    return lines


def run_summary(experiments: Iterable[str], results: str | Path = "results") -> str:
    """The end-of-run text for ``experiments``, read from ``<results>/<exp>/summary.json``."""
    lines = ["Run summary (results/<experiment>/summary.json):"]
    for name in experiments:
        path = Path(results) / str(name) / "summary.json"
        try:
            with open(path, encoding="utf-8") as fh:
                summary = json.load(fh)
            if not isinstance(summary, Mapping):
                raise ValueError(f"expected a JSON object, got {type(summary).__name__}")
            lines += experiment_lines(str(name), summary, path)
        except FileNotFoundError:
            lines.append(f"{name}: no summary ({path} does not exist)")
        except Exception as exc:  # noqa: BLE001 - the report of a finished run must never fail it
            lines.append(f"{name}: summary not readable ({path}: {type(exc).__name__}: {exc})")
    return "\n".join(lines)


def experiments_of_run(targets: Iterable[str], experiments: Sequence[str], default: Sequence[str]) -> list[str]:
    """The experiments a run was asked for: those named in a target path ``results/<exp>/...``, or
    ``default`` (the config's ``run``) when no target names one (``snakemake`` or a rule name)."""
    named = []
    for t in targets or ():
        parts = Path(str(t)).parts
        for i, part in enumerate(parts[:-1]):
            if part == "results" and parts[i + 1] in experiments and parts[i + 1] not in named:
                named.append(parts[i + 1])
    return named or list(default)
