"""Observation error covariance ``R`` (``C_D``) for dense stress-time curves.

Three models of the measurement error ``e`` of an observation vector sampled at times ``t_i``,
each with a marginal standard deviation ``sigma_i`` (scalar or one per observation, caller's units):

* ``DiagonalError``     R = diag(sigma_i^2)                                  (white noise)
* ``AR1Error``          R_ij = sigma_i sigma_j exp(-|t_i - t_j| / tau)       (AR(1) / Ornstein-Uhlenbeck)
* ``SquaredExponentialError``
                        R_ij = sigma_i sigma_j [(1 - nu) exp(-(t_i - t_j)^2 / (2 ell^2)) + nu delta_ij]
* ``DenseError``        any symmetric positive-definite matrix given by the caller.

Each model exposes its lower Cholesky factor ``L`` (``R = L L^T``) only through products, so that the
analysis never forms ``R^{-1}``:

* ``whiten(r)   = L^{-1} r``   (the whitened residual; ``chi^2 = |L^{-1} r|^2``)
* ``whiten_T(g) = L^{-T} g``
* ``color(z)    = L z``        (a draw ``L z`` with ``z ~ N(0, I)`` has covariance ``R``)

Arrays have the observation axis first: shape ``(m,)`` or ``(m, k)``.

The AR(1) model is Markov, so ``L^{-1}`` is lower bidiagonal and all three products cost ``O(m k)``
for any (also non-uniform) time grid: ``(L^{-1} r)_i = (w_i - phi_i w_{i-1}) / sqrt(1 - phi_i^2)`` with
``w = r / sigma`` and ``phi_i = exp(-(t_i - t_{i-1}) / tau)``. The squared-exponential model is dense
and gets a Cholesky factorisation (once, cached); its nugget ``nu`` (default 1e-6, a white-noise
fraction of the variance) keeps the otherwise numerically singular matrix factorisable. Note that the
SE model says the noise is very smooth: a residual with high-frequency content gets a very large
``chi^2``; prefer AR(1) unless the noise really is smooth.

``groups`` (optional, one integer label per observation) declares independent records concatenated in
one observation vector (several tests or channels): errors are uncorrelated across groups.

:func:`estimate_noise` estimates ``sigma`` and the correlation time from a record's pre-trigger part.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np
from scipy import linalg

from ._rng import RngLike, as_generator


class ObservationError(ABC):
    """Observation error model: ``R = L L^T`` accessed through ``whiten``, ``whiten_T`` and ``color``."""

    kind: str = "abstract"

    @property
    @abstractmethod
    def m(self) -> int:
        """Number of observations."""

    @property
    @abstractmethod
    def std(self) -> np.ndarray:
        """Marginal standard deviation of each observation, shape ``(m,)``."""

    @abstractmethod
    def whiten(self, r) -> np.ndarray:
        """``L^{-1} r`` along axis 0."""

    @abstractmethod
    def whiten_T(self, g) -> np.ndarray:
        """``L^{-T} g`` along axis 0."""

    @abstractmethod
    def color(self, z) -> np.ndarray:
        """``L z`` along axis 0."""

    @abstractmethod
    def dense(self) -> np.ndarray:
        """The full ``m x m`` matrix ``R`` (for checks and small problems)."""

    def sample(self, rng: RngLike, n: int) -> np.ndarray:
        """``n`` independent draws of the error, shape ``(n, m)`` (one row per draw)."""
        z = as_generator(rng).standard_normal((n, self.m))
        return self.color(z.T).T

    def chi2(self, r) -> np.ndarray:
        """``|L^{-1} r|^2`` along axis 0 (the Mahalanobis norm ``r^T R^{-1} r``)."""
        w = self.whiten(r)
        return np.sum(w * w, axis=0)

    def describe(self) -> dict:
        """JSON-ready description (kind, m, sigma range, model parameters)."""
        s = self.std
        return {"kind": self.kind, "m": int(self.m), "sigma_min": float(s.min()), "sigma_max": float(s.max())}

    def _check(self, a) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape[0] != self.m:
            raise ValueError(f"expected {self.m} observations along axis 0, got array of shape {a.shape}")
        return a


def _as_sigma(sigma, m: int) -> np.ndarray:
    s = np.asarray(sigma, dtype=float)
    s = np.full(m, float(s)) if s.ndim == 0 else s.copy()
    if s.shape != (m,):
        raise ValueError(f"sigma must be a scalar or have shape ({m},), got {s.shape}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError("sigma must be finite and strictly positive")
    return s


def _as_times_groups(times, groups):
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError("times must be a non-empty 1-D array")
    g = np.zeros(t.size, dtype=int) if groups is None else np.asarray(groups)
    if g.shape != t.shape:
        raise ValueError("groups must have the same shape as times")
    same = g[1:] == g[:-1]
    if np.any(np.diff(t)[same] <= 0):
        raise ValueError("times must be strictly increasing within each group")
    return t, g


def _col(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Reshape a length-m vector to broadcast against ``a`` along axis 0."""
    return v.reshape((-1,) + (1,) * (a.ndim - 1))


