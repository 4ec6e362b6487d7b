"""The lines the workflow prints when a run ends (the Snakefile's ``onsuccess``): for each experiment of
the run its verdict, stop reason, the posterior mean with the 90 % interval per parameter, and the path
of its ``results/<exp>/summary.json``.

Read from the ``summary.json`` files that exist. Never raises: a missing, unreadable or unexpected
file gives a line that says so (the run has succeeded; its report must not turn it into an error).
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

__all__ = ["experiment_lines", "run_summary", "experiments_of_run"]

#: SI units of the calibrated parameters (other names are printed without a unit).
UNITS = {"sigma_n": "Pa", "sigma_t": "Pa", "E_n": "J/m^2", "E_t": "J/m^2", "E": "Pa", "rho": "kg/m^3"}


def _num(x) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "?"
    return f"{x:.4g}" if math.isfinite(x) else str(x)


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
