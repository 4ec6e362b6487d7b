"""Meshed SHPB geometries: counts, exact areas, contact faces, sets, bar-length rule, determinism."""
import json
import time

import numpy as np
import pytest

from fdem.body import Material
from shpb.geometry import (GRANITE, STEEL_BAR, TITANIUM_BAR, Geometry, bar_thickness, brazilian_disc,
                           cylinder, min_bar_length, plot_geometry)
from shpb.presets import PRESETS, Preset, get_preset

PRESET_NAMES = ("fast", "standard", "paper")
# docs/shpb-models.md bands of specimen triangles; "paper" is ~17,500 (Godinez & Rougier 2021, section 3).
DISC_BANDS = {"fast": (1000, 2000), "standard": (4000, 6000), "paper": (16000, 19000)}


@pytest.fixture(scope="module")
def discs():
    return {p: brazilian_disc(p) for p in PRESET_NAMES}


@pytest.fixture(scope="module")
def cylinders():
    return {p: cylinder(p, length_m=0.040, diameter_m=0.040, rock=GRANITE) for p in PRESET_NAMES}


def areas(body):
    p = body.nodes[body.triangles]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


def edge_lengths(body):
    t = body.triangles
    e = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1), axis=0)
    return np.linalg.norm(body.nodes[e[:, 0]] - body.nodes[e[:, 1]], axis=1)


