"""The planted-effect benchmark on FDEM (issue 53, item 1): does the shipped loop name what was planted?

    python benchmarks/bench_planted.py [--plan benchmarks/planted_plan.json] [--cases rate_strength,null]
        [--seeds benchmark|development|5391,...] [--records N] [--preset standard] [--work DIR] [--out JSON]

For each case x seed of the plan (benchmarks/planted_plan.json, committed before any run): the series is
made by tools/make_planted_series.py in a work folder (the truth mesh, the plan's drivers, one effect
planted, its size measured against the same meshes with the effect off), configured the way a lab
configures its own records, ``python -m shpb init-config --diagnosis --allow-invalid --no-approximation-error`` (one record held
out; a record the reduction grades invalid is calibrated on anyway: its force imbalance is the simulator's
own, which the calibration model shares, e.g. mean R 0.107 on data/examples/planted_rate's PlantCaMa_02),
with one edit: ``diagnosis.exclude`` emptied, so the whole catalogue is offered (init-config leaves out
damping and seating, two of the planted cases). The shipped loop then runs, ``snakemake --cores N --configfile``, from
the repository; its ``results/<experiment>/diagnosis/report.json`` and ``check.json`` are read and scored:

* what was named: the first addition the confirmation walk confirmed on real FDEM runs, else the verdict
  (``base_kept``, or whatever else the report says, e.g. ``unexplained``);
* a confusion matrix planted -> named over every series; the null's false-positive rate (any confirmed
  effect); the out-of-catalogue cases' share ending ``base_kept`` or ``unexplained``; the planted
  parameter inside the shipped model's reported 90 % interval (q05-q95; a per-record parameter: each
  calibration record's copy against its own planted value);
* the proposal's power: the planted effect's place in the first round's emulated ranking and whether
  the walk ran it on real FDEM (:func:`proposals`);
* wall time and cores per series; every miss with its reason;
* with ``--realrun``, the selection on real runs too (``diagnosis.realrun_selection`` with its defaults,
  calibration.realrun): what it names beside the walk, scored by :func:`realrun_row` and
  :func:`realrun_scores` (its candidates are physical, so every non-physical case is right when it names
  nothing).

Writes ``--out`` (default benchmarks/results/bench_planted.json) after every series, so a stopped run
keeps what it measured; ``--split PART FOLDER`` files a part's series one file each, and ``--pool PART
...`` scores the parts of a run made in several sittings together. The scoring functions
(:func:`named`, :func:`parameter_coverage`, :func:`score`) are pure: tests/test_bench_planted.py checks
them on hand-made reports.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "benchmarks" / "planted_plan.json"
OUT = ROOT / "benchmarks" / "results" / "bench_planted.json"
#: Outcomes that are not an effect's name.
NOT_NAMED = ("base_kept", "unexplained")
#: An effect "moves the curve by more than the mesh scatter" when its largest change of a test's peak is
#: above this many of the fast mesh's peak standard deviations (bench_sim_variability.json).
SCATTER_MULTIPLE = 2.0

#: The drivers the plan names (planted_plan.json ``series``): the cylinders' measured incident waves, the
#: discs' trapezoid pulse amplitudes [m/s].
CAMA = "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/"
CYLINDER_DRIVERS = tuple(CAMA + f for f in ("CaMa_SHPB_016_Ti25_40b_Al12b_0_001.txt",
                                            "CaMa_SHPB_006_Ti25_70b_Al12b_0_001.txt",
                                            "CaMa_SHPB_015_Ti25_65b_Al12b_0_001.txt",
                                            "CaMa_SHPB_019_Ti25_73b_Al12b_0_001.txt"))
DISC_PULSES_M_S = (2.2, 2.6, 3.0, 3.4)

sys.path.insert(0, str(ROOT))


# ---------------------------------------------------------------------------------------------- scoring
def named(report: dict) -> str:
    """What a diagnosis report names: its first confirmed addition, else its verdict."""
    conf = report.get("confirmation") or {}
    effects = conf.get("effects") or report.get("added") or []
    if report.get("verdict") == "confirmed" and effects:
        return str(effects[0])
    return str(report.get("verdict") or "base_kept")


def gate_summary(report: dict) -> dict:
    """The identification gate's part in a report (calibration.walk.gated): the effects the walk confirmed,
    the ones shipped, and per gated model its effect, whether identified and its parameters' intervals."""
    conf = report.get("confirmation") or {}
    gate = conf.get("identification_gate") or {}

    def entry(ident):
        return None if not ident else {"effect": ident["effect"], "identified": ident["identified"],
                                       "intervals": {p["name"]: [p["lower"], p["upper"]] for p in ident["parameters"]}}
    return {"walk": [s["effect"] for s in conf.get("steps") or [] if s.get("confirmed")],
            "shipped": list(report.get("added") or []), "level": gate.get("level"), "kept": entry(gate.get("kept")),
            "dropped": [entry(d["identification"]) for d in gate.get("dropped") or []]}


