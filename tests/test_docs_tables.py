"""Numbers quoted in the README and docs come from one generated source: each block between its markers
is exactly what its tool makes from the committed JSON it names, and the README's run time is the
committed run.json's."""

import json
from pathlib import Path

from benchmarks.scores import pooled_learned_coverage
from tools import coverage_table, engine_table, loro_table, planted_table, results_table, shpb_table

ROOT = Path(__file__).resolve().parents[1]


def _block(text: str, tool) -> str:
    start, end = text.index(tool.START), text.index(tool.END) + len(tool.END)
    return text[start:end]


def test_the_readme_coverage_table_is_generated_from_the_committed_benchmark_json():
    text = (ROOT / "README.md").read_text()
    sources = coverage_table.readme_block_sources(text)
    assert sources and all((ROOT / s).is_file() for s in sources), sources
    assert _block(text, coverage_table) == coverage_table.block(*sources)


def test_the_readme_results_table_is_generated_from_the_newest_committed_default_run():
    text = (ROOT / "README.md").read_text()
    sources = results_table.readme_block_sources(text)
    assert sources == [f"benchmarks/results/default_run/{e}/summary.json" for e in results_table.DEFAULT_RUN[1]]
    assert _block(text, results_table) == results_table.block(*sources)


def test_the_censored_twins_table_is_generated_from_the_readme_table_s_json():
    """docs/inference.md scores apart the twins whose window holds no post-peak, from the JSON the README's
    coverage table names, by the harness's own scoring (tools/coverage_table.censored_table)."""
    sources = coverage_table.readme_block_sources((ROOT / "README.md").read_text())
    text = (ROOT / "docs" / "inference.md").read_text()
    start, end = text.index(coverage_table.CENSORED_START), text.index(coverage_table.CENSORED_END)
    assert text[start:end + len(coverage_table.CENSORED_END)] == coverage_table.censored_block(*sources)
    # every twin of every set lands in one of the two rows of its set
    rows = [r for r in text[start:end].splitlines() if r.startswith("| well-specified") or r.startswith("| misspecified")]
    benches = [coverage_table.as_benchmark(json.loads((ROOT / s).read_text())) for s in sources]
    total = sum(len((b.get(k) or {}).get("twins") or []) for b in benches for k in coverage_table.SETS)
    assert sum(int(r.split("|")[4]) for r in rows) == total
    # the sentence after the table: E_t's WIS over the prior's on each benchmark's well-specified twins without
    # and with their post-peak, and the censored twins' E_t coverage
    flat = " ".join(text.split())
    well = [{r.split("|")[3].strip().startswith("no"): r.split("|") for r in rows
             if r.startswith("| well-specified") and f"`{Path(src).name}`" in r} for src in sources]
    well = [w for w in well if w]  # the sources with well-specified twins (a pooled misspecified set has none)
    wis = [{k: c[6].strip().split(" / ")[1] for k, c in w.items()} for w in well]
    assert (f"(WIS {wis[0][True]} of the prior's, against {wis[0][False]} where the window holds the post-peak); on the "
            f"second's it is learned better than on the others ({wis[1][True]} against {wis[1][False]})") in flat
    assert float(wis[0][True]) > float(wis[0][False]) and float(wis[1][True]) < float(wis[1][False])
    cov = {w[True][5].strip().split(" / ")[1] for w in well}
    assert len(cov) == 1 and f"these twins' `E_t` intervals cover {cov.pop()} at 90 %" in flat
    # the bank's yardstick beside the same rows (both parameters' WIS over the prior's)
    both = [{k: c[6].strip() for k, c in w.items()} for w in well]
    assert f"and the shipped form {both[0][True]} and {both[1][True]} on the two benchmarks (the table above)" in flat
    assert f" against {both[0][False]} and {both[1][False]}. " in flat


def test_the_flag_split_table_is_generated_and_its_prose_is_its_rows():
    """docs/inference.md splits the README table's twins by the product's uninformative flag
    (tools/coverage_table.flag_table); the prose after it and the README quote its well-specified rows."""
    sources = coverage_table.readme_block_sources((ROOT / "README.md").read_text())
    text = (ROOT / "docs" / "inference.md").read_text()
    start, end = text.index(coverage_table.FLAG_START), text.index(coverage_table.FLAG_END)
    assert text[start:end + len(coverage_table.FLAG_END)] == coverage_table.flag_block(*sources)
    # per source: {(set, parameter, the product says): [n, 90 % cell, 50 % cell, WIS]}
    rows = [{(c[1], c[3], c[4]): c[5:9] for c in ([x.strip() for x in r.split("|")] for r in text[start:end].splitlines()
                                               if r.startswith("| well-specified") and f"`{Path(src).name}`" in r)}
            for src in sources]
    rows = [r for r in rows if r]  # the sources with well-specified twins

    def kn(cell):
        k, n = cell.split(" (")[0].split(" of ")
        return int(k), int(n), float(cell.split("p = ")[1].rstrip(")"))

    flat = " ".join(text.split())
    first = rows[0]
    n_inf, cov_inf = first[("well-specified", "`E_t`", "informative")][:2]
    n_unin, _, _, wis_unin = first[("well-specified", "`E_t`", "uninformative")]
    k, n, p = kn(cov_inf)
    assert n == int(n_inf) and p < 0.01  # the first benchmark's informative E_t intervals are too sure
    assert (f"it informative on {n} of the {n + int(n_unin)} well-specified twins and those 90 % intervals hold the "
            f"truth in {k} (binomial p = {p:.3f} against 90 %); the {n_unin} it flags cover at their level but score "
            f"{wis_unin} of the prior's") in flat
    # the second does not repeat it; sigma_t's learned intervals pooled are not rejected at 1 %
    k2, n2, p2 = kn(rows[1][("well-specified", "`E_t`", "informative")][1])
    assert p2 >= 0.01 and f"does not repeat the miss: {k2} of {n2} (p = {p2:.3f})" in flat
    benches = [json.loads((ROOT / src).read_text()) for src in sources]
    assert pooled_learned_coverage([b for b in benches if b.get("well_specified")], "sigma_t")["p"] >= 0.01
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert f"those the verdict calls informative held the truth in {k} of {n} and {k2} of {n2} twins at 90 %" in readme


