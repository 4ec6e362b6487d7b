"""Differential test: our ES-MDA update against Equinor's maintained `iterative_ensemble_smoother`
(ESMDA) on the same inputs: the same ensemble, responses, observations, error covariance and
observation perturbations, exact solve (truncation 1.0), identity parameter transform.

Both implement X + dX dY^T [dY dY^T + alpha (N - 1) C_D]^-1 (D - Y); ours solves through the whitened
anomalies and a thin SVD, the library through its subspace inversion, so they agree to round-off:
measured 5e-15 (diagonal), 2e-14 (AR(1)) and 3e-11 (squared exponential, whose covariance has a
condition number near 1e6 with its 1e-6 nugget) of the update's size. The tolerance 1e-9 is well above
that and far below any real difference (a wrong alpha or a missing (N - 1) moves the update by
several per cent)."""
import numpy as np
import pytest

# a test dependency (pyproject's `test` extra): a missing library fails the suite, it is not skipped
import iterative_ensemble_smoother as ies

from enkf.analysis import esmda_alphas, esmda_update
from enkf.covariance import AR1Error, DiagonalError, SquaredExponentialError
from enkf.transforms import IdentityTransform

N, N_PARAMS, M = 30, 4, 50
TIMES = np.arange(M) * 1e-6


def _problem(seed=3):
    """A mildly nonlinear forward model (tanh plus linear) so that repeated steps differ."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((M, N_PARAMS))

    def model(P):
        return np.tanh(P @ A.T) + 0.3 * (P @ A.T)

    P = rng.normal(1.0, 0.5, (N, N_PARAMS))
    d = model(np.ones((1, N_PARAMS)))[0] + 0.05 * rng.standard_normal(M)
    return model, P, d


def _errors():
    rng = np.random.default_rng(7)
    return {"diagonal": DiagonalError(0.05 * (1.0 + rng.random(M))),
            "ar1": AR1Error(0.05, TIMES, 5e-6),
            "squared_exponential": SquaredExponentialError(0.05, TIMES, 3e-6)}


def _library(err, d, alphas):
    C = err.dense()
    # the library takes a 1-D array for a diagonal covariance (its own code path) and a matrix otherwise
    cov = np.diag(C).copy() if isinstance(err, DiagonalError) else C
    return ies.ESMDA(cov, d, alpha=np.asarray(alphas, float), seed=0)


def _our_perturbations(err, seed):
    """The draws esmda_update makes with rng=seed: L e, e ~ N(0, I) in (N, m) order, as (m, N)."""
    return err.color(np.random.default_rng(seed).standard_normal((N, M)).T)


@pytest.mark.parametrize("kind", ["diagonal", "ar1", "squared_exponential"])
def test_one_esmda_step_equals_the_reference_library(kind):
    err = _errors()[kind]
    model, P, d = _problem()
    alphas = esmda_alphas(3)
    ours = esmda_update(P, model(P), d, err, alpha=alphas[0], rng=11, transform=IdentityTransform(),
                        truncation=1.0)
    lib = _library(err, d, alphas)
    assert lib.alpha[0] == pytest.approx(alphas[0], rel=1e-12)  # same schedule, sum 1/alpha = 1
    lib.prepare_assimilation(Y=model(P).T.copy(), truncation=1.0,
                             observation_perturbations=_our_perturbations(err, 11))
    X = lib.assimilate_batch(X=P.T.copy()).T
    update = np.max(np.abs(ours.params - P))
    assert update > 0.05  # the step moves the ensemble
    assert np.max(np.abs(X - ours.params)) <= 1e-9 * update


def test_three_step_esmda_equals_the_reference_library():
    """The whole schedule (7, 3.5, 1.75), the model re-run between steps, fresh perturbations each step."""
    err = _errors()["ar1"]
    model, P0, d = _problem(seed=5)
    alphas = esmda_alphas(3)
    lib = _library(err, d, alphas)
    ours, theirs = P0.copy(), P0.copy()
    for k, alpha in enumerate(alphas):
        seed = 100 + k
        ours = esmda_update(ours, model(ours), d, err, alpha=alpha, rng=seed, transform=IdentityTransform(),
                            truncation=1.0).params
        lib.prepare_assimilation(Y=model(theirs).T.copy(), truncation=1.0,
                                 observation_perturbations=_our_perturbations(err, seed))
        theirs = lib.assimilate_batch(X=theirs.T.copy()).T
    moved = np.max(np.abs(ours - P0))
    assert moved > 0.05
    assert np.max(np.abs(theirs - ours)) <= 1e-9 * moved
    # and the two ensembles fit the data equally well (the test is not of two equal no-ops)
    assert np.mean((model(ours) - d) ** 2) < 0.5 * np.mean((model(P0) - d) ** 2)
