"""The Brazilian disc fails as a Brazilian disc (fast preset; standard and paper in
benchmarks/bench_shpb.py): the crack starts in the centre and runs along the loaded diameter,
the two loaded faces carry the same force at the failure peak, the strength is granite's at this
loading rate, fragments do not pass through each other, and every run can be looked at."""
import json
import subprocess
import sys

import meshio
import numpy as np
import pytest

from shpb.fracture import BALANCE, BAND_SHARE, BAND_Y, CENTRAL_X, CENTRAL_Y, CHECK_POINTS as POINTS
from shpb.simulate import simulate


@pytest.fixture(scope="module", params=sorted(POINTS))
def run(request):
    sigma_t, E_t = POINTS[request.param]
    out = simulate("brazilian_disc", "fast", params={"sigma_t": sigma_t, "E_t": E_t})
    assert out.run["status"] == "ok", out.run["reason"]
    return request.param, out


def test_fracture_starts_in_the_centre(run):
    name, out = run
    x, y = out.run["fracture"]["first_joint_xy_over_R"]
    assert abs(x) < CENTRAL_X and abs(y) < CENTRAL_Y, f"{name}: first joint at ({x:.3f}, {y:.3f}) R"


def test_broken_joints_at_the_peak_lie_along_the_loaded_diameter(run):
    name, out = run
    f = out.run["fracture"]
    assert f["broken_at_peak"] >= 5, f"{name}: {f['broken_at_peak']} joints broken at the peak"
    assert f["band_fraction_at_peak"] >= BAND_SHARE, f"{name}: {f['band_fraction_at_peak']:.2f} within |y| < {BAND_Y} R"


def test_loaded_faces_carry_the_same_force_at_the_peak(run):
    name, out = run
    ratio = out.run["fracture"]["force_ratio_at_peak"]
    assert abs(ratio - 1.0) <= BALANCE, f"{name}: F_front / F_back = {ratio:.3f} at the peak"


def test_the_run_closes_its_energy_balance(run):
    """Up to the failure peak the energy balance closes to 0.1 % of the external work (measured: below
    0.01 %). Over the whole window, through the fragmentation after the peak, within 2 %: measured
    0.03-1.2 % at the three points; the error comes from fragment impacts late in the window and is
    a time-integration error (halving the step cut the weak-brittle point's 1.24 % to 0.08 %)."""
    name, out = run
    res = out.extra["result"]
    err = res.energy_balance_error()
    W = res.energy["external_work"]
    to_peak = res.time - out.run["arrival_s"] <= out.run["fracture"]["peak_t_s"] + 1e-12
    assert np.max(np.abs(err[to_peak])) < 1e-3 * W[to_peak][-1], name
    assert out.run["energy_balance_rel"] < 0.02, f"{name}: {out.run['energy_balance_rel']:.4f}"


def test_fragments_do_not_pass_through_each_other(run):
    """Contact: the deepest penetration the contact accepted, over the whole window, stays under 2 %
    of the specimen element size. Independently of the contact search (shpb.fracture.overlap_depth),
    no node of the disc sits inside another piece of it at the failure peak. After the peak the
    crushed pieces under the flats do pass into each other: measured at the window's end 0-11 % of an
    element here and 25 % at the standard preset (benchmarks/bench_shpb.py); the bound of a
    third of an element says it stays a local overlap of crushed fragments, not a piece passing
    through another (the earlier model, crushing under the flats, had 4.5 % at the peak)."""
    name, out = run
    h = 1.7e-3
    f = out.run["fracture"]
    assert out.run["max_penetration_over_h"] < 0.02, f"{name}: {out.run['max_penetration_over_h']:.4f} h"
    assert f["overlap_at_peak_m"] < 0.01 * h, f"{name}: {f['overlap_at_peak_m'] / h:.3f} h at the peak"
    assert f["overlap_at_end_m"] < 0.33 * h, f"{name}: {f['overlap_at_end_m'] / h:.3f} h at the end"


def test_overlap_measure_finds_a_node_pushed_into_another_piece():
    """The independent overlap check sees a node moved 0.3 mm into a neighbouring triangle."""
    from shpb.fracture import overlap_depth
    from shpb.simulate import build

    model = build("brazilian_disc", "fast")["model"]
    x = model.x0.copy()
    assert overlap_depth(model, x, "disc") == (0.0, 0)
    disc = model.body_index("disc")
    t = int(np.flatnonzero(model.tri_body == disc)[100])
    a, b, c = model.tri[t]
    # push node a across the opposite edge b-c into the triangle beyond it, 0.3 mm past the edge
    mid = 0.5 * (x[b] + x[c])
    out = (mid - x[a]) / np.linalg.norm(mid - x[a])
    x[a] = mid + 0.3e-3 * out
    depth, count = overlap_depth(model, x, "disc")
    assert count >= 1
    assert 0.1e-3 < depth <= 0.3e-3 + 1e-9


