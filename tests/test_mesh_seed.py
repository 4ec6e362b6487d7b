"""Mesh realizations (issue 30): ``mesh_seed`` perturbs the specimen's interior nodes.

None is today's mesh bit for bit; a seed gives a reproducible realization with the same topology,
boundary and sets, valid triangles, and (the physics check) the same elastic response.
"""
import json

import numpy as np
import pytest

from shpb.__main__ import main
from shpb.geometry import GRANITE, brazilian_disc, cylinder
from shpb.meshing import (MESH_JITTER, MIN_ANGLE_KEEP, _boundary_nodes, _mesh_flattened_disc, _min_angles,
                          _shortest_edge_at_nodes, _signed_areas, perturb_interior_nodes)
from shpb.presets import get_preset
from shpb.simulate import DISC_FLAT_HALF_ANGLE_DEG, simulate

SEEDS = (1, 2, 3, 4, 5)


def disc(seed=None, **kw):
    return brazilian_disc("fast", flat_half_angle_deg=DISC_FLAT_HALF_ANGLE_DEG, mesh_seed=seed, **kw)


def cyl(seed=None):
    return cylinder("fast", 0.040, 0.040, GRANITE, mesh_seed=seed)


def specimen(g):
    return g.body(g.specimen)


def fixed_mask(body):
    """Nodes that must not move: the boundary, the node sets and the element sets' nodes."""
    m = _boundary_nodes(body.triangles, len(body.nodes))
    for s in body.node_sets.values():
        m[s] = True
    for s in body.element_sets.values():
        m[body.triangles[s].ravel()] = True
    return m


# ---------------------------------------------------------------------------------------------------
# None is today's mesh
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("build", [disc, cyl], ids=["disc", "cylinder"])
def test_no_seed_is_todays_mesh_bit_for_bit(build):
    a, b = build(), build(None)
    for x, y in zip(a.bodies, b.bodies):
        assert np.array_equal(x.nodes, y.nodes) and np.array_equal(x.triangles, y.triangles)
    assert a.mesh_seed is None and a.summary()["mesh_seed"] is None


def test_no_seed_returns_the_mesher_output_itself():
    p = get_preset("fast")
    nodes, tris = _mesh_flattened_disc(0.025, p.specimen_h_m, p, np.radians(DISC_FLAT_HALF_ANGLE_DEG))
    assert perturb_interior_nodes(nodes, tris, np.array([], int), None) is nodes
    d = specimen(disc())
    assert np.array_equal(d.nodes, nodes) and np.array_equal(d.triangles, tris)


# ---------------------------------------------------------------------------------------------------
# Realizations: reproducible, same topology/boundary/sets, valid triangles
# ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("build", [disc, cyl], ids=["disc", "cylinder"])
def test_same_seed_gives_identical_nodes(build):
    a, b = build(7), build(7)
    for x, y in zip(a.bodies, b.bodies):
        assert np.array_equal(x.nodes, y.nodes)


@pytest.mark.parametrize("build", [disc, cyl], ids=["disc", "cylinder"])
def test_different_seeds_move_interior_nodes_only(build):
    base, a, b = build(), build(1), build(2)
    s0, s1, s2 = specimen(base), specimen(a), specimen(b)
    fixed = fixed_mask(s0)
    assert np.array_equal(s1.triangles, s0.triangles) and np.array_equal(s2.triangles, s0.triangles)
    for s in (s1, s2):
        assert np.array_equal(s.nodes[fixed], s0.nodes[fixed])
        for k in s0.node_sets:
            assert np.array_equal(s.node_sets[k], s0.node_sets[k])
        for k in s0.element_sets:
            assert np.array_equal(s.element_sets[k], s0.element_sets[k])
    # every free node moves (no move was dropped here) and differently under the two seeds
    assert np.all(np.any(s1.nodes[~fixed] != s0.nodes[~fixed], axis=1))
    assert np.all(np.any(s1.nodes[~fixed] != s2.nodes[~fixed], axis=1))
    for name in (base.incident_bar, base.transmission_bar):  # the bars are not touched
        assert np.array_equal(a.body(name).nodes, base.body(name).nodes)


