"""SHPB models: wave transmission, force balance, parameter sensitivity, CLI, a measured record."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from shpb.loading import TrapezoidPulse
from shpb.simulate import simulate

FREIBURG = "freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_005_Ti25_60b_Al12b_0_001.txt"


def _marble_record():
    from shpb.paths import data_dir, data_file
    return data_file(data_dir() / FREIBURG)


def _measured_reduced():
    from calibration.observations import reduce_measured_record
    red = reduce_measured_record(_marble_record())
    return red[0] if isinstance(red, tuple) else red


def test_first_transit_force_matches_1d_impedance_theory():
    """A step-like incident wave meets a low-impedance cylinder: during the first transit the force
    at the interface is F_I * 2 Z_s / (Z_s + Z_b), Z = rho c A (1D wave theory)."""
    E, rho, L, D = 5e9, 2000.0, 0.06, 0.04
    out = simulate("cylinder", "fast", params={"E": E, "rho": rho, "nu": 0.2},
                   pulse=TrapezoidPulse(1.0, 3e-6, 200e-6, 3e-6), specimen_size_m=(L, D),
                   unbreakable=True, injection_distance_m=0.1, t_end=60e-6, sample_dt=0.25e-6)
    assert out.run["status"] == "ok"
    c = out.curve
    E_b, rho_b = 110e9, 4430.0
    A_b, A_s = np.pi * 0.05**2 / 4, np.pi * D**2 / 4
    Z_b = rho_b * np.sqrt(E_b / rho_b) * A_b
    Z_s = rho * np.sqrt(E / rho) * A_s
    F_I = rho_b * np.sqrt(E_b / rho_b) * 1.0 * A_b
    transit = L / np.sqrt(E / rho)
    sel = (c.time_s > 0.25 * transit) & (c.time_s < 0.9 * transit)
    ratio = np.mean(c.stress_front_Pa[sel] * A_s) / F_I
    assert ratio == pytest.approx(2 * Z_s / (Z_s + Z_b), rel=0.05)


def test_force_balance_after_four_transits():
    """Marble-like cylinder, 10 us rise: front and back forces balance (median R over 4 to 15
    transit times below 5%; R = 2 |F1 - F2| / (F1 + F2))."""
    E, rho, L, D = 50e9, 2700.0, 0.04, 0.04
    out = simulate("cylinder", "fast", params={"E": E, "rho": rho, "nu": 0.25},
                   pulse=TrapezoidPulse(1.0, 10e-6, 150e-6, 20e-6), specimen_size_m=(L, D),
                   unbreakable=True, injection_distance_m=0.3, t_end=150e-6, sample_dt=0.25e-6)
    c = out.curve
    transit = L / np.sqrt(E / rho)
    sel = ((c.time_s > 4 * transit) & (c.time_s < 15 * transit)).to_numpy()
    R = c.force_balance.to_numpy()[sel]
    assert np.nanmedian(R) < 0.05
    early = c.force_balance.to_numpy()[((c.time_s > 0.5 * transit) & (c.time_s < transit)).to_numpy()]
    assert np.nanmedian(early) > 0.3  # and it was not balanced during the first transit


def test_face_gap_closes_when_the_free_bar_face_has_travelled_the_gap():
    """Face gap g (issue 8's ``face_gap`` effect), incident ramp v = A t / t_r at the bar's face: until
    contact the face is free and moves at 2 v (1D), so it has travelled A t^2 / t_r and the gap closes at
    t_c = sqrt(g t_r / A). Before t_c the specimen carries nothing; without the gap it is loaded from the
    start. Tolerance 1.5 us: six samples, 2.5 % of t_c, covering the 2D strip's departure from 1D."""
    E, rho, L, D = 50e9, 2700.0, 0.04, 0.04
    A, t_r, g = 2.0, 100e-6, 60e-6
    t_c = np.sqrt(g * t_r / A)  # 54.8 us
    kw = dict(pulse=TrapezoidPulse(A, t_r, 100e-6, 20e-6), specimen_size_m=(L, D), unbreakable=True,
              injection_distance_m=0.3, t_end=90e-6, sample_dt=0.25e-6)
    gap = simulate("cylinder", "fast", params={"E": E, "rho": rho, "nu": 0.25, "face_gap.gap_m": g}, **kw)
    ref = simulate("cylinder", "fast", params={"E": E, "rho": rho, "nu": 0.25}, **kw)
    assert gap.run["status"] == "ok" and ref.run["status"] == "ok"
    assert gap.run["energy_balance_rel"] < 0.01
    t, s = gap.curve.time_s.to_numpy(), gap.curve.stress_front_Pa.to_numpy()
    onset = t[np.flatnonzero(s > 1e6)[0]]
    assert onset == pytest.approx(t_c, abs=1.5e-6)
    assert np.max(np.abs(gap.curve.stress_back_Pa.to_numpy()[t < t_c - 1.5e-6])) < 0.1e6
    r = ref.curve
    assert np.interp(0.5 * t_c, r.time_s, r.stress_front_Pa) > 5e6  # loaded long before, without the gap (11 MPa)


def _peak(params):
    out = simulate("brazilian_disc", "fast", params=params)
    assert out.run["status"] == "ok", out.run["reason"]
    assert out.run["energy_balance_rel"] < 0.02
    f = out.run["fracture"]
    return f["peak_stress_Pa"], f["peak_t_s"], out.curve


def test_brazilian_peak_rises_with_shear_strength_and_post_peak_follows_E_t():
    """Paper Table 2 box: sigma_t 4-60 MPa, E_t 200-2400 J/m^2 (fast preset, failure peak = the first
    load maximum, shpb.fracture.PEAK_DROP). Measured here: peaks 11.1 / 29.1 / 33.7 MPa at sigma_t
    4 / 30 / 60 MPa (E_t 500): steep while the shear capacity is below the tensile strength's reach
    (sigma_n 15 MPa), flat above; E_t 200 -> 2400 J/m^2 raises the first peak from 30.3 to 33.4 MPa and
    delays it by 9 us, and the split halves of the tough disc then carry more than the split load
    (45.7 MPa at the end of the window, against 5.8 MPa left by the brittle one): mode II softening
    governs how the halves slide apart."""
    peaks = [_peak({"sigma_t": s})[0] for s in (4e6, 30e6, 60e6)]
    assert peaks[0] < peaks[1] < peaks[2]
    slope = (peaks[2] - peaks[0]) / 56e6
    assert 0.3 < slope < 0.6
    assert (peaks[2] - peaks[1]) / 30e6 < 0.5 * (peaks[1] - peaks[0]) / 26e6
    p_lo, t_lo, c_lo = _peak({"E_t": 200.0})
    p_hi, t_hi, c_hi = _peak({"E_t": 2400.0})
    assert p_hi > 1.05 * p_lo
    assert t_hi - t_lo > 5e-6
    # post-peak: the stress left at the end of the window
    assert c_hi.stress_Pa.iloc[-1] > p_hi and c_lo.stress_Pa.iloc[-1] < 0.25 * p_lo
    # the disc fractures at the paper's reference values: a peak, then a drop inside the window
    p_ref, t_ref, c_ref = _peak({"sigma_t": 45e6, "E_t": 500.0})
    assert 0 < t_ref < c_ref.time_s.iloc[-1] - 30e-6
    assert c_ref.stress_Pa.iloc[-1] < 0.6 * p_ref


def test_cli_writes_curve_and_run_record(tmp_path):
    out = tmp_path / "m0"
    proc = subprocess.run([sys.executable, "-m", "shpb", "simulate", "--geometry", "brazilian_disc",
                           "--preset", "fast", "--param", "sigma_t=45e6", "--param", "E_t=500",
                           "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "ok" and run["params"]["sigma_t"] == 45e6 and run["params"]["E_t"] == 500
    assert run["n_triangles"] > 1000 and run["steps"] > 1000 and run["dt_s"] > 0
    import pandas as pd
    curve = pd.read_csv(out / "curve.csv")
    assert list(curve.columns[:3]) == ["time_s", "stress_Pa", "stress_front_Pa"]
    assert curve.stress_Pa.max() > 5e6
    assert not any(p.name.startswith(".") for p in out.iterdir())  # no temporary files left


@pytest.mark.parametrize("args,needle", [
    (["--param", "sigma_t=-1"], "sigma_t"),
    (["--param", "sigma_q=1"], "sigma_q"),
    (["--param", "sigma_t"], "NAME=VALUE"),
])
def test_cli_rejects_bad_parameters(tmp_path, args, needle):
    proc = subprocess.run([sys.executable, "-m", "shpb", "simulate", "--geometry", "brazilian_disc",
                           "--out", str(tmp_path / "x")] + args, capture_output=True, text=True)
    assert proc.returncode == 2
    assert needle in proc.stderr
    assert not (tmp_path / "x" / "run.json").exists()


def test_cli_missing_record_is_a_clear_error(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "shpb", "simulate", "--geometry", "cylinder",
                           "--record", str(tmp_path / "nope.txt"), "--out", str(tmp_path / "x")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "nope.txt" in proc.stderr


def test_unstable_run_stops_with_failed_status(tmp_path):
    from fdem import stable_time_step
    from shpb.simulate import build
    dt = stable_time_step(build("brazilian_disc", "fast")["model"], 1.0)
    out = simulate("brazilian_disc", "fast", dt=3.0 * dt, out_dir=tmp_path)
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["status"] == "failed" and "instability" in run["reason"]
    assert out.run["steps"] < 0.5 * (out.run["arrival_s"] + out.run["t_end_s"]) / (3 * dt)
    # caught by the one-step motion guard within a few dozen steps, before the mesh explodes (the
    # energy test, every sample after step 100, let this run crawl for a minute through contact
    # rebuilds over a mesh metres wide)
    assert "contact buffer" in run["reason"] and out.run["steps"] < 100


def test_measured_record_drives_the_cylinder_model():
    """CaMa_005: the injected wave arrives at the specimen face on the record's own time base, and
    at plausible marble parameters the simulated peak is within a factor 2 of the measured one."""
    out = simulate("cylinder", "fast", record=_marble_record(), t_end=250e-6)
    red = out.extra["setup"]["measured"]
    g = out.extra["setup"]["geometry"]
    c = out.curve
    tau = c.time_s.to_numpy()
    tg, eg = red.incident_wave_at_gauge()
    eps_I_model = np.interp(tau, tg, eg, left=0.0, right=0.0)  # what reaches the model's face
    eps_I_meas = np.interp(tau, red.time, red.eps_incident)

    def onset(e, frac):
        return tau[int(np.argmax(e > frac * e.max()))]

    for frac in (0.2, 0.5):
        assert abs(onset(eps_I_model, frac) - onset(eps_I_meas, frac)) <= 5e-6
    # the model's own front-face force is zero before that wave arrives (no offset in the chain);
    # the 2D strip's dilatational precursor, sqrt(1/(1 - nu^2)) faster than the bar wave, leads the
    # bar-wave arrival by about 13 us over 1.25 m, so the check starts 20 us before t = 0
    F = c.stress_front_Pa.to_numpy()
    assert np.max(np.abs(F[tau < -20e-6])) < 1e-3 * np.max(F)
    assert np.max(np.abs(F[tau < 0])) < 0.01 * np.max(F)
    assert np.max(F[tau < onset(eps_I_meas, 0.2) + 50e-6]) > 0.01 * np.max(F)
    peak_sim = c.stress_Pa.max()
    assert 0.5 * red.peak_stress <= peak_sim <= 2.0 * red.peak_stress
    # the rock's modulus (the lithology's), not the spreadsheet row's 39.9 GPa from this test's own curve
    assert out.run["params"]["E"] == pytest.approx(44.8e9, rel=1e-12)


def _reflected_at_face(out):
    """The model's reflected strain on the face time axis: its incident-gauge strain minus the injected
    incident wave, moved back by the gauge-to-face travel time."""
    red, g = out.extra["setup"]["measured"], out.extra["setup"]["geometry"]
    x, c0 = g.gauge_distance_m[0], g.bar_material.c_bar
    tau = out.curve.time_s.to_numpy()
    tg, eg = red.incident_wave_at_gauge()
    e_r = out.curve.eps_incident_gauge.to_numpy() - np.interp(tau + x / c0, tg, eg, left=0.0, right=0.0)
    return tau - x / c0, e_r


def test_reflected_wave_lines_up_with_the_measured_one_once_the_records_face_gap_is_modelled():
    """CaMa_005 (issue 4, check 3): the measured incident bar's face travels 171 um before the specimen
    carries 2 % of its peak (incident and reflected waves of the record itself,
    ReducedRecord.closure_before_load), i.e. the face is free during the pulse's foot and reflects it
    whole. With that closure as the face gap, the simulated reflected strain at the face lines up with
    the measured one: best shift within 5 us over the first 60 us of reflection (the window the gauge
    sees before t_end = 340 us), and its RMS mismatch less than half of the base model's, which loads
    the specimen from the first microsecond and so reflects too little."""
    red = _measured_reduced()
    gap = red.closure_before_load(0.02)
    assert 150e-6 < gap < 200e-6
    grid = np.arange(0.0, 60e-6 + 1e-12, 0.5e-6)
    data = np.interp(grid, red.time, red.eps_reflected)
    shifts = np.arange(-20e-6, 20e-6 + 1e-12, 0.5e-6)

    def best_shift(params):
        out = simulate("cylinder", "fast", record=_marble_record(), t_end=340e-6, params=params)
        assert out.run["status"] == "ok", out.run["reason"]
        t_f, e_r = _reflected_at_face(out)
        rms = [np.sqrt(np.mean((np.interp(grid - L, t_f, e_r) - data) ** 2)) for L in shifts]
        k = int(np.argmin(rms))
        return shifts[k], rms[k]

    lag_gap, rms_gap = best_shift({"face_gap.gap_m": gap})
    lag_base, rms_base = best_shift({})
    assert abs(lag_gap) <= 5e-6, lag_gap
    assert rms_gap < 0.5 * rms_base, (rms_gap, rms_base)
    assert rms_gap < 0.25 * np.max(np.abs(data))


def _fall_to_half(t, s):
    """Time from the peak to the first sample below half of it [s]."""
    i = int(np.argmax(s))
    below = np.nonzero(s[i:] < 0.5 * s[i])[0]
    assert below.size, "the curve never falls to half its peak in the window"
    return t[i + below[0]] - t[i]


def test_marble_post_peak_fall_is_set_by_the_shear_band_dissipation_on_the_held_out_record():
    """Issue 17 item 3, confirmed on CaMa_005 (held out in the default run), its own face closure as
    the gap. The fast-preset specimen fails by a shear band that runs through in about one transit;
    with E_t inside the old box (3.3 kJ/m^2, where the default run's diagnosis had put it) the load
    halves within 20 us of the peak, the record's in 56 us. E_t = 26 kJ/m^2 (fitted by hand to
    CaMa_014 only, sigma_t 32 MPa) lets each joint of the band soften over an eight times longer slip:
    the fall takes 47 us and the whole curve follows the record (tolerances: the fall within 30 % of
    the record's, the mesh alone moves it by 80 % from fast to paper; peak within 10 %)."""
    red = _measured_reduced()
    gap = red.closure_before_load(0.02)
    grid = np.arange(0.0, 360e-6 + 1e-12, 2e-6)
    data = np.interp(grid, red.time, red.stress)

    def run(E_t):
        out = simulate("cylinder", "fast", record=_marble_record(), t_end=360e-6, sample_dt=1e-6,
                       params={"sigma_t": 32e6, "E_t": E_t, "face_gap.gap_m": gap})
        assert out.run["status"] == "ok", out.run["reason"]
        t, s = out.curve.time_s.to_numpy(), out.curve.stress_Pa.to_numpy()
        return _fall_to_half(t, s), s.max(), np.sqrt(np.mean((np.interp(grid, t, s) - data) ** 2))

    fall_rec = _fall_to_half(red.time[red.time <= 400e-6], red.stress[red.time <= 400e-6])
    fall_lo, peak_lo, rmse_lo = run(3.3e3)
    fall_hi, peak_hi, rmse_hi = run(26e3)
    assert fall_hi > 2.0 * fall_lo, (fall_hi, fall_lo)
    assert abs(fall_hi / fall_rec - 1.0) < 0.3, (fall_hi, fall_rec)
    assert abs(peak_hi / red.peak_stress - 1.0) < 0.1, (peak_hi, red.peak_stress)
    assert rmse_hi < 0.5 * rmse_lo, (rmse_hi, rmse_lo)
