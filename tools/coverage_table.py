"""The README's coverage table, generated from the coverage benchmark's JSON (one source for the numbers).

    python tools/coverage_table.py benchmarks/results/bench_coverage_<date>.json          # print it
    python tools/coverage_table.py benchmarks/results/bench_coverage_<date>.json --readme  # rewrite README's block
    python tools/coverage_table.py bench.json pooled_a.json pooled_b.json --readme  # pooled sets (well-specified: the first row)

The block sits between ``<!-- coverage-table:start -->`` and ``<!-- coverage-table:end -->`` in
README.md; ``tests/test_docs_tables.py`` checks that it equals what this tool makes from the JSON named
in the block.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
START, END = "<!-- coverage-table:start -->", "<!-- coverage-table:end -->"
NAMES = ("sigma_t", "E_t")


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _cov(c: dict) -> str:
    # a reported MCMC posterior's failed samplers count as misses (score_mcmc)
    f = c.get("fraction_counting_failures_as_misses", c["fraction"])
    lo, hi = c.get("ci95_counting_failures_as_misses", c["ci95"])
    return f"{_pct(f)} [{_pct(lo)}, {_pct(hi)}]"


def reported(bench: dict, name: str) -> dict:
    """The set's summary of the posterior the twin reports (``reported_posterior``; the ensemble before it
    was recorded)."""
    mcmc = bench.get("reported_posterior") == "emulator_mcmc"
    return bench[name]["summary_emulator_mcmc"] if mcmc else bench[name]["summary"]


def _form(entry: dict) -> str:
    """The reported posterior's emulator error (``ar1``, the only form before the key existed), and
    ``refined`` with the refinement batch (``refine_runs``, none before the key existed)."""
    refined = f" refined ({entry['refine_runs']} runs)" if entry.get("refine_runs") else ""
    return (entry.get("emulator_error") or "ar1") + refined


def _label(entry: dict) -> str:
    extra = ""
    if entry.get("approximation_pairs"):
        # a pooled JSON from before coarse_variability existed holds the form that code had
        extra = (f" + approximation error ({entry['approximation_pairs']} pairs, "
                 f"{entry.get('coarse_variability') or 'counted'})")
    if entry.get("set") is None:
        seeds = sorted({t["seed"] // 1000 for t in entry["twins"] if "seed" in t})
        where = f", seed{'s' * (len(seeds) > 1)} {', '.join(map(str, seeds))}" if seeds else ""
        return f"{entry['name'].replace('_', '-')}{extra}{where}, {_form(entry)}"
    seeds = sorted({s // 1000 for v in entry["sources"].values() for s in v["twin_seeds"]})
    return f"{entry['set'].replace('_', '-')}{extra}, seeds {', '.join(map(str, seeds))}, {_form(entry)}"


def _sets(bench: dict, pooled: list) -> list:
    """``[(label, reported summary, ensemble summary, planned-note)]``: pooled well-specified sets
    (``benchmarks/pool_coverage.py``) first, then the bench's well-specified set and either its
    misspecified set or, given pooled misspecified JSONs, those; a further
    bench_coverage JSON among ``pooled`` adds its well-specified set (another seed or emulator error), or
    its misspecified set when it ran no well-specified twins."""
    out = []
    extra = [b for b in pooled if b.get("benchmark") == "bench_coverage"]
    pooled = [b for b in pooled if b.get("benchmark") != "bench_coverage"]
    for b in (bench, *extra):
        for name in ("well_specified", "misspecified"):
            # an extra JSON's misspecified set is a row of its own only in a misspecified-only run
            # (--twins 0); otherwise the pooled misspecified JSONs hold it
            only_mis = not (b.get("well_specified") or {}).get("twins")
            if name not in b or not b[name]["twins"] or (name == "misspecified" and pooled
                                                           and (b is bench or not only_mis)):
                continue
            done = "" if b[name].get("complete", True) else f" of {b[name]['planned']} planned"
            approx = {k: b.get(k) for k in ("approximation_pairs", "coarse_variability")} if name == "misspecified" else {}
            out.append((_label({"name": name, "twins": b[name]["twins"], "emulator_error": b.get("emulator_error"),
                                "refine_runs": b.get("refine_runs"), **approx}),
                        reported(b, name), b[name]["summary"], done))
    lead = []
    for entry in pooled:
        mcmc = entry.get("reported_posterior") == "emulator_mcmc"
        row = (_label(entry), entry["summary_emulator_mcmc"] if mcmc else entry["summary"], entry["summary"], "")
        # a pooled well-specified set of the bench's own form is the headline: the most twins of the
        # reported form (one of another form, e.g. before the refinement batch, follows the bench's rows)
        same = _form(entry) == _form({"emulator_error": bench.get("emulator_error"), "refine_runs": bench.get("refine_runs")})
        (lead if entry["set"] == "well_specified" and same else out).append(row)
    # the well-specified rows first, then the misspecified ones, each in the order given
    return lead + sorted(out, key=lambda row: row[0].startswith("misspecified"))


def table(bench: dict, source: str, pooled: list | None = None, pooled_sources: tuple = ()) -> str:
    rows = ["| twins | n | converged | 90 % covers (`sigma_t` / `E_t`) | 50 % covers | SBC uniformity p (chi^2) "
            "| 90 % width / prior's | median 90 % half-width | restated bar met |",
            "|---|---|---|---|---|---|---|---|---|"]
    sets = _sets(bench, pooled or [])
    for label, s, _, done in sets:
        p = s["params"]

        def both(f):
            return " / ".join(f(p[q]) for q in NAMES)

        def sbc(q):
            return f"{q['sbc']['chi2_p']:.2g}"

        def width(q):
            return f"{q['width_over_prior_median']:.2f}"

        rows.append(
            f"| {label} | {s['n_twins'] + s.get('sampler_failed', 0)}{done} | {s['converged']} "
            f"| {both(lambda q: _cov(q['coverage_90']))} | {both(lambda q: _cov(q['coverage_50']))} "
            f"| {both(sbc)} | {both(width)} | {both(lambda q: _pct(q['half_width_90_rel_median']))} "
            f"| {both(lambda q: _pct(q['bar']['fraction_met']))} |")
    posterior = bench.get("reported_posterior", "ensemble")
    if posterior == "emulator_mcmc":
        posterior += " with self-calibration" if bench.get("self_calibrate") else ""
        posterior += ("; a row's label ends with its emulator error, `ar1` or `heteroscedastic`, and `refined` "
                      "where the reported posterior was measured at a refinement batch")
    also = "".join(f", `{x}`" for x in pooled_sources)
    head = (f"From `{source}`{also} ({bench['method']}, N = {bench['ensemble_size']}, window "
            f"{bench['window_s'][0] * 1e6:.0f}-{bench['window_s'][1] * 1e6:.0f} us; reported posterior: {posterior}; "
            f"`converged`: the loops ended by the stop test each run had; brackets: binomial 95 % intervals):")
    return "\n".join([head, "", *rows, "", _reference_line(bench, sets), *_ensemble_line(bench, sets)])


def _ensemble_line(bench: dict, sets: list) -> list:
    """Under an MCMC posterior, the last simulated ensemble's 90 % coverage on the same twins, and the
    samplers that failed or did not converge."""
    if bench.get("reported_posterior") != "emulator_mcmc":
        return []
    parts = []
    for label, m, e, _ in sets:
        e = e["params"]
        parts.append(f"{label} " + " / ".join(_pct(e[q]["coverage_90"]["fraction"]) for q in NAMES)
                     + " (width / prior's " + " / ".join(f"{e[q]['width_over_prior_median']:.2f}" for q in NAMES)
                     + f"; samplers failed {m['sampler_failed']}, chains converged {m['chains_converged']} "
                     f"of {m['n_twins']})")
    return ["", "The last simulated ensemble's own 90 % intervals on the same twins cover (`sigma_t` / `E_t`): "
            + "; ".join(parts) + "."]


def _reference_line(bench: dict, sets: list) -> str:
    """What a calibrated posterior would give with these members, and how far each coverage is from it."""
    ws = reported(bench, "well_specified")["params"]
    parts = []
    for label, s, _, _ in sets:
        p = s["params"]
        parts.append(f"{label} 90 %: " + " / ".join(f"{p[q]['coverage_90']['p_vs_reference']:.2g}" for q in NAMES)
                     + ", 50 %: " + " / ".join(f"{p[q]['coverage_50']['p_vs_reference']:.2g}" for q in NAMES))
    prediction = bool(bench["well_specified"]["twins"][0]["params"]["sigma_t"].get("interval"))
    if bench.get("reported_posterior") == "emulator_mcmc":
        lead = ("The reported intervals are the 5-95 % and 25-75 % quantiles of the emulator MCMC sample "
                "(thousands of draws: calibrated at their nominal 90 % and 50 %); binomial p of each coverage "
                "against that")
    elif prediction:
        lead = ("The reported intervals are t prediction intervals of one more draw from the members "
                "(`enkf.prediction_interval_dict`), calibrated at their nominal 90 % and 50 %; binomial p of "
                "each coverage against that")
    else:
        lead = (f"A calibrated posterior sampled by the reported members covers their 5-95 % sample interval "
                f"{_pct(ws['sigma_t']['coverage_90']['reference_for_members'])} of the time and their 25-75 % interval "
                f"{_pct(ws['sigma_t']['coverage_50']['reference_for_members'])} (the n + 1 draws argument; "
                f"`reference_coverage` in `benchmarks/bench_coverage.py`); binomial p of each coverage against that")
    return lead + " (`sigma_t` / `E_t`): " + "; ".join(parts) + "."


def block(path: str, *pooled_paths: str) -> str:
    """The README block from the benchmark JSON ``path`` and, optionally, pooled sets
    (``benchmarks/pool_coverage.py`` JSONs: a well-specified one leads the table, misspecified ones
    replace the benchmark's own misspecified row) and further bench_coverage JSONs whose sets are added
    as rows."""
    bench = json.loads((ROOT / path).read_text())
    pooled = [json.loads((ROOT / q).read_text()) for q in pooled_paths]
    return f"{START}\n{table(bench, path, pooled, pooled_paths)}\n{END}"


def readme_block_sources(text: str) -> list:
    """The JSON paths named in README's block (the benchmark's first)."""
    inner = text.split(START, 1)[1].split(END, 1)[0]
    head = inner.strip().split("\n", 1)[0]
    return [part for part in head.split("`")[1::2] if part.endswith(".json")]


def main(argv) -> int:
    paths = [a for a in argv[1:] if a != "--readme"]
    if "--readme" in argv:
        readme = ROOT / "README.md"
        text = readme.read_text()
        a, b = text.index(START), text.index(END) + len(END)
        readme.write_text(text[:a] + block(*paths) + text[b:])
    else:
        print(block(*paths))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
