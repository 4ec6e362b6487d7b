"""Effect catalogue: measurement-chain operators against exact results, catalogue structure, parameter split."""

import math

import numpy as np
import pytest

from shpb import effects as fx

H = 0.1e-6  # 10 MHz sampling
T = np.arange(0.0, 200e-6, H)


def gaussian_pulse(t, t_peak=80e-6, width=10e-6, amplitude=40e6):
    return amplitude * np.exp(-0.5 * ((t - t_peak) / width) ** 2)


def test_catalogue_declares_the_issue_effects_with_boxes_containing_their_nulls():
    names = {n for e in fx.effects() for n in e.param_names}
    assert {"trigger_shift.dt_s", "gauge_gain.g", "baseline.offset_Pa", "baseline.drift_Pa_per_s", "lowpass.tau_s",
            "rate_strength.k", "damping.beta", "interface_friction.mu",
            "seating.compliance_m_per_Pa", "face_gap.gap_m", "closure.range_m"} <= names
    assert {e.name for e in fx.effects("measurement")} == {"trigger_shift", "gauge_gain", "baseline", "lowpass"}
    assert {e.name for e in fx.effects("physical")} == {"rate_strength", "damping", "interface_friction", "seating",
                                                          "face_gap", "closure"}
    for e in fx.effects():
        assert e.description and all(lo <= z <= hi for lo, z, hi in zip(e.lower, e.nulls, e.upper))
        assert (e.apply is not None) == (e.kind == "measurement")
        assert e.kind == "measurement" or e.fdem  # physical effects say what the engine does
    assert fx.null_values(["gauge_gain.g", "lowpass.tau_s", "damping.beta"]) == {
        "gauge_gain.g": 1.0, "lowpass.tau_s": 0.0, "damping.beta": 0.0}
    lo, hi = fx.bounds(["trigger_shift.dt_s", "gauge_gain.g"])
    assert lo.tolist() == [-10e-6, 0.8] and hi.tolist() == [10e-6, 1.2]
    assert fx.RATE0_PER_S == 1.0


def test_split_params_sorts_base_physical_and_measurement_and_rejects_unknown_effects():
    base, phys, meas = fx.split_params({"sigma_t": 45e6, "damping.beta": 0.1, "gauge_gain.g": 1.1, "E_t": 500.0,
                                        "lowpass.tau_s": 1e-6, "rate_strength.k": 0.2})
    assert base == {"sigma_t": 45e6, "E_t": 500.0}
    assert phys == {"damping.beta": 0.1, "rate_strength.k": 0.2}
    assert meas == {"gauge_gain.g": 1.1, "lowpass.tau_s": 1e-6}
    with pytest.raises(KeyError, match="gauge_gian.g"):
        fx.split_params({"gauge_gian.g": 1.1})
    with pytest.raises(KeyError):
        fx.bounds(["sigma_t"])


def test_null_parameters_leave_the_curve_unchanged_and_base_or_physical_ones_are_ignored():
    s = gaussian_pulse(T)
    assert np.array_equal(fx.apply_measurement(T, s, {}), s)
    nulls = fx.null_values([n for e in fx.effects("measurement") for n in e.param_names])
    assert np.allclose(fx.apply_measurement(T, s, {**nulls, "sigma_t": 1.0, "damping.beta": 0.3}), s,
                       rtol=0, atol=1e-9)


def test_gain_of_1_1_multiplies_the_curve_by_1_1():
    s = gaussian_pulse(T)
    assert np.allclose(fx.apply_measurement(T, s, {"gauge_gain.g": 1.1}), 1.1 * s, rtol=1e-15, atol=0)


def test_baseline_adds_offset_and_drift_from_the_first_sample_and_is_not_scaled_by_the_gain():
    t = T + 50e-6  # the drift is referred to the record's first sample, not to t = 0
    s = gaussian_pulse(t)
    y = fx.apply_measurement(t, s, {"baseline.offset_Pa": 2e6, "baseline.drift_Pa_per_s": 1e10, "gauge_gain.g": 0.9})
    assert np.allclose(y, 0.9 * s + 2e6 + 1e10 * (t - t[0]), rtol=0, atol=1e-6)