def _shipped_posterior(report: dict) -> dict:
    """The posterior summary (name -> mean, q05, q95) of the model the report ships: a nested step, or a
    round's alternative where the walk confirmed that instead of the round's refuted choice."""
    effects = list((report.get("confirmation") or {}).get("effects") or report.get("added") or [])
    sel = report.get("selection") or {}
    for step in (*sel.get("steps", []), *sel.get("alternatives", [])):
        if list(step.get("effects", [])) == effects:
            return step.get("posterior") or {}
    return {}


def parameter_coverage(report: dict, truth: dict, refit: dict | None = None) -> dict:
    """Whether each planted parameter lies inside the shipped model's reported 90 % interval: its refit on
    real runs (diagnosis/refit.json, ``refit``) where the run made one, else the selection's fit in the
    report.

    A shared parameter is read once; a per-record one (``<param>@<record>`` in the report) per calibration
    record, against that record's planted value (truth.json ``tests[].planted``). A parameter the shipped
    model does not carry is not covered. Returns ``{"checks": [...], "covered": share or None, "source"}``."""
    refitted = (refit or {}).get("posterior")
    return coverage_of(refitted or _shipped_posterior(report), truth,
                       "refit on real runs" if refitted else "selection's fit")


def coverage_of(post: dict, truth: dict, source: str) -> dict:
    """parameter_coverage of the intervals ``post`` (``{name: {"q05", "q95", ...}}``)."""
    planted = {t["name"]: t.get("planted") or {} for t in truth.get("tests", [])}
    checks = []
    for param, value in (truth.get("plant") or {}).items():
        copies = {k.split("@", 1)[1]: v for k, v in post.items() if k.startswith(param + "@")}
        if param in post:
            q = post[param]
            checks.append({"param": param, "truth": value, "q05": q["q05"], "q95": q["q95"],
                           "inside": bool(q["q05"] <= value <= q["q95"])})
        elif copies:
            for rec, q in sorted(copies.items()):
                v = planted.get(rec, {}).get(param, value)
                checks.append({"param": f"{param}@{rec}", "truth": v, "q05": q["q05"], "q95": q["q95"],
                               "inside": bool(q["q05"] <= v <= q["q95"])})
        else:
            checks.append({"param": param, "truth": value, "q05": None, "q95": None, "inside": False,
                           "why": "the shipped model does not carry it"})
    share = sum(c["inside"] for c in checks) / len(checks) if checks else None
    return {"checks": checks, "covered": share, "source": source}


def named_group(report: dict) -> list[str]:
    """The group the report names with its first confirmed addition (report.json ``identification``: the
    candidates the calibration records did not tell apart from it); [] when nothing was confirmed."""
    if report.get("verdict") != "confirmed":
        return []
    ident = report.get("identification") or []
    return list(ident[0]["effects"]) if ident else [named(report)]


def planted_effect(case: dict) -> str | None:
    """The catalogue effect a case plants (None for a null or an out-of-catalogue case)."""
    if case["class"] in ("null", "out_of_catalogue"):
        return None
    return case["case"].removeprefix("disc_")


def is_correct(case: dict, name: str, report: dict) -> bool:
    """The series is read right: an effect case names its effect (a gradual closure also when the walk
    confirmed face_gap first and closure after it), a null or out-of-catalogue case names nothing."""
    planted = planted_effect(case)
    if planted is None:
        return name in NOT_NAMED
    if name == planted:
        return True
    added = (report.get("confirmation") or {}).get("effects") or []
    return planted == "closure" and "closure" in added


