"""The heteroscedastic emulated likelihood (enkf.hetero): exact algebra, the scale it learns from runs,
and the coverage it restores where the simulator's scatter differs across the box."""

import numpy as np
import pytest
from scipy import linalg

from enkf.covariance import AR1Error
from enkf.hetero import HeteroscedasticError

M = 60
T = np.arange(M) * 1e-6


def _ar1(rng, n, tau=5e-6):
    return AR1Error(np.ones(M), T, tau).color(rng.standard_normal((M, n))).T


def _noise_sd(u0):
    """The runs' scatter: 3 times larger (9 times the variance) in the lower half of parameter 0."""
    return np.where(np.asarray(u0) < 0.5, 3.0, 1.0)


def test_parts_is_the_dense_gaussian_deviance():
    rng = np.random.default_rng(1)
    B = 0.3 * np.eye(M)
    C_em = AR1Error(np.linspace(0.5, 2.0, M), T, 4e-6).dense()
    U = rng.uniform(size=(30, 2))
    het = HeteroscedasticError(B, C_em, U, _ar1(rng, 30) * _noise_sd(U[:, 0])[:, None])
    P = rng.uniform(size=(5, 2))
    r = rng.standard_normal((5, M))
    quad, logdet = het.parts(r, P)
    _, logdet_B = np.linalg.slogdet(B)
    for i, a in enumerate(het.scale(P)):
        C = B + a * C_em
        assert quad[i] == pytest.approx(float(r[i] @ linalg.solve(C, r[i])), rel=1e-9)
        assert logdet[i] == pytest.approx(np.linalg.slogdet(C)[1] - logdet_B, rel=1e-9)


def test_learns_a_planted_step_in_the_scatter():
    rng = np.random.default_rng(2)
    U = rng.uniform(size=(200, 2))
    res = _ar1(rng, 200) * _noise_sd(U[:, 0])[:, None]
    C_em = AR1Error(np.ones(M), T, 5e-6).dense()  # the scatter's shape, at the calm half's size
    het = HeteroscedasticError(0.1 * np.eye(M), C_em, U, res)
    assert het.bandwidth is not None and np.isfinite(het.bandwidth)
    a_noisy, a_calm = het.scale(np.array([[0.15, 0.5], [0.85, 0.5]]))
    assert a_noisy == pytest.approx(9.0, rel=0.3)
    assert a_calm == pytest.approx(1.0, rel=0.3)


def test_keeps_one_scale_when_the_scatter_is_alike():
    rng = np.random.default_rng(3)
    U = rng.uniform(size=(120, 2))
    het = HeteroscedasticError(0.1 * np.eye(M), AR1Error(np.ones(M), T, 5e-6).dense(), U, _ar1(rng, 120))
    a = het.scale(rng.uniform(size=(50, 2)))
    assert np.all(np.abs(a - 1.0) < 0.3)


def _coverage(rng, het_model: bool, truths: int = 80, grid: int = 41):
    """90 % marginal coverage of parameter 0 over truths in the noisy half, on a stand-in whose runs
    scatter 3 times more there: mean curve mu(theta) known exactly (no emulator error but the scatter).
    ``C_em`` is the calm half's, as when the last iteration's runs sit there (the development twins whose
    ``E_t`` missed: their runs had moved to tougher, calmer points than the truth)."""
    shape = np.exp(-((T - 30e-6) / 12e-6) ** 2)

    def mu(P):
        P = np.atleast_2d(P)
        return P[:, :1] * 20.0 * shape + P[:, 1:2] * 2.0 * (T / T[-1])

    U = rng.uniform(size=(150, 2))
    res = _ar1(rng, 150) * _noise_sd(U[:, 0])[:, None]
    B = 0.05 * np.eye(M)
    C_all = AR1Error(np.ones(M), T, 5e-6).dense()
    het = HeteroscedasticError(B, C_all, U, res)
    L = linalg.cholesky(B + C_all, lower=True)
    axis = np.linspace(0, 1, grid)
    G = np.array(np.meshgrid(axis, axis, indexing="ij")).reshape(2, -1).T
    inside = 0
    for _ in range(truths):
        truth = np.array([rng.uniform(0.05, 0.4), rng.uniform()])
        d = mu(truth)[0] + _noise_sd(truth[0]) * _ar1(rng, 1)[0] + np.sqrt(0.05) * rng.standard_normal(M)
        r = mu(G) - d
        if het_model:
            dev = np.sum(het.parts(r, G), axis=0)
        else:
            w = linalg.solve_triangular(L, r.T, lower=True)
            dev = np.sum(w * w, axis=0)
        post = np.exp(-0.5 * (dev - dev.min())).reshape(grid, grid).sum(axis=1)
        c = np.cumsum(post) / post.sum()
        inside += np.interp(0.05, c, axis) <= truth[0] <= np.interp(0.95, c, axis)
    return inside / truths


