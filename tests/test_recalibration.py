"""The location recalibration of the reported emulator posterior (``emulated.recalibrate: location``,
enkf.selfcal): the pseudo-runs' PITs read off the reported sample against exact answers, and the map that
moves the sample."""

import numpy as np
import pytest
from scipy import stats

from enkf.ces import emulator_posterior
from enkf.covariance import DiagonalError
from enkf.selfcal import location_shift, pseudo_pits, recalibrated
from tests.test_selfcal import HI, LO, M, NOISE, SMOOTHING, T, error_model, stand_in


def test_the_map_takes_each_quantile_from_the_level_the_shift_names():
    rng = np.random.default_rng(3)
    S = rng.multivariate_normal([0.0, 1.0], [[1.0, 0.6], [0.6, 2.0]], 20000)
    mu = np.array([0.5, -0.25])
    out = recalibrated(S, mu)
    levels = np.array([0.05, 0.25, 0.5, 0.75, 0.95])
    for j in range(2):
        # by construction: the moved draws' q-quantile is the original's Phi(mu + Phi^-1(q))-quantile, up
        # to the interpolation between neighbouring draws (a few thousandths of an sd here)
        want = np.quantile(S[:, j], stats.norm.cdf(mu[j] + stats.norm.ppf(levels)), method="hazen")
        assert np.quantile(out[:, j], levels) == pytest.approx(want, abs=0.01)
        # each parameter's draws keep their order, so the joint's dependence stays
        assert stats.spearmanr(S[:, j], out[:, j])[0] == pytest.approx(1.0)
    # a Gaussian's shift by mu sd: the mean moves by mu times its sd
    assert out.mean(axis=0) - S.mean(axis=0) == pytest.approx(mu * S.std(axis=0), abs=0.03)
    # no shift moves no draw
    assert np.allclose(recalibrated(S, np.zeros(2)), S, rtol=0.0, atol=1e-12)


def test_the_mean_probit_of_uniform_pits_is_zero_and_a_shifted_one_is_its_shift():
    u = (np.arange(1000) + 0.5) / 1000
    assert location_shift(np.column_stack([u, stats.norm.cdf(stats.norm.ppf(u) + 0.3)])) == pytest.approx(
        [0.0, 0.3], abs=0.01)
    # a run at the box's edge (PIT 0) counts as the clip's probit, not as minus infinity
    assert np.isfinite(location_shift(np.array([[0.0], [0.5]])))


def test_a_gaussian_pseudo_runs_pit_is_read_exactly_on_the_quasi_random_grid():
    # pseudo-run i: deviance (x - m_i)^2 / s^2 on the box [-4, 4], so its posterior at temperature lam is
    # N(m_i, s^2 lam) (the box cuts nothing) and the PIT of its own parameter x_i is exact
    from scipy.stats import qmc

    lam, s = 4.0, 0.4
    points = qmc.scale(qmc.Sobol(1, scramble=True, seed=4).random(2**14), [-4.0], [4.0])
    cases = ((0.3, 0.0), (-0.5, 0.2), (1.0, 0.9), (-2.0, -0.8))
    runs = [(np.array([x]), lambda P, m=m: (P[:, 0] - m) ** 2 / s**2) for x, m in cases]
    pits, ess = pseudo_pits(runs, lam, points)
    exact = [stats.norm.cdf((x - m) / (s * np.sqrt(lam))) for x, m in cases]
    # 2^14 points over 10 sd of the posterior: a CDF to well under 0.005
    assert pits[:, 0] == pytest.approx(exact, abs=0.005)
    assert np.all(ess > 1000)


def _grid_pit(deviance, x, lam, n=201):
    """The exact PIT of ``x`` under exp(-deviance / 2 lam) on the unit box, on an n x n grid."""
    g = (np.arange(n) + 0.5) / n
    G = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    dev = deviance(G)
    w = np.exp(-0.5 * (dev - dev.min()) / lam)
    w /= w.sum()
    return np.array([np.sum(w[G[:, j] < x[j]]) for j in range(2)])


