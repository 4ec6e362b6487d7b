"""The default run's results as a Markdown table, generated from its ``summary.json`` files (one source).

    python tools/results_table.py results twin_ref marble_loop          # the full table
    python tools/results_table.py --readme benchmarks/results/default_run/twin_ref/summary.json \
        benchmarks/results/default_run/marble_loop/summary.json           # rewrite README's block
    python tools/results_table.py --workflow-docs                        # rewrite docs/workflow.md's block

The README's block (between ``<!-- results-table:start -->`` and ``<!-- results-table:end -->``) is the
short form for a user: verdict, stop, posterior and predictive check per experiment, and the closing
of the loop where the experiment has one; ``tests/test_docs_tables.py`` checks it against the JSON it names.
docs/workflow.md's block (``<!-- default-run-table:start -->`` ... ``:end -->``) is the full table of the
committed default run with the loop's check, made from ``benchmarks/results/default_run``.

Per experiment: the verdict and its flags, how the loop stopped, the posterior mean with its 90 %
interval per parameter (and the truth for twins), the estimated discrepancy per record (its RMS size
and correlation time against the instrument noise) and the posterior-predictive check per record.
Units: MPa for stresses, J/m^2 for energies.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

SCALE = {"sigma_t": (1e-6, "MPa"), "sigma_n": (1e-6, "MPa"), "E_t": (1.0, "J/m^2"), "E_n": (1.0, "J/m^2")}


def _param(name: str, post: dict, truth: dict | None) -> str:
    f, unit = SCALE.get(name, (1.0, ""))
    text = f"`{name}` {post['mean'] * f:.4g} [{post['q05'] * f:.4g}, {post['q95'] * f:.4g}] {unit}"
    if truth and name in truth:
        text += f" (truth {truth[name] * f:.4g})"
    return text


def _discrepancy(s: dict) -> str:
    disc = (s.get("discrepancy") or {}).get("records") or {}
    if not disc:
        return "none"
    return "; ".join(f"{rec}: {' / '.join(f'{x / 1e6:.3g}' for x in v.get('sigma_phases', [v['sigma']]))} MPa "
                     f"(foot / rise / post-peak), {v['corr_time_s'] * 1e6:.3g} us" for rec, v in disc.items())


def _variability(s: dict) -> str:
    sv = (s.get("simulator_variability") or {}).get("groups") or {}
    if not sv:
        return "not measured"
    return "; ".join(f"{rec}: {v['rms_pre_peak_Pa'] / 1e6:.2g} / {v['rms_post_peak_Pa'] / 1e6:.2g} MPa"
                     for rec, v in sv.items())


def _check(s: dict) -> str:
    checks = s.get("predictive_check_90") or {}
    return "; ".join(f"{rec}: {c['coverage']:.2f} (expected {c['expected_5_95'][0]:.2f}-{c['expected_5_95'][1]:.2f}"
                     f"{', consistent' if c['consistent'] else ', NOT consistent'})" for rec, c in checks.items())


def row(s: dict) -> str:
    v = s["verdict"]
    stop = f"{s['stop_reason']} after {s['iterations']} analyses"
    params = "<br>".join(_param(p, s["posterior"][p], s.get("truth")) for p in s["posterior"])
    return (f"| `{s['experiment']}` | {v['verdict']} ({', '.join(v['flags']) or 'no flags'}) | {stop} | {params} "
            f"| {_variability(s)} | {_discrepancy(s)} | {_check(s)} |")


def table(folder: Path, names) -> str:
    rows = ["| experiment | verdict (flags) | stop | posterior mean [90 % interval] | simulator variability "
            "(rms before / after the peak) | discrepancy (amplitudes, correlation time) "
            "| 90 % predictive coverage per record |", "|---|---|---|---|---|---|---|"]
    rows += [row(json.loads((folder / n / "summary.json").read_text())) for n in names]
    return "\n".join(rows)


def diagnosis_table(folder: Path, name: str) -> str:
    """The loop's real FDEM errors per record (``diagnosis/check.json``) and its verdict in one line."""
    check = json.loads((folder / name / "diagnosis" / "check.json").read_text())
    rows = [f"`{name}` closing the loop: {check['verdict']} ({', '.join(check['added']) or 'base kept'}); "
            f"{check['fdem_confirmation']['text']}", "",
            "| record | data | RMSE before -> after [MPa] | peak error before -> after |", "|---|---|---|---|"]
    for rec, e in check["errors_per_record"].items():
        b, a = e["before"], e["after"]
        rows.append(f"| {rec} | {e['data']} | {b['rmse'] / 1e6:.1f} -> {a['rmse'] / 1e6:.1f} "
                    f"| {100 * b['peak_rel_error']:+.0f} % -> {100 * a['peak_rel_error']:+.0f} % |")
    return "\n".join(rows)


