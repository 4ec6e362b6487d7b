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