def proposals(report: dict, case: dict) -> dict:
    """What the selection proposed and what the walk ran (issue 53, item 2: the proposal's power).

    ``ranking``: the first round's candidates by their emulated gain (the fall of the cross-validated
    squared error, largest first) with its z; ``planted_rank``: the planted effect's place in it (1 = the
    first proposal; None when nothing is planted or it was not tried); ``walked``: each model of the
    confirmation walk in order, its effect, real-run z and whether it was confirmed; ``planted_walked``:
    the planted effect was run on real FDEM (proposed, or an alternative the walk reached)."""
    rounds = (report.get("selection") or {}).get("rounds") or []
    trials = sorted(rounds[0].get("trials", []), key=lambda t: -t["delta_sq_error"]) if rounds else []
    ranking = [[t["effect"], round(float(t["z"]), 3)] for t in trials]
    walked = [[s["effect"], round(float(s["z"]), 3), bool(s["confirmed"])]
              for s in (report.get("confirmation") or {}).get("steps", [])]
    planted = planted_effect(case)
    order = [e for e, _ in ranking]
    return {"ranking": ranking, "planted_rank": order.index(planted) + 1 if planted in order else None,
            "walked": walked, "planted_walked": planted is not None and any(e == planted for e, _, _ in walked)}


def realrun_row(real: dict, case: dict, truth: dict) -> dict:
    """What the selection on real runs (diagnosis/realrun.json, ``--realrun``) names, and whether that is right:
    a physical case its effect (the group may hold another), every other case nothing, since its candidates
    are physical effects only; the planted value of a shared effect beside its fit."""
    planted = planted_effect(case)
    right = real["named"] == planted if case["class"] == "physical" else real["named"] == "base_kept"
    out = {"named": real["named"], "group": real["group"], "correct": right, "runs": real.get("runs"),
           "z": {e: round(float(c["z"]), 3) for e, c in real["candidates"].items()}}
    if right and planted in real["candidates"]:
        # the reported fit: corrected for the mesh where the resolution round ran (calibration.realrun)
        c = real["resolution"] if (real.get("resolution") or {}).get("track") == planted else real["candidates"][planted]
        iv = c.get("interval_90") or {"q05": {}, "q95": {}}
        post = {k: {"mean": v, "q05": iv["q05"].get(k), "q95": iv["q95"].get(k)} for k, v in c["fit"].items()
                if k in iv["q05"]}
        out["coverage"] = coverage_of(post, truth, "selection on real runs")
    return out


def realrun_scores(results: list[dict]) -> dict | None:
    """The selection on real runs' confusion matrix and its bars' shares, over the series that ran it."""
    rows = [r for r in results if not r.get("error") and r.get("realrun")]
    if not rows:
        return None
    matrix: dict[str, dict[str, int]] = {}
    for r in rows:
        cell = matrix.setdefault(r["case"]["case"], {})
        cell[r["realrun"]["named"]] = cell.get(r["realrun"]["named"], 0) + 1

    def share(sub):
        return sum(r["realrun"]["correct"] for r in sub) / len(sub) if sub else None
    cls = lambda c: [r for r in rows if r["case"]["class"] == c]
    return {"series": len(rows), "confusion": matrix,
            "physical_named_top_share": share([r for r in cls("physical") if r.get("above_scatter")]),
            "parameter_in_90_share": (lambda sub: sum((r["realrun"]["coverage"]["covered"] or 0.0) >= 1.0 for r in sub)
                                      / len(sub) if sub else None)([r for r in rows if r["realrun"].get("coverage")]),
            "null_adds_nothing_share": share(cls("null")), "out_of_catalogue_ok_share": share(cls("out_of_catalogue")),
            "measurement_nothing_named_share": share(cls("measurement"))}


def bar_counts(results: list[dict]) -> dict[str, tuple[int, int]]:
    """``(hits, series)`` of each of the plan's bars over the finished series: a physical effect beyond
    the mesh scatter named right, its parameter inside the 90 % interval where an effect was named right,
    a null adding nothing, an out-of-catalogue case ending without a name."""
    done = [r for r in results if not r.get("error")]

    def count(rows, key):
        return sum(bool(key(r)) for r in rows), len(rows)

    return {
        "physical_named_top": count([r for r in done if r["case"]["class"] == "physical" and r.get("above_scatter")],
                                    lambda r: r["correct"]),
        "parameter_in_90": count([r for r in done if r["case"]["class"] in ("physical", "measurement") and r["correct"]],
                                 lambda r: (r["coverage"]["covered"] or 0.0) >= 1.0),
        "null_adds_nothing": count([r for r in done if r["case"]["class"] == "null"],
                                   lambda r: r["named"] in NOT_NAMED),
        "out_of_catalogue_ok": count([r for r in done if r["case"]["class"] == "out_of_catalogue"],
                                     lambda r: r["named"] in NOT_NAMED),
    }


