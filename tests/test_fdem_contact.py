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
