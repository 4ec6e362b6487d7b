"""Write a synthetic series of one rock with a planted effect, as a lab's records (issue 53, item 1).

    python tools/make_planted_series.py OUT --geometry cylinder \\
        --driver data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_016_Ti25_40b_Al12b_0_001.txt ... \\
        --param sigma_t=2.5e7 --param E_t=1.2e4 --plant rate_strength.k=0.3 --seed 53 [--null-peaks]

The simulator is the lab. Each driver makes one test: a measured record (Freiburg raw file or test sheet;
cylinders) lends its incident wave, bars, specimen size and rock, or ``pulse:<m/s>`` is a trapezoid
particle-velocity pulse (``shpb.loading.TrapezoidPulse``'s shape) on the default bars and specimen
(discs, or the test's tiny series). The model runs at ``--preset`` (``standard`` for a benchmark) on its own
mesh realization with the base parameters ``--param``, one effect of the catalogue ``--plant`` (or none:
the null) and optionally an artefact outside the catalogue (``--artefact``). What is planted:

* a physical effect goes to the simulator as its parameter;
* a measurement effect (``shpb.effects.apply_measurement``) acts on the specimen stress the transmitted
  wave carries, the quantity the catalogue defines it on (the incident wave, which drives, is untouched);
* ``gauge_ringing=A``: a decaying ring on the transmission gauge from the transmitted wave's foot,
  A x its peak strain, at the bar's first radial frequency c0 / D, decaying over 50 us (a gauge or
  bar resonance no part of the model has);
* ``gauge_nonlinearity=b``: the transmission gauge reads eps (1 + b eps / eps_peak), b too high at the
  peak and nothing at zero (a bridge out of its linear range).

A per-record effect (``Effect.scope``) may differ from test to test: ``--spread NAME=SD`` draws each test's
value from N(value, SD), clipped to the catalogue's box.

The face forces become the two bar strains a lab records, by 1D wave theory (the reduction's own
assumption): at the incident gauge the incident wave and, 2 x_I / c0 later, the reflected
F_front / (E A) - eps_I; at the transmission gauge F_back / (E A), (x_I + x_T) / c0 after the incident
wave passed the first gauge. :data:`PRE_S` of quiet bar before the wave, sampled every :data:`DT_S` (the
Freiburg records' interval), and AR(1) noise on both channels of the Freiburg records' measured level
(:data:`NOISE_SD_OVER_PEAK` of the test's peak stress, lag-1 correlation :data:`NOISE_RHO1`). One
``--seed`` fixes every draw: the mesh realizations, the per-record values, the noise.

Files in OUT: ``<name>.csv`` (time_s, incident_strain, transmitted_strain) and ``<name>.yaml`` (its test
sheet, format csv) per test; ``truth.json`` (base parameters, the effect and its values, the artefact, the
drivers, the seed, the command, and each test's reduced peak and strain rate as ``python -m shpb reduce``
reads them). ``--null-peaks`` also runs every test with the effect off on the same mesh and writes the
peaks' change (the effect's size, to compare with the mesh's scatter).
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from shpb.atomic import atomic_write_text
from shpb.effects import apply_measurement, bounds, effect_of, null_values
from shpb.loading import TrapezoidPulse
from shpb.simulate import simulate

#: Sample interval of the written signals [s]: the Freiburg records' 0.8 us.
DT_S = 0.8e-6
#: Quiet bar before the incident wave reaches the incident gauge [s].
PRE_S = 100e-6
#: Noise of the Freiburg CaMa records 004/006/015/016/019, measured on their pre-trigger as the workflow
#: does (shpb.lab.reduced_store.pretrigger_stress, enkf.estimate_noise): sd 0.31-0.43 % of the record's
#: peak stress (0.62-0.74 MPa), lag-1 correlation 0.39-0.59 at 0.8 us; the medians.
NOISE_SD_OVER_PEAK = 0.0036
NOISE_RHO1 = 0.46
#: The simulated window after the wave reaches the specimen [s], per geometry. Past it the written bars are at
#: rest, so the window must hold each test's fall: otherwise the record drops to zero where the model does not,
#: and init-config, which ends its window after the latest fall, takes that artificial drop for one (a disc
#: series simulated for 160 us got a 180 us window). Discs under these pulses peak at 90-140 us.
T_END_S = {"cylinder": 4.0e-4, "brazilian_disc": 2.5e-4}
#: A test whose simulated stress at the window's end is above this fraction of its peak has not fallen.
FALL_FRACTION = 0.5
#: Gauge distances written on a pulse-driven test's sheet [m] (a lab's, as the granite disc example's).
PULSE_GAUGES_M = (1.0, 0.5)
#: Ringing decay time [s] of the gauge_ringing artefact.
RING_DECAY_S = 50e-6
ARTEFACTS = ("gauge_ringing", "gauge_nonlinearity")


def _named_floats(items, what: str) -> dict:
    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"{what}: expected NAME=VALUE, got {item!r}")
        out[key.strip()] = float(value)
    return out


def planted_values(plant: dict, spread: dict, n: int, rng: np.random.Generator) -> list[dict]:
    """Each test's effect parameters: the planted value, or for a spread parameter of a per-record effect a
    draw from N(value, sd) clipped to the catalogue's box."""
    for name in list(plant) + list(spread):
        if effect_of(name) is None:
            raise SystemExit(f"{name}: not an effect parameter (<effect>.<param>)")
    lo, hi = bounds(list(plant))
    values = []
    for _ in range(n):
        v = {}
        for j, (name, x) in enumerate(plant.items()):
            sd = spread.get(name, 0.0)
            if sd > 0 and effect_of(name).scope != "per_record":
                raise SystemExit(f"--spread {name}: {effect_of(name).name} is shared by the tests, not per record")
            v[name] = float(np.clip(x + sd * rng.standard_normal(), lo[j], hi[j])) if sd > 0 else float(x)
        values.append(v)
    return values


