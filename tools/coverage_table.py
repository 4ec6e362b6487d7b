"""The README's coverage table: how often the reported intervals hold the truth over twins drawn from the
whole prior box, generated from the coverage benchmark's JSON (one source for the numbers).

    python tools/coverage_table.py benchmarks/results/coverage_well_specified.json [more.json]          # print
    python tools/coverage_table.py benchmarks/results/coverage_well_specified.json [more.json] --readme # rewrite

(``--readme`` also rewrites docs/inference.md's tables of the same twins split by whether the window
holds their post-peak, :func:`censored_table`, and by the product's ``uninformative`` flag,
:func:`flag_table`.)

Each JSON is a ``benchmarks/bench_coverage.py`` output; each of its sets with twins (well-specified,
misspecified) is one row, with the weighted interval score over the prior's, the ``uninformative`` share
and the bars of :func:`benchmarks.scores.verdict` it does not meet (a JSON scored before those exist is
refused: ``bench_coverage.py --rescore`` it). The JSONs must share the twin's setting (method, ensemble
size, window and the reported posterior's form), so the rows compare like with like. The block sits between
``<!-- coverage-table:start -->`` and ``<!-- coverage-table:end -->`` in README.md;
``tests/test_docs_tables.py`` checks that it equals what this tool makes from the JSON named in it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: the harness's bars are benchmarks.scores

from benchmarks.scores import (COVERAGE_90_BAR, COVERAGE_90_MISSPECIFIED_MIN, SBC_ALPHA,  # noqa: E402
                               WIS_BAR, set_verdict_of)
from enkf.scores import INFORMATIVE_RATIO  # noqa: E402

START, END = "<!-- coverage-table:start -->", "<!-- coverage-table:end -->"
CENSORED_START, CENSORED_END = "<!-- censored-table:start -->", "<!-- censored-table:end -->"
FLAG_START, FLAG_END = "<!-- flag-table:start -->", "<!-- flag-table:end -->"
INFERENCE_DOC = ROOT / "docs" / "inference.md"
NAMES = ("sigma_t", "E_t")
#: a benchmark's sets with twins, in the table's order (bench_coverage.py)
SETS = ("well_specified", "misspecified", "misspecified_rate")
# what makes two benchmark runs the same experiment: rows of different settings are refused
SETTING = ("method", "ensemble_size", "window_s", "reported_posterior", "self_calibrate", "emulator_error",
           "refine_runs")


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _cov(c: dict) -> str:
    # a reported MCMC posterior's failed samplers count as misses (score_mcmc)
    f = c.get("fraction_counting_failures_as_misses", c["fraction"])
    lo, hi = c.get("ci95_counting_failures_as_misses", c["ci95"])
    return f"{_pct(f)} [{_pct(lo)}, {_pct(hi)}]"


def reported(bench: dict, name: str) -> dict:
    """The set's summary of the posterior the twin reports (``reported_posterior``)."""
    mcmc = bench.get("reported_posterior") == "emulator_mcmc"
    return bench[name]["summary_emulator_mcmc"] if mcmc else bench[name]["summary"]


def _label(bench: dict, name: str) -> str:
    if name == "well_specified":
        return "well-specified"
    pairs = bench.get("approximation_pairs")
    extra = f", approximation error from {pairs} paired runs" if pairs else ""
    if name == "misspecified_rate":
        twins = (bench.get(name) or {}).get("twins") or [{}]
        k = (twins[0].get("planted") or {}).get("rate_strength.k")
        mesh = "data from the `standard` mesh" if bench.get("rate_data_preset") == "standard" else "data"
        return (f"misspecified ({mesh} with an undeclared rate dependence{f', rate_strength.k = {k:g}' if k else ''}"
                f"{extra})")
    return f"misspecified (data from the `standard` mesh{extra})"


def _unin(q: dict) -> str:
    """The share the product flags ``uninformative`` (benchmarks.scores.product_flag_split)."""
    return _pct(q["product_flag"]["uninformative_share"])


def _width(q: dict) -> str:
    return f"{q['width_over_prior_median']:.2f}"


def _wis(q: dict) -> str:
    return f"{q.get('wis_over_prior_counting_failures_as_prior', q['wis_over_prior']):.2f}"