def min_angles_deg(body):
    p = body.nodes[body.triangles]
    out = []
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        w = p[:, (i + 2) % 3] - p[:, i]
        cosang = np.sum(u * w, axis=1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        out.append(np.degrees(np.arccos(np.clip(cosang, -1, 1))))
    return np.min(out, axis=0)


def centroids(body, idx=slice(None)):
    return body.nodes[body.triangles[idx]].mean(axis=1)


# ---------------------------------------------------------------------------------------------------
# Counts and sizes
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_disc_triangle_count_is_inside_the_preset_band(discs, preset):
    lo, hi = DISC_BANDS[preset]
    n = discs[preset].element_counts["disc"]
    assert lo <= n <= hi, (preset, n)


def test_paper_preset_has_about_5000_bar_triangles(discs):
    c = discs["paper"].element_counts
    n_bars = c["incident_bar"] + c["transmission_bar"]
    assert 4500 <= n_bars <= 5500, n_bars
    assert 17000 <= c["disc"] <= 18600, c["disc"]


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_bars_are_coarser_than_the_specimen(discs, preset):
    c = discs[preset].element_counts
    # the bars cover 2 x 2.019 m x 50 mm = 0.2019 m^2, about 100 times the disc's area
    assert c["incident_bar"] + c["transmission_bar"] < 1.3 * c["disc"]


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_cylinder_triangle_count_follows_the_specimen_element_size(cylinders, preset):
    h = PRESETS[preset].specimen_h_m
    n_equilateral = 0.040 * 0.040 / (np.sqrt(3) / 4 * h * h)  # 1,279 / 4,103 / 14,780 triangles
    n = cylinders[preset].element_counts["cylinder"]
    assert 0.8 * n_equilateral <= n <= 1.2 * n_equilateral, (preset, n, n_equilateral)


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_specimen_mean_edge_length_is_within_20_percent_of_the_preset_size(discs, cylinders, preset):
    h = PRESETS[preset].specimen_h_m
    for g in (discs[preset], cylinders[preset]):
        mean = edge_lengths(g.body(g.specimen)).mean()
        assert abs(mean / h - 1.0) < 0.2, (g.kind, preset, mean, h)


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_bar_edges_are_fine_at_the_specimen_face_and_coarse_far_away(discs, preset):
    p = PRESETS[preset]
    bar = discs[preset].body("incident_bar")
    face = bar.node_sets["specimen_face"]
    y = np.sort(bar.nodes[face, 1])
    assert np.allclose(np.diff(y), np.diff(y).mean()) and abs(np.diff(y).mean() / p.bar_near_h_m - 1) < 0.2
    x_front = discs[preset].specimen_face_x[0]
    far = bar.nodes[bar.triangles][:, :, 0].max(axis=1) < x_front - 0.5  # triangles > 0.5 m from the face
    sub = type(bar)("far", bar.nodes, bar.triangles[far], bar.material, bar.thickness)
    assert abs(edge_lengths(sub).mean() / p.bar_h_m - 1.0) < 0.2


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_all_triangles_are_counter_clockwise_and_of_good_quality(discs, cylinders, preset):
    for g in (discs[preset], cylinders[preset]):
        for b in g.bodies:
            assert np.all(areas(b) > 0), b.name
            assert min_angles_deg(b).min() > 25.0, b.name


# ---------------------------------------------------------------------------------------------------
# Exact areas and thicknesses
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_disc_area_is_within_half_a_percent_of_pi_r_squared(discs, preset):
    g = discs[preset]
    a = areas(g.body("disc")).sum()
    exact = np.pi * 0.025**2
    assert abs(a / exact - 1.0) < 0.005
    # every boundary vertex is on the circle (inscribed polygon): no node outside R
    r = np.hypot(*g.body("disc").nodes.T)
    assert r.max() <= 0.025 * (1 + 1e-14)


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_bar_and_cylinder_areas_are_exact(discs, cylinders, preset):
    for g in (discs[preset], cylinders[preset]):
        L_i, L_t = g.bar_length_m
        assert areas(g.body("incident_bar")).sum() == pytest.approx(L_i * 0.050, rel=1e-12)
        assert areas(g.body("transmission_bar")).sum() == pytest.approx(L_t * 0.050, rel=1e-12)
    assert areas(cylinders[preset].body("cylinder")).sum() == pytest.approx(0.040 * 0.040, rel=1e-12)


def test_plane_stress_thickness_matches_the_round_cross_section(discs, cylinders):
    for D in (0.020, 0.050, 0.0765):
        assert abs(D * bar_thickness(D) - np.pi * D**2 / 4) <= 1e-12 * np.pi * D**2 / 4
    for g in (discs["fast"], cylinders["fast"]):
        for name in ("incident_bar", "transmission_bar"):
            b = g.body(name)
            assert abs(0.050 * b.thickness - np.pi * 0.050**2 / 4) <= 1e-12 * np.pi * 0.050**2 / 4
            assert g.bar_thickness_m == b.thickness
    assert discs["fast"].body("disc").thickness == 0.025  # the disc's real thickness
    cyl = cylinders["fast"].body("cylinder")
    assert abs(0.040 * cyl.thickness - np.pi * 0.040**2 / 4) <= 1e-12 * np.pi * 0.040**2 / 4
    assert not discs["fast"].body("incident_bar").fracturable and discs["fast"].body("disc").fracturable


# ---------------------------------------------------------------------------------------------------
# Contact faces: zero gap, no overlap
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_disc_touches_each_bar_at_its_extreme_node_with_zero_gap(discs, preset):
    g = discs[preset]
    inc, disc, tr = g.body("incident_bar"), g.body("disc"), g.body("transmission_bar")
    assert g.specimen_face_x == (-0.025, 0.025)
    # no overlap: the bodies occupy [.., -R], [-R, R], [R, ..] in x
    assert inc.nodes[:, 0].max() == -0.025 and disc.nodes[:, 0].min() == -0.025
    assert tr.nodes[:, 0].min() == 0.025 and disc.nodes[:, 0].max() == 0.025
    # the disc's extreme nodes are exactly (-R, 0) and (R, 0), and they are the only ones at x = -+R
    assert np.array_equal(disc.nodes[disc.node_sets["front_face"]], [[-0.025, 0.0]])
    assert np.array_equal(disc.nodes[disc.node_sets["back_face"]], [[0.025, 0.0]])
    assert np.count_nonzero(disc.nodes[:, 0] == -0.025) == 1
    for bar, x in ((inc, -0.025), (tr, 0.025)):
        y = np.sort(bar.nodes[bar.node_sets["specimen_face"], 1])
        assert np.all(bar.nodes[bar.node_sets["specimen_face"], 0] == x)
        assert y[0] == -0.025 and y[-1] == 0.025
        # the contact point y = 0 lies inside a face edge, not on a bar node
        assert not np.any(y == 0.0)
        k = np.searchsorted(y, 0.0)
        assert y[k - 1] < 0.0 < y[k]


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_cylinder_end_faces_coincide_with_the_bar_faces(cylinders, preset):
    g = cylinders[preset]
    inc, cyl, tr = g.body("incident_bar"), g.body("cylinder"), g.body("transmission_bar")
    x_front, x_back = g.specimen_face_x
    assert (x_front, x_back) == (-0.020, 0.020)
    assert inc.nodes[:, 0].max() == x_front == cyl.nodes[:, 0].min()
    assert tr.nodes[:, 0].min() == x_back == cyl.nodes[:, 0].max()
    for name, x in (("front_face", x_front), ("back_face", x_back)):
        face = cyl.nodes[cyl.node_sets[name]]
        assert np.all(face[:, 0] == x)
        assert face[:, 1].min() == -0.020 and face[:, 1].max() == 0.020
        assert len(face) == np.count_nonzero(cyl.nodes[:, 0] == x)
    # the bar face (50 mm) covers the specimen face (40 mm)
    for bar in (inc, tr):
        y = bar.nodes[bar.node_sets["specimen_face"], 1]
        assert y.min() == -0.025 and y.max() == 0.025


# ---------------------------------------------------------------------------------------------------
# Node and element sets
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["disc", "cylinder"])
def test_bar_node_sets_hold_exactly_the_end_face_nodes(discs, cylinders, kind):
    g = discs["standard"] if kind == "disc" else cylinders["standard"]
    inc, tr = g.body("incident_bar"), g.body("transmission_bar")
    x_front, x_back = g.specimen_face_x
    L_i, L_t = g.bar_length_m
    checks = [(inc, "load_end", x_front - L_i), (inc, "specimen_face", x_front),
              (tr, "specimen_face", x_back), (tr, "free_end", x_back + L_t)]
    for body, name, x in checks:
        idx = body.node_sets[name]
        assert len(idx) >= 2 and len(np.unique(idx)) == len(idx)
        assert np.all(body.nodes[idx, 0] == x), (body.name, name)
        assert np.array_equal(np.sort(idx), np.flatnonzero(body.nodes[:, 0] == x))
        assert body.nodes[idx, 1].min() == -0.025 and body.nodes[idx, 1].max() == 0.025
    assert inc.nodes[:, 0].min() == x_front - L_i and tr.nodes[:, 0].max() == x_back + L_t


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_gauge_sets_are_a_slab_around_the_gauge_section(discs, cylinders, preset):
    h = PRESETS[preset].bar_h_m  # the gauges are far from the faces, where the bar size is bar_h
    for g in (discs[preset], cylinders[preset]):
        for name, xg in zip(("incident_bar", "transmission_bar"), g.gauge_x):
            b = g.body(name)
            idx = b.element_sets["gauge"]
            xc = centroids(b)[:, 0]
            assert len(idx) >= 3
            assert np.all(np.abs(xc[idx] - xg) <= h)
            assert np.array_equal(np.sort(idx), np.flatnonzero(np.abs(xc - xg) <= h))
            # the slab spans the bar's height
            yc = centroids(b, idx)[:, 1]
            assert yc.min() < -0.010 and yc.max() > 0.010
    d = discs[preset]
    assert d.gauge_x[0] == pytest.approx(-0.025 - d.gauge_distance_m[0], abs=1e-15)
    assert d.gauge_x[1] == pytest.approx(0.025 + d.gauge_distance_m[1], abs=1e-15)


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_specimen_centre_set_is_a_small_disc_at_the_centre(discs, cylinders, preset):
    for g, radius in ((discs[preset], 0.050 / 20), (cylinders[preset], 0.040 / 20)):
        s = g.body(g.specimen)
        idx = s.element_sets["centre"]
        assert len(idx) >= 6
        assert g.centre_radius_m == pytest.approx(radius)
        r = np.hypot(*centroids(s, idx).T)
        assert r.max() <= radius
        assert np.array_equal(np.sort(idx), np.flatnonzero(np.hypot(*centroids(s).T) <= radius))


