"""Reduction of synthetic SHPB records whose waves are known exactly.

A record is built from face-time waves that satisfy 1-D wave theory at a balanced specimen:
eps_R = eps_T - eps_I (so F_front = F_back), placed at the gauges with the nominal delays
2 x_I / c0 (reflected) and (x_I + x_T) / c0 (transmitted), converted to volts, split into two opposite
gauges with bending of opposite sign, offset by a baseline and covered with Gaussian noise. The
reduction must give back the exact stress, strain rate, strain, force balance and noise level.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from shpb.lab.records import RawRecord
from shpb.lab.reduction import (
    CSV_COLUMNS,
    FREIBURG_BAR,
    BarSetup,
    despike,
    detect_arrival,
    reduce_record,
    reduced_to_dataframe,
    write_reduced_csv,
)

DT = 0.8e-6
N = 3000
T0_INDEX = 700                 # first sample of the incident pulse at the incident gauge
PULSE = 300e-6                 # incident pulse duration [s]
AMP = 2.0e-3                   # incident strain amplitude
BETA = 0.45                    # transmitted / incident amplitude
L_S, D_S = 0.040, 0.040        # specimen [m]
NOISE_V = 4.0e-3               # per-gauge noise [V]


def pulse(tau: np.ndarray) -> np.ndarray:
    """Smooth compressive pulse sin^2(pi tau / T) on [0, T], zero outside."""
    tau = np.asarray(tau, dtype=float)
    return np.where((tau >= 0) & (tau <= PULSE), np.sin(np.pi * np.clip(tau, 0, PULSE) / PULSE) ** 2, 0.0)


def exact_waves(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e_i = AMP * pulse(tau)
    e_t = BETA * e_i
    return e_i, e_t - e_i, e_t


def synthetic_record(bar: BarSetup = FREIBURG_BAR, seed: int = 0, noise_v: float = NOISE_V,
                     stuck_a4_after: float | None = None, quantum_v: float | None = None) -> RawRecord:
    rng = np.random.default_rng(seed)
    time = 1.0e-3 + DT * np.arange(N)           # arbitrary DAQ origin
    t_arr = time[T0_INDEX]
    c0 = bar.c0
    tg = time - t_arr                            # gauge time relative to the incident arrival
    e_i, _, _ = exact_waves(tg)
    _, e_r, _ = exact_waves(tg - 2 * bar.gauge_distance_incident / c0)
    _, _, e_t = exact_waves(tg - (bar.gauge_distance_incident + bar.gauge_distance_transmitted) / c0)
    s = bar.compression_sign
    u_inc = s * (e_i + e_r) / bar.strain_per_volt_incident
    u_tra = s * e_t / bar.strain_per_volt_transmitted
    bend = 0.15 * np.gradient(u_inc) / np.max(np.abs(np.gradient(u_inc))) * np.max(np.abs(u_inc))
    chans = np.vstack([u_inc + bend + 0.021, u_inc - bend - 0.013, u_tra + 0.008, u_tra - 0.004])
    chans += rng.normal(0.0, noise_v, size=chans.shape)
    if quantum_v is not None:
        chans = np.round(chans / quantum_v) * quantum_v
    if stuck_a4_after is not None:
        i_stuck = int(np.searchsorted(tg, stuck_a4_after))
        chans[3, i_stuck:i_stuck + 300] = -5.12
    return RawRecord(name="synthetic", source="memory", time=time, incident=chans[:2], transmitted=chans[2:],
                     unit="V", sample_rate=1.0 / DT, incident_channels=("A1", "A2"),
                     transmitted_channels=("A3", "A4"), bar=bar, specimen_length=L_S, specimen_diameter=D_S)


def stress_factor(bar: BarSetup = FREIBURG_BAR) -> float:
    return bar.E * bar.area / (math.pi * D_S ** 2 / 4)


@pytest.fixture(scope="module")
def reduced():
    return reduce_record(synthetic_record())


def test_arrival_found_at_the_pulse_foot(reduced):
    # the sin^2 foot rises out of the noise within a few microseconds
    lag = reduced.arrival_time_gauge - (1.0e-3 + DT * T0_INDEX)
    assert 0.0 <= lag <= 8e-6
    assert reduced.time[0] == 0.0 and reduced.dt == pytest.approx(DT)


def test_window_is_two_gauge_transit_times(reduced):
    c0 = FREIBURG_BAR.c0
    assert reduced.time[-1] == pytest.approx(2 * 1.25 / c0, abs=DT)
    assert reduced.shift_reflected == pytest.approx(2 * 1.25 / c0)
    assert reduced.shift_transmitted == pytest.approx(2.25 / c0)


def test_face_waves_and_stress_match_the_exact_solution(reduced):
    lag = reduced.arrival_time_gauge - (1.0e-3 + DT * T0_INDEX)
    e_i, e_r, e_t = exact_waves(reduced.time + lag)
    tol = 5 * NOISE_V * FREIBURG_BAR.strain_per_volt_incident / math.sqrt(2)
    np.testing.assert_allclose(reduced.eps_incident, e_i, atol=tol)
    np.testing.assert_allclose(reduced.eps_reflected, e_r, atol=tol)
    np.testing.assert_allclose(reduced.eps_transmitted, e_t, atol=tol)
    k = stress_factor()
    assert reduced.peak_stress == pytest.approx(k * BETA * AMP, rel=0.01)
    np.testing.assert_allclose(reduced.stress_back, k * e_t, atol=k * tol)
    np.testing.assert_allclose(reduced.stress_front, k * (e_i + e_r), atol=2 * k * tol)


def test_strain_rate_and_strain_match_the_exact_solution(reduced):
    lag = reduced.arrival_time_gauge - (1.0e-3 + DT * T0_INDEX)
    e_i, e_r, e_t = exact_waves(reduced.time + lag)
    c0 = FREIBURG_BAR.c0
    rate = c0 / L_S * (e_i - e_r - e_t)           # = 2 c0 / L (1 - beta) eps_I
    assert np.max(np.abs(reduced.strain_rate - rate)) < 0.02 * rate.max()
    final_strain = 2 * c0 / L_S * (1 - BETA) * AMP * PULSE / 2   # integral of sin^2 over T is T/2
    assert reduced.strain[-1] == pytest.approx(final_strain, rel=0.02)


def test_front_face_travel_is_the_integral_of_incident_minus_reflected(reduced):
    # u_1 = c0 int (e_I - e_R) dt; with e_R = e_T - e_I, u_1 = c0 (2 - beta) AMP int sin^2, which is
    # (2 - beta) AMP c0 T / 2 at the end of the pulse and (2 - beta) AMP c0 (tau/2 - T sin(2 pi tau/T)/(4 pi))
    # on the way; before the load reaches 2 % of the peak (sin^2 = 0.02) the face has moved that much
    lag = reduced.arrival_time_gauge - (1.0e-3 + DT * T0_INDEX)
    c0 = FREIBURG_BAR.c0
    tau = np.clip(reduced.time + lag, 0.0, PULSE)
    exact = (2 - BETA) * AMP * c0 * (tau / 2 - PULSE * np.sin(2 * np.pi * tau / PULSE) / (4 * np.pi))
    u = reduced.front_face_displacement()
    sel = reduced.time >= 0
    assert np.max(np.abs(u[sel] - exact[sel])) < 0.01 * exact.max()
    tau_2 = PULSE * np.arcsin(np.sqrt(0.02)) / np.pi
    u_2 = (2 - BETA) * AMP * c0 * (tau_2 / 2 - PULSE * np.sin(2 * np.pi * tau_2 / PULSE) / (4 * np.pi))
    assert reduced.closure_before_load(0.02) == pytest.approx(u_2, rel=0.05, abs=0.2e-6)


def test_force_balance_is_zero_for_balanced_waves(reduced):
    i = reduced.peak_index
    assert reduced.force_balance_at_peak < 0.01
    # within +-80 us of the peak F1 + F2 > 1.2 x its peak value / 2, so noise alone gives R < 0.04
    assert np.nanmax(reduced.force_balance[i - 100:i + 100]) < 0.04
    # undefined (NaN) where the forces are small, not a division by noise
    assert np.isnan(reduced.force_balance[0])


def test_noise_level_recovered_in_strain_and_in_pascal(reduced):
    # two gauges averaged: noise / sqrt(2) in volts, times the bridge factor
    expected = NOISE_V / math.sqrt(2) * FREIBURG_BAR.strain_per_volt_incident
    assert reduced.noise_std_strain["incident"] == pytest.approx(expected, rel=0.15)
    assert reduced.noise_std_strain["transmitted"] == pytest.approx(expected, rel=0.15)
    assert reduced.noise_std_strain["A1"] == pytest.approx(expected * math.sqrt(2), rel=0.15)
    k = stress_factor()
    assert reduced.noise_std_Pa["stress"] == pytest.approx(k * reduced.noise_std_strain["transmitted"])
    assert reduced.noise_std_Pa["stress_front"] == pytest.approx(
        k * math.sqrt(2) * reduced.noise_std_strain["incident"])


def test_incident_wave_at_gauge_is_exposed_in_gauge_time(reduced):
    t, e = reduced.incident_wave_at_gauge()
    lag = reduced.arrival_time_gauge - (1.0e-3 + DT * T0_INDEX)
    assert t[0] == 0.0 and np.allclose(np.diff(t), DT)
    assert t[-1] == pytest.approx(2 * 1.25 / FREIBURG_BAR.c0, abs=DT)
    np.testing.assert_allclose(e, AMP * pulse(t + lag), atol=5 * NOISE_V * 1.005e-3 / math.sqrt(2))


def test_compression_negative_records_give_the_same_result():
    bar_neg = BarSetup(E=FREIBURG_BAR.E, rho=FREIBURG_BAR.rho, diameter=FREIBURG_BAR.diameter,
                       gauge_distance_incident=1.25, gauge_distance_transmitted=1.0,
                       strain_per_volt_incident=FREIBURG_BAR.strain_per_volt_incident,
                       strain_per_volt_transmitted=FREIBURG_BAR.strain_per_volt_transmitted,
                       compression_sign=-1)
    pos = reduce_record(synthetic_record(seed=3))
    neg = reduce_record(synthetic_record(bar=bar_neg, seed=3))
    assert neg.peak_stress == pytest.approx(pos.peak_stress, rel=0.01)
    assert neg.peak_stress > 0


def test_a_gauge_stuck_at_the_rail_is_dropped_and_its_partner_used():
    red = reduce_record(synthetic_record(stuck_a4_after=2.25 / FREIBURG_BAR.c0 + 100e-6))
    assert red.channels_used == {"incident": ("A1", "A2"), "transmitted": ("A3",)}
    assert any("A4: saturated" in n for n in red.notes)
    assert red.peak_stress == pytest.approx(stress_factor() * BETA * AMP, rel=0.01)


def test_coarse_quantization_plateaus_are_not_taken_for_saturation():
    # an 8-bit scope (50 mV steps) shows flat tops on both gauges at once: nothing is dropped
    red = reduce_record(synthetic_record(noise_v=2e-3, quantum_v=0.05))
    assert red.channels_used == {"incident": ("A1", "A2"), "transmitted": ("A3", "A4")}
    assert red.peak_stress == pytest.approx(stress_factor() * BETA * AMP, rel=0.03)


def test_exclude_channels_override():
    red = reduce_record(synthetic_record(), exclude_channels=("A2",))
    assert red.channels_used["incident"] == ("A1",)
    assert any("A2: excluded" in n for n in red.notes)


def test_missing_specimen_size_is_an_error():
    raw = synthetic_record()
    raw.specimen_length = None
    with pytest.raises(ValueError, match="specimen length and diameter"):
        reduce_record(raw)


def test_detect_arrival_threshold_follows_the_noise_level():
    rng = np.random.default_rng(5)
    sigma = 1e-3
    noise = rng.normal(0, sigma, 4000)
    with pytest.raises(ValueError, match="no pulse above the threshold"):
        detect_arrival(noise, sigma, DT)
    # trapezoid: 20 us linear rise to 50 sigma starting at sample 1500
    ramp = np.clip(DT * (np.arange(4000) - 1500) / 20e-6, 0.0, 1.0)
    i = detect_arrival(noise + 50 * sigma * ramp, sigma, DT)
    assert abs(i - 1500) <= 2
    # a slow sin^2 foot is found where it leaves the noise (2 sigma / sqrt(w), w = 2 samples): ~16 us late
    i = detect_arrival(noise + 50 * sigma * pulse(DT * (np.arange(4000) - 1500)), sigma, DT)
    t_level = PULSE / np.pi * np.arcsin(np.sqrt(2 / np.sqrt(2) / 50))
    assert abs((i - 1500) * DT - t_level) < 8e-6
    # a single huge spike does not trigger (not sustained)
    spiky = noise.copy()
    spiky[300] = 1.0
    with pytest.raises(ValueError):
        detect_arrival(spiky, sigma, DT)


def test_despike_removes_glitches_and_keeps_a_steep_smooth_peak():
    t = np.arange(2000) * DT
    x = 2.0 * pulse(t - 200e-6) + np.random.default_rng(2).normal(0, 3e-3, t.size)
    y = x.copy()
    y[100] += 0.5
    y[500:502] += 0.4          # a two-sample glitch
    clean, n = despike(y, 3e-3)
    assert n >= 3
    assert abs(clean[100] - x[100]) < 0.02 and np.all(np.abs(clean[500:502] - x[500:502]) < 0.02)
    assert clean.max() == pytest.approx(x.max(), abs=0.01)


def test_csv_is_written_atomically_with_si_columns(tmp_path, reduced):
    out = write_reduced_csv(reduced, tmp_path / "sub" / "curve.csv")
    assert out.exists() and [p.name for p in out.parent.iterdir()] == ["curve.csv"]  # no temp file left
    import pandas as pd

    back = pd.read_csv(out)
    assert tuple(back.columns) == CSV_COLUMNS
    df = reduced_to_dataframe(reduced)
    np.testing.assert_allclose(back["stress_Pa"], df["stress_Pa"], rtol=1e-8)
    np.testing.assert_allclose(back["time_s"], reduced.time, rtol=1e-8, atol=1e-15)
    assert np.array_equal(np.isnan(back["force_balance"]), np.isnan(reduced.force_balance))
    # a second write replaces the file in one step
    write_reduced_csv(reduced, out)
    assert [p.name for p in out.parent.iterdir()] == ["curve.csv"]


def test_cumulative_trapezoid_is_scipys_to_the_bit():
    """The reduction's strain integral (shpb.lab.signals.cumulative_trapezoid, kept off scipy.integrate's
    import cost) gives scipy's floats exactly, on a non-uniform grid, and the exact integral of a line."""
    from scipy.integrate import cumulative_trapezoid as scipy_ct

    from shpb.lab.signals import cumulative_trapezoid

    rng = np.random.default_rng(3)
    x = np.cumsum(rng.uniform(0.5e-6, 1.5e-6, 4001))
    y = np.sin(2e5 * x) * 1e3 + rng.normal(0.0, 1.0, x.size)
    assert np.array_equal(cumulative_trapezoid(y, x), scipy_ct(y, x, initial=0.0))
    # the trapezoid rule is exact for a linear integrand: int_0^t (2 s + 1) ds = t^2 + t
    t = np.linspace(0.0, 3.0, 31)
    assert np.allclose(cumulative_trapezoid(2.0 * t + 1.0, t), t * t + t, rtol=0.0, atol=1e-12)


def test_running_filters_are_scipy_ndimages_to_the_bit():
    """The reduction's moving average and median (shpb.lab.signals.running_mean / running_median, kept off
    scipy.ndimage's import cost) give scipy's floats exactly: window sizes odd and even, signals shorter
    than the window, scales from strain to stress; and the moving average of a line away from its ends is
    the line."""
    from scipy.ndimage import median_filter, uniform_filter1d

    from shpb.lab.signals import running_mean, running_median

    rng = np.random.default_rng(4)
    for _ in range(400):
        n, size = int(rng.integers(1, 300)), int(rng.integers(1, 40))
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 8) + rng.normal() * 10.0 ** rng.uniform(-6, 6)
        assert np.array_equal(running_mean(x, size), uniform_filter1d(x, size, mode="nearest"))
        if size % 2:
            assert np.array_equal(running_median(x, size), median_filter(x, size=size, mode="nearest"))
    t = np.arange(100.0)
    assert np.allclose(running_mean(3.0 * t + 1.0, 9)[4:-4], 3.0 * t[4:-4] + 1.0, rtol=0.0, atol=1e-12)
    assert running_mean(np.array([]), 5).size == 0
    with pytest.raises(ValueError, match="odd"):
        running_median(t, 4)