def score(results: list[dict]) -> dict:
    """The benchmark's numbers from its series (each: ``case`` (the plan's case), ``seed``, ``named``,
    ``correct``, ``coverage``, ``above_scatter``; ``error`` for a series that did not finish)."""
    matrix: dict[str, dict[str, int]] = {}
    done = [r for r in results if not r.get("error")]
    for r in done:
        row = matrix.setdefault(r["case"]["case"], {})
        row[r["named"]] = row.get(r["named"], 0) + 1

    def share(rows, key):
        return (sum(bool(key(r)) for r in rows) / len(rows)) if rows else None

    def ratio(hits_series):
        hits, n = hits_series
        return hits / n if n else None

    bars = bar_counts(results)
    nulls_ok, nulls_n = bars["null_adds_nothing"]

    effect_rows = [r for r in done if r["case"]["class"] in ("physical", "measurement")]
    misses = [{"case": r["case"]["case"], "seed": r["seed"], "named": r["named"], "why": r.get("why", ""),
               "below_scatter": r.get("above_scatter") is False} for r in done if not r["correct"]]
    misses += [{"case": r["case"]["case"], "seed": r["seed"], "named": None, "why": r["error"]}
               for r in results if r.get("error")]
    return {
        "series": len(results), "finished": len(done),
        "confusion": matrix,
        "physical_named_top_share": ratio(bars["physical_named_top"]),
        "physical_below_scatter": sorted({r["case"]["case"] for r in done
                                          if r["case"]["class"] == "physical" and r.get("above_scatter") is False}),
        "effect_named_share": share(effect_rows, lambda r: r["correct"]),
        "parameter_in_90_share": ratio(bars["parameter_in_90"]),
        "parameter_in_90_share_all": share(effect_rows, lambda r: (r["coverage"]["covered"] or 0.0) >= 1.0),
        # reported beside the plan's bars, not one of them: the planted effect inside the named group
        "planted_in_named_group_share": share(effect_rows, lambda r: planted_effect(r["case"]) in r.get("group", [])),
        # the emulator's proposal on its own (issue 53, item 2), over the effect series that carry it
        "planted_proposed_first_share": share([r for r in effect_rows if r.get("proposals")],
                                              lambda r: r["proposals"]["planted_rank"] == 1),
        "planted_walked_share": share([r for r in effect_rows if r.get("proposals")],
                                      lambda r: r["proposals"]["planted_walked"]),
        "planted_ranks": sorted([r["case"]["case"], r["seed"], r["proposals"]["planted_rank"]]
                                for r in effect_rows if r.get("proposals")),
        "null_false_positive_rate": (nulls_n - nulls_ok) / nulls_n if nulls_n else None,
        "out_of_catalogue_ok_share": ratio(bars["out_of_catalogue_ok"]),
        "misses": misses,
        "realrun": realrun_scores(results),
    }


def acceptance(scores: dict, bars: dict) -> dict:
    """Each of the plan's bars against the measured share (None: nothing measured for it)."""
    def at_least(x, bar):
        return None if x is None else bool(x >= bar)
    fp = scores["null_false_positive_rate"]
    return {"physical_named": at_least(scores["physical_named_top_share"], bars["physical_named_top_share_min"]),
            "parameter_in_90": at_least(scores["parameter_in_90_share"], bars["parameter_in_90_interval_share_min"]),
            "null_adds_nothing": None if fp is None else bool(1.0 - fp >= bars["null_adds_nothing_share_min"]),
            "out_of_catalogue": at_least(scores["out_of_catalogue_ok_share"],
                                         bars["out_of_catalogue_unexplained_or_base_kept_share_min"])}


