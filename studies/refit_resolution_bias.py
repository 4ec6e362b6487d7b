"""Is what the refit leaves on the default run's planted series the `fast` model against `standard`-mesh
data? (issue 53: "its parameter inside the reported 90 % interval")

On `planted_gap` the refit on real runs (:mod:`calibration.refit`) put the calibration records' gaps at
99.1 and 74.6 um for planted 102.6 and 79.8, both just outside their 90 % intervals, its three check
meshes agreeing within 3 um. The series was made at the `standard` mesh and is calibrated at `fast`.
This study runs the same refit, from the same selection (the finished run's ``selection.pkl``: its
shipped fit, surrogate box, noise and mesh-scatter terms), on two data sets of the two calibration
records:

* ``standard``: the shipped records (``data/examples/planted_gap``);
* ``fast``: the same series made again at the `fast` mesh (``tools/make_planted_series.py`` with the
  shipped series' own command, ``--preset fast``: the same planted gaps, truth mesh seeds, noise seed).

Each record read through :func:`calibration.observations.measured_observations`, as the workflow reads
a lab's sheets. The refit's runs are made here, in a process pool, on the workflow's check meshes of the
experiment (:func:`calibration.model_error.run_mesh_seed`), driven by the shipped sheets, so the two data
sets meet the same runs. If the `fast` data's planted gaps fall inside their intervals and the
`standard` data's do not, the miss is the resolution difference.

Run: ``python studies/refit_resolution_bias.py --run <results>/planted_gap --fast-series <dir>
--out studies/results/refit_resolution_bias.json`` (about 110 `fast` runs, 5 min on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.model_error import run_mesh_seed  # noqa: E402
from calibration.observations import measured_observations  # noqa: E402
from calibration.refit import first_round, next_round, refit_summary  # noqa: E402
from enkf.scores import interval_score  # noqa: E402
from studies.reanchored_refit import _run  # noqa: E402
from studies.sigma_t_bias import write  # noqa: E402

PARAM = "face_gap.gap_m"


def refit_on(data: dict, saved: dict, shipped: int, exp: dict, sheets: dict, pool, records: list) -> dict:
    """The product's refit rounds, their runs made in ``pool``, on the observations ``data``."""
    sel, model = saved["selection"], saved["model"]
    order = list(records)
    state, curves = first_round(sel, shipped, model), {}
    while state["phase"] != "done":
        tasks = [(exp["geometry"], exp["preset"], sheets[row["record"]], row["simulator"],
                  run_mesh_seed(exp, "check", 0, int(row["replicate"]), order.index(row["record"])),
                  float(exp["simulation"]["t_end"])) for row in state["rows"]]
        curves[state["round"]] = list(pool.map(_run, tasks))
        state = next_round(state, curves.__getitem__, model, data, saved["noise"], saved["simulator"], sel.settings,
                           rounds=int(exp["diagnosis"].get("refit_rounds", 3)), replicates=3)
    return refit_summary(state)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", required=True, help="a finished planted_gap results folder (diagnosis/selection.pkl)")
    ap.add_argument("--fast-series", required=True, help="the series made again with --preset fast")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    import yaml

    t0 = time.time()
    run = Path(args.run)
    exp = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["experiments"]["planted_gap"]
    saved = pickle.loads((run / "diagnosis" / "selection.pkl").read_bytes())
    shipped = int(json.loads((run / "diagnosis" / "report.json").read_text())["shipped_step"])
    calib = list(saved["selection"].calib_records)
    o = exp["observations"]
    shipped_sheets = {Path(p).stem: ROOT / p for p in o["records"]}
    sets = {"standard": (ROOT / "data" / "examples" / "planted_gap", shipped_sheets),
            "fast": (Path(args.fast_series), {r: Path(args.fast_series) / f"{r}.yaml" for r in calib})}
    out = {"study": "refit_resolution_bias", "what": __doc__.split("\n\n")[0].replace("\n", " "), "run": str(run),
           "cores": args.cores, "sets": {}}
    with ProcessPoolExecutor(args.cores) as pool:
        for label, (folder, sheets) in sets.items():
            truth = json.loads((folder / "truth.json").read_text())
            planted = {t["name"]: t["planted"][PARAM] for t in truth["tests"]}
            obs, _ = measured_observations({r: sheets[r] for r in calib}, t_start=o["t_start"], t_end=o["t_end"],
                                           dt=o["dt"])
            data = {r: obs.values[obs.record_slice(r)] for r in calib}
            ref = refit_on(data, saved, shipped, exp, {r: str(shipped_sheets[r]) for r in calib}, pool, calib)
            rows = {}
            for r in calib:
                q = ref["posterior"][f"{PARAM}@{r}"]
                rows[r] = {"planted_m": planted[r], "mean_m": q["mean"], "q05_m": q["q05"], "q95_m": q["q95"],
                           "inside_90": bool(q["q05"] <= planted[r] <= q["q95"]),
                           "interval_score_m": float(interval_score(q["q05"], q["q95"], planted[r], 0.1))}
            out["sets"][label] = {"truth_preset": truth["preset"], "records": rows, "rounds": ref["rounds"],
                                  "runs": ref["runs"], "converged": ref["converged"], "refit": ref}
            print(label, {r: (round(v["mean_m"] * 1e6, 1), round(v["q05_m"] * 1e6, 1), round(v["q95_m"] * 1e6, 1),
                              round(v["planted_m"] * 1e6, 1), v["inside_90"]) for r, v in rows.items()},
                  file=sys.stderr, flush=True)
    out["wall_s"] = time.time() - t0
    return write(out, args.out)


if __name__ == "__main__":
    main()
