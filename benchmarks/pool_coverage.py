"""One set of the coverage benchmark's twins scored over several of its JSONs (twins of different seeds).

    python benchmarks/pool_coverage.py misspecified A.json B.json --out benchmarks/results/<name>.json
    python benchmarks/pool_coverage.py misspecified+misspecified_rate A.json B.json C.json  (every misspecified twin)

Each JSON is a ``benchmarks/bench_coverage.py`` output; the set's twins of all of them are scored
together by the benchmark's own ``score`` / ``score_mcmc`` (coverage with Clopper-Pearson intervals,
SBC, widths, the restated bar, the proper scores of ``benchmarks/scores.py``) with the pooled set's
``verdict`` (the harness's bars), and each JSON's own score is kept beside the pooled one. Refuses a
twin seed met twice (the same twin counted twice) and JSONs of different twin settings. Prints one
JSON object (and writes it with ``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import score, score_mcmc, set_verdict, twin_experiment  # noqa: E402
from calibration.experiment import ExperimentSpec  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

SETTINGS = ("experiment", "method", "ensemble_size", "window_s", "model_error", "mesh_realizations",
            "emulator_smoothing", "self_calibrate", "reported_posterior", "approximation_pairs",
            "coarse_variability", "emulator_error", "refine_runs")


def setting(bench: dict, key: str):
    """A twin setting of a bench_coverage JSON; ``coarse_variability`` of one made before the key existed
    (2026-11-28, seeds 41 and 43) is the form that code had: ``counted``."""
    if key == "coarse_variability" and key not in bench and bench.get("approximation_pairs"):
        return "counted"
    if key == "emulator_error" and key not in bench:
        return "ar1"  # the only form before 2026-11-28d
    if key in ("approximation_pairs", "refine_runs"):
        return bench.get(key) or 0  # absent before the option existed: none
    if key == "model_error" and bench.get(key):
        # the twin block's approximation_error is off in every set (the bench sets it per set: the keys
        # approximation_pairs and coarse_variability); JSONs made before 2026-11-28c recorded it with
        # schema defaults filled in, which do not change a twin
        return {k: v for k, v in bench[key].items() if k != "approximation_error"}
    return bench.get(key)


def pool(name: str, benches: dict[str, dict]) -> dict:
    """``benches``: path -> bench_coverage JSON. The set ``name`` scored over all their twins; ``name`` may
    list several sets joined by ``+`` (``misspecified+misspecified_rate``: every misspecified twin, each
    JSON contributing the listed sets it holds)."""
    names = name.split("+")
    if len(names) > 1:
        parts = {path: [r for n in names for r in (b.get(n) or {}).get("twins") or []] for path, b in benches.items()}
        benches = {path: {**b, name: {"twins": parts[path],
                                      "summary_emulator_mcmc": {n: b[n]["summary_emulator_mcmc"]
                                                                for n in names if b.get(n)}}}
                   for path, b in benches.items()}
    first = next(iter(benches.values()))
    for path, b in benches.items():
        differ = [k for k in SETTINGS if setting(b, k) != setting(first, k)]
        if differ:
            raise SystemExit(f"{path}: twin settings {differ} differ from {next(iter(benches))}'s")
    seeds = {path: [r["seed"] for r in b[name]["twins"]] for path, b in benches.items()}
    flat = [s for v in seeds.values() for s in v]
    if len(flat) != len(set(flat)):
        twice = sorted({s for s in flat if flat.count(s) > 1})
        raise SystemExit(f"the same twin seed twice ({twice[:5]}...): those twins would count twice")
    # the rate set's data mesh matters to its twins only: one value over the JSONs that hold rate twins
    rate_mesh = {b.get("rate_data_preset", "fast") for b in benches.values()
                 if "misspecified_rate" in names and (b.get("misspecified_rate") or {}).get("twins")}
    if len(rate_mesh) > 1:
        raise SystemExit(f"the rate twins' data come from different meshes ({sorted(rate_mesh)}): not one set")
    spec = ExperimentSpec.from_config(first["experiment"], twin_experiment())
    twins = [r for b in benches.values() for r in b[name]["twins"]]
    scored = {"summary": score(twins, spec.lower, spec.upper, spec.names),
              "summary_emulator_mcmc": score_mcmc(twins, spec.lower, spec.upper, spec.names)}
    return {"benchmark": "pool_coverage", "set": name, "sources": {p: {"twin_seeds": seeds[p],
            "twins": len(b[name]["twins"]), "wall_s_this_call": b.get("wall_s_this_call"),
            "summary_emulator_mcmc": b[name]["summary_emulator_mcmc"]} for p, b in benches.items()},
            **{k: setting(first, k) for k in SETTINGS}, "n_twins": len(twins),
            **({"rate_data_preset": rate_mesh.pop()} if rate_mesh else {}),
            **scored, "verdict": set_verdict(scored, setting(first, "reported_posterior") or "ensemble",
                                             names[0] if len(set(names)) == 1 else "misspecified")}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("set", help="well_specified, misspecified or misspecified_rate, or several misspecified sets "
                                "joined by '+' (misspecified+misspecified_rate)")
    ap.add_argument("jsons", nargs="+")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    sets = a.set.split("+")
    if not sets or any(n not in ("well_specified", "misspecified", "misspecified_rate") for n in sets) or (
            len(sets) > 1 and "well_specified" in sets):
        ap.error(f"set {a.set!r}: expected well_specified, misspecified, misspecified_rate or misspecified sets "
                 "joined by '+'")
    benches = {str(Path(p)): json.loads(Path(p).read_text()) for p in a.jsons}
    return emit_json(pool(a.set, benches), a.out)


if __name__ == "__main__":
    main()