def test_centre_set_grows_to_six_triangles_on_a_coarse_mesh():
    coarse = Preset("coarse", specimen_h_m=6e-3, bar_h_m=20e-3, bar_near_h_m=8e-3, bar_near_length_m=25e-3)
    g = brazilian_disc(coarse)
    idx = g.body("disc").element_sets["centre"]
    assert len(idx) >= 6
    assert g.centre_radius_m > 0.050 / 20


# ---------------------------------------------------------------------------------------------------
# Bar lengths vs the recorded window
# ---------------------------------------------------------------------------------------------------

def test_default_bar_lengths_keep_end_reflections_out_of_the_recorded_window(discs):
    g = discs["fast"]
    c = np.sqrt(200e9 / 7850)  # 5,047.5 m/s
    W = 400e-6
    L_i, L_t = g.bar_length_m
    d_i, d_t = g.gauge_distance_m
    assert g.window_s == W and g.bar_wave_speed_m_s == pytest.approx(c, rel=1e-15)
    # defaults: gauges at mid-length, bars c * W = 2.019 m long
    assert L_i == pytest.approx(2.0190, abs=1e-4) and L_t == pytest.approx(2.0190, abs=1e-4)
    assert d_i == pytest.approx(L_i / 2, rel=1e-14) and d_t == pytest.approx(L_t / 2, rel=1e-14)
    # time of flight, window starting when the incident front reaches the specimen (t_s)
    t_s = L_i / c
    assert g.arrival_time_s == pytest.approx(t_s, rel=1e-15)
    # incident bar: the specimen-reflected wave bounces off the loaded end and comes back
    assert t_s + 2 * L_i / c >= t_s + W                          # at the specimen
    assert t_s + (2 * L_i - d_i) / c >= t_s + d_i / c + W * (1 - 1e-12)  # at the gauge: 2 (L - d) / c >= W
    # transmission bar: the free-end reflection
    assert t_s + 2 * L_t / c >= t_s + W
    assert t_s + (2 * L_t - d_t) / c >= t_s + d_t / c + W * (1 - 1e-12)
    # and the defaults are the tightest bars that do it
    assert 2 * (L_i - d_i) / c == pytest.approx(W, rel=1e-12)
    # incident and reflected waves of a pulse up to W long pass the incident gauge one after the other
    assert 2 * d_i / c == pytest.approx(W, rel=1e-12)


