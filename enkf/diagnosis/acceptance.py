"""Curve errors of a prediction against the data: RMSE, peak and time-to-peak errors, what the frozen
protocol reports for its confirmation runs and held-out records (:mod:`enkf.diagnosis`)."""
from __future__ import annotations

import math

import numpy as np

from ..diagnostics import rmse


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


def replicate_curve_errors(times, sims, obs) -> dict:
    """:func:`curve_errors` of one curve, or of ``(K, m)`` replicated runs (one per realization of the
    simulator): then ``rmse`` is the root of the mean squared error over all of them (the expected error
    of one run), the other errors their means, with ``replicates`` and ``rmse_per_replicate``."""
    s = np.asarray(sims, dtype=float)
    if s.ndim == 1:
        return curve_errors(times, s, obs)
    each = [curve_errors(times, row, obs) for row in s]
    out = {k: float(np.mean([e[k] for e in each])) for k in each[0]}
    out["rmse"] = float(np.sqrt(np.mean([e["rmse"] ** 2 for e in each])))
    span = float(np.ptp(np.asarray(obs, dtype=float)))
    out["nrmse"] = out["rmse"] / span if span > 0 else math.nan
    out["replicates"] = int(s.shape[0])
    out["rmse_per_replicate"] = [e["rmse"] for e in each]
    return out