def test_restores_coverage_where_the_runs_scatter_most():
    # the calm half's covariance under-covers where the simulator scatters most (0.34-0.51 over ten
    # seeds); the local scale restores it (0.875-0.975, mean 0.93). 80 truths: a calibrated 0.90 lies in
    # 0.80-0.98 with probability 0.99
    assert _coverage(np.random.default_rng(4), het_model=False) < 0.75
    assert 0.80 <= _coverage(np.random.default_rng(4), het_model=True) <= 0.98


def test_a_twin_takes_it_on_request_and_bad_settings_are_named():
    from calibration.experiment import ExperimentSpec
    from tests._shipped import twin_ref

    assert ExperimentSpec.from_config("twin_ref", twin_ref()).emulator_error == "ar1"
    exp = twin_ref(emulated={"emulator_error": "heteroscedastic"})
    assert ExperimentSpec.from_config("twin_ref", exp).emulator_error == "heteroscedastic"
    with pytest.raises(Exception, match="emulator_error"):
        twin_ref(emulated={"emulator_error": "smooth"})
    with pytest.raises(Exception, match="emulated.emulator_error: 'heteroscedastic' is a setting of the reported emulator "
                                        "posterior, which posterior: ensemble does not use"):
        twin_ref(emulated={"emulator_error": "heteroscedastic"}, posterior="ensemble")


def test_the_emulator_mcmc_samples_the_heteroscedastic_posterior():
    # a linear stand-in whose runs scatter 3 times more in the lower half of p: the MCMC's marginal of p
    # matches the grid posterior of the same likelihood (enkf.hetero's deviance), within the sampler's
    # error (1.5 % of the box in the quantiles, a few hundred effective samples)
    from enkf.ces import emulator_posterior

    rng = np.random.default_rng(5)
    X = rng.uniform(size=(120, 2))
    shape = np.exp(-((T - 30e-6) / 12e-6) ** 2)
    Y = X[:, :1] * 20.0 * shape + X[:, 1:2] * 2.0 * (T / T[-1]) + _ar1(rng, 120) * _noise_sd(X[:, 0])[:, None]
    latest = X[:, 0] > 0.5
    d = 0.2 * 20.0 * shape + 0.5 * 2.0 * (T / T[-1]) + 3.0 * _ar1(rng, 1)[0]
    R = AR1Error(np.full(M, 0.2), T, 0.0)
    post = emulator_posterior(X, Y, latest, d, R, lower=np.zeros(2), upper=np.ones(2), times=T, rng=6,
                              names=["p", "q"], smoothing=1.0, heteroscedastic=True)
    info = post.diagnostics["emulator_error"]["heteroscedastic"]
    assert info["bandwidth"] is not None
    # the same likelihood on a grid, from the emulator and error terms the sampler used
    from enkf.emulated import emulator_error_model
    from enkf.emulator import CurveEmulator

    em = CurveEmulator(X, Y, np.zeros(2), np.ones(2), smoothing=1.0)
    het = HeteroscedasticError(R.dense(), emulator_error_model(em.loo_residuals()[latest], T)[0].dense(), X,
                               em.loo_residuals())
    axis = np.linspace(0, 1, 101)
    G = np.array(np.meshgrid(axis, axis, indexing="ij")).reshape(2, -1).T
    dev = np.sum(het.parts(em(G) - d, G), axis=0)
    marg = np.exp(-0.5 * (dev - dev.min())).reshape(101, 101).sum(axis=1)
    c = np.cumsum(marg) / marg.sum()
    for q in ("q05", "q50", "q95"):
        exact = np.interp(float(q[1:]) / 100, c, axis)
        assert post.summary["p"][q] == pytest.approx(exact, abs=0.015)