@pytest.mark.parametrize("dt", [3e-6, -2.35e-6, 0.05e-6])
def test_trigger_shift_moves_the_peak_by_dt_within_one_sample(dt):
    s = gaussian_pulse(T)
    y = fx.apply_measurement(T, s, {"trigger_shift.dt_s": dt})
    moved = T[np.argmax(y)] - T[np.argmax(s)]
    assert abs(moved - dt) <= H
    # away from the record ends the shifted curve is the pulse at t - dt, to the interpolation error
    # (h^2/8 max|s''| = 40e6 * (0.1/10)^2 / 8 = 500 Pa)
    assert np.max(np.abs(y - gaussian_pulse(T - dt))) < 600.0


def test_lowpass_step_response_reaches_63_2_percent_at_tau():
    tau = 2e-6
    t_step = 20e-6
    x = np.where(T >= t_step, 1.0, 0.0)
    y = fx.lowpass(T, x, tau)
    assert fx.apply_measurement(T, x, {"lowpass.tau_s": tau}) == pytest.approx(y)
    k = np.searchsorted(T, t_step + tau)
    # the sampled step rises over the sample before t_step (linear interpolation): half a sample early
    assert y[k] == pytest.approx(1.0 - math.exp(-(tau + H / 2) / tau), rel=1e-3)
    assert abs(y[k] - (1.0 - math.exp(-1.0))) < 0.01
    crossing = T[np.argmax(y >= 1.0 - math.exp(-1.0))]
    assert abs(crossing - (t_step + tau)) <= H
    assert np.all(y[T < t_step - H] == 0.0) and y[-1] == pytest.approx(1.0, abs=1e-12)


def test_lowpass_is_exact_for_a_ramp_and_has_minus_3_db_at_the_cutoff():
    tau = 1.5e-6
    # tau y' + y = t, y(0) = 0: y = t - tau (1 - exp(-t/tau)); the first-order hold is exact for a ramp
    y = fx.lowpass(T, T, tau)
    assert np.allclose(y, T - tau * (1.0 - np.exp(-T / tau)), rtol=0, atol=1e-12 * T[-1])
    # a sine at f_c = 1/(2 pi tau) comes out with amplitude 1/sqrt(2), 45 degrees late
    fc = fx.cutoff_hz(tau)
    t = np.arange(0.0, 400e-6, 0.02e-6)
    y = fx.lowpass(t, np.sin(2 * np.pi * fc * t), tau)
    late = t > 20 * tau
    expected = np.sin(2 * np.pi * fc * t - np.pi / 4) / np.sqrt(2.0)
    assert np.max(np.abs(y[late] - expected[late])) < 2e-4
    assert fx.cutoff_hz(0.0) == math.inf


def test_lowpass_passes_constants_and_tau_zero_is_the_identity():
    s = gaussian_pulse(T) + 3e6
    assert np.allclose(fx.lowpass(T, np.full(T.size, 5e6), 1e-6), 5e6, rtol=1e-14)
    assert np.array_equal(fx.lowpass(T, s, 0.0), s)
    b, a = fx.lowpass_coefficients(H, 1e-9)  # tau << h: almost no filtering
    assert b.sum() == pytest.approx(1.0 + a[1]) and abs(a[1]) < 1e-40


def test_lowpass_and_shift_commute_and_a_small_lowpass_is_a_delay_to_first_order():
    s = gaussian_pulse(T)
    a = fx.apply_measurement(T, fx.lowpass(T, s, 1e-6), {"trigger_shift.dt_s": 2e-6})
    b = fx.lowpass(T, fx.apply_measurement(T, s, {"trigger_shift.dt_s": 2e-6}), 1e-6)
    assert np.max(np.abs(a - b)) < 1e-3 * s.max()
    tau = 0.2e-6  # LP_tau[s] = s - tau s' + O(tau^2)
    lp = fx.lowpass(T, s, tau)
    delayed = fx.time_shift(T, s, tau)
    assert np.max(np.abs(lp - delayed)) < 0.03 * np.max(np.abs(lp - s))


def test_lowpass_refuses_a_non_uniform_grid_and_bad_tau():
    t = np.sort(np.concatenate([T[:100], T[100:200] + 0.03e-6]))
    with pytest.raises(ValueError, match="uniform"):
        fx.lowpass(t, np.ones(t.size), 1e-6)
    with pytest.raises(ValueError):
        fx.lowpass(T, np.ones(T.size), -1e-6)
    with pytest.raises(ValueError):
        fx.apply_measurement(T, np.ones(T.size), {"gauge_gain.g": float("nan")})