def _failed(v: dict) -> str:
    """The bars a set's reported posterior does not meet, each with its value."""
    out = []
    for name in v["failed"]:
        kind, p = name.split(" ")
        x = v["bars"][name]["value"]
        # a bar the table cannot name is a KeyError, never a row that leaves it out
        out.append({"coverage_90": f"90 % coverage `{p}` {_pct(x)}", "sbc": f"ranks `{p}` p = {x:.3f}",
                    "wis_over_prior": f"WIS `{p}` {x:.2f}"}[kind])
    return ", ".join(out) if out else "none"


def _row(bench: dict, name: str, source: str) -> str:
    rep, ens = reported(bench, name), bench[name]["summary"]
    p, e = rep["params"], ens["params"]
    missing = [f"{name}.{x}.{k}" for x in NAMES for k in ("wis_over_prior", "product_flag")
               if k not in p.get(x, {})]
    if missing:
        raise ValueError(f"coverage table: {source} has no {missing[0]} (scored before the proper scores): run "
                         f"`python benchmarks/bench_coverage.py --rescore {source}`")

    def both(f, q=p):
        return " / ".join(f(q[x]) for x in NAMES)

    n = rep["n_twins"] + rep.get("sampler_failed", 0)
    return (f"| {_label(bench, name)} | `{Path(source).name}` | {n} | {both(lambda q: _cov(q['coverage_90']))} "
            f"| {both(lambda q: _cov(q['coverage_50']))} "
            f"| {both(_width)} "
            f"| {both(lambda q: _pct(q['coverage_90']['fraction']), e)} "
            f"| {both(_wis)} | {both(_unin)} "
            f"| {_failed(set_verdict_of(name, rep))} |")


def _setting(bench: dict) -> tuple:
    return tuple(json.dumps(bench.get(k)) for k in SETTING)