def _reference_realization(nodes, tris, fixed, mesh_seed):
    """perturb_interior_nodes as written first, in NumPy, node after node: the compiled loop must give
    its nodes bit for bit (the meshes, and so every recorded curve, did not change with it)."""
    from shpb.meshing import MAX_HALVINGS, _draws_in_unit_disc

    move = _draws_in_unit_disc(np.random.default_rng(mesh_seed), len(nodes))
    move *= (MESH_JITTER * _shortest_edge_at_nodes(nodes, tris))[:, None]
    floor = MIN_ANGLE_KEEP * float(_min_angles(nodes, tris).min())
    order = np.argsort(tris.ravel(), kind="stable")
    star = np.split(order // 3, np.cumsum(np.bincount(tris.ravel(), minlength=len(nodes)))[:-1])
    out = np.array(nodes, dtype=np.float64, copy=True)
    for i in np.flatnonzero(~fixed):
        old = out[i].copy()
        for k in range(MAX_HALVINGS + 1):
            out[i] = old + move[i] * 0.5**k
            if _min_angles(out, tris[star[i]]).min() >= floor:
                break
        else:
            out[i] = old
    return out


@pytest.mark.parametrize("preset", ["fast", "standard"])
def test_the_compiled_realization_is_the_numpy_one_bit_for_bit(preset):
    p = get_preset(preset)
    nodes, tris = _mesh_flattened_disc(0.025, p.specimen_h_m, p, np.radians(DISC_FLAT_HALF_ANGLE_DEG))
    keep = np.array([0, 5, 17])
    fixed = _boundary_nodes(tris, len(nodes))
    fixed[keep] = True
    for seed in (1, 2, 664916189):
        ref = _reference_realization(nodes, tris, fixed, seed)
        got = perturb_interior_nodes(nodes, tris, keep, seed)
        assert np.array_equal(got, ref), seed
        assert np.count_nonzero(np.any(got != nodes, axis=1)) > 0.5 * np.count_nonzero(~fixed)


@pytest.mark.parametrize("build", [disc, cyl], ids=["disc", "cylinder"])
def test_realizations_keep_valid_triangles_and_the_area(build):
    s0 = specimen(build())
    area0 = _signed_areas(s0.nodes, s0.triangles).sum()
    min0 = _min_angles(s0.nodes, s0.triangles).min()
    radius = MESH_JITTER * _shortest_edge_at_nodes(s0.nodes, s0.triangles)
    for seed in SEEDS:
        s = specimen(build(seed))
        a = _signed_areas(s.nodes, s.triangles)
        assert a.min() > 0.0, seed
        assert _min_angles(s.nodes, s.triangles).min() >= MIN_ANGLE_KEEP * min0, seed
        assert abs(a.sum() / area0 - 1.0) < 1e-12, seed
        assert np.all(np.linalg.norm(s.nodes - s0.nodes, axis=1) <= radius * (1 + 1e-12)), seed


def test_moves_fill_the_disc_of_the_jitter_radius():
    """The draw is uniform in the disc: mean |move|/radius 2/3, both directions, no bias."""
    s0, s = specimen(disc()), specimen(disc(11))
    free = ~fixed_mask(s0)
    r = (MESH_JITTER * _shortest_edge_at_nodes(s0.nodes, s0.triangles))[free]
    d = (s.nodes - s0.nodes)[free] / r[:, None]
    n = len(d)
    assert np.mean(np.hypot(d[:, 0], d[:, 1])) == pytest.approx(2 / 3, abs=4 * 0.24 / np.sqrt(n))
    assert np.all(np.abs(d.mean(axis=0)) < 4 * 0.5 / np.sqrt(n))


def test_bad_seeds_and_jitter_are_rejected():
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(ValueError, match="mesh_seed"):
            disc(bad)
    with pytest.raises(ValueError, match="jitter"):
        disc(1, mesh_jitter=0.5)


def test_cli_rejects_a_negative_mesh_seed(tmp_path, capsys):
    assert main(["simulate", "--geometry", "brazilian_disc", "--mesh-seed", "-1", "--out", str(tmp_path)]) == 2
    assert "mesh_seed" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------
# Physics: the elastic response does not depend on the realization
# ---------------------------------------------------------------------------------------------------

def test_elastic_part_of_the_disc_curve_is_the_same_on_perturbed_meshes(tmp_path):
    """fast preset, the twin's truth (45 MPa, 500 J/m^2): the unperturbed mesh and two realizations.

    The elastic part is the curve before the first joint reaches its strength in any of the three
    runs (run.json's ``fracture.first_joint_t_s``, about 70 us of the 160). Tolerance: 1 % of the
    unperturbed failure peak, the twin experiment's observation noise (config twin_ref); a mesh whose
    elastic response moved by more would put a mesh effect at the level of the data's noise.
    Measured (2026-11-25): at most 0.06 % of the peak.
    """
    params = {"sigma_t": 45e6, "E_t": 500.0}
    runs = {s: simulate("brazilian_disc", "fast", params, t_end=1.6e-4, sample_dt=5e-7, mesh_seed=s,
                        out_dir=tmp_path / f"seed_{s}")
            for s in (None, 1, 2)}
    for s, out in runs.items():
        assert out.run["status"] == "ok", out.run["reason"]
        assert json.loads((tmp_path / f"seed_{s}" / "run.json").read_text())["mesh_seed"] == s
    t_elastic = min(out.run["fracture"]["first_joint_t_s"] for out in runs.values())
    assert 40e-6 < t_elastic < 100e-6
    grid = np.arange(0.0, t_elastic, 1e-6)
    peak = runs[None].run["fracture"]["peak_stress_Pa"]
    curves = {s: np.interp(grid, out.curve["time_s"], out.curve["stress_Pa"]) for s, out in runs.items()}
    assert curves[None][-1] > 0.3 * peak  # the window covers a good part of the rise
    for s in (1, 2):
        assert np.max(np.abs(curves[s] - curves[None])) < 0.01 * peak, s
        assert not np.array_equal(curves[s], curves[None])  # the mesh did change
