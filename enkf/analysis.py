"""Ensemble analysis: the paper's EnKF smoother (eqs. 3-5) and ES-MDA, in the unbounded parameter space.

Notation (rows of the caller's matrices are members, ``i = 1..N``):

* ``p_i``  parameters (bounded, ``n`` of them), ``z_i = T(p_i)`` their unbounded image (logit/probit).
* ``y_i``  the simulated response of member ``i`` on the observation grid (``m`` values), ``H x_i`` in the
  paper: the state is the augmented vector ``x_i = [z_i; y_i]`` (parameters + the whole curve, the
  paper's smoother), and ``H`` picks the curve.
* ``y_o``  the observations, ``R = L L^T`` their error covariance (:mod:`enkf.covariance`).

Paper eqs. (3)-(4), with the ensemble covariance ``P_f`` and perturbed observations
``y_i^o = y_o + sqrt(alpha) L e_i``, ``e_i ~ N(0, I)``::

    x_i^a = x_i^f + K (y_i^o - H x_i^f)                                    (3)
    K     = P_f H^T (H P_f H^T + alpha R)^{-1}                             (4)

``alpha = 1`` is the paper's EnKF; ES-MDA (Emerick & Reynolds 2013) repeats the update with
``alpha_k`` such that ``sum_k 1/alpha_k = 1`` and fresh perturbations each time.

How it is solved (never an explicit ``m x m`` inverse): with ``dZ = (Z - z_bar)^T / sqrt(N-1)`` and the
whitened response anomalies ``S = L^{-1} (Y - y_bar)^T / sqrt(N-1)`` (``m x N``),
``P_f H^T = [dZ S^T L^T; L S S^T L^T]`` and ``H P_f H^T + alpha R = L (S S^T + alpha I) L^T``, so the
parameter increment is ``dZ S^T (S S^T + alpha I)^{-1} L^{-1} (y^o - y)``. With the thin SVD
``S = U Sigma V^T``, truncated to the ``r`` leading singular values that hold ``truncation`` of their sum
(0.99 by default for ES-MDA; 1.0 keeps every non-zero one, the exact update), this is::

    delta z_i = dZ V_r diag(s / (s^2 + alpha)) U_r^T L^{-1} (y_i^o - y_i)
    delta y_i = L U_r diag(s^2 / (s^2 + alpha)) U_r^T L^{-1} (y_i^o - y_i)      (curve part of x^a)

Cost ``O(m N^2)`` plus the products with ``L`` (``O(m N)`` for diagonal/AR(1), ``O(m^2 N)`` dense).

Localization (paper, section 4): the user declares which parameter/observation pairs are unrelated,
as a weight matrix ``M`` of shape ``(n, m)`` (0 = unrelated, 1 = keep; values in between taper). The
parameter-observation cross-covariance is replaced by ``M o C_zy`` (Schur product), i.e.
``K_z = (M o C_zy) (C_yy + alpha R)^{-1}`` with ``C_zy = dZ S_r^T L^T`` from the same truncated
ensemble, and ``(S_r S_r^T + alpha I)^{-1} = U_r [diag(1/(s^2+alpha)) - I/alpha] U_r^T + I/alpha``.
With ``M`` all ones this equals the unmasked update.

Inflation (paper eq. 5) follows the update, on ``z``; see :mod:`enkf.inflation`.

Failed members: a member is dead if ``alive`` says so or if its response (or parameters) contain a
non-finite value. Means, anomalies and the gain use the survivors only. The update runs while
``n_alive >= min_alive_fraction * N`` (and ``n_alive >= 2``), otherwise :class:`EnsembleFailure` is
raised. Dead members are not dropped: each is *replaced* by a fresh draw from the Gaussian fitted to
the survivors' analysis in the unbounded space, ``z = z_bar^a + (Z^a - z_bar^a)^T w / sqrt(n_alive - 1)``,
``w ~ N(0, I)``, so the ensemble keeps its ``N`` members (one Snakemake job per member and iteration)
and the draw has exactly the survivors' analysis covariance. Their analysis responses are NaN (they
must be simulated), and ``replaced_members`` lists them.

Random numbers: perturbations are drawn for all ``N`` members (``N x m`` standard normals, in member
order) before anything else, then the replacement draws, all from the ``rng`` passed in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from ._rng import RngLike, as_generator
from .covariance import ObservationError
from .diagnostics import default_names, jsonable, nrmse, rmse
from .inflation import as_inflation, inflate
from .transforms import BoxTransform, IdentityTransform


class EnsembleFailure(RuntimeError):
    """Too few members survived to compute an update."""


def esmda_alphas(n_steps: int = 3, base: Sequence[float] | None = None) -> np.ndarray:
    """ES-MDA inflation coefficients ``alpha_k`` rescaled so that ``sum_k 1/alpha_k = 1``.

    ``base`` defaults to the halving sequence ``2^(n-1-k)``, i.e. (4, 2, 1) for three steps, giving
    ``alpha = (7, 3.5, 1.75)``. Any positive ``base`` is rescaled by ``c = sum_k 1/base_k``.
    """
    if base is None:
        if n_steps < 1:
            raise ValueError("n_steps must be >= 1")
        base = 2.0 ** np.arange(n_steps - 1, -1, -1)
    b = np.asarray(base, dtype=float)
    if b.ndim != 1 or b.size == 0 or np.any(~np.isfinite(b)) or np.any(b <= 0):
        raise ValueError("ES-MDA base coefficients must be a non-empty sequence of positive numbers")
    return b * np.sum(1.0 / b)


def localization_mask(n_params: int, n_obs: int, unrelated: Mapping[int, object] | None = None) -> np.ndarray:
    """0/1 localization weights ``M`` (``n_params x n_obs``): ones except the declared unrelated pairs.

    ``unrelated`` maps a parameter index to the observations it is known not to influence, given as
    an index array, a slice, or a boolean mask of length ``n_obs``.
    """
    mask = np.ones((n_params, n_obs))
    for j, obs_sel in (unrelated or {}).items():
        if not 0 <= int(j) < n_params:
            raise IndexError(f"parameter index {j} out of range")
        sel = np.asarray(obs_sel) if not isinstance(obs_sel, slice) else obs_sel
        if isinstance(sel, np.ndarray) and sel.dtype == bool and sel.shape != (n_obs,):
            raise ValueError(f"boolean observation mask for parameter {j} must have length {n_obs}")
        mask[int(j), sel] = 0.0
    return mask


def truncation_rank(s: np.ndarray, truncation: float) -> int:
    """Number of leading singular values kept: the fewest holding ``truncation`` of their sum.

    ``truncation = 1`` keeps every numerically non-zero singular value (``s > 1e-12 s_max``); the
    anomalies of ``N`` members have rank at most ``N - 1``, so at least one is always zero.
    """
    if not 0.0 < truncation <= 1.0:
        raise ValueError("truncation must lie in (0, 1]")
    if s.size == 0 or s[0] <= 0.0:
        return 0
    significant = int(np.count_nonzero(s > s[0] * 1e-12))
    if truncation >= 1.0:
        return significant
    frac = np.cumsum(s) / np.sum(s)
    return min(int(np.searchsorted(frac, truncation) + 1), significant)


@dataclass
class AnalysisResult:
    """Output of one analysis.

    Attributes
    ----------
    params : (N, n) updated parameters, bounded (inside the box for a :class:`BoxTransform`).
    params_unbounded : (N, n) the same in the unbounded space.
    responses : (N, m) analysis of the simulated curves (curve part of the augmented state, eq. 3);
        a linear prediction, NaN for replaced members.
    alive : (N,) bool, the members used in the statistics.
    replaced_members : indices of dead members replaced by draws from the survivors' analysis.
    inflation : (n,) the factors ``lambda_j`` applied (eq. 5), ones if none.
    rank : singular values kept in the truncated SVD.
    diagnostics : JSON-ready dict (see :func:`enkf_update`).
    """

    params: np.ndarray
    params_unbounded: np.ndarray
    responses: np.ndarray
    alive: np.ndarray
    replaced_members: list[int]
    inflation: np.ndarray
    rank: int
    diagnostics: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return jsonable(self.diagnostics)


def enkf_update(params, responses, obs, obs_error: ObservationError, *, rng: RngLike,
                transform: BoxTransform | IdentityTransform | None = None, localization=None,
                inflation="paper", prior_std=None, alive=None, min_alive_fraction: float = 0.5,
                truncation: float = 1.0, names: Sequence[str] | None = None) -> AnalysisResult:
    """The paper's EnKF analysis as a smoother: eqs. (3)-(4) with ``alpha = 1``, localization, eq. (5).

    Parameters
    ----------
    params : (N, n) array
        Forecast parameters, one row per member (bounded if ``transform`` is a box).
    responses : (N, m) array
        Simulated curves on the observation grid; rows of failed members may be NaN.
    obs : (m,) array
        Observations ``y_o``.
    obs_error : ObservationError
        ``R``; used in the gain and in the perturbation draws.
    rng : numpy.random.Generator or int
        Source of the perturbations (and of dead-member replacements).
    transform : BoxTransform or None
        Bounded <-> unbounded map; ``None`` means the parameters are already unbounded.
    localization : (n, m) array or None
        Weights ``M`` on the parameter-observation cross-covariance (0 = unrelated), see
        :func:`localization_mask`.
    inflation : ``"paper"`` (default, :class:`~enkf.inflation.SpreadFloor` at 0.45), a number
        (multiplicative ``lambda``), an inflation object, or ``None``.
    prior_std : (n,) array or None
        Initial-ensemble std in the unbounded space for the spread floor; default
        ``transform.prior_std()`` (uniform prior on the box).
    alive : (N,) bool array or None
        Members whose simulation succeeded (non-finite responses are also treated as dead).
    min_alive_fraction : float
        Raise :class:`EnsembleFailure` when fewer members than this fraction survive.
    truncation : float
        Fraction of the singular-value sum kept; 1.0 (default here) is the exact eq. (4).
    names : parameter names for the diagnostics.

    Returns
    -------
    AnalysisResult
        ``diagnostics`` holds: method, alpha, counts of members/alive, dead and replaced members,
        SVD rank, inflation factors, per-parameter mean and std before/after (bounded and unbounded),
        the forecast misfit per member (``rmse``, ``nrmse``, ``chi2_per_obs``) and of the mean response.
    """
    return _analysis("enkf", params, responses, obs, obs_error, alpha=1.0, rng=rng, transform=transform,
                     localization=localization, inflation=inflation, prior_std=prior_std, alive=alive,
                     min_alive_fraction=min_alive_fraction, truncation=truncation, names=names)


def esmda_update(params, responses, obs, obs_error: ObservationError, *, alpha: float, rng: RngLike,
                 transform: BoxTransform | IdentityTransform | None = None, localization=None,
                 inflation=None, prior_std=None, alive=None, min_alive_fraction: float = 0.5,
                 truncation: float = 0.99, names: Sequence[str] | None = None) -> AnalysisResult:
    """One ES-MDA step: eqs. (3)-(4) with the error covariance inflated to ``alpha R``.

    Use the ``alpha_k`` of :func:`esmda_alphas` in turn (``sum 1/alpha_k = 1``), re-running the model
    between steps; each call draws fresh perturbations ``y_o + sqrt(alpha) L e_i``. The solve goes
    through the whitened responses and a truncated SVD (``truncation`` of the singular-value sum,
    0.99 by default, 1.0 = exact). No inflation by default. Other arguments as :func:`enkf_update`.
    """
    if not (np.isfinite(alpha) and alpha > 0):
        raise ValueError("alpha must be finite and positive")
    return _analysis("esmda", params, responses, obs, obs_error, alpha=float(alpha), rng=rng,
                     transform=transform, localization=localization, inflation=inflation,
                     prior_std=prior_std, alive=alive, min_alive_fraction=min_alive_fraction,
                     truncation=truncation, names=names)


def _thin_svd(S: np.ndarray):
    """Thin SVD by LAPACK's divide and conquer (``gesdd``), falling back to ``gesvd`` on the rare
    matrices where ``gesdd`` fails to converge (met on an emulated ES-MDA whose members had nearly
    collapsed onto a few points: finite, well-scaled anomalies, still ``LinAlgError``)."""
    try:
        return linalg.svd(S, full_matrices=False, lapack_driver="gesdd", check_finite=False)
    except np.linalg.LinAlgError:
        return linalg.svd(S, full_matrices=False, lapack_driver="gesvd", check_finite=False)


def _analysis(method, params, responses, obs, obs_error, *, alpha, rng, transform, localization,
              inflation, prior_std, alive, min_alive_fraction, truncation, names) -> AnalysisResult:
    rng = as_generator(rng)
    transform = IdentityTransform() if transform is None else transform
    P = np.array(params, dtype=float, ndmin=2)
    Y = np.array(responses, dtype=float, ndmin=2)
    d = np.asarray(obs, dtype=float)
    N, n = P.shape
    m = d.size
    if Y.shape != (N, m):
        raise ValueError(f"responses must have shape (N, m) = ({N}, {m}), got {Y.shape}")
    if d.ndim != 1 or not np.all(np.isfinite(d)):
        raise ValueError("obs must be a finite 1-D array")
    if obs_error.m != m:
        raise ValueError(f"obs_error describes {obs_error.m} observations, obs has {m}")
    names = default_names(n, names)
    M = None
    if localization is not None:
        M = np.asarray(localization, dtype=float)
        if M.shape != (n, m):
            raise ValueError(f"localization must have shape (n, m) = ({n}, {m}), got {M.shape}")
    infl = as_inflation(inflation)

    Z = transform.to_unbounded(P)
    live = np.all(np.isfinite(Y), axis=1) & np.all(np.isfinite(Z), axis=1)
    if alive is not None:
        alive = np.asarray(alive, dtype=bool)
        if alive.shape != (N,):
            raise ValueError(f"alive must have shape ({N},)")
        live &= alive
    n_alive = int(live.sum())
    needed = max(2, math.ceil(min_alive_fraction * N - 1e-12))
    if n_alive < needed:
        raise EnsembleFailure(
            f"only {n_alive} of {N} members alive ({100.0 * n_alive / N:.0f}%), below the minimum of "
            f"{needed} (min_alive_fraction={min_alive_fraction}); refusing to update"
        )

    # Perturbed observations y_i^o = y_o + sqrt(alpha) L e_i for every member (fixed draw order).
    E = obs_error.color(rng.standard_normal((N, m)).T)  # (m, N)
    Za, Ya = Z[live], Y[live]
    D = d[:, None] + math.sqrt(alpha) * E[:, live]  # (m, Na)

    scale = 1.0 / math.sqrt(n_alive - 1)
    z_bar, y_bar = Za.mean(axis=0), Ya.mean(axis=0)
    dZ = (Za - z_bar).T * scale  # (n, Na)
    whitened = obs_error.whiten(np.hstack([(Ya - y_bar).T * scale, D - Ya.T, (y_bar - d)[:, None]]))
    S, innov, w_mean = whitened[:, :n_alive], whitened[:, n_alive:2 * n_alive], whitened[:, -1]

    U, s, Vt = _thin_svd(S)
    r = truncation_rank(s, truncation)
    U, s, Vt = U[:, :r], s[:r], Vt[:r]
    Ut_innov = U.T @ innov  # (r, Na)
    if M is None or np.all(M == 1.0):
        delta_z = dZ @ (Vt.T @ ((s / (s * s + alpha))[:, None] * Ut_innov))
    else:
        # (S_r S_r^T + alpha I)^{-1} innov, then L^{-T}, then the masked cross-covariance M o C_zy.
        G = U @ ((1.0 / (s * s + alpha) - 1.0 / alpha)[:, None] * Ut_innov) + innov / alpha
        C_zy = ((dZ @ Vt.T) * s) @ obs_error.color(U).T  # (n, m) = dZ S_r^T L^T
        delta_z = (M * C_zy) @ obs_error.whiten_T(G)
    delta_y = obs_error.color(U @ ((s * s / (s * s + alpha))[:, None] * Ut_innov))  # (m, Na)

    Za_new = Za + delta_z.T
    Ya_new = Ya + delta_y.T

    # Inflation, paper eq. (5), in the unbounded space, over the survivors.
    lam = np.ones(n)
    if infl is not None:
        ref = prior_std if prior_std is not None else transform.prior_std()
        lam = infl.factors(Za_new, ref)
        Za_new = inflate(Za_new, lam)

    Z_new = np.empty_like(Z)
    Y_new = np.full_like(Y, np.nan)
    Z_new[live], Y_new[live] = Za_new, Ya_new
    dead = np.flatnonzero(~live)
    if dead.size:
        z_bar_a = Za_new.mean(axis=0)
        w = rng.standard_normal((dead.size, n_alive))
        Z_new[dead] = z_bar_a + w @ (Za_new - z_bar_a) * scale
    P_new = transform.to_bounded(Z_new)

    # Diagnostics (forecast misfit from the whitened anomalies: L^{-1}(y_i - y_o) = S_i sqrt(Na-1) + w_mean).
    chi2_members = np.full(N, np.nan)
    chi2_members[live] = np.sum((S * math.sqrt(n_alive - 1) + w_mean[:, None]) ** 2, axis=0) / m
    rmse_members = np.full(N, np.nan)
    nrmse_members = np.full(N, np.nan)
    rmse_members[live] = rmse(Ya, d)
    nrmse_members[live] = nrmse(Ya, d)
    diagnostics = {
        "method": method,
        "alpha": alpha,
        "n_members": N,
        "n_alive": n_alive,
        "alive_fraction": n_alive / N,
        "dead_members": dead.tolist(),
        "replaced_members": dead.tolist(),
        "n_obs": m,
        "obs_error": obs_error.describe(),
        "truncation": truncation,
        "svd_rank": r,
        "singular_values": s.tolist(),
        "localization": None if M is None else {"fraction_kept": float(np.mean(M != 0.0))},
        "inflation": {"spec": None if infl is None else infl.describe(), "lambda": dict(zip(names, lam))},
        "params": {
            name: {
                "mean_before": float(P[live, j].mean()), "mean_after": float(P_new[:, j].mean()),
                "std_before": float(P[live, j].std(ddof=1)), "std_after": float(P_new[:, j].std(ddof=1)),
                "std_unbounded_before": float(Za[:, j].std(ddof=1)),
                "std_unbounded_after": float(Z_new[:, j].std(ddof=1)),
            }
            for j, name in enumerate(names)
        },
        "misfit_members": {"rmse": rmse_members, "nrmse": nrmse_members, "chi2_per_obs": chi2_members},
        "misfit_mean": {"rmse": float(rmse(y_bar, d)), "nrmse": float(nrmse(y_bar, d)),
                        "chi2_per_obs": float(np.dot(w_mean, w_mean) / m)},
    }
    return AnalysisResult(params=P_new, params_unbounded=Z_new, responses=Y_new, alive=live,
                          replaced_members=dead.tolist(), inflation=lam, rank=r,
                          diagnostics=jsonable(diagnostics))
