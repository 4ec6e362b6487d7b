"""Model choice: BIC with the effective sample size, parameters pinned at bounds, the acceptance rule
of an effect, and curve errors (:mod:`enkf.diagnosis`, step 4)."""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..covariance import ObservationError
from ..diagnostics import rmse
from .structure import autocorrelation


# ----------------------------------------------------------------------------------------------
# 4. Model choice
# ----------------------------------------------------------------------------------------------

def bic(chi2: float, n_params: int, n_eff: float) -> float:
    """``BIC = chi2 + n_params ln(n_eff)`` (``chi2`` = ``-2 ln L`` up to a constant; module docstring)."""
    if not n_eff >= 1:
        raise ValueError(f"n_eff must be >= 1, got {n_eff}")
    return float(chi2) + int(n_params) * math.log(float(n_eff))


def effective_sample_size(source, n: int | None = None) -> float:
    """Effective number of independent observations.

    ``source``:

    * an :class:`~enkf.covariance.ObservationError`: ``1^T C^{-1} 1 = |L^{-1} sigma|^2`` with ``C`` its
      correlation matrix (``m`` for independent errors; for AR(1) ``(m - (m-2) rho_1)/(1 + rho_1)``);
    * a residual vector (e.g. whitened): ``m (1 - rho_1) / (1 + rho_1)`` with its sample lag-one
      autocorrelation ``rho_1`` clipped to ``[0, 0.999]``;
    * a number: ``rho_1`` itself, with ``n`` given.
    """
    if isinstance(source, ObservationError):
        return float(source.chi2(source.std))
    if np.ndim(source) == 0:
        if n is None:
            raise ValueError("give n with a scalar rho1")
        rho, m = float(source), int(n)
    else:
        x = np.asarray(source, dtype=float)
        m = x.size if n is None else int(n)
        rho = float(autocorrelation(x, 1)[1])
    rho = min(max(rho, 0.0), 0.999)
    return max(1.0, m * (1.0 - rho) / (1.0 + rho))


def pinned_at_bounds(samples, lower, upper, names: Sequence[str], *, nulls: Mapping[str, float] | None = None,
                     fraction: float = 0.02) -> list[dict]:
    """Parameters whose posterior median lies within ``fraction`` of the box width of a bound of the box
    the calibration was confined to: there the box, not the data, decided the estimate (a bounded
    transform piles the ensemble up against a bound the data push it through). A bound equal to the
    parameter's null value (``nulls``) is exempt: an estimate at the null is the null criterion's
    business, not a box limit. Returns one dict per pinned parameter: ``name``, ``median``, ``side``
    (``"lower"``/``"upper"``), ``bound``, ``text``."""
    X = np.array(samples, dtype=float, ndmin=2)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    if X.shape[1] != len(names) or lo.shape != (len(names),) or hi.shape != (len(names),):
        raise ValueError("samples, lower, upper and names must describe the same parameters")
    nulls = nulls or {}
    out = []
    for j, n in enumerate(names):
        med, width = float(np.median(X[:, j])), float(hi[j] - lo[j])
        for side, b in (("lower", lo[j]), ("upper", hi[j])):
            if n in nulls and math.isclose(float(nulls[n]), float(b), rel_tol=0.0, abs_tol=1e-12 * width):
                continue
            if abs(med - b) <= fraction * width:
                out.append({"name": n, "median": med, "side": side, "bound": float(b),
                            "text": f"{n} median {med:.4g} at its {side} bound {b:.4g}"})
    return out


