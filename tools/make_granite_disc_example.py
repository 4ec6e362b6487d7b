"""Write the synthetic dynamic Brazilian test of data/examples/granite_disc/ (issue 31, item 5).

    python tools/make_granite_disc_example.py [OUT_FOLDER]

The simulator itself is the lab: the paper's granite disc (50 mm x 25 mm, flats of 20 degrees, Table 1
rock) between steel bars of 50 mm, loaded by the default trapezoid pulse, at the truth
sigma_t = 45 MPa, E_t = 500 J/m^2 (the twin's, Table 2), fast preset. Its face forces are written
as the two bar strains a lab would record at gauges 1.0 m (incident) and 0.5 m (transmission) from
the disc, by 1D wave theory (the reduction's own assumption): the incident gauge sees the incident
wave eps_I and, 2 x 1.0 m / c0 later, the reflected eps_R = F1/(E A) - eps_I; the transmission gauge
sees eps_T = F2/(E A), (1.0 + 0.5) m / c0 after the incident wave passed the first gauge. 100 us of
quiet bar before the pulse; white noise of 1e-6 strain (seed 31) on both channels. Files: signals.csv
(time_s, incident_strain, transmitted_strain), granite_disc.yaml (the sheet), truth.json.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from shpb.atomic import atomic_write_text
from shpb.loading import TrapezoidPulse
from shpb.simulate import simulate

TRUTH = {"sigma_t": 45.0e6, "E_t": 500.0}
BAR = {"E": 200.0e9, "rho": 7850.0, "nu": 0.29, "diameter": 0.050}   # shpb.geometry.STEEL_BAR, 50 mm
GAUGES = (1.0, 0.5)
DISC = {"diameter": 0.050, "thickness": 0.025, "flat_angle_deg": 20.0}
DT, PRE, NOISE, SEED, T_SIM = 0.5e-6, 100e-6, 1.0e-6, 31, 300e-6

SHEET = """# Synthetic dynamic Brazilian test (tools/make_granite_disc_example.py; the truth in PROVENANCE.md).
name: granite_disc
signals:
  file: signals.csv
  format: csv
  compression_sign: 1
  time: {column: time_s, unit: s}
  incident: {columns: [incident_strain], unit: strain}
  transmitted: {columns: [transmitted_strain], unit: strain}
bars: {material: steel, E: 2.0e+11, rho: 7850.0, nu: 0.29, diameter: 0.050,
       gauge_distance_incident: 1.0, gauge_distance_transmitted: 0.5}
specimen: {geometry: brazilian_disc, diameter: 0.050, thickness: 0.025, flat_angle_deg: 20.0}
rock: {lithology: granite_godinez2021}
metadata: {notes: "synthetic: the fast-preset model at sigma_t 45 MPa, E_t 500 J/m^2, 1e-6 strain noise"}
"""


def main(out: Path) -> None:
    sim = simulate("brazilian_disc", "fast", params=dict(TRUTH), t_end=T_SIM, sample_dt=DT)
    curve = sim.curve
    c0 = math.sqrt(BAR["E"] / BAR["rho"])
    EA = BAR["E"] * math.pi * BAR["diameter"] ** 2 / 4
    to_force = math.pi * DISC["diameter"] * DISC["thickness"] / 2.0     # stress = 2F/(pi D t)
    tau = curve["time_s"].to_numpy()
    F1 = curve["stress_front_Pa"].to_numpy() * to_force
    F2 = curve["stress_back_Pa"].to_numpy() * to_force
    t_v, v_v = TrapezoidPulse().history()

    def eps_inc(t):          # incident strain at the face, time 0 = its arrival there: v / c0
        return np.interp(t, t_v, v_v, left=0.0, right=0.0) / c0

    def on_faces(t, values):  # the simulated window, the bar at rest outside it
        return np.interp(t, tau, values, left=0.0, right=0.0)

    d_i, d_t = GAUGES
    n = int(round((PRE + 2 * d_i / c0 + T_SIM + 50e-6) / DT))
    t = -PRE + DT * np.arange(n)          # DAQ time, 0 = the incident wave at the incident gauge
    refl = t - 2 * d_i / c0
    inc = eps_inc(t) + on_faces(refl, F1 / EA) - np.where((refl >= 0) & (refl <= tau[-1]), eps_inc(refl), 0.0)
    tra = on_faces(t - (d_i + d_t) / c0, F2 / EA)
    rng = np.random.default_rng(SEED)
    inc = inc + NOISE * rng.standard_normal(n)
    tra = tra + NOISE * rng.standard_normal(n)
    out.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame({"time_s": t, "incident_strain": inc, "transmitted_strain": tra})
    atomic_write_text(out / "signals.csv", frame.to_csv(index=False, float_format="%.9g"))
    atomic_write_text(out / "granite_disc.yaml", SHEET)
    peak = float(curve["stress_Pa"].max())
    truth = {"params": TRUTH, "preset": "fast", "peak_stress_Pa": peak,
             "peak_time_s": float(tau[int(np.argmax(curve["stress_Pa"].to_numpy()))]),
             "noise_strain": NOISE, "seed": SEED, "gauges_m": list(GAUGES), "sample_dt_s": DT}
    atomic_write_text(out / "truth.json", json.dumps(truth, indent=2) + "\n")
    print(f"granite_disc: peak {peak / 1e6:.2f} MPa at {truth['peak_time_s'] * 1e6:.1f} us -> {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("data/examples/granite_disc"))