def effect_size(truth: dict, mesh_sd_rel: float, mesh_pre_peak_sd_rel: float | None = None) -> dict:
    """The planted effect's change of each test (truth.json, same meshes with the effect off) against the
    fast mesh's scatter: above it when the largest change of a peak exceeds SCATTER_MULTIPLE peak sd, or
    the largest rms change of a curve up to its peak (``pre_peak_change_rms_rel``: an onset effect moves
    the rise, not the peak) exceeds SCATTER_MULTIPLE of the mesh's rms sd before the peak."""
    changes = [t["peak_change_rel"] for t in truth.get("tests", []) if "peak_change_rel" in t]
    if not changes:
        return {"peak_change_rel": [], "above_scatter": None}
    big = max(abs(c) for c in changes)
    out = {"peak_change_rel": changes, "spread_rel": max(changes) - min(changes), "mesh_sd_rel": mesh_sd_rel,
           "above_scatter": bool(big > SCATTER_MULTIPLE * mesh_sd_rel)}
    rise = [t["pre_peak_change_rms_rel"] for t in truth.get("tests", []) if "pre_peak_change_rms_rel" in t]
    if rise and mesh_pre_peak_sd_rel is not None:
        out.update(pre_peak_change_rms_rel=rise, mesh_pre_peak_sd_rel=mesh_pre_peak_sd_rel,
                   above_scatter=out["above_scatter"] or bool(max(rise) > SCATTER_MULTIPLE * mesh_pre_peak_sd_rel))
    return out


# ---------------------------------------------------------------------------------------------- running
def _mesh_variability(geometry: str) -> dict:
    """The fast mesh's realizations of the marble cylinder or the twin disc
    (benchmarks/results/bench_sim_variability.json)."""
    d = json.loads((ROOT / "benchmarks/results/bench_sim_variability.json").read_text())
    return d["cases"]["marble" if geometry == "cylinder" else "twin"]["mesh_variability"]


def mesh_sd_rel(geometry: str) -> float:
    """The fast mesh's peak standard deviation over its mean."""
    case = _mesh_variability(geometry)["peak_stress_Pa"]
    return float(case["std"] / case["mean"])


def mesh_pre_peak_sd_rel(geometry: str) -> float:
    """The fast mesh's rms standard deviation of the curve before its peak, over the peak."""
    return float(_mesh_variability(geometry)["std_rms_pre_peak_over_peak"])


def series_kwargs(plan: dict, case: dict, seed: int, preset: str, records: int | None) -> dict:
    """make_series' arguments for one case and seed of the plan."""
    spec = plan["series"][case["series"]]
    geometry = "cylinder" if case["series"] == "cylinder" else "brazilian_disc"
    if geometry == "cylinder":
        drivers = [str(ROOT / p) for p in CYLINDER_DRIVERS]
        lithology = "CaMa"
    else:
        drivers = [f"pulse:{v}" for v in DISC_PULSES_M_S]
        lithology = "granite_godinez2021"
    n = records or len(drivers)
    return {"geometry": geometry, "drivers": drivers[:n], "params": dict(spec["base_truth"]),
            "plant": dict(case.get("plant") or {}), "spread": dict(case.get("per_record_sd") or {}),
            "artefact": dict(case.get("artefact") or {}), "preset": preset, "seed": int(seed),
            "lithology": lithology, "prefix": "Plant" + "".join(w.title() for w in case["case"].split("_")),
            "null_peaks": bool(case.get("plant"))}     # a measurement effect's costs no run: the same curve


def heldout_summary(check: dict) -> dict:
    """Per held-out record of check.json: its RMSE before and after, the share of its curve inside the
    predictive 90 % band the report shows (``predictive_coverage_90``) and inside the model band alone
    (``band_coverage``: posterior members x population draws, no error model)."""
    return {r: {"rmse_before_Pa": v["before"]["rmse"], "rmse_after_Pa": v["after"]["rmse"],
                "predictive_coverage_90_after": v["after"].get("predictive_coverage_90"),
                "band_coverage_after": v["after"].get("band_coverage")}
            for r, v in (check.get("heldout") or {}).items()}


