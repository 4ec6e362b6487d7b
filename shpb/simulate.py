"""One SHPB simulation: geometry + parameters + loading -> FDEM run -> lab-style curves.

Measurement chain (docs/shpb-models.md): the specimen stress is computed from the bar-specimen contact
forces, F_front on the incident bar and F_back on the transmission bar: Brazilian disc
sigma = 2 F / (pi d h), cylinder sigma = F / A_s with A_s = pi D^2 / 4; `stress_Pa` (the quantity
the lab reports) uses F_back. Force balance R = 2 |F_front - F_back| / (F_front + F_back). Bar
strains at the gauges are the mean axial stress of the gauge triangles over E_bar (compression
positive). Time 0 is when the incident wave reaches the specimen's front face.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from fdem import ContactParams, JointParams, Material, TractionBC, build_model, run
from fdem.model import DEFAULT_SAFETY, stable_time_step
from fdem.numba_load import without_blas_probe

from . import contract
from . import geometry as geo
from .atomic import atomic_write_text
from .fracture import PEAK_DROP, PEAK_FLOOR_PA, summarize
from .loading import TrapezoidPulse, face_tributary_areas
from .parameters import resolve

# Bars in the model: only the part between the injection section and the specimen, and a
# transmission bar ending in an absorbing boundary (both semi-infinite in effect). Three bar diameters
# keep the specimen's end of each bar clear of the injection section's and the dashpot's 2D field.
DISC_INCIDENT_LENGTH_M = 0.15
DISC_GAUGE_M = 0.075
DISC_TRANSMISSION_LENGTH_M = 0.15
CYL_TRANSMISSION_LENGTH_M = 1.10
# Flattened Brazilian disc with a loading angle 2 alpha = 20 degrees: Wang, Jia, Kou, Zhang &
# Lindqvist (2004, Int. J. Rock Mech. Min. Sci. 41:245-253) derive from Griffith's criterion that the
# crack starts at the centre when 2 alpha >= 19.47 degrees and recommend 20 degrees; the centre's
# tensile stress is then k 2F/(pi D t) with k = 0.96 (their eq.; tests/test_shpb_models.py checks it
# against the elastic model). With a round disc the single contact node crushes at any mesh size,
# and narrower flats (2 alpha = 10 degrees, the earlier choice) crush under the flats first.
DISC_FLAT_HALF_ANGLE_DEG = 10.0
# Recorded window after the incident wave reaches the specimen: under the default pulse the reference
# disc reaches its failure peak about 115 us after arrival and has split (stress back to zero) by about
# 150 us; the window ends before the fragments' free flight, which the curve does not need.
DEFAULT_WINDOW = {"brazilian_disc": 160e-6, "cylinder": 400e-6}

CURVE_COLUMNS = list(contract.CURVE_COLUMNS)


@dataclass
class SimulationOutput:
    """One run: ``columns`` maps CURVE_COLUMNS to 1-D arrays (SI); ``curve`` is the same as a DataFrame."""
    columns: dict
    run: dict
    extra: dict = field(default_factory=dict)

    @cached_property
    def curve(self):
        # pandas imported on first use: a simulation process (one per member job) never needs it
        import pandas as pd

        return pd.DataFrame({c: self.columns[c] for c in CURVE_COLUMNS})


def curve_csv_text(columns: dict) -> str:
    """``curve.csv``: the header, then one row per sample in ``%.9e``, a missing value empty (the text of
    pandas' ``to_csv(index=False, float_format="%.9e")``, written without importing pandas)."""
    data = np.column_stack([np.asarray(columns[c], dtype=float) for c in CURVE_COLUMNS])
    rows = (",".join("" if v != v else "%.9e" % v for v in row) for row in data.tolist())
    return "\n".join([",".join(CURVE_COLUMNS), *rows]) + "\n"


def write_outputs(out_dir, columns: dict, run_info: dict) -> None:
    """curve.csv then run.json, each atomically (run.json last: its presence means complete)."""
    out = Path(out_dir)
    atomic_write_text(out / "curve.csv", curve_csv_text(columns))
    atomic_write_text(out / "run.json", json.dumps(run_info, indent=1, default=float))


def _measured_incident(record):
    """A measured record's wave and set-up: a reduced record stored by the workflow's observations stage
    (its folder or ``record.json``, :mod:`shpb.lab.reduced_store`: read, not reduced again), a test sheet
    (``.yaml``: its bars, specimen and rock, shpb.lab.sheet) or a Freiburg raw file (the Freiburg bars,
    its spreadsheet row and lithology), the last two reduced here. Returns a dict: ``reduced`` (what
    gives ``incident_wave_at_gauge()``), ``length``, ``diameter`` [m], ``rock`` (E, nu, rho) and ``bars``
    (None for the Freiburg layout, whose bars are the geometry's defaults; else the sheet's material,
    diameter and gauge distances), ``geometry`` (the specimen's), ``specimen``, ``source`` (the raw file)."""
    from .lab.reduced_store import is_reduced, read_reduced, simulation_inputs

    path = Path(record)
    if is_reduced(path):
        stored = read_reduced(path)
        sim, red, source = stored["simulation"], stored["incident"], stored["source"]
    else:
        if not path.is_file():
            raise FileNotFoundError(f"measured record {path} not found")
        from .lab.sheet import is_sheet
        if is_sheet(path):
            from .lab.lab_reduce import reduce_sheet
            from .lab.sheet_readers import check_sheet
            sheet, raw = check_sheet(path)
            red, sim = reduce_sheet(sheet, raw), simulation_inputs(path, sheet=sheet)
        else:
            from .lab.records import freiburg_specimen, read_freiburg_raw
            from .lab.reduction import reduce_record
            raw = read_freiburg_raw(path)
            spec = freiburg_specimen(path)
            red = reduce_record(raw, specimen_length_m=float(spec["length_m"]),
                                specimen_diameter_m=float(spec["diameter_m"]))
            sim = simulation_inputs(path, spec=spec)
        source = str(path)
    bars = sim["bars"]
    if bars is not None:
        mat = bars["material"]
        bars = {**bars, "material": Material(mat["E"], mat["nu"], mat["rho"]),
                "gauge_distance_m": tuple(bars["gauge_distance_m"])}
    return {"reduced": red, "length": sim["length"], "diameter": sim["diameter"], "rock": sim["rock"],
            "bars": bars, "geometry": sim["geometry"], "specimen": sim["specimen"], "source": source}


def _measured_disc(record):
    """(reduced record, brazilian_disc arguments, rock, the raw record's path) of a disc test sheet. The lab's incident wave,
    read at its gauge, enters the model DISC_INCIDENT_LENGTH_M from the disc as it is: the model's bars
    stay short (the wave's travel over the lab's longer distance is the 1D shift the reduction makes
    too, and it would only add simulated time), but their material and diameter are the sheet's."""
    m = _measured_incident(record)
    if m["geometry"] != "brazilian_disc":
        raise ValueError(f"--record {record}: the record's specimen is a {m['geometry']}, not a Brazilian disc "
                         f"(use --geometry {m['geometry']})")
    spec, bars = m["specimen"], m["bars"]
    kw = {"diameter_m": float(spec["diameter"]), "thickness_m": float(spec["thickness"]),
          "flat_half_angle_deg": 0.5 * float(spec["flat_angle_deg"]), "bar": bars["material"],
          "bar_diameter_m": float(bars["diameter_m"])}
    rock = m["rock"]
    return m["reduced"], kw, {"E": rock["E"], "nu": rock["nu"], "rho": rock["rho"]}, m["source"]


def _sheet_bars(bars) -> dict:
    """The cylinder builder's bar arguments for a sheet's bars (empty: the Freiburg defaults). The
    transmission bar ends in an absorbing boundary 0.1 m past its gauge (1.10 m for Freiburg's 1.00 m)."""
    if bars is None:
        return {}
    d_i, d_t = bars["gauge_distance_m"]
    return {"bar": bars["material"], "bar_diameter_m": float(bars["diameter_m"]), "incident_gauge_m": float(d_i),
            "transmission_gauge_m": float(d_t),
            "transmission_length_m": max(CYL_TRANSMISSION_LENGTH_M, float(d_t) + 0.10)}


def _faces(p: dict) -> dict:
    """The builders' face arguments for the catalogue's mean face gap and its spread across the face
    (``face_gap.gap_m``, ``closure.range_m``; ``shpb.geometry.closure_faces``): first touch and tilt."""
    lo, tilt = geo.closure_faces(p["face_gap.gap_m"], p["closure.range_m"])
    return {"face_gap_m": lo, "closure_range_m": tilt}


def build(geometry: str, preset: str, params: dict | None = None, record=None,
          pulse: TrapezoidPulse | None = None, window_s: float | None = None,
          specimen_size_m: tuple[float, float] | None = None, unbreakable: bool = False,
          injection_distance_m: float | None = None, mesh_seed: int | None = None,
          mesh_jitter: float = geo.MESH_JITTER):
    """Assemble the FDEM model, loads and probes of one SHPB simulation.

    The cylinder is driven by a measured record's incident wave (record) or, for verification, by
    a trapezoid pulse with an explicit specimen_size_m = (length, diameter).
    injection_distance_m: cylinder only, where the incident wave enters the model, measured from
    the specimen (default: the record's incident gauge, 1.25 m, so the model sees the pulse the lab
    gauge saw, after the same dispersion).
    mesh_seed, mesh_jitter: the specimen mesh's realization (None: today's mesh; a seed moves its
    interior nodes at random, ``shpb.meshing.perturb_interior_nodes``): replicate runs that differ
    only in the mesh measure the simulator's own variability.

    Returns a dict with the model, traction BCs, probes and metadata (geometry object, parameters,
    arrival time, window).
    """
    p_given = dict(params or {})
    window = DEFAULT_WINDOW.get(geometry) if window_s is None else float(window_s)
    if geometry == "brazilian_disc":
        red, disc_kw, base, source = None, {}, {}, None
        if record is not None:
            red, disc_kw, base, source = _measured_disc(record)
        base.update(p_given)
        p = resolve(geometry, base)
        faces = _faces(p)
        disc = Material(p["E"], p["nu"], p["rho"])
        g = geo.brazilian_disc(preset, disc=disc, incident_gauge_m=DISC_GAUGE_M,
                               transmission_gauge_m=DISC_GAUGE_M,
                               incident_length_m=DISC_INCIDENT_LENGTH_M,
                               transmission_length_m=DISC_TRANSMISSION_LENGTH_M, enforce_window=False,
                               **faces,
                               mesh_seed=mesh_seed, mesh_jitter=mesh_jitter,
                               **{"flat_half_angle_deg": DISC_FLAT_HALF_ANGLE_DEG, **disc_kw})
        bar = g.bar_material
        if red is not None:
            t_g, eps_g = red.incident_wave_at_gauge()
            sigma_I = (np.asarray(t_g, float), bar.E * np.asarray(eps_g, float))
        else:
            t_v, v_v = (pulse or TrapezoidPulse()).history()
            sigma_I = (t_v, bar.rho * bar.c_bar * v_v)
        measured = red
    elif geometry == "cylinder":
        if record is None and (specimen_size_m is None or pulse is None):
            raise ValueError("the cylinder geometry needs --record <Freiburg raw file> (its measured "
                             "incident wave drives the model)")
        bar_kw = {"transmission_length_m": CYL_TRANSMISSION_LENGTH_M}
        if record is not None:
            m = _measured_incident(record)
            if m["geometry"] != "cylinder":
                raise ValueError(f"--record {record}: the sheet's specimen is a {m['geometry']}, not a cylinder "
                                 f"(use --geometry {m['geometry']})")
            red, L, D, rock, source = m["reduced"], m["length"], m["diameter"], m["rock"], m["source"]
            base = {"E": rock["E"], "nu": rock["nu"], "rho": rock["rho"]}
            bar_kw.update(_sheet_bars(m["bars"]))
        else:
            red, (L, D), base, source = None, specimen_size_m, {}, None
        base.update(p_given)
        p = resolve(geometry, base)
        faces = _faces(p)
        if injection_distance_m is not None:
            bar_kw["incident_gauge_m"] = float(injection_distance_m)
        g = geo.cylinder(preset, L, D, Material(p["E"], p["nu"], p["rho"]), enforce_window=False,
                         **faces,
                         mesh_seed=mesh_seed, mesh_jitter=mesh_jitter, **bar_kw)
        bar = g.bar_material
        if red is not None:
            t_g, eps_g = red.incident_wave_at_gauge()
            sigma_I = (np.asarray(t_g, float), bar.E * np.asarray(eps_g, float))
        else:
            t_v, v_v = pulse.history()
            sigma_I = (t_v, bar.rho * bar.c_bar * v_v)
        measured = red
    else:
        raise ValueError(f"unknown geometry {geometry!r}: expected 'brazilian_disc' or 'cylinder'")

    jp = JointParams(sigma_n=p["sigma_n"], sigma_t=p["sigma_t"], E_n=p["E_n"], E_t=p["E_t"],
                     a=p["a"], b=p["b"], c=p["c"], penalty_factor=p["penalty_factor"],
                     compensate_compliance=True, friction_angle_deg=p["phi_deg"],
                     unbreakable=unbreakable, rate_k=p["rate_strength.k"], rate0=1.0)
    # Seating: a face compliance C [m/Pa] in series with the contact penalty. The penalty acts per
    # node (F = p w d) over a tributary length of about one specimen element h, so the series
    # stiffness is 1 / (1/p + C/h).
    p_c = p["contact_penalty_factor"] * p["E"]
    C = p["seating.compliance_m_per_Pa"]
    pairs = {}
    if C > 0:
        h_s = g.element_size_m["specimen"]
        p_seat = 1.0 / (1.0 / p_c + C / h_s)
        pairs = {(g.incident_bar, g.specimen): p_seat, (g.transmission_bar, g.specimen): p_seat}
    contact = ContactParams(penalty=p_c, friction=p["interface_friction.mu"], pair_penalty=pairs,
                            pair_friction={(g.specimen, g.specimen): p["mu_crack"]})
    model = build_model(g.bodies, joints={g.specimen: jp}, contact=contact,
                        damping_beta=p["damping.beta"])
    inc = g.body(g.incident_bar)
    trn = g.body(g.transmission_bar)
    load = model.node_sets[f"{g.incident_bar}.load_end"]
    far = model.node_sets[f"{g.transmission_bar}.free_end"]
    imp = bar.rho * bar.c_bar
    a_load = face_tributary_areas(inc.nodes, inc.node_sets["load_end"], inc.thickness)
    a_far = face_tributary_areas(trn.nodes, trn.node_sets["free_end"], trn.thickness)
    t_hist = np.asarray(sigma_I[0], float)
    bcs = [TractionBC(load, 0, a_load, t_hist, 2.0 * np.asarray(sigma_I[1], float), impedance=imp),
           TractionBC(far, 0, a_far, np.array([0.0, 1.0]), np.zeros(2), impedance=imp)]
    arrival = g.gauge_distance_m[0] / bar.c_bar if geometry == "cylinder" else \
        DISC_INCIDENT_LENGTH_M / bar.c_bar
    probes = [f"{g.incident_bar}.gauge", f"{g.transmission_bar}.gauge", f"{g.specimen}.centre"]
    return {"model": model, "traction_bcs": bcs, "stress_probes": probes, "geometry": g,
            "params": p, "arrival_s": float(arrival), "window_s": float(window),
            # run.json's record: the raw file it stands for, also when the stored reduction was read
            "measured": measured, "record": source}


def warm_up(steps: int = 20) -> float:
    """Load the compiled engine into this process: a few time steps of the `fast` disc, with the
    probes, tractions and peak tracking of a real run, so that each kernel's cached machine code is
    loaded (about 0.65 s, bench_member_overhead.json's ``numba_first_call``). A process that forks its
    simulations (calibration.batch) pays this once instead of in every child. Returns the wall time [s]."""
    t0 = time.perf_counter()
    with without_blas_probe():  # the engine calls no BLAS: 0.2 s of SciPy imports saved per job
        setup = build("brazilian_disc", "fast", mesh_seed=0)  # a realization: the mesh's compiled loop too
        g = setup["geometry"]
        model = setup["model"]
        dt = stable_time_step(model)
        run(model, steps * dt, dt=dt, sample_dt=dt, traction_bcs=setup["traction_bcs"],
            stress_probes=setup["stress_probes"], snapshot_times=[], track_peak=(g.transmission_bar, 0, 1),
            peak_drop=PEAK_DROP[g.kind], peak_floor=PEAK_FLOOR_PA / _stress_factor(g))
    return time.perf_counter() - t0


def snapshot_times(snapshots, window_s: float) -> list[float]:
    """Snapshot times on the curve's time axis [s]: ``n`` (int) spreads n over the window (the last at
    its end), a sequence is taken as given. Raises ValueError naming what was expected."""
    if snapshots is None:
        return []
    if isinstance(snapshots, (int, np.integer)) and not isinstance(snapshots, bool):
        if snapshots < 1:
            raise ValueError(f"--snapshots: expected a number of snapshots >= 1 or times in s, got {snapshots}")
        return [window_s * (k + 1) / snapshots for k in range(int(snapshots))]
    times = [float(t) for t in snapshots]
    bad = [t for t in times if not (np.isfinite(t) and 0.0 <= t <= window_s * (1 + 1e-9))]
    if bad:
        raise ValueError(f"--snapshots: times must lie in the recorded window [0, {window_s:g}] s "
                         f"(0 = the incident wave reaches the specimen), got {bad}")
    return sorted(times)


def simulate(geometry: str, preset: str = "fast", params: dict | None = None, record=None,
             out_dir=None, t_end: float | None = None, sample_dt: float = 0.5e-6,
             pulse: TrapezoidPulse | None = None, safety: float = DEFAULT_SAFETY,
             specimen_size_m: tuple[float, float] | None = None,
             unbreakable: bool = False, injection_distance_m: float | None = None,
             dt: float | None = None, snapshots=None, mesh_seed: int | None = None,
             mesh_jitter: float = geo.MESH_JITTER) -> SimulationOutput:
    """Run one SHPB simulation and return (and optionally write) its curve and run record.

    t_end: end of the recorded window after the incident wave reaches the specimen [s] (default:
    DEFAULT_WINDOW). unbreakable: elastic verification runs (joints never fail). dt: explicit time
    step [s] (default: the stable step times `safety`). snapshots: None, a count n, or times on the
    curve's axis [s] (snapshot_times); with out_dir, the mesh and joint damage are written at those
    times, at the failure peak and at the window's end to out_dir/snapshots/ (VTK, shpb.snapshots),
    with PNG damage maps of the peak and the end. run.json always carries the failure pattern
    (``fracture``, shpb.fracture). mesh_seed, mesh_jitter: the specimen mesh's realization (build);
    run.json records both.
    """
    t0 = time.perf_counter()
    setup = build(geometry, preset, params, record, pulse, t_end, specimen_size_m, unbreakable,
                  injection_distance_m, mesh_seed=mesh_seed, mesh_jitter=mesh_jitter)
    model, g, p = setup["model"], setup["geometry"], setup["params"]
    arrival = setup["arrival_s"]
    t_total = arrival + setup["window_s"]
    snap_t = snapshot_times(snapshots, setup["window_s"])
    to_stress = _stress_factor(g)
    res = run(model, t_total, dt=dt, safety=safety, sample_dt=sample_dt,
              traction_bcs=setup["traction_bcs"],
              stress_probes=setup["stress_probes"],
              snapshot_times=[arrival + t for t in snap_t] + ([t_total] if snapshots is not None else []),
              track_peak=(g.transmission_bar, 0, 1), peak_drop=PEAK_DROP[g.kind],
              peak_floor=PEAK_FLOOR_PA / to_stress)
    bar = g.bar_material
    F_front = -res.body_force_of(g.incident_bar)[:, 0]
    F_back = res.body_force_of(g.transmission_bar)[:, 0]
    denom = F_front + F_back
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.where(np.abs(denom) > 1e-3 * max(np.max(np.abs(denom)), 1e-30),
                     2.0 * np.abs(F_front - F_back) / denom, np.nan)
    st = res.stress
    centre = st[f"{g.specimen}.centre"]
    curve = {
        "time_s": res.time - arrival,
        "stress_Pa": F_back * to_stress,
        "stress_front_Pa": F_front * to_stress,
        "stress_back_Pa": F_back * to_stress,
        "force_balance": R,
        "centre_sxx_Pa": centre[:, 0],
        "centre_syy_Pa": centre[:, 1],
        "eps_incident_gauge": -st[f"{g.incident_bar}.gauge"][:, 0] / bar.E,
        "eps_transmitted_gauge": -st[f"{g.transmission_bar}.gauge"][:, 0] / bar.E,
    }
    finite = all(np.all(np.isfinite(v)) for k, v in curve.items() if k != "force_balance")
    status = "ok" if (res.status == "ok" and finite) else "failed"
    reason = res.message if res.status != "ok" else ("" if finite else "non-finite values in the curve")
    W = float(res.energy["external_work"][-1]) if len(res.time) else 0.0
    err = float(res.energy_balance_error()[-1]) if len(res.time) else float("nan")
    info = {
        "status": status, "reason": reason, "geometry": g.kind, "preset": g.preset,
        "params": {k: float(v) for k, v in p.items()}, "record": setup["record"],
        "mesh_seed": None if g.mesh_seed is None else int(g.mesh_seed), "mesh_jitter": float(g.mesh_jitter),
        "n_triangles": int(model.n_triangles), "n_joints": int(model.n_joints),
        "specimen_triangles": int(np.sum(model.tri_body == model.body_index(g.specimen))),
        "steps": int(res.steps), "dt_s": float(res.dt), "time_step_safety": float(safety),
        "wall_s": float(time.perf_counter() - t0), "solver_wall_s": float(res.wall_s),
        "element_updates_per_s": float(res.updates_per_s),
        "energy_balance_rel": float(abs(err) / W) if W > 0 else float("nan"),
        "external_work_J": W, "broken_joints": int(res.broken[-1]) if len(res.broken) else 0,
        "t_end_s": float(setup["window_s"]), "arrival_s": float(arrival),
        "bars": {**g.summary()["bar"], "gauge_distance_m": [float(x) for x in g.gauge_distance_m]},
        "specimen": {k: float(v) for k, v in g.specimen_dims.items()},
        "contact_rebuilds": int(res.contact_rebuilds),
        "max_penetration_m": float(np.max(res.penetration)) if len(res.penetration) else 0.0,
        "max_penetration_over_h": (float(np.max(res.penetration)) / g.element_size_m["specimen"]
                                   if len(res.penetration) else 0.0),
    }
    if len(res.time) > 1:
        info["fracture"] = summarize(model, g, res, curve, arrival).to_dict()
    if out_dir is not None:
        if snapshots is not None:
            info["snapshots"] = _write_snapshots(Path(out_dir) / "snapshots", model, g, res, arrival,
                                                 to_stress, curve)
        write_outputs(out_dir, curve, info)
    return SimulationOutput(columns=curve, run=info, extra={"result": res, "setup": setup})


def _stress_factor(g) -> float:
    """Specimen stress per unit bar force [1/m^2]: 2 / (pi d h) (disc), 1 / A_s (cylinder)."""
    dims = g.specimen_dims
    if g.kind == "brazilian_disc":
        return 2.0 / (np.pi * dims["diameter_m"] * dims["thickness_m"])
    return 1.0 / (np.pi * dims["diameter_m"] ** 2 / 4.0)


def _write_snapshots(folder: Path, model, g, res, arrival: float, to_stress: float, curve) -> list[dict]:
    """VTK of every snapshot plus the failure peak; PNG damage maps of the peak and the end, and the
    curve next to both (fracture.png)."""
    from .snapshots import damage_map, fracture_overview, write_vtk

    written = []
    for snap in res.snapshots:
        t_us = (snap.time - arrival) * 1e6
        path = write_vtk(folder / f"t_{t_us:07.2f}us.vtu", model, snap)
        written.append({"time_s": snap.time - arrival, "vtk": path.name})
    ends = [("peak", res.peak, "failure peak")] if res.peak is not None else []
    if res.snapshots:
        ends.append(("end", res.snapshots[-1], "end of the window"))
    for name, snap, what in ends:
        t_rel = snap.time - arrival
        i = int(np.argmin(np.abs(res.time - snap.time)))
        stress = res.body_force_of(g.transmission_bar)[i, 0] * to_stress
        title = (f"{g.kind}, {g.preset}: {what}, t = {t_rel * 1e6:.1f} us, "
                 f"stress {stress / 1e6:.1f} MPa, {int(np.sum(snap.D >= 1.0))} joints broken")
        vtk = write_vtk(folder / f"{name}.vtu", model, snap)
        png = damage_map(folder / f"damage_{name}.png", model, g, snap, title)
        written.append({"time_s": t_rel, "what": name, "vtk": vtk.name, "png": png.name})
    if ends:
        png = fracture_overview(folder / "fracture.png", model, g, curve,
                                [(what, snap, snap.time - arrival) for _, snap, what in ends])
        written.append({"what": "overview", "png": png.name})
    return written
