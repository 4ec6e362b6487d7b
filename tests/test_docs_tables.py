"""Numbers quoted in the README come from one generated source: the coverage table between its markers
is exactly what tools/coverage_table.py makes from the benchmark JSON it names."""

from pathlib import Path

from tools import coverage_table, engine_table

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_coverage_table_is_generated_from_the_committed_benchmark_json():
    tool = coverage_table
    text = (ROOT / "README.md").read_text()
    sources = tool.readme_block_sources(text)
    assert sources and all((ROOT / s).is_file() for s in sources), sources
    start, end = text.index(tool.START), text.index(tool.END) + len(tool.END)
    assert text[start:end] == tool.block(*sources)


def test_the_engine_speed_tables_are_generated_from_the_committed_benchmark_json():
    tool = engine_table
    text = (ROOT / "docs" / "engine.md").read_text()
    bench, prof = tool.doc_block_sources(text)
    assert (ROOT / bench).is_file() and (ROOT / prof).is_file(), (bench, prof)
    start, end = text.index(tool.START), text.index(tool.END) + len(tool.END)
    assert text[start:end] == tool.block(bench, prof)


def test_the_readme_loro_table_is_generated_from_the_committed_loro_summaries():
    from tools import loro_table as tool

    text = (ROOT / "README.md").read_text()
    sources = tool.readme_block_sources(text)
    assert sources and all((ROOT / s).is_file() for s in sources), sources
    start, end = text.index(tool.START), text.index(tool.END) + len(tool.END)
    assert text[start:end] == tool.block(sources)
