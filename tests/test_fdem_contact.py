"""Penalty contact: momentum, penetration, restitution of an elastic impact."""
import numpy as np
import pytest

from fdem import Body, ContactParams, Material, build_model, run
from fdem import meshing

STEEL = Material(200e9, 0.29, 7850.0)


@pytest.mark.parametrize("ny_b,penalty_factor", [(5, 1.0), (4, 3.0)])
def test_colliding_elastic_bars_conserve_momentum_and_exchange_velocity(ny_b, penalty_factor):
    """Two equal slender bars, one at rest: 1D wave theory predicts a full velocity exchange.

    ny_b = 5 gives face nodes exactly opposite each other (the hardest case for node-to-edge
    contact); ny_b = 4 gives non-matching faces.
    """
    h = 0.002
    n1, t1 = meshing.rectangle(0.0, 0.0, 0.2, 0.01, 100, 5, pattern="alternate")
    n2, t2 = meshing.rectangle(0.2 + 1e-6, 0.0, 0.2, 0.01, 100, ny_b, pattern="alternate")
    model = build_model([Body("A", n1, t1, STEEL, 0.01), Body("B", n2, t2, STEEL, 0.01)],
                        contact=ContactParams(penalty=penalty_factor * STEEL.E))
    v0 = np.zeros_like(model.x0)
    v0[model.node_body == 0, 0] = 1.0
    c0 = np.sqrt(STEEL.E / STEEL.rho)
    res = run(model, 3 * 0.2 / c0, v_init=v0, sample_dt=1e-7)
    assert res.status == "ok"
    P0 = (model.mass[:, None] * v0).sum(axis=0)
    P1 = (model.mass[:, None] * res.v).sum(axis=0)
    assert np.max(np.abs(P1 - P0)) / abs(P0[0]) < 1e-10
    # Contact forces on the two bodies are equal and opposite at every sample.
    bf = res.body_force
    assert np.max(np.abs(bf[:, 0, :] + bf[:, 1, :])) <= 1e-9 * np.max(np.abs(bf))
    assert np.max(np.abs(bf[:, 0, 0])) > 0  # they did touch
    # Penetration tolerance: 0.1% of the element size.
    assert res.penetration.max() < 1e-3 * h
    KE0 = 0.5 * np.sum(model.mass * (v0**2).sum(axis=1))
    rigid_ke = []
    for b in (0, 1):
        sel = model.node_body == b
        M = model.mass[sel].sum()
        vc = (model.mass[sel, None] * res.v[sel]).sum(axis=0) / M
        rigid_ke.append(0.5 * M * vc @ vc)
    assert rigid_ke[1] / KE0 >= 0.95   # the struck bar leaves with >= 95% of the kinetic energy
    assert rigid_ke[0] / KE0 < 0.01    # the striker stops
    assert abs(res.energy_balance_error()[-1]) < 0.01 * KE0


def test_pair_penalty_table_is_symmetric_and_softens_one_interface():
    c = ContactParams(penalty=2e11, pair_penalty={("A", "C"): 1e9})
    t = c.table(["A", "B", "C"])
    assert t[0, 2] == t[2, 0] == 1e9
    assert t[0, 1] == t[1, 2] == t[1, 1] == 2e11
    with pytest.raises(KeyError, match="unknown bodies"):
        ContactParams(penalty=1.0, pair_penalty={("A", "Z"): 1.0}).table(["A"])


def _sliding_friction_ratio(friction, pair_friction):
    """A granite block pressed on a fixed base (10 MPa, 1 kN) and dragged along it: tangential over
    normal contact force on the base while it slides (60-150 us)."""
    from fdem import TractionBC, VelocityBC

    granite = Material(35e9, 0.16, 2550.0)
    t = 0.01
    nb, tb = meshing.rectangle(0.0, 0.0, 0.04, 0.005, 20, 3, pattern="alternate")
    nk, tk = meshing.rectangle(0.015, 0.005 + 1e-7, 0.01, 0.004, 8, 3, pattern="alternate")
    model = build_model([Body("base", nb, tb, granite, t), Body("block", nk, tk, granite, t)],
                        contact=ContactParams(penalty=2 * granite.E, friction=friction,
                                              pair_friction=pair_friction))
    x0 = model.x0
    bottom = np.flatnonzero((model.node_body == 0) & (x0[:, 1] < 1e-9))
    block = np.flatnonzero(model.node_body == 1)
    top = block[x0[block, 1] > x0[block, 1].max() - 1e-9]
    area = np.full(top.size, 0.01 * t / (top.size - 1))
    area[[0, -1]] *= 0.5
    T = 150e-6
    hold = (np.array([0.0, T]), np.zeros(2))
    bcs = [VelocityBC(bottom, 0, *hold), VelocityBC(bottom, 1, *hold),
           # every block node is dragged (a rigid translation in x), so the block cannot tip
           VelocityBC(block, 0, np.array([0.0, 40e-6, 60e-6, T]), np.array([0.0, 0.0, 0.5, 0.5]))]
    press = TractionBC(top, 1, area, np.array([0.0, 30e-6, T]), np.array([0.0, -10e6, -10e6]))
    res = run(model, T, velocity_bcs=bcs, traction_bcs=[press], sample_dt=1e-6)
    assert res.status == "ok"
    F = res.body_force_of("base")
    sliding = res.time > 60e-6
    assert np.mean(-F[sliding, 1]) == pytest.approx(1000.0, rel=0.1)  # the block is pressed on
    return np.sum(np.abs(F[sliding, 0])) / np.sum(np.abs(F[sliding, 1]))