class DiagonalError(ObservationError):
    """Independent errors, ``R = diag(sigma^2)``."""

    kind = "diagonal"

    def __init__(self, sigma, m: int | None = None):
        if m is None:
            m = np.size(sigma)
        self._sigma = _as_sigma(sigma, int(m))

    @property
    def m(self) -> int:
        return self._sigma.size

    @property
    def std(self) -> np.ndarray:
        return self._sigma

    def whiten(self, r):
        r = self._check(r)
        return r / _col(self._sigma, r)

    def whiten_T(self, g):
        return self.whiten(g)

    def color(self, z):
        z = self._check(z)
        return z * _col(self._sigma, z)

    def dense(self):
        return np.diag(self._sigma**2)


class AR1Error(ObservationError):
    """AR(1) (exponential, Ornstein-Uhlenbeck) correlation in time: ``R_ij = s_i s_j exp(-|t_i - t_j| / tau)``.

    ``tau`` (``corr_time``) in the units of ``times``; ``tau = 0`` gives white noise. ``L^{-1}`` is
    bidiagonal, so whitening, its transpose and colouring are exact and ``O(m)`` per column.
    """

    kind = "ar1"

    def __init__(self, sigma, times, corr_time: float, groups=None):
        t, g = _as_times_groups(times, groups)
        self._sigma = _as_sigma(sigma, t.size)
        if not np.isfinite(corr_time) or corr_time < 0:
            raise ValueError("corr_time must be finite and >= 0")
        self.corr_time = float(corr_time)
        self.times, self.groups = t, g
        phi = np.zeros(t.size)
        if self.corr_time > 0:
            phi[1:] = np.where(g[1:] == g[:-1], np.exp(-np.diff(t) / self.corr_time), 0.0)
        self._phi = phi
        self._c = np.sqrt(1.0 - phi**2)  # innovation std of the unit-variance AR(1) recursion

    @property
    def m(self) -> int:
        return self._sigma.size

    @property
    def std(self) -> np.ndarray:
        return self._sigma

    def whiten(self, r):
        r = self._check(r)
        w = r / _col(self._sigma, r)
        out = w.copy()
        out[1:] -= _col(self._phi[1:], w[1:]) * w[:-1]
        return out / _col(self._c, out)

    def whiten_T(self, g):
        g = self._check(g)
        h = g / _col(self._c, g)
        out = h.copy()
        out[:-1] -= _col(self._phi[1:], h[1:]) * h[1:]
        return out / _col(self._sigma, out)

    def color(self, z):
        z = self._check(z)
        # L_R = B^{-1}, B lower bidiagonal: diag 1/c_i, sub-diagonal -phi_i/c_i.
        ab = np.zeros((2, self.m))
        ab[0] = 1.0 / self._c
        ab[1, :-1] = -self._phi[1:] / self._c[1:]
        e = linalg.solve_banded((1, 0), ab, z)
        return e * _col(self._sigma, e)

    def dense(self):
        t, g = self.times, self.groups
        if self.corr_time > 0:
            rho = np.exp(-np.abs(t[:, None] - t[None, :]) / self.corr_time)
        else:
            rho = np.eye(t.size)
        rho = np.where(g[:, None] == g[None, :], rho, 0.0)
        return self._sigma[:, None] * rho * self._sigma[None, :]

    def describe(self) -> dict:
        return {**super().describe(), "corr_time": self.corr_time}


