"""Cohesive joints: fracture energy per mode, the softening integral, mixed-mode coupling, irreversibility."""
import numpy as np
import pytest

from fdem import Body, JointParams, Material, VelocityBC, build_model, run
from fdem.kernels import joint_forces
from fdem.state import joint_state, joints_of
from fdem.softening import A0, z, z_numpy

GRANITE = Material(35e9, 0.16, 2550.0)
L = 1e-3        # joint length [m]
THICK = 0.01    # thickness [m]


def _two_triangles(jp):
    # Triangle A left of the shared edge x = 0, triangle B right of it.
    nodes = np.array([[0.0, 0.0], [0.0, L], [-0.8 * L, 0.5 * L], [0.8 * L, 0.5 * L]])
    tris = np.array([[0, 2, 1], [0, 1, 3]])
    return build_model([Body("pair", nodes, tris, GRANITE, THICK, fracturable=True)],
                       joints={"pair": jp})


def _pull(jp, direction, speed=0.05):
    """Move triangle B rigidly away (direction 0: mode I) or along the joint (1: mode II)."""
    model = _two_triangles(jp)
    assert model.n_joints == 1
    shared = np.nonzero(np.abs(model.x0[:, 0]) < 1e-12)[0]
    nodes_A = model.tri[0]
    nodes_B = model.tri[1]
    delta = jp.delta_n_max if direction == 0 else jp.delta_t_max
    t_end = 1.3 * delta / speed
    hist_t = np.array([0.0, 1.0])
    bcs = [VelocityBC(nodes_A, 0, hist_t, np.zeros(2)), VelocityBC(nodes_A, 1, hist_t, np.zeros(2)),
           VelocityBC(nodes_B, direction, hist_t, np.full(2, speed)),
           VelocityBC(nodes_B, 1 - direction, hist_t, np.zeros(2))]
    res = run(model, t_end, velocity_bcs=bcs, sample_dt=t_end / 200)
    assert res.status == "ok"
    assert shared.size == 4
    return model, res


@pytest.mark.parametrize("abc", [(0.63, 1.8, 6.0), (0.5, 1.5, 4.0)])
@pytest.mark.parametrize("mode", ["I", "II"])
def test_joint_dissipates_its_fracture_energy(abc, mode):
    a, b, c = abc
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=300.0, a=a, b=b, c=c)
    model, res = _pull(jp, 0 if mode == "I" else 1)
    area = L * THICK
    dissipated = res.energy["joint_dissipated"][-1] / area
    assert res.joint_broken.all()
    E_mode = jp.E_n if mode == "I" else jp.E_t
    strength = jp.sigma_n if mode == "I" else jp.sigma_t
    k = model.kn[0] if mode == "I" else model.kt[0]
    # Exact for this law: the softening branch (E) plus the elastic pre-peak energy f^2 / (2k).
    exact = E_mode + strength**2 / (2.0 * k)
    assert dissipated == pytest.approx(exact, rel=0.02)
    assert dissipated == pytest.approx(E_mode, rel=0.02)
    # Energy balance: the work done pulling the joint apart went into dissipation only.
    W = res.energy["external_work"][-1] - res.energy["kinetic"][-1]
    assert res.energy["joint_dissipated"][-1] == pytest.approx(W, rel=0.02)


@pytest.mark.parametrize("abc,tabulated", [((0.63, 1.8, 6.0), 0.3863), ((0.5, 1.5, 4.0), 0.4005),
                                           ((0.3, 1.0, 6.0), 0.2786)])
def test_A0_matches_independent_quadrature(abc, tabulated):
    x = np.linspace(0.0, 1.0, 400_001)
    y = z_numpy(x, *abc)
    simpson = (x[1] - x[0]) / 3.0 * (y[0] + y[-1] + 4 * y[1:-1:2].sum() + 2 * y[2:-1:2].sum())
    assert abs(A0(*abc) - simpson) < 1e-6
    assert A0(*abc) == pytest.approx(tabulated, abs=5e-5)
    assert z(0.0, *abc) == 1.0 and abs(z_numpy(1.0, *abc)) < 1e-12