def test_reference_strength_is_granites_at_this_loading_rate():
    """Kuru granite in SHPB Brazilian tests (Saksala et al. 2013, read off its figures):
    sigma_td = 21 MPa + 0.017 x loading rate [GPa/s], with peaks of 25-40 MPa under these pulses. The
    model's loading rate is the slope of its Brazilian stress between 20 % and 80 % of the peak;
    the peak must lie within 25 % of the law there: the two laboratories that tested Kuru granite
    differ by 17 % (Wessling & Kajberg 2022 against the law) and one laboratory's tests at this rate
    scatter by about +-7 %. Measured: 33.2 MPa at 402 GPa/s, 19 % above the law's 27.8 MPa."""
    out = simulate("brazilian_disc", "fast")
    c = out.curve
    f = out.run["fracture"]
    peak = f["peak_stress_Pa"]
    t, s = c.time_s.to_numpy(), c.stress_Pa.to_numpy()
    rise = t <= f["peak_t_s"]
    t20 = np.interp(0.2 * peak, s[rise], t[rise])
    t80 = np.interp(0.8 * peak, s[rise], t[rise])
    rate_GPa_s = 0.6 * peak / (t80 - t20) / 1e9
    law = 21e6 + 0.017e6 * rate_GPa_s
    assert 100 < rate_GPa_s < 1000
    assert peak == pytest.approx(law, rel=0.25)
    assert 25e6 <= peak <= 40e6


@pytest.mark.parametrize("preset", ["fast", "standard"])
def test_flattened_disc_centre_stress_follows_wang_et_al(preset):
    """Static flattened disc (2 alpha = 20 degrees) under a uniform pressure P / (2 R sin a t) on its
    flats, relaxed by mass damping: the centre's tensile stress is k 2P/(pi D t) with
    k = (2 cos^3 a + cos a + sin a / a)^2 / (8 (cos a + sin a / a)) a / sin a = 0.960 (Wang et al. 2004)
    and the compressive one about -3 x 2P/(pi D t). Tolerance 1.5 %: the centre probe averages the
    triangles within D/20 of the centre (measured: 0.4 %). In the SHPB model the bar's face presses
    harder at the flats' edges (a flat punch), which lowers k to about 0.93 (measured)."""
    from fdem import JointParams, Material, TractionBC, build_model, run as fdem_run
    from shpb.geometry import brazilian_disc
    from shpb.loading import face_tributary_areas

    granite = Material(35e9, 0.16, 2550.0)
    g = brazilian_disc(preset, disc=granite, flat_half_angle_deg=10.0, enforce_window=False)
    disc = g.body("disc")
    R, t = 0.025, disc.thickness
    a = np.radians(10.0)
    k = (2 * np.cos(a)**3 + np.cos(a) + np.sin(a) / a)**2 / (8 * (np.cos(a) + np.sin(a) / a)) * a / np.sin(a)
    assert k == pytest.approx(0.960, abs=1e-3)
    model = build_model([disc], joints={"disc": JointParams(10e6, 30e6, 100.0, 500.0, unbreakable=True)},
                        alpha_mass=np.pi * granite.c_plane_stress / (2 * R))
    P = 50e3
    T = 40 * 2 * R / granite.c_plane_stress
    bcs = []
    for face, sign in (("front_face", 1.0), ("back_face", -1.0)):
        nodes = model.node_sets[f"disc.{face}"]
        # a mesh vertex's tributary area, shared among the triangles' copies of it
        vertex, inverse, copies = np.unique(model.node_vertex[nodes], return_inverse=True, return_counts=True)
        one = np.array([nodes[np.flatnonzero(inverse == i)[0]] for i in range(vertex.size)])
        area = face_tributary_areas(model.x0, one, t)[inverse] / copies[inverse]
        pressure = P / (2 * R * np.sin(a) * t)
        bcs.append(TractionBC(nodes, 0, area, np.array([0.0, 0.5 * T, T]),
                              sign * pressure * np.array([0.0, 1.0, 1.0])))
    xc = model.x0[model.tri].mean(axis=1)
    centre = np.flatnonzero(np.hypot(*xc.T) < 2 * R / 20)
    res = fdem_run(model, T, traction_bcs=bcs, stress_probes=[("centre", centre)], sample_dt=T / 50)
    sxx, syy, _ = res.stress["centre"][-1]
    nominal = 2 * P / (np.pi * 2 * R * t)
    assert syy == pytest.approx(k * nominal, rel=0.015)
    assert sxx == pytest.approx(-3.0 * nominal, rel=0.03)
    assert res.energy["kinetic"][-1] < 1e-6 * res.energy["strain"][-1]