def table(entries: list) -> str:
    """The table from ``[(source path, benchmark dict), ...]``; a ValueError when their settings differ."""
    if not entries:
        raise ValueError("coverage table: no benchmark JSON given")
    first_src, first = entries[0]
    for src, bench in entries[1:]:
        if _setting(bench) != _setting(first):
            diff = [k for k, a, b in zip(SETTING, _setting(first), _setting(bench)) if a != b]
            raise ValueError(f"coverage table: {src} differs from {first_src} in {', '.join(diff)}; "
                             "rows must share the twin's setting")
    rows = ["| twins | source | n | reported 90 % interval covers (`sigma_t` / `E_t`) | reported 50 % interval "
            "covers | 90 % width / prior's | last ensemble's 90 % prediction interval covers | WIS / prior's "
            "| uninformative | bars not met |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for src, bench in entries:
        rows += [_row(bench, name, src) for name in SETS if (bench.get(name) or {}).get("twins")]
    posterior = first.get("reported_posterior", "ensemble")
    if posterior == "emulator_mcmc":
        posterior = "`emulator_mcmc`, the 5-95 % and 25-75 % quantiles of the MCMC sample on the emulator"
    else:
        posterior = "`ensemble`, prediction intervals of one more draw from the members"
    sources = ", ".join(f"`{src}`" for src, _ in entries)
    head = (f"From {sources} ({first['method']}, N = {first['ensemble_size']}, window "
            f"{first['window_s'][0] * 1e6:.0f}-{first['window_s'][1] * 1e6:.0f} us; reported posterior: {posterior}; "
            "a sampler that failed counts as a miss; brackets: binomial 95 % intervals; WIS / prior's: the weighted "
            "interval score of the 50 % and 90 % intervals and the median, its mean over the twins over the prior "
            f"box's on the same truths (1: learned nothing); uninformative: {_flag_words(entries)}; the bars: "
            "90 % coverage "
            f"{100 * COVERAGE_90_BAR[0]:.0f}-{100 * COVERAGE_90_BAR[1]:.0f} %, rank tests p >= {SBC_ALPHA}, "
            f"WIS / prior's <= {WIS_BAR['sigma_t']} (`sigma_t`) and {WIS_BAR['E_t']} (`E_t`); misspecified sets: "
            f"90 % coverage >= {100 * COVERAGE_90_MISSPECIFIED_MIN:.0f} %):")
    return "\n".join([head, "", *rows])


def _flag_words(entries) -> str:
    """What the uninformative column counts: the product's flag, read from each record or estimated from
    its quantiles (benchmarks.scores.score_over_prior_of)."""
    params = [p for _, bench in entries for name in SETS for t in (bench.get(name) or {}).get("twins") or []
              for p in ((t.get("emulator_mcmc") or {}).get("params") or t.get("params") or {}).values()]
    scored = sum(p.get("score_over_prior") is not None for p in params)
    words = f"twins whose posterior expects over {INFORMATIVE_RATIO} of the prior's score, the product's flag"
    if scored == len(params):
        return words
    if scored == 0:
        return words + ", estimated from each record's five quantiles (the records predate that score)"
    return words + ", estimated from the five quantiles of the records written before that score"


# A twin's post-peak is not in its window when the observed maximum lies this close to the window's end
# (the curve still rising at the end): its E_t, which acts after the peak, is then seen only through the
# small shift of the peak (review of the harness). Set on the window (its last two samples at 1 us), not
# on any twin's score.
CENSOR_S = 2e-6


def _peak_time(twin: dict) -> float | None:
    """The arg-max of the twin's observed stress (its data's own peak time), as the harness recorded it."""
    rec = ((twin.get("discrepancy") or {}).get("records") or {}).get("synthetic") or {}
    return rec.get("split_time_s")


def censored_table(entries: list) -> str:
    """Per set, the reported posterior scored apart on the twins whose window holds no post-peak and on
    the others (coverage at 90 %, WIS over the prior's, the uninformative share), by the harness's own
    scoring (benchmarks.bench_coverage.score_mcmc / score)."""
    # the harness's scoring and box (its twin experiment's, as bench_coverage.py --rescore), imported when asked
    from benchmarks.bench_coverage import EXPERIMENT, score, score_mcmc, twin_experiment
    from calibration.experiment import ExperimentSpec

    spec = ExperimentSpec.from_config(EXPERIMENT, twin_experiment())
    if list(spec.names) != list(NAMES):
        raise ValueError(f"coverage table: the twin's parameters are {spec.names}, the table's {NAMES}")
    lower, upper = list(spec.lower), list(spec.upper)

    rows = ["| twins | source | post-peak in the window | n | 90 % interval covers (`sigma_t` / `E_t`) "
            "| WIS / prior's | uninformative |", "|---|---|---|---|---|---|---|"]
    for src, bench in entries:
        end = bench["window_s"][1]
        for name in SETS:
            twins = (bench.get(name) or {}).get("twins") or []
            if not twins:
                continue
            missing = [t["seed"] for t in twins if _peak_time(t) is None]
            if missing:
                raise ValueError(f"coverage table: {src} {name}: no observed peak time for twins {missing[:5]}")
            for label, keep in (("no (observed maximum in the last 2 us)", lambda t: _peak_time(t) >= end - CENSOR_S),
                                ("yes", lambda t: _peak_time(t) < end - CENSOR_S)):
                part = [t for t in twins if keep(t)]
                scorer = score_mcmc if bench.get("reported_posterior") == "emulator_mcmc" else score
                res = scorer(part, lower, upper, list(NAMES)) if part else None
                if not res or not res.get("params"):
                    rows.append(f"| {_label(bench, name)} | `{Path(src).name}` | {label} | {len(part)} | - | - | - |")
                    continue
                q = res["params"]
                rows.append(f"| {_label(bench, name)} | `{Path(src).name}` | {label} | {len(part)} "
                            f"| {' / '.join(_pct(q[x]['coverage_90'].get('fraction_counting_failures_as_misses', q[x]['coverage_90']['fraction'])) for x in NAMES)} "
                            f"| {' / '.join(_wis(q[x]) for x in NAMES)} "
                            f"| {' / '.join(_unin(q[x]) for x in NAMES)} |")
    return "\n".join(["The same posteriors scored apart by whether the twin's window holds its post-peak:", "", *rows])


def _part_wis(part: dict) -> str:
    return "-" if part.get("wis_over_prior") is None else f"{part['wis_over_prior']:.2f}"


def _flag_cell(part: dict) -> str:
    c = part.get("coverage_90")
    return "-" if c is None else f"{c['covered']} of {part['n']} (p = {c['p_vs_level']:.3f})"


def flag_table(entries: list) -> str:
    """Per set and parameter, the reported posterior's twins split by the product's ``uninformative``
    flag (benchmarks.scores.product_flag_split): a calibrated posterior covers at its level in both parts."""
    rows = ["| twins | source | parameter | the product says | n | 90 % interval covers (binomial p against 90 %) "
            "| 50 % interval covers | WIS / prior's |", "|---|---|---|---|---|---|---|---|"]
    for src, bench in entries:
        for name in SETS:
            if not (bench.get(name) or {}).get("twins"):
                continue
            for x in NAMES:
                split = reported(bench, name)["params"][x]["product_flag"]
                for key in ("informative", "uninformative"):
                    part = split[key]
                    c50 = part.get("coverage_50")
                    rows.append(f"| {_label(bench, name)} | `{Path(src).name}` | `{x}` | {key} | {part['n']} | {_flag_cell(part)} "
                                f"| {'-' if c50 is None else _pct(c50['fraction'])} "
                                f"| {_part_wis(part)} |")
    head = ("The same posteriors split by whether the product calls each parameter `uninformative` in a run's "
            f"verdict ({_flag_words(entries)}):")
    return "\n".join([head, "", *rows])


def flag_block(*paths: str) -> str:
    """docs/inference.md's block: :func:`flag_table` of the README table's JSONs ``paths``."""
    return f"{FLAG_START}\n{flag_table(_entries(paths))}\n{FLAG_END}"


def _entries(paths) -> list:
    """``[(path, benchmark dict), ...]`` of the JSONs ``paths`` (relative to the repository root)."""
    return [(p, as_benchmark(json.loads((ROOT / p).read_text()))) for p in paths]


def as_benchmark(bench: dict) -> dict:
    """A ``benchmarks/pool_coverage.py`` JSON as a ``bench_coverage.py`` one with its one set: the pooled
    scores and verdict, the twins read from its sources (paths from the repository root); any other
    JSON as it is."""
    if bench.get("benchmark") != "pool_coverage":
        return bench
    name = bench["set"]
    twins = [t for src in bench["sources"] for t in json.loads((ROOT / src).read_text())[name]["twins"]]
    rest = {k: v for k, v in bench.items() if k not in ("summary", "summary_emulator_mcmc", "verdict", "set", "sources")}
    return {**rest, name: {"summary": bench["summary"], "summary_emulator_mcmc": bench["summary_emulator_mcmc"],
                           "verdict": bench["verdict"], "twins": twins}}


def block(*paths: str) -> str:
    """The README block from the benchmark JSONs ``paths`` (relative to the repository root)."""
    return f"{START}\n{table(_entries(paths))}\n{END}"


def censored_block(*paths: str) -> str:
    """docs/inference.md's block: :func:`censored_table` of the README table's JSONs ``paths``."""
    return f"{CENSORED_START}\n{censored_table(_entries(paths))}\n{CENSORED_END}"


def readme_block_sources(text: str) -> list:
    """The JSON paths named in README's block, in order."""
    inner = text.split(START, 1)[1].split(END, 1)[0]
    head = inner.strip().split("\n", 1)[0]
    return [part for part in head.split("`")[1::2] if part.endswith(".json")]


def main(argv) -> int:
    paths = [a for a in argv[1:] if a != "--readme"]
    if "--readme" in argv:
        for doc, (start, end), make in ((ROOT / "README.md", (START, END), block),
                                        (INFERENCE_DOC, (CENSORED_START, CENSORED_END), censored_block),
                                        (INFERENCE_DOC, (FLAG_START, FLAG_END), flag_block)):
            text = doc.read_text()
            a, b = text.index(start), text.index(end) + len(end)
            doc.write_text(text[:a] + make(*paths) + text[b:])
    else:
        print(block(*paths))
        print(censored_block(*paths))
        print(flag_block(*paths))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