class _Joint:
    """Drive one joint quasi-statically through prescribed (opening, slip) states."""

    def __init__(self, jp):
        self.model = _two_triangles(jp)
        self.m = self.model
        self.Dmax = np.zeros(1)
        self.broken = np.zeros(1, np.bool_)
        self.nB = self.model.jn[0, 2:]
        self.nA = self.model.jn[0, :2]
        self.slip_p = np.zeros(1)
        self.kappa = np.zeros(1)
        self.zeta = np.ones(1)
        self.dissipated = 0.0
        self.stored = 0.0

    def traction(self, o, s):
        """Mean (normal, shear) traction [Pa] on side B for a uniform gap (o, s)."""
        x = self.m.x0.copy()
        # joint normal points from A to B = +x; tangent along a1->a2 = -y here (CCW of A)
        a1, a2 = self.m.x0[self.nA]
        t = (a2 - a1) / np.linalg.norm(a2 - a1)
        n = np.array([t[1], -t[0]])
        x[self.nB] += o * n + s * t
        f = np.zeros_like(x)
        self.stored, diss, _, _ = joint_forces(x, np.zeros_like(x), joints_of(self.m), joint_state(
            1, Dmax=self.Dmax, broken=self.broken, slip_p=self.slip_p, kappa=self.kappa, zeta=self.zeta), f)
        self.dissipated += diss
        F = -f[self.nB].sum(axis=0) / self.m.jarea[0]
        return float(F @ n), float(F @ t)


def test_opening_past_peak_reduces_shear_capacity_by_coupling_rule():
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=300.0)
    j = _Joint(jp)
    o_p = jp.sigma_n / j.m.kn[0]
    D1 = 0.3
    o1 = o_p + D1 * jp.delta_n_max
    sig, _ = j.traction(o1, 0.0)
    zeta = z(D1, jp.a, jp.b, jp.c)
    assert sig == pytest.approx(jp.sigma_n * zeta, rel=1e-9)
    assert j.Dmax[0] == pytest.approx(D1, rel=1e-9)
    # Hold the opening and slide: the shear stress saturates at sigma_t z(D1), not sigma_t.
    s_p = jp.sigma_t / j.m.kt[0]
    taus = [j.traction(o1, s)[1] for s in np.linspace(0.0, 1.0 * s_p, 50)]
    assert max(np.abs(taus)) == pytest.approx(jp.sigma_t * zeta, rel=1e-9)
    assert max(np.abs(taus)) < 0.6 * jp.sigma_t
    # Slipping further grows the coupled damage D = sqrt(D1^2 + (kappa / delta_t)^2), kappa the slip
    # beyond the elastic branch (plastic slip: s minus the elastic slip tau / k_t).
    ds = 0.2 * jp.delta_t_max
    _, tau = j.traction(o1, s_p + ds)
    kappa = s_p + ds - tau / j.m.kt[0]
    assert j.kappa[0] == pytest.approx(kappa, rel=1e-9)
    assert j.Dmax[0] == pytest.approx(np.hypot(D1, kappa / jp.delta_t_max), rel=1e-9)
    # kappa exceeds ds by the elastic slip given up, (1 - zeta) sigma_t / k_t: 0.3 % of ds here
    assert kappa / jp.delta_t_max == pytest.approx(0.2, rel=5e-3)


def test_shear_slip_is_plastic_so_a_compression_slip_cycle_dissipates():
    """Slide out under light compression, squeeze, slide back under strong compression, release. A
    secant shear cap that follows the Mohr-Coulomb capacity, tau = f_s(sigma_c) sign(s), would push the
    joint back with the strong-compression capacity after resisting with the light one, returning
    more work than it took; plastic slip resists in both directions."""
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=3000.0, friction_angle_deg=50.0)
    j = _Joint(jp)
    kn = j.m.kn[0]
    o_hi, o_lo = -60e6 / kn, -1e6 / kn
    s_max = 0.05 * jp.delta_t_max
    path = ([(o_lo * u, 0.0) for u in np.linspace(0, 1, 20)]
            + [(o_lo, s) for s in np.linspace(0, s_max, 200)]
            + [(o_lo + (o_hi - o_lo) * u, s_max) for u in np.linspace(0, 1, 50)]
            + [(o_hi, s) for s in np.linspace(s_max, 0, 200)]
            + [(o_hi + (o_lo - o_hi) * u, 0.0) for u in np.linspace(0, 1, 50)])
    work = 0.0
    prev_t, prev_g = j.traction(*path[0]), np.array(path[0])
    stored0, diss0 = j.stored, j.dissipated
    for g in path[1:]:
        t = j.traction(*g)
        # work done on the joint: mean traction x gap increment (per unit area)
        work += 0.5 * (np.array(t) + np.array(prev_t)) @ (np.array(g) - prev_g)
        prev_t, prev_g = t, np.array(g)
    area = j.m.jarea[0]
    dissipated = (j.dissipated - diss0) / area
    # all the work went into dissipation (the path ends where it started; the residual elastic slip
    # energy is what the joint still stores)
    assert work == pytest.approx(dissipated + (j.stored - stored0) / area, rel=0.01)
    # ... and the joint took work in both directions: sliding back under 60 MPa compression costs the
    # frictional capacity f = sigma_t + tan(phi) 60 MPa (the secant cap would have returned it)
    f_hi = jp.sigma_t + np.tan(np.radians(50.0)) * 60e6
    assert work > 0.8 * f_hi * s_max