def test_the_readme_quotes_the_default_runs_time_from_its_idle_run():
    # the committed default run: a fresh clone on an idle machine (its run.json), its results beside it
    run = json.loads((ROOT / "benchmarks" / "results" / "default_run" / "run.json").read_text())
    text = (ROOT / "README.md").read_text()
    assert run["exit_code"] == 0 and run["cores"] == 2 and run["fresh_clone_empty_folder"] and run["machine_idle"]
    assert run["load_average_at_start"][0] < 0.5  # idle when it started
    assert f"on an idle 2-core machine the default run took {run['run_s']} s, {run['fdem_runs']} FDEM runs" in " ".join(
        text.split())


def test_the_workflow_docs_default_run_tables_are_the_tools_output():
    text = results_table.WORKFLOW_DOC.read_text()
    start, end = text.index(results_table.WORKFLOW_START), text.index(results_table.WORKFLOW_END)
    assert text[start:end + len(results_table.WORKFLOW_END)] == results_table.workflow_block()
    folder = ROOT / "benchmarks" / "results" / "default_run"
    assert results_table.table(folder, results_table.DEFAULT_RUN[1]) in text
    for loop in ("marble_loop", "planted_gap"):
        assert results_table.diagnosis_table(folder, loop) in text


def test_the_engine_speed_tables_are_generated_from_the_committed_benchmark_json():
    text = (ROOT / "docs" / "engine.md").read_text()
    bench, prof = engine_table.doc_block_sources(text)
    assert (ROOT / bench).is_file() and (ROOT / prof).is_file(), (bench, prof)
    assert _block(text, engine_table) == engine_table.block(bench, prof)


def test_the_loro_table_is_generated_from_the_committed_loro_summaries():
    text = loro_table.DOC.read_text()
    sources = loro_table.doc_block_sources(text)
    assert sources and all((ROOT / s).is_file() for s in sources), sources
    assert _block(text, loro_table) == loro_table.block(sources)


def test_the_workflow_docs_kill_figures_are_the_committed_benchmarks():
    kill = json.loads((ROOT / "benchmarks" / "results" / "bench_kill.json").read_text())
    text = " ".join((ROOT / "docs" / "workflow.md").read_text().split())
    # the trials whose run was still going when its kill came (the others finished before it)
    waits = [t["wait_s"] for t in kill["trials"] if not t["finished_before_kill"]]
    assert kill["cores"] == 2 and len(waits) == kill["kills"]
    assert (f"{kill['kills']} SIGKILLs of Snakemake alone (not its process group) at random points "
            f"{min(waits):.1f}-{max(waits):.0f} s into a small twin with the stand-in simulator "
            f"({kill['members']} members, two analyses)") in text
    assert kill["analyses"] == 2 and kill["kills_with_live_processes"] == kill["kills_with_files_written_after"] == 0
    assert kill["temporaries_left_after_a_completed_run"] == 0
    assert f"each of the {kill['completed_runs']} runs that got to the end identical" in text
    assert kill["completed_runs_identical_to_reference_and_clean"] == kill["completed_runs"]


def test_the_shpb_models_tables_are_generated_from_the_committed_benchmark_json():
    text = shpb_table.DOC.read_text()
    for start, end, block in ((shpb_table.PRESET_START, shpb_table.PRESET_END, shpb_table.preset_block()),
                              (shpb_table.VAR_START, shpb_table.VAR_END, shpb_table.variability_block())):
        assert text[text.index(start):text.index(end) + len(end)] == block


def test_the_planted_benchmark_s_score_is_generated_from_its_committed_json():
    """docs/closing-the-loop.md's score of the planted-effect benchmark is what tools/planted_table.py makes
    from benchmarks/results/bench_planted.json, which pools every case x benchmark seed of the committed plan
    once (the series' files in bench_planted_records/)."""
    text = (ROOT / "docs" / "closing-the-loop.md").read_text()
    path = "benchmarks/results/bench_planted.json"
    assert _block(text, planted_table) == planted_table.block(path)
    doc = json.loads((ROOT / path).read_text())
    plan = json.loads((ROOT / "benchmarks" / "planted_plan.json").read_text())
    planned = {(c["case"], s) for c in plan["cases"] for s in plan["seeds"]["benchmark"]["per_case"]}
    assert sorted((r["case"]["case"], r["seed"]) for r in doc["series"]) == sorted(planned)
    # each pooled series is the one committed in the records folder
    for r in doc["series"]:
        rec = json.loads((ROOT / "benchmarks/results/bench_planted_records" / f"{r['case']['case']}_{r['seed']}.json").read_text())
        assert rec["series"][0]["named"] == r["named"] and rec["series"][0]["wall_s"] == r["wall_s"]
