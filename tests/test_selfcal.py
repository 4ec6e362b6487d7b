"""The emulated likelihood's self-calibration on its own runs (enkf.selfcal), on a stand-in.

Each run of the stand-in departs from its mean curve by white noise and, in the planted case, by a
random ramp over the whole window (a departure correlated as a mesh's stiffness moves a rise). The
emulator's error model (per-time rms, one AR(1) correlation time from the lag-1 correlation) cannot
represent the ramp: it counts it as many independent departures, and the 90 % region of the emulated
likelihood holds the truth far less often than 90 %. The self-calibration sees that on the runs, with no
truth, and its factor restores the coverage; with white departures only (the AR(1) model right) it
stays near 1.
"""

import numpy as np
import pytest
from scipy import linalg, stats

from enkf.ces import emulator_posterior
from enkf.covariance import DiagonalError
from enkf.emulated import emulated_esmda_update, emulator_error_model
from enkf.emulator import CurveEmulator
from enkf.sampling import latin_hypercube
from enkf.selfcal import self_calibration

M = 40
T = np.linspace(0.0, 1.0, M)
LO, HI = np.zeros(2), np.ones(2)
NOISE = 0.05
SMOOTHING = 1e-3


def mean_curve(P):
    P = np.atleast_2d(P)
    return 10.0 * np.outer(P[:, 0], T) + 5.0 * np.outer(P[:, 1] ** 2, np.sin(3.0 * T))


def stand_in(seed: int, ramp: float):
    """A design over the box, a latest batch around the truth, the data; each run its own departure."""
    rng = np.random.default_rng(seed)

    def departure(k):
        return rng.normal(0.0, NOISE, (k, M)) + rng.normal(0.0, ramp, (k, 1)) * T[None, :]

    truth = rng.uniform(0.15, 0.85, 2)
    X = np.vstack([latin_hypercube(LO, HI, 30, rng), np.clip(truth + rng.normal(0.0, 0.08, (12, 2)), 0.01, 0.99)])
    Y = mean_curve(X) + departure(X.shape[0])
    latest = np.r_[np.zeros(30, bool), np.ones(12, bool)]
    d = mean_curve(truth)[0] + departure(1)[0] + rng.normal(0.0, NOISE, M)
    return X, Y, latest, d, truth, rng


def error_model(residuals):
    return emulator_error_model(residuals, T)[0]


def covers(seed: int, ramp: float) -> tuple[bool, bool, float]:
    """Whether the truth lies in the emulated likelihood's 90 % region, as is and at lambda; lambda."""
    X, Y, latest, d, truth, rng = stand_in(seed, ramp)
    R = DiagonalError(np.full(M, NOISE))
    em = CurveEmulator(X, Y, LO, HI, smoothing=SMOOTHING)
    L = linalg.cholesky(R.dense() + error_model(em.loo_residuals()[latest]).dense(), lower=True)
    g = np.linspace(0.0, 1.0, 61)
    G = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    chi2 = lambda P: np.sum(linalg.solve_triangular(L, (em(P) - d).T, lower=True) ** 2, axis=0)  # noqa: E731
    delta = float(chi2(truth[None, :])[0] - chi2(G).min())
    lam = self_calibration(X, Y, latest, R, lower=LO, upper=HI, smoothing=SMOOTHING, error_model=error_model,
                           rng=rng, search_points=200)["lambda"]
    q = stats.chi2.ppf(0.90, 2)
    return delta <= q, delta / lam <= q, lam


def test_the_self_calibration_restores_the_coverage_an_ar1_emulator_error_loses():
    # seeds 0-29 (ramp sd 0.4, eight times the noise): covered 9 of 30 as is, 28 of 30 at lambda (median
    # 6.5); seeds 100-119 here: 4 and 17 of 20. Bars: as is at most 10 (a calibrated 90 % region does so
    # with binomial probability ~ 1e-6), at lambda at least 15 (a calibrated one: P(>= 15) = 0.99)
    res = np.array([covers(s, 0.4) for s in range(100, 120)])
    assert res[:, 0].sum() <= 10
    assert res[:, 1].sum() >= 15
    assert np.median(res[:, 2]) > 2.0


def test_the_self_calibration_leaves_a_right_error_model_nearly_alone():
    # seeds 200-209, white departures: lambda median 1.19, 9 of 10 covered as is and at lambda
    lams = np.array([covers(s, 0.0)[2] for s in range(200, 210)])
    assert np.median(lams) < 1.8 and lams.min() >= 1.0


def _grid_sd(em, C, d, scale: float, n: int = 201) -> np.ndarray:
    """Marginal sds of the box-prior posterior exp(-chi2 / 2 scale) on an n x n grid (exact, no sampler)."""
    g = np.linspace(0.0, 1.0, n)
    G = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    L = linalg.cholesky(C, lower=True)
    c2 = np.sum(linalg.solve_triangular(L, (em(G) - d).T, lower=True) ** 2, axis=0)
    w = np.exp(-0.5 * (c2 - c2.min()) / scale)
    w /= w.sum()
    mean = w @ G
    return np.sqrt(w @ (G - mean) ** 2)