def test_measurement_chain_order_is_shift_lowpass_gain_then_baseline():
    s = gaussian_pulse(T)
    p = {"trigger_shift.dt_s": 1e-6, "lowpass.tau_s": 0.5e-6, "gauge_gain.g": 1.05,
         "baseline.offset_Pa": -1e6, "baseline.drift_Pa_per_s": 2e9}
    expected = 1.05 * fx.lowpass(T, fx.time_shift(T, s, 1e-6), 0.5e-6) - 1e6 + 2e9 * (T - T[0])
    assert np.allclose(fx.apply_measurement(T, s, p), expected, rtol=0, atol=1e-6)
    assert fx.MEASUREMENT_ORDER == ("trigger_shift", "lowpass", "gauge_gain", "baseline")


def test_effects_serve_as_diagnosis_candidates_and_describe_themselves_for_json():
    import json

    e = fx.get_effect("baseline")
    assert e.param_names == ("baseline.offset_Pa", "baseline.drift_Pa_per_s")
    assert e.nulls == (0.0, 0.0)
    d = e.to_dict()
    json.dumps(d)
    assert d["params"]["baseline.offset_Pa"]["unit"] == "Pa"
    assert [c.name for c in fx.candidates(["gauge_gain", "lowpass"])] == ["gauge_gain", "lowpass"]
    with pytest.raises(KeyError, match="catalogue"):
        fx.get_effect("ringing")


def test_every_catalogue_entry_declares_a_scope_and_per_record_copies_resolve_to_their_effect():
    assert fx.SCOPES == ("per_record", "shared")
    scopes = {e.name: e.scope for e in fx.effects()}
    assert set(scopes.values()) <= set(fx.SCOPES) and len(scopes) == 10
    assert {n for n, s in scopes.items() if s == "per_record"} == {
        "face_gap", "closure", "seating", "trigger_shift", "gauge_gain", "baseline", "lowpass"}
    assert {n for n, s in scopes.items() if s == "shared"} == {"rate_strength", "damping", "interface_friction"}
    assert fx.get_effect("face_gap").to_dict()["scope"] == "per_record"
    with pytest.raises(ValueError, match="scope must be one of"):
        fx.Effect("x", "physical", (fx.EffectParam("a", 0.0, 1.0, 0.0, "-"),), "no scope", fdem="none")
    # per-record copies are named <effect>.<param>@<record> and resolve to their effect
    name = fx.record_param("face_gap.gap_m", "CaMa_SHPB_004")
    assert name == "face_gap.gap_m@CaMa_SHPB_004" and fx.split_record(name) == ("face_gap.gap_m", "CaMa_SHPB_004")
    assert fx.effect_of(name).name == "face_gap" and fx.null_values([name]) == {name: 0.0}
    assert fx.bounds([name])[1].tolist() == [4e-4]
    t = np.linspace(0.0, 1e-4, 11)
    with pytest.raises(ValueError, match="per-record parameters"):
        fx.apply_measurement(t, t, {"gauge_gain.g@A": 1.1})


def test_an_end_of_the_catalogue_range_away_from_the_null_is_an_edge_and_the_null_is_not():
    # gauge gain: box [0.8, 1.2], null 1 (inside); lowpass: [0, 5 us], null 0 (its lower end); face gap: null 0
    assert fx.catalogue_edge("gauge_gain.g@A", 0.8) == "lower" and fx.catalogue_edge("gauge_gain.g", 1.2) == "upper"
    assert fx.catalogue_edge("gauge_gain.g", 1.0) is None and fx.catalogue_edge("gauge_gain.g", 0.801) is None
    assert fx.catalogue_edge("gauge_gain.g", 0.801, 0.005) == "lower"  # within 0.5 % of the 0.4 width
    # the end test it rests on, for any box (summary.html's prior-box ends use it too)
    assert fx.box_end(0.801, 0.8, 1.2, 0.005) == "lower" and fx.box_end(1.199, 0.8, 1.2, 0.005) == "upper"
    assert fx.box_end(0.803, 0.8, 1.2, 0.005) is None and fx.box_end(1.0, 0.8, 1.2) is None
    assert fx.catalogue_edge("lowpass.tau_s@B", 5e-6) == "upper" and fx.catalogue_edge("lowpass.tau_s", 0.0) is None
    assert fx.catalogue_edge("face_gap.gap_m", 0.0, 0.005) is None
