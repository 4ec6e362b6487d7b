"""How often could any selection name a planted physical effect on the planted benchmark's series? An oracle.

The planted benchmark (issue 53, benchmarks/results/bench_planted.json) asks that a physical effect be
named first in 80 % of its series. The walk names an effect only when real FDEM runs of the model with
it predict the calibration records better than the base model's, by its paired test at its level
(0.005: 0.05 over ten candidates). This study gives that test the best case any selection could reach:
the effect at its planted value (no fitting error), against the base model fitted to each record's
cross-validation training records (the two others) at the point that best absorbs the effect. The
fraction of data realizations on which the test passes is an upper bound on how often the walk can
confirm the effect on those records, whatever proposed it.

Why an upper bound: by default the data are simulated on the `fast` mesh the models run on (the
benchmark's are on the `standard` one, whose own error is one more misfit both models carry:
``--data-preset standard`` measures that case too); the effect enters at its
truth, not at a fit; the base model's fit is to the effect's mean curve over eleven meshes with the
noise left out (an easier target than one noisy record). What it shares with the walk: the records
(the plan's three calibration drivers of each series), the `fast` mesh on three common realizations per
record, the weights per time (1 / (noise^2 + mesh scatter^2)), the paired test
(enkf.diagnosis.crossval.compare_replicated) and its level.

Per case: each calibration record run with the effect at its planted value on 3 model meshes and 8
data meshes (the data: one of those runs plus AR(1) noise of the plan's level, 8 realizations); the
base model linearised in (sigma_t, E_t) by finite differences on 2 meshes, at the truth and again at
the all-record fit (Gauss-Newton, two steps); each record's cross-validation fit from the other two;
the base run there on the 3 model meshes. Nothing is chosen from the result; the benchmark's seeds are
not re-scored.

    python studies/oracle_power.py [--cases rate_strength,...] [--data-meshes 8] [--data-preset standard] --out F
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from multiprocessing import Pool
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from enkf.covariance import AR1Error  # noqa: E402
from enkf.diagnosis.crossval import compare_replicated  # noqa: E402

CAMA = ROOT / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa"
CYLINDERS = [str(CAMA / f) for f in ("CaMa_SHPB_016_Ti25_40b_Al12b_0_001.txt",
                                     "CaMa_SHPB_006_Ti25_70b_Al12b_0_001.txt",
                                     "CaMa_SHPB_015_Ti25_65b_Al12b_0_001.txt")]
DISCS = [2.2, 2.6, 3.0]
#: The plan's cases (benchmarks/planted_plan.json), the calibration drivers of each series.
CASES = {
    "rate_strength": ("cylinder", {"rate_strength.k": 0.3}),
    "interface_friction": ("cylinder", {"interface_friction.mu": 0.3}),
    "seating": ("cylinder", {"seating.compliance_m_per_Pa": 1e-12}),
    "face_gap": ("cylinder", {"face_gap.gap_m": 1e-4}),
    "disc_rate_strength": ("brazilian_disc", {"rate_strength.k": 0.25}),
}
TRUTH = {"cylinder": {"sigma_t": 2.5e7, "E_t": 1.2e4}, "brazilian_disc": {"sigma_t": 3.8e7, "E_t": 650.0}}
T_END = {"cylinder": 4.0e-4, "brazilian_disc": 2.5e-4}
WINDOW = {"cylinder": 360e-6, "brazilian_disc": 200e-6}
DT_OBS = 2e-6
MODEL_MESHES = (1001, 1002, 1003)
DATA_MESHES = tuple(range(2001, 2009))  # --data-meshes N: 2001 ... 2000 + N
STEPS = {"sigma_t": 0.03, "E_t": 0.15}            # relative finite-difference steps
NOISE_SD_OVER_PEAK, NOISE_RHO1_08US = 0.0036, 0.46  # the plan's noise (its lag-1 correlation at 0.8 us)
LEVEL = 0.005
SMOOTH = 11
#: the data's mesh (--data-preset): fast, the models' own (an upper bound), or standard, the benchmark's
DATA_PRESET = "fast"


def _grid(geometry):
    return np.arange(0.0, WINDOW[geometry] + 1e-12, DT_OBS)


def _run(job):
    geometry, driver, params, mesh, preset = job if len(job) == 5 else (*job, "fast")
    from shpb.loading import TrapezoidPulse
    from shpb.simulate import simulate
    kw = {"pulse": TrapezoidPulse(amplitude_m_s=driver)} if geometry == "brazilian_disc" else {"record": driver}
    sim = simulate(geometry, preset, params=dict(params), t_end=T_END[geometry], sample_dt=1e-6, mesh_seed=mesh, **kw)
    if sim.run["status"] != "ok":
        raise RuntimeError(f"{driver} {params} mesh {mesh}: {sim.run.get('reason')}")
    return np.interp(_grid(geometry), np.asarray(sim.columns["time_s"], float),
                     np.asarray(sim.columns["stress_back_Pa"], float))


def _batch(pool, jobs):
    return dict(zip(jobs, pool.map(_run, jobs)))


def _key(params):
    return tuple(sorted(params.items()))


def _weights(eff_runs, peak):
    var = np.var(eff_runs, axis=0, ddof=1)
    var = np.convolve(var, np.ones(SMOOTH) / SMOOTH, mode="same")
    return 1.0 / ((NOISE_SD_OVER_PEAK * peak) ** 2 + var)


def _fit(base_at, jac, target, w, records):
    """Gauss-Newton step: the (sigma_t, E_t) shift that best fits ``target`` on ``records`` (weighted)."""
    A = np.vstack([np.sqrt(w[r])[:, None] * jac[r] for r in records])
    b = np.concatenate([np.sqrt(w[r]) * (target[r] - base_at[r]) for r in records])
    scale = np.linalg.norm(A, axis=0)
    d, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return d / scale


def _linearise(pool, geometry, drivers, theta):
    names = ("sigma_t", "E_t")
    pts = [dict(theta)] + [{**theta, n: theta[n] * (1 + STEPS[n])} for n in names]
    jobs = [(geometry, d, p, m) for d in drivers for p in pts for m in MODEL_MESHES[:2]]
    got = _batch(pool, [(g, d, tuple(sorted(p.items())), m) for g, d, p, m in jobs])
    mean = {d: [np.mean([got[(geometry, d, tuple(sorted(p.items())), m)] for m in MODEL_MESHES[:2]], axis=0)
                for p in pts] for d in drivers}
    base = {d: mean[d][0] for d in drivers}
    jac = {d: np.column_stack([(mean[d][i + 1] - mean[d][0]) / (theta[n] * STEPS[n]) for i, n in enumerate(names)])
           for d in drivers}
    return base, jac


def _clip(theta, truth):
    return {"sigma_t": float(np.clip(theta["sigma_t"], 0.3 * truth["sigma_t"], 3 * truth["sigma_t"])),
            "E_t": float(np.clip(theta["E_t"], 0.1 * truth["E_t"], 10 * truth["E_t"]))}


def _ar1(n, sd, rng):
    rho = NOISE_RHO1_08US ** (DT_OBS / 0.8e-6)
    x = np.empty(n)
    x[0] = sd * rng.standard_normal()
    e = rng.standard_normal(n) * sd * math.sqrt(1 - rho ** 2)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + e[k]
    return x, rho


def study_case(pool, name):
    t0 = time.perf_counter()
    geometry, plant = CASES[name]
    truth = TRUTH[geometry]
    drivers = DISCS if geometry == "brazilian_disc" else CYLINDERS
    eff_p = tuple(sorted({**truth, **plant}.items()))
    eff = _batch(pool, [(geometry, d, eff_p, m) for d in drivers for m in MODEL_MESHES + DATA_MESHES])
    # the data: the effect on the data meshes at DATA_PRESET (the models stay at fast)
    data = eff if DATA_PRESET == "fast" else {(geometry, d, eff_p, m): c for (g, d, p, m, _), c in _batch(
        pool, [(geometry, d, eff_p, m, DATA_PRESET) for d in drivers for m in DATA_MESHES]).items()}
    data_meshes = (MODEL_MESHES if DATA_PRESET == "fast" else ()) + DATA_MESHES
    target = {d: np.mean([data[(geometry, d, eff_p, m)] for m in data_meshes], axis=0) for d in drivers}
    peak = {d: float(np.max(target[d])) for d in drivers}
    w = {d: _weights(np.array([eff[(geometry, d, eff_p, m)] for m in MODEL_MESHES + DATA_MESHES]), peak[d])
         for d in drivers}
    # two Gauss-Newton steps on every record, then each record's cross-validation fit from the others
    theta = dict(truth)
    for _ in range(2):
        base_at, jac = _linearise(pool, geometry, drivers, theta)
        step = _fit(base_at, jac, target, w, drivers)
        last = dict(theta)
        theta = _clip({"sigma_t": theta["sigma_t"] + step[0], "E_t": theta["E_t"] + step[1]}, truth)
    cv = {}
    for d in drivers:
        others = [o for o in drivers if o != d]
        s = _fit(base_at, jac, target, w, others)
        cv[d] = _clip({"sigma_t": last["sigma_t"] + s[0], "E_t": last["E_t"] + s[1]}, truth)
    base = _batch(pool, [(geometry, d, tuple(sorted(cv[d].items())), m) for d in drivers for m in MODEL_MESHES])
    rng = np.random.default_rng(53)
    n = _grid(geometry).size
    tests = []
    for dm in DATA_MESHES:
        y, cur, cand, noise = {}, {}, {}, {}
        for d in drivers:
            sd = NOISE_SD_OVER_PEAK * peak[d]
            e, rho = _ar1(n, sd, rng)
            sw = np.sqrt(w[d])
            y[d] = sw * (data[(geometry, d, eff_p, dm)] + e)
            cur[d] = np.array([sw * base[(geometry, d, tuple(sorted(cv[d].items())), m)] for m in MODEL_MESHES])
            cand[d] = np.array([sw * eff[(geometry, d, eff_p, m)] for m in MODEL_MESHES])
            # the noise the data were drawn with, weighted as the curves are
            noise[d] = AR1Error(sw * sd, _grid(geometry), -DT_OBS / math.log(rho))
        c = compare_replicated(y, cur, cand, noise)
        tests.append({"data_mesh": dm, "z": c["z"], "p": c["p"], "dof": c["dof"], "passes": bool(c["p"] < LEVEL),
                      "per_record_delta_over_sd": {Path(str(k)).name[:13]: v["delta"] / v["sd"]
                                                   for k, v in c["records"].items()}})
    # the base at the last linearisation point (the first Gauss-Newton step's), not at the final fit
    peak_change = {Path(str(d)).name[:13]: float(np.max(target[d]) / np.max(base_at[d]) - 1) for d in drivers}
    return {"geometry": geometry, "plant": plant, "truth": truth, "data_preset": DATA_PRESET,
            "base_fit_all_records": theta, "base_fit_cv": {Path(str(d)).name[:13]: v for d, v in cv.items()},
            "effect_peak_over_base_peak_minus_1": peak_change,
            "tests": tests, "power": float(np.mean([t["passes"] for t in tests])),
            "z_median": float(np.median([t["z"] for t in tests])), "level": LEVEL,
            "wall_s": round(time.perf_counter() - t0, 1)}


def main(argv):
    cases = list(CASES)
    if "--cases" in argv:
        cases = argv[argv.index("--cases") + 1].split(",")
    if "--data-preset" in argv:
        global DATA_PRESET
        DATA_PRESET = argv[argv.index("--data-preset") + 1]
    if "--data-meshes" in argv:
        global DATA_MESHES
        DATA_MESHES = tuple(range(2001, 2001 + int(argv[argv.index("--data-meshes") + 1])))
    out = argv[argv.index("--out") + 1] if "--out" in argv else None
    result = {"study": "oracle_power", "cores": 2, "model_meshes": list(MODEL_MESHES),
              "data_meshes": list(DATA_MESHES), "cases": {}}
    with Pool(2) as pool:
        for name in cases:
            result["cases"][name] = study_case(pool, name)
            r = result["cases"][name]
            print(f"{name}: power {r['power']:.2f}, median z {r['z_median']:.2f}, base fit {r['base_fit_all_records']}, "
                  f"{r['wall_s']} s", flush=True)
            if out:
                Path(out).write_text(json.dumps(result, indent=1) + "\n")
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
