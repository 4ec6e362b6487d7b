"""The simulator's own variability (issue 30): replicate runs that differ only in the specimen mesh.

FDEM results depend on the mesh a crack has to follow. ``mesh_seed`` (``shpb.meshing.
perturb_interior_nodes``) moves the specimen's interior nodes at random by up to a quarter of the
shortest edge at each; K realizations of the same model at the same parameters then show how much of
a simulated curve is the mesh's. Two cases at the `fast` preset, each K = 8 seeds plus the
unperturbed mesh:

* ``twin``: the default twin's truth, Brazilian disc, sigma_t 45 MPa, E_t 500 J/m^2, 160 us window,
  observation grid 0..160 us step 1 us (config twin_ref); for comparison 8 more runs on the
  unperturbed mesh with sigma_t spread evenly over +-1 %;
* ``marble``: the cylinder driven by CaMa_SHPB_004's measured incident wave, sigma_t 34.96 MPa,
  E_t 27.4 kJ/m^2, 360 us window, grid 0..360 us step 2 us (config marble_loop).

Per case, on the observation grid (statistics over the K seeded replicates; the unperturbed mesh is
reported beside them, as one mesh of better quality than a random realization): the replicates'
standard deviation per time, its RMS before and after the failure peak of the replicate mean
(``shpb.fracture.first_peak``), the spread of the replicates' failure peaks (run.json), the
correlation time of the deviations from the replicate mean after the peak (the lag at which their
mean autocorrelation falls to 1/e), everything also relative to the mean curve's peak; and a control:
the unperturbed mesh run at the realizations' (smaller) time steps.

Prints one JSON object and writes it to ``benchmarks/results/bench_sim_variability_<date>.json``
(cases run on the same day are merged into one file), the curves and std per case to
``benchmarks/results/sim_variability_<case>.csv`` (the twin's sigma_t runs to
``sim_variability_twin_sigma_t.csv``) and both cases' replicates to
``benchmarks/results/sim_variability.png``. Runs one simulation at a time, in-process.

Run: ``python benchmarks/bench_sim_variability.py`` (both cases, about 3 min on one core), or
``--case twin`` / ``--case marble``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd

from calibration.observations import curve_on_grid, observation_grid
from shpb.fracture import PEAK_DROP, first_peak
from shpb.meshing import MESH_JITTER
from shpb.simulate import simulate

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]
RECORD = "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
CASES = {
    "twin": {"geometry": "brazilian_disc", "record": None, "params": {"sigma_t": 45e6, "E_t": 500.0},
             "t_end": 1.6e-4, "grid": (0.0, 1.6e-4, 1e-6)},
    "marble": {"geometry": "cylinder", "record": RECORD, "params": {"sigma_t": 34.96e6, "E_t": 27.4e3},
               "t_end": 3.6e-4, "grid": (0.0, 3.6e-4, 2e-6)},
}
PRESET, SAMPLE_DT = "fast", 5e-7
#: The twin's parameter comparison: sigma_t x these factors, on the unperturbed mesh.
SIGMA_T_FACTORS = 1.0 + np.linspace(-0.01, 0.01, 8)


def run_one(case: dict, grid: np.ndarray, mesh_seed=None, params: dict | None = None, dt=None) -> dict:
    """One simulation: its stress on the grid and the run record's numbers we report."""
    p = dict(case["params"], **(params or {}))
    record = None if case["record"] is None else str(ROOT / case["record"])
    out = simulate(case["geometry"], PRESET, p, record=record, t_end=case["t_end"], sample_dt=SAMPLE_DT,
                   mesh_seed=mesh_seed, dt=dt)
    r, f = out.run, out.run.get("fracture", {})
    return {"mesh_seed": mesh_seed, "params": p, "status": r["status"], "dt_s": r["dt_s"], "steps": r["steps"],
            "wall_s": r["wall_s"], "energy_balance_rel": r["energy_balance_rel"],
            "peak_stress_Pa": f.get("peak_stress_Pa"), "peak_t_s": f.get("peak_t_s"),
            "first_joint_t_s": f.get("first_joint_t_s"), "first_joint_xy_over_R": f.get("first_joint_xy_over_R"),
            "checks": f.get("checks"), "broken_at_end": r["broken_joints"],
            "curve": curve_on_grid(out.columns["time_s"], out.columns["stress_Pa"], grid)}