def test_bar_lengths_scale_with_the_window_and_too_short_bars_are_rejected():
    c = STEEL_BAR.c_bar
    assert min_bar_length(1.0, c, 200e-6) == pytest.approx(1.0 + 0.5 * 5047.54 * 200e-6, rel=1e-5)  # 1.5048 m
    g = brazilian_disc("fast", window_s=200e-6)
    assert g.bar_length_m[0] == pytest.approx(c * 200e-6, rel=1e-12)  # 1.0095 m
    with pytest.raises(ValueError, match="incident_length_m"):
        brazilian_disc("fast", incident_length_m=1.5)  # < 1.0095 + 1.0095 m
    with pytest.raises(ValueError, match="transmission_length_m"):
        brazilian_disc("fast", transmission_gauge_m=0.5, transmission_length_m=1.4)  # < 0.5 + 1.0095 m
    ok = brazilian_disc("fast", transmission_gauge_m=0.5, transmission_length_m=1.51)
    assert ok.bar_length_m[1] == 1.51 and ok.gauge_x[1] == pytest.approx(0.525)
    short = brazilian_disc("fast", incident_length_m=1.5, enforce_window=False)
    assert short.body("incident_bar").nodes[:, 0].min() == pytest.approx(-1.525)


def test_cylinder_incident_bar_starts_at_the_gauge_and_transmission_bar_fits_the_window(cylinders):
    g = cylinders["fast"]
    c = np.sqrt(110e9 / 4430)  # 4,983 m/s
    assert g.bar_material == TITANIUM_BAR and g.loading == "gauge_injection"
    assert g.gauge_distance_m == (1.25, 1.00)
    x_front, x_back = g.specimen_face_x
    inc = g.body("incident_bar")
    assert g.bar_length_m[0] == 1.25
    assert g.gauge_x[0] == x_front - 1.25 == inc.nodes[:, 0].min()
    assert np.all(inc.nodes[inc.node_sets["load_end"], 0] == g.gauge_x[0])
    assert g.gauge_x[1] == x_back + 1.00
    L_t = g.bar_length_m[1]
    assert L_t == pytest.approx(1.00 + 0.5 * c * 400e-6, rel=1e-12)  # 1.9966 m
    assert 2 * (L_t - 1.00) / c == pytest.approx(400e-6, rel=1e-12)
    assert g.arrival_time_s == pytest.approx(1.25 / c, rel=1e-12)  # 250.9 us from injection to specimen
    with pytest.raises(ValueError, match="transmission_length_m"):
        cylinder("fast", 0.04, 0.04, GRANITE, transmission_length_m=1.5)
    absorbing = cylinder("fast", 0.04, 0.04, GRANITE, transmission_length_m=1.2, enforce_window=False)
    assert absorbing.body("transmission_bar").nodes[:, 0].max() == pytest.approx(1.22)


# ---------------------------------------------------------------------------------------------------
# Determinism, speed, errors, summary, plot
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_same_preset_gives_identical_arrays(discs, preset):
    a, b = discs[preset], brazilian_disc(preset)
    for ba, bb in zip(a.bodies, b.bodies):
        assert np.array_equal(ba.nodes, bb.nodes) and np.array_equal(ba.triangles, bb.triangles)
        for name in ba.node_sets:
            assert np.array_equal(ba.node_sets[name], bb.node_sets[name])
        for name in ba.element_sets:
            assert np.array_equal(ba.element_sets[name], bb.element_sets[name])
    c1 = cylinder("fast", 0.035, 0.038, GRANITE)
    c2 = cylinder("fast", 0.035, 0.038, GRANITE)
    assert all(np.array_equal(x.nodes, y.nodes) and np.array_equal(x.triangles, y.triangles)
               for x, y in zip(c1.bodies, c2.bodies))