def test_cli_snapshots_write_vtk_and_damage_maps(tmp_path):
    out = tmp_path / "ref"
    proc = subprocess.run([sys.executable, "-m", "shpb", "simulate", "--geometry", "brazilian_disc",
                           "--preset", "fast", "--snapshots", "2", "--out", str(out)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    run = json.loads((out / "run.json").read_text())
    names = {s.get("what", "t"): s for s in run["snapshots"]}
    assert {"peak", "end"} <= set(names)
    vtk = sorted((out / "snapshots").glob("*.vtu"))
    assert len(vtk) == 4  # two times, the peak, the end
    peak = meshio.read(out / "snapshots" / "peak.vtu")
    D_lines = peak.cell_data["damage"][1]
    broken = peak.cell_data["broken"][1]
    assert D_lines.shape[0] == run["n_joints"]
    assert 0.0 <= D_lines.min() and D_lines.max() <= 1.0
    assert int(broken.sum()) == run["fracture"]["broken_at_peak"]
    assert names["overview"]["png"] == "fracture.png"
    for name in ("damage_peak.png", "damage_end.png", "fracture.png"):
        png = (out / "snapshots" / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    bad = subprocess.run([sys.executable, "-m", "shpb", "simulate", "--geometry", "brazilian_disc",
                          "--snapshots", "1e-3", "--out", str(tmp_path / "bad")], capture_output=True, text=True)
    assert bad.returncode == 2 and "--snapshots" in bad.stderr


def test_hondros_field_tends_to_the_point_load_solution_on_the_loaded_diameter():
    """As the loaded arcs shrink to points, Hondros' field on the diameter becomes the point-load
    solution (Timoshenko & Goodier): sigma_theta = 1 and sigma_r = -(4 / (1 - rho^2) - 1), in units
    of 2F/(pi D t). Tolerance 0.1 % at alpha = 0.05 degrees (measured: 6e-5 for sigma_theta, 1e-5 for
    sigma_r; a wrong sign or factor in either term is off by tens of per cent). At 2 alpha = 20
    degrees the centre's tension is (sin 2a - a) / a = 0.9596."""
    from shpb.disc_theory import hondros_on_diameter

    rho = np.array([0.0, 0.3, 0.6, 0.8])
    s_r, s_th = hondros_on_diameter(rho, np.radians(0.05))
    assert s_th == pytest.approx(np.ones_like(rho), rel=1e-3)
    assert s_r == pytest.approx(-(4.0 / (1.0 - rho**2) - 1.0), rel=1e-3)
    a = np.radians(10.0)
    s_r0, s_th0 = hondros_on_diameter(0.0, a)
    assert s_th0 == pytest.approx((np.sin(2 * a) - a) / a, rel=1e-12)
    assert s_th0 == pytest.approx(0.9596, abs=1e-4)


def test_onset_theory_puts_the_weakest_joint_at_the_centre_with_the_default_tensile_strength():
    """The joint law's onset criterion on Hondros' field (docs: why sigma_n is 15 MPa): the centre's
    joint along the diameter starts in tension at sigma_n / sigma_theta(0). With the earlier
    sigma_n = 25 MPa and phi = 54 degrees, the weakest place at the reference (sigma_t 45 MPa) lay
    off-centre near 0.55 R, in shear, about 8 % below the centre (at the strong-tough point, 50 MPa,
    the centre was weakest); with the default sigma_n = 15 MPa the centre is weakest at all three
    points of the box."""
    from shpb.disc_theory import hondros_on_diameter, joint_onset, onset_along_diameter

    a, phi = np.radians(10.0), np.radians(54.0)
    p0, th0, mode0 = joint_onset(0.0, a, 25e6, 45e6, phi)
    assert (th0, mode0) == (0.0, "tension")
    assert p0 == pytest.approx(25e6 / hondros_on_diameter(0.0, a)[1], rel=1e-12)

    def weakest(sigma_n, sigma_t):
        return min(onset_along_diameter(a, sigma_n, sigma_t, phi), key=lambda r: r["onset_brazilian_stress_Pa"])

    w = weakest(25e6, 45e6)
    assert w["mode"] == "shear" and 0.45 <= w["x_over_R"] <= 0.6
    assert 0.90 < w["onset_brazilian_stress_Pa"] / p0 < 0.95
    assert weakest(25e6, 50e6)["x_over_R"] == 0.0
    for sigma_t in (30e6, 45e6, 50e6):
        assert weakest(15e6, sigma_t)["x_over_R"] == 0.0