def correlation_time(dev: np.ndarray, dt: float) -> float | None:
    """Lag [s] at which the mean (over rows) autocorrelation of the rows of ``dev`` first falls to 1/e,
    linear between grid lags; None if it never does within the rows' length. The rows are deviations
    from the replicate mean, zero-mean across replicates at every time, so no time mean is removed: a
    replicate that stays above the others is correlation, not an offset to drop."""
    n = dev.shape[1]
    acf = np.array([np.mean(np.sum(dev[:, :n - k] * dev[:, k:], axis=1) / np.sum(dev**2, axis=1))
                    for k in range(n)])
    below = np.flatnonzero(acf < np.exp(-1.0))
    if not len(below):
        return None
    k = int(below[0])
    frac = (acf[k - 1] - np.exp(-1.0)) / (acf[k - 1] - acf[k])
    return float((k - 1 + frac) * dt)


def spread(values) -> dict:
    v = np.asarray([x for x in values if x is not None], float)
    return {"std": float(np.std(v, ddof=1)), "min": float(v.min()), "max": float(v.max()),
            "mean": float(v.mean())}


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def replicate_stats(grid: np.ndarray, runs: list[dict], kind: str) -> dict:
    """The variability of a set of replicate curves on the grid (module docstring)."""
    Y = np.array([r["curve"] for r in runs])
    mean, std = Y.mean(axis=0), Y.std(axis=0, ddof=1)
    ip = first_peak(mean, PEAK_DROP[kind])
    peak = float(mean[ip])
    pre, post = grid <= grid[ip], grid > grid[ip]
    t_el = min(r["first_joint_t_s"] for r in runs if r["first_joint_t_s"] is not None)
    elastic = grid < t_el
    dt = float(grid[1] - grid[0])
    return {
        "n_runs": len(runs), "mean_curve_peak_Pa": peak, "mean_curve_peak_t_s": float(grid[ip]),
        "std_rms_pre_peak_Pa": rms(std[pre]), "std_rms_post_peak_Pa": rms(std[post]),
        "std_rms_elastic_Pa": rms(std[elastic]), "elastic_until_s": float(t_el),
        "std_max_Pa": float(std.max()), "std_max_t_s": float(grid[int(np.argmax(std))]),
        "std_rms_pre_peak_over_peak": rms(std[pre]) / peak, "std_rms_post_peak_over_peak": rms(std[post]) / peak,
        "std_rms_elastic_over_peak": rms(std[elastic]) / peak, "std_max_over_peak": float(std.max()) / peak,
        "peak_stress_Pa": spread(r["peak_stress_Pa"] for r in runs),
        "peak_t_s": spread(r["peak_t_s"] for r in runs),
        "post_peak_correlation_time_s": correlation_time((Y - mean)[:, post], dt),
        "mean_Pa": mean, "std_Pa": std,
    }


def write_csv(path: Path, grid: np.ndarray, stats: dict, base: dict, runs: list[dict]) -> None:
    cols = {"time_s": grid, "mean_Pa": stats["mean_Pa"], "std_Pa": stats["std_Pa"], "unperturbed": base["curve"]}
    cols.update({f"seed_{r['mesh_seed']}": r["curve"] for r in runs})
    pd.DataFrame(cols).to_csv(path, index=False, float_format="%.9e")