def run_series(plan: dict, case: dict, seed: int, work: Path, preset: str, records: int | None,
               cores: int, dry_run: bool = False, realrun: dict | None = None) -> dict:
    """Make, configure, run and score one series; returns its result row. ``dry_run``: the loop is only
    planned (``snakemake -n``) and nothing is scored, to check the wiring. ``realrun``: the
    ``diagnosis.realrun_selection`` block each series gets (the selection on real runs, scored beside the walk)."""
    from tools.make_planted_series import make_series

    name = f"planted_{case['case']}_{seed}"
    folder = work / name
    row = {"case": case, "seed": int(seed), "experiment": name, "cores": cores}
    t0 = time.perf_counter()
    try:
        kw = series_kwargs(plan, case, seed, preset, records)
        truth = make_series(folder / "series", **kw, command=f"benchmarks/bench_planted.py ({name})")
        row["make_wall_s"] = round(time.perf_counter() - t0, 1)
        row["effect_size"] = effect_size(truth, mesh_sd_rel(kw["geometry"]), mesh_pre_peak_sd_rel(kw["geometry"]))
        row["above_scatter"] = row["effect_size"]["above_scatter"]
        sheets = sorted(str(p) for p in (folder / "series").glob("*.yaml"))
        cfg = folder / "config.yaml"
        # the planned benchmark's configs carry no approximation error (init-config's default before it was on)
        subprocess.run([sys.executable, "-m", "shpb", "init-config", *sheets, "--diagnosis", "--allow-invalid",
                        "--no-approximation-error", "--name", name, "--out", str(cfg)], cwd=ROOT, check=True)
        doc = yaml.safe_load(cfg.read_text())
        doc["experiments"][name]["diagnosis"]["exclude"] = []     # the whole catalogue (module docstring)
        if realrun is not None:
            doc["experiments"][name]["diagnosis"]["realrun_selection"] = dict(realrun)
        cfg.write_text(yaml.safe_dump(doc, sort_keys=False))
        t1 = time.perf_counter()
        log = folder / "snakemake.log"
        with open(log, "w") as fh:
            subprocess.run(["snakemake", *(["-n"] if dry_run else []), "--cores", str(cores),
                            "--configfile", str(cfg)], cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT, check=True)
        row["loop_wall_s"] = round(time.perf_counter() - t1, 1)
        if dry_run:
            row["error"] = "dry run: the loop was planned, not run"
            row["wall_s"] = round(time.perf_counter() - t0, 1)
            return row
        diag = ROOT / "results" / name / "diagnosis"
        report = json.loads((diag / "report.json").read_text())
        check = json.loads((diag / "check.json").read_text())
        row["named"] = named(report)
        row["group"] = named_group(report)
        row["correct"] = is_correct(case, row["named"], report)
        row["proposals"] = proposals(report, case)
        refit = json.loads((diag / "refit.json").read_text()) if (diag / "refit.json").exists() else None
        row["coverage"] = parameter_coverage(report, truth, refit)
        row["gate"] = gate_summary(report)
        row["why"] = report.get("why", "")
        row["heldout"] = heldout_summary(check)
        if realrun is not None:
            row["realrun"] = realrun_row(json.loads((diag / "realrun.json").read_text()), case, truth)
            if (diag / "realrun_heldout.json").exists():     # its fits' held-out errors, reported, not scored
                row["realrun"]["heldout"] = json.loads((diag / "realrun_heldout.json").read_text())["records"]
    except (subprocess.CalledProcessError, OSError, KeyError, ValueError, SystemExit) as exc:
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["wall_s"] = round(time.perf_counter() - t0, 1)
    return row


def result_doc(series: list[dict], bars: dict, **fields) -> dict:
    """A result file: ``fields`` (plan, seeds, cores, wall time, ...), then the scores of ``series``
    against the plan's ``bars`` (its ``acceptance`` block), then the series."""
    scores = score(series)
    return {**fields, "scores": scores, "acceptance": acceptance(scores, bars), "series": series}


def pool(parts: list[str], plan: dict) -> dict:
    """One result of a benchmark run in parts: every part's series scored together (a case x seed in two
    parts is refused: a benchmark seed is run once)."""
    docs = [json.loads(Path(p).read_text()) for p in parts]
    series, seen = [], set()
    for part, doc in zip(parts, docs):
        for row in doc["series"]:
            key = (row["case"]["case"], row["seed"])
            if key in seen:
                raise SystemExit(f"{part}: {key[0]} seed {key[1]} is already in an earlier part")
            seen.add(key)
            series.append(row)
    return result_doc(series, plan["acceptance"], plan=docs[0]["plan"],
                      parts=[{"file": str(p), "wall_s": d["wall_s"], "cores": d["cores"], "series": len(d["series"])}
                             for p, d in zip(parts, docs)],
                      cores=docs[0]["cores"], wall_s=round(sum(d["wall_s"] for d in docs), 1))