def test_unloading_and_reloading_does_not_restore_strength():
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=300.0)
    j = _Joint(jp)
    o_p = jp.sigma_n / j.m.kn[0]
    o1 = o_p + 0.25 * jp.delta_n_max
    j.traction(o1, 0.0)
    zeta = z(0.25, jp.a, jp.b, jp.c)
    # Unload to closed, reload in tension: the peak is the damaged strength sigma_n z(0.25).
    assert j.traction(0.0, 0.0)[0] == 0.0
    reload = [j.traction(o, 0.0)[0] for o in np.linspace(0.0, o1, 200)]
    assert max(reload) == pytest.approx(jp.sigma_n * zeta, rel=1e-9)
    assert max(reload) < 0.8 * jp.sigma_n
    # Damage never decreases.
    assert j.Dmax[0] == pytest.approx(0.25, rel=1e-9)
    # Compression is carried undamaged by the penalty.
    sig_c, _ = j.traction(-o_p, 0.0)
    assert sig_c == pytest.approx(-jp.sigma_n, rel=1e-9)


def test_mohr_coulomb_term_raises_shear_strength_under_compression():
    phi = 30.0
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=300.0, friction_angle_deg=phi)
    j = _Joint(jp)
    o_c = -0.5 * jp.sigma_n / j.m.kn[0]          # 4 MPa compression
    s_max = 3 * jp.sigma_t / j.m.kt[0]
    taus = [abs(j.traction(o_c, s)[1]) for s in np.linspace(0, s_max, 400)]
    expected = jp.sigma_t + np.tan(np.radians(phi)) * 4e6
    assert max(taus) == pytest.approx(expected, rel=2e-3)


def test_rate_dependent_strength_raises_the_peak_by_the_DIF_and_keeps_the_fracture_energy():
    k_rate = 0.3
    jp = JointParams(sigma_n=8e6, sigma_t=20e6, E_n=60.0, E_t=300.0, rate_k=k_rate, rate0=1.0)
    j = _Joint(jp)
    m = j.m
    h = m.jrate[0, 0]
    V = 2.0  # opening velocity [m/s] -> rate V / h
    dif = 1.0 + k_rate * np.log10(V / h)
    a1, a2 = m.x0[j.nA]
    t = (a2 - a1) / np.linalg.norm(a2 - a1)
    n = np.array([t[1], -t[0]])
    vel = np.zeros_like(m.x0)
    vel[j.nB] = V * n
    o_p = jp.sigma_n / m.kn[0]

    def traction(o):
        x = m.x0.copy()
        x[j.nB] += o * n
        f = np.zeros_like(x)
        jdif = j.jdif
        joint_forces(x, vel, joints_of(m), joint_state(1, Dmax=j.Dmax, broken=j.broken, dif=jdif,
                                                       slip_p=j.slip_p, kappa=j.kappa, zeta=j.zeta), f)
        return float((-f[j.nB].sum(axis=0) / m.jarea[0]) @ n)

    j.jdif = np.ones(1)
    # still elastic just below the raised strength; the static strength would have capped it
    assert traction(0.999 * dif * o_p) == pytest.approx(0.999 * dif * jp.sigma_n, rel=1e-9)
    assert j.Dmax[0] == 0.0
    # just past it: damage starts, the DIF is frozen, the traction is the dynamic strength
    assert traction(1.0001 * dif * o_p) == pytest.approx(dif * jp.sigma_n, rel=1e-3)
    assert j.jdif[0] == pytest.approx(dif, rel=1e-12)
    # the same joint pulled apart still dissipates E_n (softening displacement shrinks by the DIF)
    model, res = _pull(jp, 0, speed=V)
    dissipated = res.energy["joint_dissipated"][-1] / (L * THICK)
    assert dissipated == pytest.approx(jp.E_n, rel=0.02)


def test_the_stored_default_area_is_the_quadrature_bit_for_bit():
    """A0 of the default curve is stored (importing scipy.integrate was half of a simulation's start-up):
    it must be the very float the quadrature gives, so that no answer moves."""
    from scipy.integrate import quad

    from fdem.softening import A0_DEFAULT, DEFAULT_A, DEFAULT_B, DEFAULT_C

    val, _ = quad(lambda x: float(z_numpy(x, DEFAULT_A, DEFAULT_B, DEFAULT_C)), 0.0, 1.0, epsabs=1e-13, epsrel=1e-12)
    assert A0_DEFAULT == val and A0(DEFAULT_A, DEFAULT_B, DEFAULT_C) == val