def test_the_pseudo_runs_pits_read_off_the_sample_match_their_exact_posteriors():
    X, Y, latest, d, truth, _ = stand_in(7, 0.4)
    R = DiagonalError(np.full(M, NOISE))
    post = emulator_posterior(X, Y, latest, d, R, lower=LO, upper=HI, times=T, smoothing=SMOOTHING, walkers=16,
                              min_steps=2000, rng=np.random.default_rng(1), self_calibrate=True,
                              recalibrate="location")
    rec = post.diagnostics["emulator_error"]["self_calibration"]["recalibration"]
    lam = post.diagnostics["emulator_error"]["self_calibration"]["lambda"]
    # the same pseudo-runs (the same random stream), kept this time, and each one's exact PIT on a grid
    from enkf.selfcal import self_calibration

    kept = []
    self_calibration(X, Y, latest, R, lower=LO, upper=HI, smoothing=SMOOTHING, error_model=error_model,
                     rng=np.random.default_rng(1), keep_runs=kept)
    exact = np.array([_grid_pit(dev, x, lam) for x, dev in kept])
    mu_exact = location_shift(exact)
    # the recalibration's mu (a quasi-random grid of 2^14 points) against a regular 201 x 201 grid's:
    # within a few hundredths of a probit, where the pseudo-runs' own spread (the mean of 12) is ~0.3
    assert list(rec["mu"].values()) == pytest.approx(mu_exact, abs=0.03)
    assert rec["effective_points_min"] > 100


def test_the_recalibrated_sample_is_the_plain_one_moved_and_the_default_is_unchanged():
    X, Y, latest, d, truth, _ = stand_in(7, 0.4)
    R = DiagonalError(np.full(M, NOISE))
    kw = dict(lower=LO, upper=HI, times=T, smoothing=SMOOTHING, walkers=16, min_steps=2000, self_calibrate=True)
    plain = emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), **kw)
    moved = emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), recalibrate="location", **kw)
    assert "recalibration" not in plain.diagnostics["emulator_error"]["self_calibration"]
    mu = np.array(list(moved.diagnostics["emulator_error"]["self_calibration"]["recalibration"]["mu"].values()))
    assert np.allclose(moved.samples, recalibrated(plain.samples, mu))
    with pytest.raises(ValueError, match="recalibrate"):
        emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), recalibrate="scale", **kw)
    with pytest.raises(ValueError, match="power form"):
        emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), recalibrate="location",
                           **{**kw, "self_calibrate": False})


def test_the_config_switch_reaches_the_spec():
    from calibration.experiment import ExperimentSpec
    from tests._shipped import twin_ref

    assert ExperimentSpec.from_config("twin_ref", twin_ref()).recalibrate == "none"
    assert ExperimentSpec.from_config("twin_ref", twin_ref(emulated={"recalibrate": "location"})).recalibrate == "location"


def test_the_refinement_batch_is_designed_without_the_recalibration(monkeypatch):
    # the batch is where the runs go, not a reported interval: the same whatever emulated.recalibrate says,
    # so that a form scored on kept runs (bench_coverage --keep-runs) is what the workflow would report
    import calibration.posterior as cp
    from calibration.experiment import ExperimentSpec
    from tests._shipped import twin_ref

    spec = ExperimentSpec.from_config("twin_ref", twin_ref(emulated={"recalibrate": "location"}))
    seen = {}

    class Drawn:
        samples = np.random.default_rng(0).uniform(spec.lower, spec.upper, (400, 2))

    def sample_posterior(spec, params, responses, last_analysis, obs, refine=None, *, temper=1.0, recalibrate=None):
        seen.update(temper=temper, recalibrate=recalibrate)
        return Drawn

    monkeypatch.setattr(cp, "sample_posterior", sample_posterior)
    design = cp.refine_design(spec, [], [], {}, None)
    assert seen == {"temper": spec.refine_temper, "recalibrate": "none"} and len(design) == spec.refine_runs