def run_case(name: str, replicates: int) -> dict:
    case = CASES[name]
    grid = observation_grid(*case["grid"])
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    base = run_one(case, grid)
    runs = [run_one(case, grid, mesh_seed=s) for s in range(1, replicates + 1)]
    stats = replicate_stats(grid, runs, case["geometry"])
    RESULTS.mkdir(exist_ok=True)
    write_csv(RESULTS / f"sim_variability_{name}.csv", grid, stats, base, runs)
    out = {"case": {k: v for k, v in case.items() if k != "grid"} | {"grid_s": list(case["grid"])},
           "preset": PRESET, "sample_dt_s": SAMPLE_DT, "mesh_jitter": MESH_JITTER,
           "mesh_variability": _public(stats), "unperturbed": _public(base),
           "replicates": [_public(r) for r in runs],
           "unperturbed_vs_mean_rms_Pa": rms(base["curve"] - stats["mean_Pa"])}
    out["dt_control"] = _dt_control(case, grid, base, runs, stats)
    curves = {"grid": grid, "base": base["curve"], "mesh": [r["curve"] for r in runs]}
    if name == "twin":
        out["sigma_t_pm_1pct"], curves["sigma"] = _sigma_t_comparison(case, grid, stats)
        pd.DataFrame({"time_s": grid} | {f"sigma_t_x{f:.4f}": y for f, y in zip(SIGMA_T_FACTORS, curves["sigma"])}
                     ).to_csv(RESULTS / f"sim_variability_{name}_sigma_t.csv", index=False, float_format="%.9e")
    # The machine's 1-min load before and after: wall times mean little if others shared the cores.
    out["wall_s"], out["load_average_1min"] = time.perf_counter() - t0, [load0, os.getloadavg()[0]]
    return out, curves


def _dt_control(case: dict, grid: np.ndarray, base: dict, runs: list[dict], stats: dict) -> list[dict]:
    """The unperturbed mesh at the realizations' shortest and median stable steps: every realization
    has a smaller step than the unperturbed mesh (its sharpest triangles), so this is how much of the
    spread the step alone makes. The difference of two runs has sqrt(2) times a replicate std."""
    pre = grid <= stats["mean_curve_peak_t_s"]
    out = []
    for dt in (min(r["dt_s"] for r in runs), float(np.median([r["dt_s"] for r in runs]))):
        r = run_one(case, grid, dt=dt)
        d = r["curve"] - base["curve"]
        out.append({"dt_s": dt, "peak_stress_Pa": r["peak_stress_Pa"], "peak_t_s": r["peak_t_s"],
                    "peak_change_Pa": r["peak_stress_Pa"] - base["peak_stress_Pa"],
                    "rms_diff_pre_peak_Pa": rms(d[pre]), "rms_diff_post_peak_Pa": rms(d[~pre]),
                    "wall_s": r["wall_s"]})
    return out


def _sigma_t_comparison(case: dict, grid: np.ndarray, mesh: dict):
    """8 runs on the unperturbed mesh, sigma_t spread evenly over +-1 %: the same statistics, the
    peak's sensitivity to sigma_t, and the sigma_t change that moves the peak by the mesh's peak std."""
    s0 = case["params"]["sigma_t"]
    runs = [run_one(case, grid, params={"sigma_t": float(s0 * f)}) for f in SIGMA_T_FACTORS]
    stats = replicate_stats(grid, runs, case["geometry"])
    x = np.array([r["params"]["sigma_t"] for r in runs])
    slope = float(np.polyfit(x, [r["peak_stress_Pa"] for r in runs], 1)[0])
    # Curve-wise sensitivity: d stress / d sigma_t at each time, and the sigma_t change whose effect
    # has the RMS of the mesh's std (pre and post peak).
    Y = np.array([r["curve"] for r in runs])
    dYdx = np.polyfit(x, Y, 1)[0]
    pre, post = grid <= mesh["mean_curve_peak_t_s"], grid > mesh["mean_curve_peak_t_s"]
    res = _public(stats) | {
        "sigma_t_factors": SIGMA_T_FACTORS.tolist(),
        "sigma_t_std_rel": float(np.std(SIGMA_T_FACTORS, ddof=1)),
        "dpeak_dsigma_t": slope,
        "sigma_t_rel_equivalent_to_mesh_peak_std": mesh["peak_stress_Pa"]["std"] / slope / s0,
        "sigma_t_rel_equivalent_to_mesh_std_pre_peak": mesh["std_rms_pre_peak_Pa"] / rms(dYdx[pre]) / s0,
        "sigma_t_rel_equivalent_to_mesh_std_post_peak": mesh["std_rms_post_peak_Pa"] / rms(dYdx[post]) / s0,
        "runs": [_public(r) for r in runs],
    }
    return res, [r["curve"] for r in runs]


