"""The result numbers quoted in README.md and docs/*.md that no test ties to a committed JSON.

    python tools/docs_numbers.py    # list them (file:line, number, context) and the checked quotes whose
                                    # JSON changed, with the words the doc must now say; exit 1 if any

A *result* is a figure that came out of a run or a benchmark (a coverage, a score, a time, an error, a
count of runs, a z value). Inputs (config values, box bounds, windows), physical constants, literature
values with their citation and thresholds stated as settings are not results.

What is looked at: the text outside the generated blocks (``<!-- name:start -->`` ... ``<!-- name:end
-->``, or ``:begin``), outside code (fenced blocks and `inline code`, which hold commands, config keys
and their values) and outside link targets, less every quote that ``tests/test_docs_numbers.py``
checks against its JSON (``QUOTES`` there, passed in as ``checked``).

Which numbers look like results (``RESULT``): a number with a decimal fraction, a percentage, a
duration (s, min, h), a memory size, a factor (``3.1x``), a count of successes (``7/9``, ``5 of 5``)
and an integer (or a range of them) with a unit or a count noun: ``45 MPa``, ``13 -> 28 us``,
``171 um``, ``230 simulations``, ``22 Slurm jobs``, ``25 members``. Most of the latter are inputs (a
config value, a box, a window, an ensemble's size, a literature value, a pulse); those are listed in
``NOT_RESULTS`` as (file, regex on the number with its words around it, reason), with the other inputs
of a result's shape (a safety factor 0.6, a section number 5.2, a version 2.0.1, an interval level 90 %,
a threshold "at most 10 %"). A space in a regex matches any white space, and inline code is blanked
before the regex is read, so a parameter's name (`` `sigma_t` 45 MPa``) reads as a run of spaces.
``PENDING`` names results of files only their owner may rewrite that no JSON holds yet; they are
printed, not counted, and a test fails once their words are gone.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

GENERATED = re.compile(r"<!-- ([\w-]+):(?:start|begin).*?<!-- \1:end -->", re.S)
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
# inline code may run over a line break; a blank line ends a paragraph, so it cannot be inside
CODE = re.compile(r"`(?:[^`\n]|\n(?!\s*\n))*`")
LINK_TARGET = re.compile(r"\]\([^)\s]*\)")
IMAGE = re.compile(r"!\[[^\]]*\]\([^)]*\)")

_N = r"\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?"
# a number (or a range a-b of numbers) followed by what makes it look like a result
RESULT = re.compile(
    r"(?<![\w.\-/^])(?:[-+])?(?P<num>"
    r"\d[\d,]*\.\d+(?:e[-+]?\d+)?"                       # a decimal fraction: 0.22, 1.4e-4
    r"|" + _N + r"(?:\s?-\s?" + _N + r")?\s?(?:%|x\b|s\b|min\b|h\b|MB\b|GB\b|ms\b)"  # 88-90 %, 704 s, 3.1x
    r"|\d+\s?/\s?\d+(?![\w/^.])"                         # 7/9 (not 1/s, not J/m^2)
    r"|\d+(?:-\d+)?\sof\s(?:the\s)?\d+"                   # 5 of 5, 28-35 of 40
    r"|" + _N + r"(?:\s?(?:-|->|to)\s?" + _N + r")?\s?(?:[kMG]Pa|us|um|mm|m/s|kJ/m\^2|J/m\^2|1/s|nats|"  # 45 MPa, 13 -> 28 us
    r"k?Hz|degrees|(?:FDEM\s|Slurm\s)?(?:runs?|simulations?|jobs?|members?|records?|twins?|steps?|folds?|discs?|cylinders?|samples?|points?|iterations?|analyses|ensembles?|nodes?|elements?|triangles?|joints?|SIGKILLs?|kills?|populations?|realizations?|predictions?))\b"
    r")")

# (file or "*", regex): numbers that have a result's shape and are not results. The regex is searched in
# the number's context (80 characters either side) and must cover the number itself.
NOT_RESULTS: list[tuple[str, str, str]] = [
    ("*", r"section \d+(?:\.\d+)*", "a section of a paper"),
    ("*", r">= ?\d+(?:\.\d+)+", "a version"),
    ("*", r"YAML 1\.1", "a version"),
    ("*", r"Figs?\. \d+(?:/\d+)?", "a figure of the paper"),
    ("*", r"(?<![\d.])(?:5|25|50|75|90|95) ?% (?:\w+[ -]){0,3}?(?:intervals?|band|quantiles?|coverage|predictive|"
          r"prediction|posterior-predictive|credible|central|regions?|width|levels?|\()", "a probability level, a setting"),
    ("*", r"(?:5|25|50|75|90|95) ?% (?:or|and|/) (?:5|25|50|75|90|95) ?%", "probability levels"),
    ("*", r"(?:within|more than|at most|at least|above|below|exceeds?|than|under|over|at) "
          r"(?:\d+ ?%(?: ?(?:/|and|or) )?)+(?! of the twins)", "a threshold stated as a setting (whole percents)"),
    ("*", r"\d+ % / \d+ % bar", "the accuracy bar, a setting"),
    ("*", r"\d+ ?% (?:\(of the peak\) )?(?:white )?noise", "the twins' noise, an input"),
    ("*", r"99 ?% of the singular-value sum", "the SVD's truncation, a setting"),
    ("*", r"defaults? (?:\d+ s[\s,]*)+", "the members' time limits, settings"),
    ("docs/workflow.md", r"alive 2 s after any kill", "how long the kill benchmark waits before it looks"),
    ("*", r"(?:threshold|default)\)?:? \(?(?:default )?\d+(?:\.\d+)?", "a default or a threshold, a setting"),
    ("*", r"(?:at|below|above) \d\.\d+ it (?:selects|would)", "a threshold, a setting"),
    ("docs/sensitivity.md", r"a dummy input below 0\.01", "the test's bound"),
    ("*", r"\|?[xy]?\|? ?< ?0\.\d+ R", "a fracture check's bound, a setting"),
    ("*", r"within 0\.15 R of the diameter", "the fracture check's band, a setting"),
    ("*", r"(?:dips|keep) (?:1|15) %|a (?:1|15) % (?:dip|drop)", "the failure peak's rule, a setting"),
    ("*", r"reaches 2 % of its peak", "the closure's definition, a setting"),
    ("*", r"rate / 1 s\^-1", "a unit"),
    ("docs/shpb-models.md", r"disc's = 0\.96|with = 0\.960", "the flattened disc's factor, Wang et al. 2004"),
    ("docs/shpb-models.md", r"bounds it at 0\.1 % up to the peak and 2 %", "the suite's bounds"),
    ("docs/shpb-models.md", r"between 20 and 80 % of the peak", "the loading rate's definition"),
    ("docs/shpb-models.md", r"the 25 % the test allows", "the test's bound"),
    ("docs/shpb-models.md", r"differ by 17 % \(Wessling|about \+-7 %", "literature"),
    ("docs/shpb-models.md", r"0\.017 x rate", "Saksala et al. 2013's law"),
    ("docs/shpb-models.md", r"16\.9 MPa, Wessling", "literature"),
    ("docs/shpb-models.md", r"1\.5-2 MPa m\^0\.5", "literature"),
    ("docs/shpb-models.md", r"friction 0\.85 \(Byerlee", "literature"),
    ("docs/shpb-models.md", r"0\.15 m for the disc \(gauge at 0\.075 m\)|gauge, 1\.25 m away", "the model's bars, inputs"),
    ("docs/shpb-models.md", r"Table 1, 50 x", "the paper's disc, an input"),
    ("docs/shpb-models.md", r"2\.9 m/s particle velocity", "the default pulse, an input"),
    ("docs/shpb-models.md", r"radius 0\.25 x|radius 0\.1 R", "the mesh jitter's settings"),
    ("docs/shpb-models.md", r"noise \(1 % of the peak\)", "the twin's noise, an input"),
    ("*", r"safety factor 0\.6|at 0\.8 fracture runs|(?:than|as) at 0\.6", "the time step's safety factor, a setting"),
    ("*", r">= \d+ ?%", "a bound"),
    ("docs/engine.md", r"\(-13% at", "the formula's value at f = 10"),
    ("*", r"(?:a|the) 1 % (?:change|scale)", "a perturbation of the input"),
    ("docs/inference.md", r"approximately 45% of the standard", "the paper's words"),
    ("docs/closing-the-loop.md", r"\( 0\.05\), against|level 0\.05 / 8", "the walk's level, a setting"),
    ("docs/closing-the-loop.md", r"1\.5 MPa mesh scatter(?: 90 % shared)?|rate law k = 0\.3|1\.5 % noise", "the stand-ins' inputs"),
    ("docs/closing-the-loop.md", r"scatters widely around 0\.90", "the band's level"),
    ("docs/inference.md", r"within 0\.1 sd, sd within 7 %, quantiles within 0\.12 sd", "the test's tolerances"),
    ("docs/inference.md", r"83 % at N = 25, 70 % at N = 8", "the formula's values"),
    ("docs/inference.md", r"within 2 % \( ?\) / 10 %", "the accuracy bar, a setting"),
    ("*", r"90 % coverage 0\.85-0\.95|not rejected at 1 %|at most 0\.25 \( ?\) and 0\.55", "the harness's bars, settings"),
    ("docs/inference.md", r"bandwidth \(0\.05 \.\.\. 0\.4", "the bandwidths tried, settings"),
    ("docs/cluster.md", r"\d+ x \d+ =\s+\d+ min|plus 5 min", "the time a group asks for, from the settings"),
    ("docs/cluster.md", r"\(\d+ runs: \d+ x \d+ \+ \d+ = \d+ min",
     "the time a batch asks for, from the settings (member_time_limit_s, simulations_per_job)"),
    ("docs/cluster.md", r"\d+ x \d+ records", "the default config's replicates and records, inputs"),
    ("docs/cluster.md", r"MinJobAge >= 15 s|default is (?:300|40) s|comes 5 s after|= 40 s|stopped at 40 s",
     "Slurm's and the plugin's settings"),
    ("docs/engine.md", r"exceeds 10x the work|at 3x the stable step", "the guard's threshold; an input"),
    ("docs/engine.md", r"within 0\.5% over 20,500 steps|less than 0\.1% of the element", "the tests' bounds"),
    ("docs/sensitivity.md", r"shape 0\.3-0\.9, 1\.0-2\.5", "the design's box, an input"),
    ("docs/architecture.md", r"exit codes 0 / 2 / 3", "exit codes"),
    ("docs/own-data.md", r"at most 0\.05 valid|above 0\.10 invalid|between 0\.05 and 0\.10|from 10 % of the peak|"
     r"onset \(5 % of its peak\)|plus 10 %|\(1, 2, 2\.5 or 5 x 10\^k s\)", "the lab checks' limits and the config's rules"),
    ("docs/own-data.md", r"\(0\.57 c0 for nu = 0\.32\)|for nu = 0\.32", "the Rayleigh speed's ratio, physics"),
    ("docs/own-data.md", r"short \(0\.15 m, the wave enters 0\.15 m", "the disc's bars, inputs"),
    ("docs/own-data.md", r"0\.05-1\s+times it for a cylinder, 0\.25-5 times it", "init-config's PEAK_MULTIPLES, a setting"),
    # integers with a unit: inputs, settings, data and literature
    # inline code is blanked before this is read, so a parameter's name reads as a run of spaces
    ("*", r"\x20{3,}\s*=?\s*\d[\d,]*(?:-\d[\d,]*)?\s(?:MPa|J/m\^2|um)\b",
     "a number right after a parameter's name: its value, box or default, an input"),
    ("*", r"(?:granite|marble|sandstone) \d[\d,]*-\d[\d,]* MPa|\d[\d,]*-\d[\d,]* J/m\^2 for a (?:disc|cylinder)"
          r"|[Bb]ox (?:is )?(?:\[0, )?\d[\d,]*(?:-\d[\d,]*)? (?:um|J/m\^2)|box reaches 50 kJ/m\^2", "a prior box, a setting"),
    ("*", r"the truth, 500 J/m\^2", "the twin's truth, an input"),
    ("*", r"(?:[Ww]indow:? \(?|over |window's |that file's |the (?:whole )?|simulate a longer window \()(?:0-)?(?:160|170|280|360|600) us"
          r"(?: against 160| after arrival| window)?|(?:a|on a) [12] us grid|[Ww]indows?\.\*\* Disc: 0-160 us|Cylinder: 0-360 us"
          r"|run to 600 us|crushed by 160 us", "a window or a grid, a setting"),
    ("*", r"(?:\(|, |its own |rests on |same size \(|size \(|\(`fast` preset, |itself \(|makes it a small )"
          r"(?:6|8|10|25|100|400) (?:members|runs)(?: x 2 records)?|(?:400 members.{0,60}?)?8 steps\)"
          r"|with 10 members|n_params \+ 2 runs|1,000 step members|2 ES-MDA steps, 20 simulations"
          r"|(?:24 points|before/after) x 3 records|\(x 3 records|four ensembles, 100 simulations",
     "an ensemble's or a design's size, a setting"),
    ("*", r"(?:\(|at |SHPB_004 \(|SHPB_014 \()\d+(?:-\d+)? 1/s", "a measured record's strain rate, data"),
    ("docs/closing-the-loop.md", r"level at 3-5 records", "the population sizes the study simulated, inputs"),
    ("docs/closing-the-loop.md", r"N\(100, 25 um\)|`g` 135 um and `Delta` 150 um|100 us of quiet bar",
     "the planted records' inputs"),
    ("docs/own-data.md", r"-20 us on the Freiburg", "10 cm over the bar's wave speed, physics"),
    ("docs/own-data.md", r"a 10 us rise on 50 mm|on 50 mm titanium", "the dispersion test's pulse and bars, inputs"),
    ("docs/own-data.md", r"at least 10 us\), rounded up to 10 us", "init-config's window rule, a setting"),
    ("docs/own-data.md", r"truth of the example is sigma_t = 45 MPa, E_t = 500 J/m\^2|the 160 us window",
     "the example's truth and config, inputs"),
    ("docs/sensitivity.md", r"post-peak slope \(over 20 us\)|within 20 us of the window's end", "the outputs' definitions"),
    ("docs/sensitivity.md", r"Window 0-(?:280|160) us, [12] us grid", "the design's window, a setting"),
    ("docs/sensitivity.md", r"`E_n` 50-200 J/m\^2|(?:`sigma_n`|`sigma_t`) \d+-\d+ MPa|`E_t` 200-2,400 J/m\^2|`E_n` 20-200 J/m\^2"
     r"|`E_t` 100-5,000 J/m\^2", "the design's box, an input"),
    ("docs/shpb-models.md", r"\(statically, the tensile strength `sigma_n` 15 MPa|Why `sigma_n` is 15 MPa|about 13 MPa, Saksala"
     r"|Why is 15 MPa|earlier default, 25 MPa|25 and 15 MPa|at 15 MPa the centre|had cured it at 25 MPa|13-16\.9 MPa in two",
     "the joint strength: literature and the default chosen from it"),
    ("docs/shpb-models.md", r"2013: 21 MPa", "Saksala et al. 2013's law"),
    ("docs/shpb-models.md", r"slower pulse \(rise 200 us\)", "a pulse tried, an input"),
    ("docs/shpb-models.md", r"50 x 25 mm, steel bars 50 mm \(200 GPa|titanium bars \(110 GPa, 4430 kg/m\^3, 50 mm\)",
     "the paper's disc and the bars, inputs"),
    ("docs/shpb-models.md", r"the 5 m/s striker|\(115 MPa: rise 120 us, plateau 45 us, fall 115 us|the 225 MPa Kuru pulse",
     "the Kuru granite pulses, inputs"),
    ("docs/shpb-models.md", r"At `sigma_t` 4 MPa \(the box's low end\)", "the box's end, a setting"),
    ("docs/shpb-models.md", r"2 alpha (?:= )?\d+(?:-\d+)? degrees|friction angle (?: )?\d+ degrees",
     "the loading angles tried and the friction angles (literature, the Freiburg sheet), inputs"),
    ("docs/shpb-models.md", r"runs 8 realizations", "the benchmark's size, a setting"),
    ("docs/inference.md", r"N = 25, 3 iterations|100 runs, 101 samples", "a test's and an analysis' sizes, settings"),
    ("docs/workflow.md", r"\): 20 SIGKILLs", "the kill benchmark's number of kills, a setting"),
]

# Result numbers in README.md and docs/workflow.md that no committed JSON holds yet: the lead regenerates
# those two files from a new default run, and only the lead edits their words. Listed (and printed by
# main) rather than hidden: each must become a quote or words when the files are rewritten.
PENDING: list[tuple[str, str, str]] = []


def masked(text: str, checked: list[str] = ()) -> str:
    """``text`` with generated blocks, code, link targets and the ``checked`` quotes blanked out (line
    breaks kept, so line numbers stay)."""
    def blank(m):
        return re.sub(r"[^\n]", " ", m.group(0))
    text = GENERATED.sub(blank, text)
    # the quotes first: they may hold code and links of their own
    for q in checked:
        pattern = r"\s+".join(re.escape(w) for w in q.split())
        text = re.sub(pattern, blank, text)
    for rx in (FENCE, IMAGE, CODE, LINK_TARGET):
        text = rx.sub(blank, text)
    return text


def _excused(name: str, text: str, start: int, end: int) -> str | None:
    lo, hi = max(0, start - 80), min(len(text), end + 80)
    window = text[lo:hi]
    for doc, rx, why in NOT_RESULTS + PENDING:
        if doc not in ("*", name):
            continue
        # a space in a pattern is any run of white space (the docs wrap lines anywhere)
        for m in re.finditer(rx.replace(" ?", r"\s*").replace(" ", r"\s+"), window):
            if lo + m.start() <= start and lo + m.end() >= end:
                return why
    return None


def unchecked(name: str, text: str, checked: list[str] = ()) -> list[tuple[int, str, str]]:
    """``[(line, number, context)]`` of every result-looking number of ``text`` (the file ``name``,
    relative to the repository) that is neither generated, nor checked, nor a listed non-result."""
    body = masked(text, checked)
    out = []
    for m in RESULT.finditer(body):
        if _excused(name, body, m.start(), m.end()):
            continue
        line = body.count("\n", 0, m.start()) + 1
        ctx = " ".join(text[max(0, m.start() - 50):m.end() + 30].split())
        out.append((line, m.group(0).strip(), ctx))
    return out


def docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def main(argv: list[str]) -> int:
    sys.path.insert(0, str(ROOT))
    from tests.test_docs_numbers import QUOTES  # the checked table lives with its test
    checked: dict = {}
    n = 0
    for q in QUOTES:
        text = q.text()
        checked.setdefault(q.doc, []).append(text)
        # a quote whose JSON changed (a new default run): the words the doc must now say
        if " ".join(text.split()) not in " ".join((ROOT / q.doc).read_text().split()):
            print(f"{q.doc}\tstale quote, now: {text}")
            n += 1
    for path in docs():
        name = str(path.relative_to(ROOT))
        for line, num, ctx in unchecked(name, path.read_text(), checked.get(name, [])):
            print(f"{name}:{line}\t{' '.join(num.split())}\t{ctx}")
            n += 1
    for doc, rx, why in PENDING:
        print(f"{doc}\tpending (not counted), {rx!r}: {why}", file=sys.stderr)
    print(f"{n} stale quotes and unchecked result numbers", file=sys.stderr)
    return 1 if n else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
