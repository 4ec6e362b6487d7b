"""Does a score test on real FDEM derivatives rank the default run's candidates as the loop's real-run
check did? A development look at issue 53, item 2 (a selection with power), on the default run's
measured marble, not a benchmark: one series, whose answer was read before.

The loop's emulator selection could not tell candidates apart on planted series (every emulated trial's
|z| below 0.06). ``enkf.diagnosis.rank_candidates`` (the score test at each effect's null, the base
parameters free) needs only each candidate's sensitivity at the calibrated point. Here they come from
real FDEM runs on one mesh realization (common random numbers, so the difference is the effect's, not
the mesh's): per calibration record the base run at the workflow's posterior mean (``summary.json``),
one run with each base parameter 5 % higher, one with each physical effect at a small step; a
measurement effect acts on the base run's curve (``shpb.effects.apply_measurement``), no run needed.
The residual (record minus base run) and every column are whitened by the record's noise and the
simulator's own variability of the last analysis (``R + S``: the candidate must explain the residual's
structure beyond what the instrument and the mesh leave).

Compared with what the default run's walk found on real runs (``diagnosis/report.json``).

    snakemake --cores 2     # a default run
    python studies/fdem_score_ranking.py --results results --out studies/results/fdem_score_ranking.json
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import yaml
from scipy import linalg

from calibration.model_error import stored_error
from calibration.observations import curve_on_grid, read_observations
from calibration.workflow_io import read_json
from enkf.diagnosis import rank_candidates
from shpb import effects as fx
from shpb.atomic import emit_json
from shpb.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
EXP = "marble_loop"
MESH_SEED = 20261203
BASE_STEP = 0.05  # relative step of each base parameter
#: the physical effects' steps from their nulls (about a tenth of their boxes) and the measurement ones'
STEPS = {"rate_strength.k": 0.06, "damping.beta": 0.1, "interface_friction.mu": 0.06, "face_gap.gap_m": 4.0e-5,
         "closure.range_m": 4.0e-5, "seating.compliance_m_per_Pa": 2.0e-13,
         "trigger_shift.dt_s": 1.0e-6, "lowpass.tau_s": 5.0e-7, "gauge_gain.g": 1.02,
         "baseline.offset_Pa": 5.0e5, "baseline.drift_Pa_per_s": 1.0e9}


def _curve(out, grid):
    return curve_on_grid(out.columns["time_s"], out.columns["stress_Pa"], grid)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", default="results")
    ap.add_argument("--config", default=str(ROOT / "config" / "config.yaml"))
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    res = Path(a.results) / EXP
    exp = yaml.safe_load(Path(a.config).read_text())["experiments"][EXP]
    summary = read_json(res / "summary.json")
    base = {p: float(v["mean"]) for p, v in summary["posterior"].items()}
    obs = read_observations(res / "observations" / "obs.csv", res / "observations" / "obs.json")
    its = sorted(int(p.name.split("_")[-1]) for p in res.glob("iter_*"))
    terms = stored_error(obs, read_json(res / f"iter_{its[-1]}" / "analysis.json"))
    sim = exp["simulation"]
    t0 = time.perf_counter()
    resid, base_cols, cand_cols, blocks = [], {p: [] for p in base}, {}, []
    for r, rec in enumerate(obs.records):
        rows = obs.frame["record"].to_numpy(str) == rec
        grid, y = obs.time[rows], obs.values[rows]
        record = res / "observations" / rec / "record.json"

        def run(params, record=record, grid=grid):
            return _curve(simulate(exp["geometry"], exp["preset"], params, record=str(record), t_end=sim["t_end"],
                                   sample_dt=sim["sample_dt"], mesh_seed=MESH_SEED), grid)

        f0 = run(base)
        resid.append(y - f0)
        for p in base:
            base_cols[p].append((run({**base, p: base[p] * (1 + BASE_STEP)}) - f0) / (BASE_STEP * base[p]))
        for name, step in STEPS.items():
            effect = fx.get_effect(name.split(".")[0])
            if effect.kind == "physical":
                col = (run({**base, name: step}) - f0) / step
            else:
                null = {q.name: q.null for q in effect.params}
                moved = fx.apply_measurement(grid, f0, {f"{effect.name}.{k}": v for k, v in null.items()} | {name: step})
                col = (moved - f0) / (step - null[name.split(".")[1]])
            # a per-record effect has one parameter per record: its column is zero outside the record's block
            key = name.split(".")[0]
            cand_cols.setdefault(key, {}).setdefault(name + ("" if effect.scope == "shared" else f"@{rec}"), {})[r] = col
        blocks.append(rows)
    m = obs.values.size
    Sigma = terms.R + terms.S
    L = linalg.cholesky(Sigma, lower=True)

    def stack(per_record: dict) -> np.ndarray:
        v = np.zeros(m)
        for r, col in per_record.items():
            v[blocks[r]] = col
        return v

    def white(v):
        return linalg.solve_triangular(L, v, lower=True)

    w = white(np.concatenate(resid))
    B = np.column_stack([white(stack(dict(enumerate(cols)))) for cols in base_cols.values()])
    cands = {}
    for effect, params in cand_cols.items():
        cands[effect] = np.column_stack([white(stack(cols)) for cols in params.values()])
    table = rank_candidates(w, B, cands)
    report = read_json(res / "diagnosis" / "report.json")
    result = {"study": "fdem_score_ranking", "experiment": EXP, "cores": os.cpu_count(), "mesh_seed": MESH_SEED,
              "base_point": base, "records": list(obs.records), "fdem_runs": len(obs.records) * (1 + len(base) + sum(
                  fx.get_effect(n.split(".")[0]).kind == "physical" for n in STEPS)),
              "wall_s": round(time.perf_counter() - t0, 1), "steps": STEPS,
              "ranking": json.loads(table.to_json(orient="records")),
              "walk": {"verdict": report["verdict"], "added": report["added"],
                       "steps": [{k: s.get(k) for k in ("effects", "text") if k in s}
                                 for s in report["confirmation"]["steps"]]}}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