def split(part: str, folder: str, plan: dict, note: str = "", wall_is_cost: bool = True) -> list[Path]:
    """One file per series of a part's JSON, ``<case>_<seed>.json`` in ``folder`` (each with its own
    wall time and one-series scores, which are not the benchmark's: :func:`pool` scores them together).
    ``wall_is_cost`` False: the part shared the machine, so its wall times are no cost figure."""
    doc = json.loads(Path(part).read_text())
    out = []
    for row in doc["series"]:
        path = Path(folder) / f"{row['case']['case']}_{row['seed']}.json"
        if path.exists():
            raise SystemExit(f"{path} exists: a benchmark series is run once")
        one = result_doc([row], plan["acceptance"], plan=doc["plan"], seeds=str(row["seed"]), cores=doc["cores"],
                         cpu_count=doc.get("cpu_count"), wall_s=row["wall_s"])
        extra = {} if wall_is_cost else {"wall_is_cost": False}
        path.write_text(json.dumps({**one, "note": note or doc.get("note", ""), **extra}, indent=1, default=float)
                        + "\n")
        out.append(path)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", default=str(PLAN))
    ap.add_argument("--cases", help="comma-separated case names (default: every case of the plan)")
    ap.add_argument("--seeds", default="benchmark", help="benchmark | development | comma-separated seeds")
    ap.add_argument("--records", type=int, help="tests per series (default: the plan's drivers)")
    ap.add_argument("--preset", default=None, help="the truth's mesh (default: the plan's truth_mesh)")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--dry-run", action="store_true", help="make and configure each series, plan the loop "
                    "(snakemake -n), score nothing")
    ap.add_argument("--realrun", action="store_true", help="each series also runs the selection on real runs "
                    "(diagnosis.realrun_selection with its defaults), scored beside the walk")
    ap.add_argument("--work", default=str(ROOT / "results" / "bench_planted"))
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--pool", nargs="+", metavar="PART", help="score the series of these parts' JSON together "
                    "(a benchmark run in parts) into --out; runs nothing")
    ap.add_argument("--split", nargs=2, metavar=("PART", "FOLDER"), help="write one file per series of a part's "
                    "JSON into FOLDER (benchmarks/results/bench_planted_records); runs nothing")
    ap.add_argument("--note", default="", help="with --split: what the part was (its commit, how it was stopped)")
    ap.add_argument("--shared-machine", action="store_true", help="with --split: the part ran beside other work, "
                    "so its wall times are marked as no cost figure (wall_is_cost false)")
    args = ap.parse_args(argv)
    plan = json.loads(Path(args.plan).read_text())
    if args.split:
        for path in split(*args.split, plan, args.note, wall_is_cost=not args.shared_machine):
            print(path)
        return 0
    if args.pool:
        Path(args.out).write_text(json.dumps(pool(args.pool, plan), indent=1, default=float) + "\n")
        return 0
    cases = [c for c in plan["cases"] if not args.cases or c["case"] in args.cases.split(",")]
    if args.seeds in ("benchmark", "development"):
        seeds = plan["seeds"][args.seeds]["per_case"] if args.seeds == "benchmark" else plan["seeds"]["development"]
    else:
        seeds = [int(s) for s in args.seeds.split(",")]
    results, work, t0 = [], Path(args.work), time.perf_counter()
    for case in cases:
        for seed in seeds:
            row = run_series(plan, case, seed, work, args.preset or plan["truth_mesh"], args.records, args.cores,
                             args.dry_run, {} if args.realrun else None)
            results.append(row)
            print(f"{case['case']} seed {seed}: {row.get('named', row.get('error'))} ({row['wall_s']:.0f} s)",
                  flush=True)
            plan_path = Path(args.plan).resolve()
            shown = plan_path.relative_to(ROOT) if plan_path.is_relative_to(ROOT) else plan_path
            out = result_doc(results, plan["acceptance"], plan=str(shown),
                             seeds=args.seeds, cores=args.cores, cpu_count=os.cpu_count(),
                             wall_s=round(time.perf_counter() - t0, 1))
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.out).write_text(json.dumps(out, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