def test_the_reported_emulator_posterior_samples_the_scaled_likelihood():
    # the sample's marginal sds against the exact grid posterior of the same emulator and C_em, with and
    # without lambda: the sampler targets lambda (R + C_em), and the scaling widens what it reports
    X, Y, latest, d, truth, _ = stand_in(7, 0.4)
    R = DiagonalError(np.full(M, NOISE))
    kw = dict(lower=LO, upper=HI, times=T, smoothing=SMOOTHING, walkers=16, min_steps=2000)
    plain = emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), **kw)
    cal = emulator_posterior(X, Y, latest, d, R, rng=np.random.default_rng(1), self_calibrate=True, **kw)
    lam = cal.diagnostics["emulator_error"]["self_calibration"]["lambda"]
    assert "self_calibration" not in plain.diagnostics["emulator_error"] and lam > 2.0
    em = CurveEmulator(X, Y, LO, HI, smoothing=SMOOTHING)
    C = R.dense() + error_model(em.loo_residuals()[latest]).dense()
    # 2000 steps x 16 walkers give thousands of effective draws: an sd to a few per cent; 15 % allowed
    assert cal.samples.std(axis=0) == pytest.approx(_grid_sd(em, C, d, lam), rel=0.15)
    assert plain.samples.std(axis=0) == pytest.approx(_grid_sd(em, C, d, 1.0), rel=0.15)
    assert np.all(cal.samples.std(axis=0) > 1.5 * plain.samples.std(axis=0))


def test_the_analyses_are_not_scaled():
    # the loop's analyses keep R + C_em: the scaling is the reported posterior's (a wider analysis would
    # spread the next design and slow the stop rule, which the default twin must still reach)
    import inspect

    assert "self_calibrate" not in inspect.signature(emulated_esmda_update).parameters


def test_the_config_switch_is_on_by_default_and_refused_beside_the_ensemble_posterior():
    from calibration.experiment import ExperimentSpec
    from tests._shipped import twin_ref

    exp = twin_ref()
    assert ExperimentSpec.from_config("twin_ref", exp).self_calibrate is True
    assert exp["posterior"] == "emulator_mcmc"
    assert ExperimentSpec.from_config("twin_ref", twin_ref(emulated={"self_calibrate": False})).self_calibrate is False
    with pytest.raises(Exception, match="self_calibrate"):
        twin_ref(emulated={"self_calibrate": "yes"})
    with pytest.raises(Exception, match="emulated.self_calibrate: True is a setting of the reported emulator posterior"):
        twin_ref(emulated={"self_calibrate": True}, posterior="ensemble")


def test_other_runs_as_pseudo_data_are_the_runs_it_takes():
    # ``pseudo`` equal to ``latest`` is the default exactly; the design's first 30 runs (the hypercube
    # over the box) give one delta each; fewer than 3 pseudo-data runs are refused by name
    X, Y, latest, _, _, _ = stand_in(3, 0.4)
    R = DiagonalError(np.full(M, NOISE))
    kw = dict(lower=LO, upper=HI, smoothing=SMOOTHING, error_model=error_model, search_points=100)
    base = self_calibration(X, Y, latest, R, rng=7, **kw)
    assert self_calibration(X, Y, latest, R, rng=7, pseudo=latest, **kw) == base
    spread = self_calibration(X, Y, latest, R, rng=7, pseudo=~latest, **kw)
    assert spread["runs"] == 30 and len(spread["delta_chi2"]) == 30
    with pytest.raises(ValueError, match="at least 3 pseudo-data runs"):
        self_calibration(X, Y, latest, R, rng=7, pseudo=np.r_[np.ones(2, bool), np.zeros(40, bool)], **kw)



def test_the_curvature_forms_factor_solves_its_median_equation():
    """``enkf.selfcal._curvature_lambda``: the least lambda >= 1 at which the pseudo-runs' median delta is the
    reference. A quadratic likelihood's delta falls as 1/lambda when the run is brought sqrt(lambda) closer
    to the maximum (lambda = median delta / reference, the power form's); one with a kink at its maximum
    (a box end) as 1/sqrt(lambda) (lambda = that ratio squared); deltas already below the reference give 1."""
    from enkf.selfcal import _curvature_lambda

    deltas = np.array([3.0, 9.0, 12.0, 20.0, 40.0])
    ref = stats.chi2.median(2)
    quadratic = [lambda lam, d=d: d / lam for d in deltas]
    kink = [lambda lam, d=d: d / np.sqrt(lam) for d in deltas]
    assert _curvature_lambda(quadratic, ref) == pytest.approx(12.0 / ref, rel=1e-9)
    assert _curvature_lambda(kink, ref) == pytest.approx((12.0 / ref) ** 2, rel=1e-9)
    assert _curvature_lambda([lambda lam: 0.5] * 3, ref) == 1.0


def test_the_self_calibration_names_its_form_and_refuses_an_unknown_one():
    X, Y, latest, d, truth, rng = stand_in(3, 0.3)
    kw = dict(lower=LO, upper=HI, smoothing=SMOOTHING, error_model=error_model)
    R = DiagonalError(np.full(M, NOISE))
    curvature = self_calibration(X, Y, latest, R, rng=5, tempering="curvature", **kw)
    assert curvature["tempering"] == "curvature" and curvature["lambda"] > 1.0
    # at lambda the median delta is the chi-square median, so at least half lie inside the 90 % region
    assert curvature["fraction_inside_90_at_lambda"] >= 0.5
    with pytest.raises(ValueError, match="tempering must be one of .*, got 'sqrt'"):
        self_calibration(X, Y, latest, R, rng=5, tempering="sqrt", **kw)