class DenseError(ObservationError):
    """Any symmetric positive-definite ``R``, factorised once (``R = L L^T``, lower Cholesky)."""

    kind = "dense"

    def __init__(self, matrix, *, _symmetric: bool = False):
        c = np.array(matrix, dtype=float)
        if c.ndim != 2 or c.shape[0] != c.shape[1]:
            raise ValueError("covariance matrix must be square")
        if not _symmetric:
            if not np.allclose(c, c.T, rtol=1e-10, atol=1e-14 * np.abs(c).max()):
                raise ValueError("covariance matrix must be symmetric")
            c = 0.5 * (c + c.T)  # remove round-off asymmetry
        self._matrix = c
        try:
            self._L = linalg.cholesky(c, lower=True, check_finite=True)
        except linalg.LinAlgError as exc:  # pragma: no cover - message only
            raise ValueError(f"covariance matrix is not positive definite: {exc}") from exc
        self._std = np.sqrt(np.diag(c))

    @property
    def m(self) -> int:
        return self._matrix.shape[0]

    @property
    def std(self) -> np.ndarray:
        return self._std

    @property
    def cholesky(self) -> np.ndarray:
        return self._L

    def whiten(self, r):
        r = self._check(r)
        return linalg.solve_triangular(self._L, r, lower=True, check_finite=False)

    def whiten_T(self, g):
        g = self._check(g)
        return linalg.solve_triangular(self._L, g, lower=True, trans="T", check_finite=False)

    def color(self, z):
        z = self._check(z)
        return self._L @ z

    def dense(self):
        return self._matrix.copy()


def _sqexp_matrix(s: np.ndarray, t: np.ndarray, g: np.ndarray, ell: float, nugget: float) -> np.ndarray:
    """``s_i s_j [(1 - nu) exp(-(t_i - t_j)^2 / (2 ell^2)) + nu delta_ij]``, zero across groups; exactly
    symmetric. A single record on a uniform grid is Toeplitz: only ``m`` exponentials are evaluated."""
    m = t.size
    if ell <= 0:
        return np.diag(s * s)
    steps = np.diff(t)
    if np.all(g == g[0]) and m > 1 and np.allclose(steps, steps[0], rtol=1e-12, atol=0.0):
        lag = np.arange(m) * (steps[0] / ell)
        rho = linalg.toeplitz(np.exp(-0.5 * lag * lag))
    else:
        x = t / ell
        rho = x[:, None] - x[None, :]
        np.multiply(rho, rho, out=rho)
        np.multiply(rho, -0.5, out=rho)
        np.exp(rho, out=rho)
        if not np.all(g == g[0]):
            rho[g[:, None] != g[None, :]] = 0.0
    rho *= 1.0 - nugget
    rho[np.diag_indices(m)] += nugget
    rho *= np.outer(s, s)  # s_i s_j == s_j s_i exactly, so the product stays symmetric
    return rho


class SquaredExponentialError(DenseError):
    """Squared-exponential correlation in time with a white nugget ``nu``:

    ``R_ij = s_i s_j [(1 - nu) exp(-(t_i - t_j)^2 / (2 ell^2)) + nu delta_ij]``,
    ``ell`` = ``corr_time`` in the units of ``times``. Dense; Cholesky-factorised once.
    """

    kind = "sqexp"

    def __init__(self, sigma, times, corr_time: float, groups=None, nugget: float = 1e-6):
        t, g = _as_times_groups(times, groups)
        s = _as_sigma(sigma, t.size)
        if not np.isfinite(corr_time) or corr_time < 0:
            raise ValueError("corr_time must be finite and >= 0")
        if not 0.0 <= nugget <= 1.0:
            raise ValueError("nugget must lie in [0, 1]")
        self.corr_time, self.nugget = float(corr_time), float(nugget)
        self.times, self.groups = t, g
        super().__init__(_sqexp_matrix(s, t, g, self.corr_time, self.nugget), _symmetric=True)

    def describe(self) -> dict:
        return {**super().describe(), "corr_time": self.corr_time, "nugget": self.nugget}


def observation_error(kind: str, sigma, *, times=None, corr_time: float = 0.0, groups=None,
                      nugget: float = 1e-6, m: int | None = None) -> ObservationError:
    """Build an error model by name: ``"diagonal"``, ``"ar1"`` or ``"sqexp"``.

    ``times`` is required for the correlated kinds (and gives ``m`` for the diagonal one when ``sigma``
    is a scalar and ``m`` is not given).
    """
    if kind == "diagonal":
        if m is None:
            m = np.size(times) if times is not None else np.size(sigma)
        return DiagonalError(sigma, m=m)
    if times is None:
        raise ValueError(f"kind={kind!r} needs the observation times")
    if kind == "ar1":
        return AR1Error(sigma, times, corr_time, groups=groups)
    if kind in ("sqexp", "squared_exponential"):
        return SquaredExponentialError(sigma, times, corr_time, groups=groups, nugget=nugget)
    raise ValueError(f"unknown observation error kind {kind!r}; use 'diagonal', 'ar1' or 'sqexp'")