def _public(d: dict) -> dict:
    """JSON-ready copy without the per-time arrays (they are in the CSV)."""
    return {k: v for k, v in d.items() if k not in ("curve", "mean_Pa", "std_Pa")}


def plot(curves: dict, results: dict, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(curves), squeeze=False)[0]
    for ax, (name, c) in zip(axes, curves.items()):
        t_us = c["grid"] * 1e6
        if "sigma" in c:
            for k, y in enumerate(c["sigma"]):
                ax.plot(t_us, y / 1e6, color="tab:orange", lw=0.7, alpha=0.8,
                        label="unperturbed mesh, sigma_t +-1 %" if k == 0 else None)
        for k, y in enumerate(c["mesh"]):
            ax.plot(t_us, y / 1e6, color="tab:blue", lw=0.7, alpha=0.8,
                    label=f"{len(c['mesh'])} mesh realizations" if k == 0 else None)
        ax.plot(t_us, c["base"] / 1e6, color="k", lw=1.2, ls="--", label="unperturbed mesh")
        std = np.array(c["mesh"]).std(axis=0, ddof=1)
        ax2 = ax.twinx()
        ax2.plot(t_us, std / 1e6, color="tab:red", lw=1.0, label="std of the realizations")
        ax2.set_ylim(0, max(std.max() / 1e6 * 4, 1e-3))
        ax2.set_ylabel("std [MPa]", color="tab:red")
        m = results[name]["mesh_variability"]
        ax.axvline(m["mean_curve_peak_t_s"] * 1e6, color="grey", lw=0.6)
        ax.set_title(f"{name}: peak {m['peak_stress_Pa']['mean'] / 1e6:.1f} MPa, "
                     f"std {m['peak_stress_Pa']['std'] / 1e6:.2f} MPa; RMS std pre/post "
                     f"{m['std_rms_pre_peak_Pa'] / 1e6:.2f}/{m['std_rms_post_peak_Pa'] / 1e6:.2f} MPa", fontsize=9)
        ax.set_xlabel("time after the wave reaches the specimen [us]")
        ax.set_ylabel("specimen stress [MPa]")
        ax.legend(loc="upper left", fontsize=7)
        ax2.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--replicates", type=int, default=8)
    args = ap.parse_args()
    path = RESULTS / f"bench_sim_variability_{datetime.date.today().isoformat()}.json"
    report = json.loads(path.read_text()) if path.is_file() else {"cases": {}}
    curves = {}
    for name in args.case:  # one case at a time, one simulation at a time
        report["cases"][name], curves[name] = run_case(name, args.replicates)
    report.update({"benchmark": "sim_variability", "replicates": args.replicates, "cpu_count": os.cpu_count(),
                   "wall_s": sum(c["wall_s"] for c in report["cases"].values()),
                   "date": datetime.date.today().isoformat()})
    text = json.dumps(report, indent=1, default=float)
    RESULTS.mkdir(exist_ok=True)
    path.write_text(text + "\n")
    print(text)
    _plot_all(curves)


def _plot_all(curves: dict) -> None:
    """The figure from the CSVs, so that a run of one case still draws both panels."""
    results = json.loads(sorted(RESULTS.glob("bench_sim_variability_*.json"))[-1].read_text())["cases"]
    for name in CASES:
        csv = RESULTS / f"sim_variability_{name}.csv"
        if name in curves or not csv.is_file() or name not in results:
            continue
        df = pd.read_csv(csv)
        curves[name] = {"grid": df["time_s"].to_numpy(), "base": df["unperturbed"].to_numpy(),
                        "mesh": [df[c].to_numpy() for c in df.columns if c.startswith("seed_")]}
        sig = RESULTS / f"sim_variability_{name}_sigma_t.csv"
        if sig.is_file():
            curves[name]["sigma"] = [v.to_numpy() for k, v in pd.read_csv(sig).items() if k != "time_s"]
    order = {n: curves[n] for n in CASES if n in curves}
    plot(order, results, RESULTS / "sim_variability.png")


if __name__ == "__main__":
    main()