ROOT = Path(__file__).resolve().parents[1]
START, END = "<!-- results-table:start -->", "<!-- results-table:end -->"


def _closing(summary_path: Path) -> str:
    """The diagnosis's verdict (``confirmed`` with the effects added, or ``base_kept``), or "-"."""
    check = summary_path.parent / "diagnosis" / "check.json"
    if not check.is_file():
        return "-"
    c = json.loads(check.read_text())
    return f"{c['verdict']}" + (f" ({', '.join(c['added'])})" if c["added"] else "")


def readme_table(paths) -> str:
    """The README's short table from ``summary.json`` paths (relative to the repository root)."""
    rows = ["| experiment | verdict (flags) | stop | posterior mean [90 % interval] "
            "| 90 % predictive coverage per record | closing the loop |", "|---|---|---|---|---|---|"]
    for p in paths:
        s = json.loads((ROOT / p).read_text())
        v = s["verdict"]
        params = "<br>".join(_param(q, s["posterior"][q], s.get("truth")) for q in s["posterior"])
        rows.append(f"| `{s['experiment']}` | `{v['verdict']}` ({', '.join(v['flags']) or 'no flags'}) "
                    f"| {s['stop_reason']} after {s['iterations']} analyses | {params} | {_check(s)} "
                    f"| {_closing(ROOT / p)} |")
    head = "From " + ", ".join(f"`{p}`" for p in paths) + " (the default run, `snakemake --cores 2`):"
    return "\n".join([head, "", *rows])


def block(*paths: str) -> str:
    return f"{START}\n{readme_table(paths)}\n{END}"


def readme_block_sources(text: str) -> list:
    """The summary.json paths named in README's block, in order."""
    head = text.split(START, 1)[1].split(END, 1)[0].strip().split("\n", 1)[0]
    return [part for part in head.split("`")[1::2] if part.endswith(".json")]


WORKFLOW_DOC = ROOT / "docs" / "workflow.md"
WORKFLOW_START, WORKFLOW_END = "<!-- default-run-table:start -->", "<!-- default-run-table:end -->"
def _default_experiments() -> tuple[str, ...]:
    """The experiments of the default run: config/config.yaml's ``run`` list."""
    import yaml

    return tuple(yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["run"])


DEFAULT_RUN = ("benchmarks/results/default_run", _default_experiments())


def workflow_block(folder: str = DEFAULT_RUN[0], names=DEFAULT_RUN[1]) -> str:
    """docs/workflow.md's block: the full table of the committed default run and the loop's check."""
    parts = [table(ROOT / folder, names)]
    parts += [diagnosis_table(ROOT / folder, n) for n in names
              if (ROOT / folder / n / "diagnosis" / "check.json").is_file()]
    return "\n".join([WORKFLOW_START, "\n\n".join(parts), WORKFLOW_END])


def _write_workflow_docs() -> None:
    text = WORKFLOW_DOC.read_text()
    a, b = text.index(WORKFLOW_START), text.index(WORKFLOW_END) + len(WORKFLOW_END)
    WORKFLOW_DOC.write_text(text[:a] + workflow_block() + text[b:])


def _write_readme(paths) -> None:
    readme = ROOT / "README.md"
    text = readme.read_text()
    a, b = text.index(START), text.index(END) + len(END)
    readme.write_text(text[:a] + block(*paths) + text[b:])


if __name__ == "__main__":
    if sys.argv[1] == "--readme":
        _write_readme(sys.argv[2:])
        sys.exit(0)
    if sys.argv[1] == "--workflow-docs":
        _write_workflow_docs()
        sys.exit(0)
    folder, names = Path(sys.argv[1]), sys.argv[2:]
    print(table(folder, names))
    for n in names:
        if (folder / n / "diagnosis" / "check.json").is_file():
            print("\n" + diagnosis_table(folder, n))