def ar1_noise(n: int, sd: float, rho1: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary AR(1) series of standard deviation sd and lag-1 correlation rho1."""
    e = rng.standard_normal(n) * sd * math.sqrt(1.0 - rho1 ** 2)
    x = np.empty(n)
    x[0] = sd * rng.standard_normal()
    for k in range(1, n):
        x[k] = rho1 * x[k - 1] + e[k]
    return x


def _driver(spec: str, geometry: str):
    """(kwargs for simulate, label): a measured record's path, or ``pulse:<m/s>``."""
    if spec.startswith("pulse:"):
        pulse = TrapezoidPulse(amplitude_m_s=float(spec.split(":", 1)[1]))
        kw = {"pulse": pulse}
        if geometry == "cylinder":
            raise SystemExit("a cylinder is driven by a measured record's incident wave (--driver PATH)")
        return kw, spec
    if not Path(spec).is_file():
        raise SystemExit(f"--driver {spec}: no such file")
    return {"record": spec}, Path(spec).name


def _incident_at_gauge(sim, kw: dict, c0: float):
    """(time from the wave's arrival at the incident gauge [s], strain) of the wave that drove the run."""
    red = sim.extra["setup"]["measured"]
    if red is not None:
        t, e = red.incident_wave_at_gauge()
        return np.asarray(t, float), np.asarray(e, float)
    t, v = kw["pulse"].history()
    return np.asarray(t, float), np.asarray(v, float) / c0


def _stress_to_force(run: dict) -> float:
    spec = run["specimen"]
    if run["geometry"] == "brazilian_disc":
        return math.pi * spec["diameter_m"] * spec["thickness_m"] / 2.0          # stress = 2F / (pi D t)
    return math.pi * spec["diameter_m"] ** 2 / 4.0


def bar_signals(sim, kw: dict, gauges: tuple[float, float], measurement: dict, artefact: dict,
                noise_sd_over_peak: float, rho1: float, rng: np.random.Generator, dt: float = DT_S,
                pre: float = PRE_S) -> tuple[pd.DataFrame, dict]:
    """The two gauge signals (strain, DAQ time 0 = the incident wave's arrival at the incident gauge) of one
    simulated test, with its measurement effect, artefact and noise; and what was made (peaks, noise sd)."""
    run, cols = sim.run, sim.columns
    bars = run["bars"]
    E, rho = bars["E"], bars["rho"]
    c0 = math.sqrt(E / rho)                            # the reduction's wave speed
    EA = E * math.pi * bars["diameter_m"] ** 2 / 4.0
    to_force = _stress_to_force(run)
    tau = np.asarray(cols["time_s"], float)
    s_front = np.asarray(cols["stress_front_Pa"], float)
    s_back = apply_measurement(tau, np.asarray(cols["stress_back_Pa"], float), measurement)
    t_i, e_i = _incident_at_gauge(sim, kw, c0)
    d_i, d_t = gauges
    # the record runs until the later of the reflected and transmitted waves has left the window (the
    # reduction cuts its window at the record's end)
    n = int(round((pre + max(2.0 * d_i, d_i + d_t) / c0 + tau[-1] + 50e-6) / dt))
    t = -pre + dt * np.arange(n)

    def inc_at_gauge(x):
        return np.interp(x, t_i, e_i, left=0.0, right=0.0)

    def on_faces(x, values):                           # the simulated window; the bar at rest outside it
        inside = (x >= tau[0]) & (x <= tau[-1])
        return np.where(inside, np.interp(x, tau, values), 0.0)

    refl_t = t - 2.0 * d_i / c0
    refl = on_faces(refl_t, s_front * to_force / EA) - np.where((refl_t >= tau[0]) & (refl_t <= tau[-1]),
                                                                inc_at_gauge(refl_t), 0.0)
    inc = inc_at_gauge(t) + refl
    tra = on_faces(t - (d_i + d_t) / c0, s_back * to_force / EA)
    peak_tra = float(np.max(tra))
    if artefact.get("gauge_nonlinearity"):
        tra = tra * (1.0 + artefact["gauge_nonlinearity"] * tra / peak_tra)
    if artefact.get("gauge_ringing"):
        foot = t[int(np.argmax(tra > 0.05 * peak_tra))]
        x = np.clip(t - foot, 0.0, None)
        f = c0 / bars["diameter_m"]
        tra = tra + np.where(t >= foot, artefact["gauge_ringing"] * peak_tra * np.exp(-x / RING_DECAY_S)
                             * np.sin(2.0 * math.pi * f * x), 0.0)
    peak_stress = float(np.max(s_back))
    sd_strain = noise_sd_over_peak * peak_stress * to_force / EA
    inc = inc + ar1_noise(n, sd_strain, rho1, rng)
    tra = tra + ar1_noise(n, sd_strain, rho1, rng)
    frame = pd.DataFrame({"time_s": t, "incident_strain": inc, "transmitted_strain": tra})
    return frame, {"peak_stress_Pa": peak_stress, "noise_sd_strain": sd_strain,
                   "noise_sd_Pa": noise_sd_over_peak * peak_stress}


def sheet_text(name: str, run: dict, gauges: tuple[float, float], lithology: str | None, note: str) -> str:
    """The test sheet (shpb/lab/sheet_schema.json) of one synthetic test, format csv, strain."""
    b, spec, p = run["bars"], run["specimen"], run["params"]
    if run["geometry"] == "brazilian_disc":
        specimen = (f"{{geometry: brazilian_disc, diameter: {spec['diameter_m']!r}, thickness: {spec['thickness_m']!r}, "
                    f"flat_angle_deg: 20.0}}")
    else:
        specimen = f"{{geometry: cylinder, length: {spec['length_m']!r}, diameter: {spec['diameter_m']!r}}}"
    rock = f"{{lithology: {lithology}, " if lithology else "{"
    rock += f"E: {p['E']!r}, nu: {p['nu']!r}, rho: {p['rho']!r}}}"
    return (f"# Synthetic test with a planted effect (tools/make_planted_series.py; the truth in truth.json).\n"
            f"name: {name}\n"
            f"signals:\n  file: {name}.csv\n  format: csv\n  compression_sign: 1\n"
            f"  time: {{column: time_s, unit: s}}\n"
            f"  incident: {{columns: [incident_strain], unit: strain}}\n"
            f"  transmitted: {{columns: [transmitted_strain], unit: strain}}\n"
            f"bars: {{material: synthetic, E: {b['E']!r}, rho: {b['rho']!r}, nu: {b['nu']!r}, diameter: {b['diameter_m']!r},\n"
            f"       gauge_distance_incident: {gauges[0]!r}, gauge_distance_transmitted: {gauges[1]!r}}}\n"
            f"specimen: {specimen}\n"
            f"rock: {rock}\n"
            f"metadata: {{notes: {json.dumps(note)}}}\n")


def _reduced_summary(sheet: Path) -> dict:
    """What ``python -m shpb reduce`` reads of the sheet: the peak stress, its time and the peak strain rate."""
    from shpb.lab.lab_reduce import reduce_sheet
    from shpb.lab.sheet_readers import check_sheet

    s, raw = check_sheet(sheet)
    red = reduce_sheet(s, raw)
    stress = np.asarray(red.stress, float)
    k = int(np.nanargmax(stress))
    return {"peak_stress_Pa": float(stress[k]), "peak_time_s": float(red.time[k]),
            "strain_rate_per_s": float(np.nanmax(red.strain_rate[: k + 1]))}


def make_series(out, *, geometry: str, drivers: list[str], params: dict, plant: dict | None = None,
                spread: dict | None = None, artefact: dict | None = None, preset: str = "standard",
                seed: int = 0, prefix: str = "PLANT", lithology: str | None = None,
                t_end: float | None = None, noise_sd_over_peak: float = NOISE_SD_OVER_PEAK,
                noise_rho1: float = NOISE_RHO1, null_peaks: bool = False, command: str = "") -> dict:
    """Simulate, write and check one series (module docstring); returns the truth written to truth.json."""
    out = Path(out)
    plant, spread, artefact = dict(plant or {}), dict(spread or {}), dict(artefact or {})
    unknown = sorted(set(artefact) - set(ARTEFACTS))
    if unknown:
        raise SystemExit(f"--artefact {unknown}: known artefacts are {list(ARTEFACTS)}")
    names = {effect_of(n).name for n in plant}
    if len(names) > 1 and names != {"face_gap", "closure"}:
        raise SystemExit("plant one effect per series (face_gap with closure counts as one)")
    rng = np.random.default_rng(seed)
    values = planted_values(plant, spread, len(drivers), rng)
    mesh_seeds = [int(s) for s in rng.integers(1, 2 ** 31 - 1, size=len(drivers))]
    t_end = T_END_S[geometry] if t_end is None else float(t_end)
    out.mkdir(parents=True, exist_ok=True)
    tests = []
    for i, spec in enumerate(drivers):
        kw, label = _driver(spec, geometry)
        physical = {k: v for k, v in values[i].items() if effect_of(k).kind == "physical"}
        measurement = {k: v for k, v in values[i].items() if k not in physical}
        t0 = time.perf_counter()
        sim = simulate(geometry, preset, params={**params, **physical}, t_end=t_end, sample_dt=DT_S / 2,
                       mesh_seed=mesh_seeds[i], **kw)
        if sim.run["status"] != "ok":
            raise SystemExit(f"{label}: the simulation failed ({sim.run['reason']})")
        wall = time.perf_counter() - t0
        gauges = tuple(sim.run["bars"]["gauge_distance_m"]) if "record" in kw else PULSE_GAUGES_M
        name = f"{prefix}_{i + 1:02d}"
        frame, made = bar_signals(sim, kw, gauges, measurement, artefact, noise_sd_over_peak, noise_rho1, rng)
        atomic_write_text(out / f"{name}.csv", frame.to_csv(index=False, float_format="%.9g"))
        # what was planted stays in truth.json: a sheet is what the calibration and its reader see
        note = f"synthetic: {preset} mesh, driven by {label}; the truth in truth.json"
        atomic_write_text(out / f"{name}.yaml", sheet_text(name, sim.run, gauges, lithology, note))
        end_over_peak = float(sim.columns["stress_back_Pa"][-1] / np.max(sim.columns["stress_back_Pa"]))
        if end_over_peak > FALL_FRACTION:
            print(f"{name}: WARNING the stress is still {end_over_peak:.0%} of its peak at the window's end "
                  f"({t_end * 1e6:.0f} us): the written record drops to zero there; give a longer --t-end", flush=True)
        test = {"name": name, "driver": spec, "mesh_seed": mesh_seeds[i], "planted": values[i],
                "end_over_peak": end_over_peak,
                "model_peak_stress_Pa": made["peak_stress_Pa"], "noise_sd_Pa": made["noise_sd_Pa"],
                "noise_sd_strain": made["noise_sd_strain"], "sim_wall_s": round(wall, 1),
                "reduced": _reduced_summary(out / f"{name}.yaml")}
        if null_peaks:
            off = {k: _null(k) for k in physical}
            base = simulate(geometry, preset, params={**params, **off}, t_end=t_end, sample_dt=DT_S / 2,
                            mesh_seed=mesh_seeds[i], **kw) if physical else sim
            off_curve = np.asarray(base.columns["stress_back_Pa"], dtype=float)
            # the two runs' windows may differ by a few samples (an onset effect moves where the run
            # stops): the effect's curve is read at the effect-free run's times
            sim_t = np.asarray(sim.columns["time_s"], dtype=float)
            on_curve = np.interp(np.asarray(base.columns["time_s"], dtype=float), sim_t,
                                 np.asarray(apply_measurement(sim_t, sim.columns["stress_back_Pa"], measurement),
                                            dtype=float))
            p_off, p_on = float(np.max(off_curve)), float(np.max(on_curve))
            test["effect_off_peak_stress_Pa"] = p_off
            test["peak_change_rel"] = p_on / p_off - 1.0
            # an effect on the onset (a gap, a trigger) leaves the peak where it was: its size is the
            # change of the curve up to the peak, where the mesh's own scatter is small
            rise = slice(0, int(np.argmax(off_curve)) + 1)
            test["pre_peak_change_rms_rel"] = float(np.sqrt(np.mean((on_curve[rise] - off_curve[rise]) ** 2)) / p_off)
        tests.append(test)
        print(f"{name}: {label}, peak {made['peak_stress_Pa'] / 1e6:.1f} MPa, reduced "
              f"{test['reduced']['peak_stress_Pa'] / 1e6:.1f} MPa at {test['reduced']['strain_rate_per_s']:.0f} 1/s"
              + (f", effect {test['peak_change_rel'] * 100:+.1f} % on the peak" if null_peaks else "")
              + f" ({wall:.0f} s)", flush=True)
    effect = sorted({effect_of(n).name for n in plant}) or None
    truth = {"geometry": geometry, "preset": preset, "params": params,
             "effect": effect, "plant": plant, "spread": spread, "artefact": artefact or None,
             "seed": int(seed), "drivers": list(drivers), "lithology": lithology, "t_end_s": t_end,
             "noise": {"kind": "ar1", "sd_over_peak": noise_sd_over_peak, "lag1_correlation": noise_rho1,
                       "sample_dt_s": DT_S, "pretrigger_s": PRE_S},
             "how": "tools/make_planted_series.py: the simulator at the preset on each test's own mesh "
                    "realization, face forces written as bar gauge strains by 1D wave theory, AR(1) noise",
             "command": command, "tests": tests}
    atomic_write_text(out / "truth.json", json.dumps(truth, indent=1) + "\n")
    return truth


def _null(name: str) -> float:
    return null_values([name])[name]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="folder to write")
    ap.add_argument("--geometry", required=True, choices=["cylinder", "brazilian_disc"])
    ap.add_argument("--driver", action="append", required=True,
                    help="a measured record (its incident wave, bars, specimen, rock) or pulse:<m/s>; one per test")
    ap.add_argument("--param", action="append", help="base parameter NAME=VALUE (SI), e.g. sigma_t=2.5e7")
    ap.add_argument("--plant", action="append", help="effect parameter NAME=VALUE, e.g. rate_strength.k=0.3")
    ap.add_argument("--spread", action="append", help="per-record effect parameter NAME=SD")
    ap.add_argument("--artefact", action="append", help=f"one of {list(ARTEFACTS)}: NAME=SIZE")
    ap.add_argument("--preset", default="standard", choices=["fast", "standard", "paper"])
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--prefix", default="PLANT", help="test names <prefix>_01, ...")
    ap.add_argument("--lithology", help="the sheets' rock.lithology label (the rock's constants are written too)")
    ap.add_argument("--t-end", type=float, help="simulated window after the wave reaches the specimen [s]")
    ap.add_argument("--null-peaks", action="store_true", help="also run each test with the effect off")
    args = ap.parse_args(argv)
    command = "python tools/make_planted_series.py " + " ".join(shlex.quote(a) for a in
                                                               (sys.argv[1:] if argv is None else argv))
    make_series(args.out, geometry=args.geometry, drivers=args.driver, params=_named_floats(args.param, "--param"),
                plant=_named_floats(args.plant, "--plant"), spread=_named_floats(args.spread, "--spread"),
                artefact=_named_floats(args.artefact, "--artefact"), preset=args.preset, seed=args.seed,
                prefix=args.prefix, lithology=args.lithology, t_end=args.t_end, null_peaks=args.null_peaks,
                command=command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