@dataclass(frozen=True)
class NoiseEstimate:
    """Noise level and correlation time estimated from a pre-trigger record."""

    sigma: float
    corr_time: float
    rho1: float
    n_samples: int
    model: str

    def to_dict(self) -> dict:
        return asdict(self)

    def error_model(self, times, groups=None, nugget: float = 1e-6) -> ObservationError:
        """The :class:`ObservationError` with this sigma and correlation time on ``times``."""
        kind = self.model if self.corr_time > 0 else "diagonal"
        return observation_error(kind, self.sigma, times=times, corr_time=self.corr_time,
                                 groups=groups, nugget=nugget)


def _autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocorrelation ``rho_k = sum x_i x_{i+k} / sum x_i^2`` pooled over rows, k = 0..max_lag."""
    denom = np.sum(x * x)
    return np.array([np.sum(x[:, : x.shape[1] - k] * x[:, k:]) / denom for k in range(max_lag + 1)])


def estimate_noise(pre_trigger_samples, dt: float, *, model: str = "ar1", detrend: str = "constant",
                   max_lag: int = 50) -> NoiseEstimate:
    """Estimate the noise std and correlation time from the pre-trigger part of a record.

    Parameters
    ----------
    pre_trigger_samples : array_like, shape (n,) or (k, n)
        Samples before the pulse arrives (rows = independent segments, pooled).
    dt : float
        Sampling interval (the returned correlation time has its units).
    model : ``"ar1"`` or ``"sqexp"``
        ``ar1``: Yule-Walker, ``phi = rho_1``, ``tau = -dt / ln(rho_1)``.
        ``sqexp``: least-squares fit of ``-ln rho_k = (k dt)^2 / (2 ell^2)`` over the lags with
        ``rho_k > 0.1`` (at least lag 1), returned as ``corr_time = ell``.
        A non-positive lag-1 autocorrelation gives ``corr_time = 0`` (white noise).
    detrend : ``"constant"`` (remove the mean, the baseline offset) or ``"linear"`` (remove a line).

    Returns
    -------
    NoiseEstimate
        ``sigma`` (std of the detrended samples, ``ddof`` = number of trend coefficients),
        ``corr_time``, ``rho1``, ``n_samples``, ``model``.
    """
    x = np.atleast_2d(np.asarray(pre_trigger_samples, dtype=float))
    if x.ndim != 2 or x.shape[1] < 8:
        raise ValueError("need at least 8 pre-trigger samples per segment")
    if not np.all(np.isfinite(x)):
        raise ValueError("pre-trigger samples contain non-finite values")
    if dt <= 0:
        raise ValueError("dt must be positive")
    n = x.shape[1]
    if detrend == "constant":
        x = x - x.mean(axis=1, keepdims=True)
        ddof = 1
    elif detrend == "linear":
        k = np.arange(n, dtype=float)
        coef = np.polynomial.polynomial.polyfit(k, x.T, 1)
        x = x - np.polynomial.polynomial.polyval(k, coef)
        ddof = 2
    else:
        raise ValueError("detrend must be 'constant' or 'linear'")
    sigma = float(np.sqrt(np.sum(x * x) / (x.size - ddof * x.shape[0])))
    rho = _autocorrelation(x, min(max_lag, n - 2))
    rho1 = float(rho[1])
    if rho1 <= 0.0:
        corr_time = 0.0
    elif model == "ar1":
        corr_time = float(-dt / np.log(min(rho1, 1.0 - 1e-12)))
    elif model in ("sqexp", "squared_exponential"):
        lags = np.arange(1, rho.size)
        use = rho[1:] > 0.1
        use &= np.cumprod(use).astype(bool)  # contiguous from lag 1
        use[0] = True
        k = lags[use] * dt
        y = -np.log(np.clip(rho[1:][use], 1e-12, 1.0 - 1e-12))
        inv_2ell2 = np.sum(k * k * y) / np.sum(k**4)
        corr_time = float(np.sqrt(0.5 / inv_2ell2))
        model = "sqexp"
    else:
        raise ValueError("model must be 'ar1' or 'sqexp'")
    return NoiseEstimate(sigma=sigma, corr_time=corr_time, rho1=rho1, n_samples=int(x.size), model=model)