def test_paper_preset_meshes_in_under_five_seconds():
    t0 = time.perf_counter()
    brazilian_disc("paper")
    cylinder("paper", 0.040, 0.040, GRANITE)
    assert time.perf_counter() - t0 < 5.0


def test_unknown_preset_and_non_physical_dimensions_raise_value_error():
    with pytest.raises(ValueError, match=r"preset must be one of \['fast', 'paper', 'standard'\]"):
        brazilian_disc("ultra")
    with pytest.raises(ValueError, match="preset must be one of"):
        get_preset(3)
    with pytest.raises(ValueError, match="diameter_m must be a finite positive number"):
        brazilian_disc("fast", diameter_m=-0.05)
    with pytest.raises(ValueError, match="thickness_m"):
        brazilian_disc("fast", thickness_m=0.0)
    with pytest.raises(ValueError, match="window_s"):
        brazilian_disc("fast", window_s=float("nan"))
    with pytest.raises(ValueError, match="bar_diameter_m"):
        brazilian_disc("fast", bar_diameter_m=-1.0)
    with pytest.raises(ValueError, match="diameter_m = 0.005 m is too small for preset 'fast'"):
        brazilian_disc("fast", diameter_m=0.005)
    with pytest.raises(ValueError, match="length_m"):
        cylinder("fast", length_m=0.0, diameter_m=0.04, rock=GRANITE)
    with pytest.raises(ValueError, match="must not exceed bar_diameter_m"):
        cylinder("fast", length_m=0.04, diameter_m=0.06, rock=GRANITE)
    with pytest.raises(ValueError, match="transmission_gauge_m"):
        cylinder("fast", 0.04, 0.04, GRANITE, transmission_gauge_m=-1.0)
    with pytest.raises(TypeError, match="rock must be a fdem.body.Material"):
        cylinder("fast", 0.04, 0.04, rock={"E": 1e9})
    with pytest.raises(ValueError, match="bar_h_m"):
        Preset("bad", specimen_h_m=1e-3, bar_h_m=-1.0, bar_near_h_m=1e-3, bar_near_length_m=0.02)


def test_summary_is_json_ready_and_reports_the_metadata(discs, cylinders):
    g = discs["fast"]
    s = json.loads(json.dumps(g.summary()))
    assert s["kind"] == "brazilian_disc" and s["preset"] == "fast" and s["loading"] == "free_end_velocity"
    assert s["roles"] == {"incident_bar": "incident_bar", "specimen": "disc", "transmission_bar": "transmission_bar"}
    assert s["element_counts"] == g.element_counts
    assert s["n_triangles_total"] == sum(g.element_counts.values())
    assert s["specimen_dims_m"] == {"diameter_m": 0.05, "thickness_m": 0.025}
    assert s["specimen_face_x_m"] == [-0.025, 0.025]
    assert s["bar"]["E"] == 200e9 and s["bar"]["diameter_m"] == 0.05
    assert s["bodies"][1]["element_sets"]["centre"] == len(g.body("disc").element_sets["centre"])
    c = json.loads(json.dumps(cylinders["fast"].summary()))
    assert c["specimen_dims_m"]["length_m"] == 0.04 and c["gauge_distance_m"] == [1.25, 1.0]
    assert isinstance(g, Geometry) and g.body("disc") is g.bodies[1]
    with pytest.raises(KeyError):
        g.body("striker")


def test_custom_materials_and_sizes_are_used():
    rock = Material(E=60e9, nu=0.25, rho=2700.0)
    g = cylinder("fast", length_m=0.030, diameter_m=0.038, rock=rock, bar=STEEL_BAR)
    s = g.body("cylinder")
    assert s.material == rock and g.body("incident_bar").material == STEEL_BAR
    assert s.nodes[:, 0].min() == -0.015 and s.nodes[:, 1].max() == 0.019
    assert areas(s).sum() == pytest.approx(0.030 * 0.038, rel=1e-12)
    d = brazilian_disc("fast", diameter_m=0.040, thickness_m=0.016)
    assert d.specimen_face_x == (-0.020, 0.020) and d.body("disc").thickness == 0.016
    assert areas(d.body("disc")).sum() == pytest.approx(np.pi * 0.020**2, rel=0.005)


def test_plot_geometry_writes_a_png(tmp_path, discs):
    path = tmp_path / "disc.png"
    plot_geometry(discs["fast"], path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