def accept_effect(bic_base: float, bic_aug: float, posterior_samples_of_effect_param, null_value,
                  heldout_err_base: float | None, heldout_err_aug: float | None, *, margin: float = 10.0,
                  interval: float = 0.90, null_tolerance=0.0, explained: float | None = None,
                  min_explained: float = 0.25, pinned: Sequence[dict] | None = None) -> tuple[bool, list[str]]:
    """Keep an added effect only if all hold:

    1. the BIC improves by at least ``margin`` (default 10, "very strong" on Kass & Raftery's scale);
    2. the central ``interval`` (default 90%) of its parameter's posterior excludes the null value by
       more than ``null_tolerance`` (for an effect with several parameters: at least one of them does;
       the tolerance matters for a null at a bound, e.g. a low-pass ``tau = 0``, which every member
       trivially exceeds);
    3. the error on held-out data falls (skipped, and said so, when no held-out data are given);
    4. if ``explained`` is given (the re-calibrated model's drop in chi-square as a fraction of the
       base residual's excess over its noise expectation), it is at least ``min_explained``;
    5. if ``pinned`` is given (:func:`pinned_at_bounds` of the augmented calibration), it is empty: an
       estimate the box decided says only that the answer lies outside the box.

    Returns ``(accepted, reasons)``, one human-readable line per criterion starting with ``pass`` or ``fail``.
    """
    reasons: list[str] = []
    gain = float(bic_base) - float(bic_aug)
    ok_bic = gain >= margin
    reasons.append(f"{'pass' if ok_bic else 'fail'}: BIC {bic_base:.6g} -> {bic_aug:.6g} "
                   f"(improves by {gain:.4g}, margin {margin:g})")

    X = np.asarray(posterior_samples_of_effect_param, dtype=float)
    X = X[:, None] if X.ndim == 1 else X
    nulls = np.broadcast_to(np.asarray(null_value, dtype=float), (X.shape[1],))
    tols = np.broadcast_to(np.asarray(null_tolerance, dtype=float), (X.shape[1],))
    lo_q, hi_q = 0.5 - interval / 2.0, 0.5 + interval / 2.0
    q_lo, q_hi = np.quantile(X, lo_q, axis=0), np.quantile(X, hi_q, axis=0)
    excl = (q_lo - nulls > tols) | (nulls - q_hi > tols)
    ok_null = bool(np.any(excl))
    parts = [f"[{a:.4g}, {b:.4g}] {'excludes' if e else 'contains'} null {z:.4g}"
             for a, b, z, e in zip(q_lo, q_hi, nulls, excl)]
    reasons.append(f"{'pass' if ok_null else 'fail'}: {100 * interval:.0f}% interval " + "; ".join(parts)
                   + (f" (tolerance {', '.join(f'{t:.3g}' for t in tols)})" if np.any(tols > 0) else ""))

    if heldout_err_base is None or heldout_err_aug is None:
        ok_ho = True
        reasons.append("pass: no held-out data, held-out criterion skipped")
    else:
        ok_ho = float(heldout_err_aug) < float(heldout_err_base)
        reasons.append(f"{'pass' if ok_ho else 'fail'}: held-out error {heldout_err_base:.4g} -> "
                       f"{heldout_err_aug:.4g}")
    ok_ex = True
    if explained is not None:
        ok_ex = bool(np.isfinite(explained) and explained >= min_explained)
        reasons.append(f"{'pass' if ok_ex else 'fail'}: explains {explained:.1%} of the excess residual "
                       f"(minimum {min_explained:.0%})")
    ok_box = True
    if pinned is not None:
        ok_box = not pinned
        reasons.append("pass: no estimate at a bound of its box" if ok_box else
                       "fail: set by the box, not the data: " + "; ".join(p["text"] for p in pinned))
    return bool(ok_bic and ok_null and ok_ho and ok_ex and ok_box), reasons


def curve_errors(times, sim, obs) -> dict:
    """``rmse``, ``nrmse`` (by the observed range), ``peak_error`` (``max sim - max obs``), ``peak_rel_error``
    (by ``max obs``) and ``time_to_peak_error`` (``t[argmax sim] - t[argmax obs]``), in the caller's units."""
    t = np.asarray(times, dtype=float)
    y = np.asarray(sim, dtype=float)
    d = np.asarray(obs, dtype=float)
    span = float(d.max() - d.min())
    e = float(rmse(y, d))
    peak_d = float(d.max())
    return {"rmse": e, "nrmse": e / span if span > 0 else math.nan,
            "peak_error": float(y.max()) - peak_d,
            "peak_rel_error": (float(y.max()) - peak_d) / abs(peak_d) if peak_d != 0 else math.nan,
            "time_to_peak_error": float(t[int(np.argmax(y))] - t[int(np.argmax(d))])}