def test_sliding_contact_carries_coulomb_friction_of_its_own_body_pair():
    """Coulomb's law, F_t = mu F_n while sliding, with the coefficient of the touching pair of bodies:
    a pair value overrides the default, and a body's own crack-face coefficient ((body, body), the
    FDEM model's mu_crack) does not reach its interface with another body. Tolerance 2 %: the normal
    force rings by about 10 % as the block is dragged, and the sum over the window averages it
    (measured: 0.594 for 0.6, 0.09999 for 0.1)."""
    assert _sliding_friction_ratio(0.1, {("base", "block"): 0.6}) == pytest.approx(0.6, rel=0.02)
    assert _sliding_friction_ratio(0.6, {("base", "block"): 0.1}) == pytest.approx(0.1, rel=0.02)
    assert _sliding_friction_ratio(0.6, {("block", "block"): 0.1}) == pytest.approx(0.6, rel=0.02)


def test_disc_model_gives_crack_faces_and_bar_faces_their_own_friction():
    """shpb's disc: (disc, disc) is mu_crack, (bar, disc) is interface_friction.mu."""
    from shpb.simulate import build

    setup = build("brazilian_disc", "fast", {"mu_crack": 0.7, "interface_friction.mu": 0.2})
    model = setup["model"]
    table = model.contact.friction_table(model.body_names)
    g = setup["geometry"]
    d, i, t = (model.body_names.index(n) for n in (g.specimen, g.incident_bar, g.transmission_bar))
    assert table[d, d] == 0.7
    assert table[i, d] == table[d, i] == table[t, d] == 0.2


def test_the_filtered_contact_list_equals_a_fresh_search_of_a_fragmented_disc():
    """fdem.contact.refresh_pairs (candidates within two extra buffers, filtered) gives the pairs of a
    fresh search (build_pairs) in the same order, on a fast disc after its failure (crack faces
    active) whose nodes then moved: by less than half the margin (filtered from the old candidates)
    and by more (searched again). Its node normals agree on every node of a body that cannot
    fracture, the only ones the contact kernel reads."""
    from fdem.contact import build_pairs, refresh_pairs, surface_nodes
    from shpb.fracture import CHECK_POINTS
    from shpb.simulate import simulate
    out = simulate("brazilian_disc", "fast", params=dict(zip(("sigma_t", "E_t"), CHECK_POINTS["weak_brittle"])))
    m, res = out.extra["setup"]["model"], out.extra["result"]
    active = m.edge_active0.copy()
    for j in np.flatnonzero(res.Dmax > 0):
        for side in range(2):
            active[m.tri_edges[m.edge_tri[m.jedges[j, side]]]] = True
    buffer = 0.3 * float(np.min(m.edge_dlim[m.edge_active0]) * 2.0)
    margin = 2.0 * buffer
    all_edges = np.arange(m.edges.shape[0])
    edge_nodes = surface_nodes(m.edges, np.ones(m.edges.shape[0], np.bool_), m.n_nodes)
    rigid = ~m.body_fracturable[m.node_body[m.edges[:, 0]]]
    x0 = res.x.copy()
    x_cand = x0.copy()
    cand = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    rng = np.random.default_rng(1)
    for step in (0.0, 0.2, 0.9):  # node moves in units of the margin: none, filtered, searched again
        x = x0 + step * margin * rng.uniform(-0.5, 0.5, x0.shape) / np.sqrt(2.0)
        pn, pe, nrm, snodes, *cand = refresh_pairs(x, m.edges, active, m.edge_tri, m.node_vertex, m.node_body,
                                                   m.node_tri, m.tri, m.body_fracturable, buffer, margin,
                                                   cand[0], cand[1], x_cand, all_edges, edge_nodes, rigid)
        ref_snodes = surface_nodes(m.edges, active, m.n_nodes)
        rn, re_, rnrm = build_pairs(x, m.edges, active, m.edge_tri, ref_snodes, m.node_vertex, m.node_body,
                                    m.node_tri, m.tri, m.body_fracturable, buffer)
        assert np.array_equal(snodes, ref_snodes)
        assert np.array_equal(pn, rn) and np.array_equal(pe, re_)
        on_rigid = ~m.body_fracturable[m.node_body]
        assert np.array_equal(nrm[on_rigid], rnrm[on_rigid])
        assert pn.size > 0 and snodes.size > 1000  # a fragmented disc, with pairs to agree on
