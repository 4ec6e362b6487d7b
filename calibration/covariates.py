"""Test covariates across records: the residual's trends against every covariate a test sheet gives.

Closing the loop (docs/closing-the-loop.md) looks across records for a residual that
trends with a property of the test: a trend names the effect that depends on it. The strain rate
points at a rate law; the specimen's length-to-diameter ratio at a geometry effect (end-friction
confinement of a short specimen, the records' L/D runs from 0.74 to 1.1); the gas (striker) pressure
at the loading itself. Each record's ``record_info`` (:func:`calibration.observations.measured_observations`)
carries them:

============================ ============================= =====================================
column                       record_info key               source
============================ ============================= =====================================
``strain_rate_per_s``        ``strain_rate_at_peak_per_s`` the reduction (strain rate at the peak)
``length_to_diameter``       ``length_to_diameter``        the sheet / spreadsheet (L / D) [-]
``gas_pressure_Pa``          ``gas_pressure_Pa``           the Freiburg spreadsheet's "P (bar)",
                                                           or a sheet's metadata [Pa]
``striker_velocity_m_s``     ``striker_velocity_m_s``      a sheet's metadata, when given [m/s]
============================ ============================= =====================================

(``length_to_diameter`` falls back to ``specimen_length_m / specimen_diameter_m`` for record
information written before it existed.) :func:`record_covariates` returns one row per record with one
column per covariate (NaN where the record does not give it) and the residual's statistics;
:func:`covariate_table_trends` runs :func:`enkf.diagnosis.covariate_trends` against each covariate that
varies across the records; :func:`pointed_at` names the covariates with a significant trend. The
workflow's table (:func:`calibration.closing.covariate_table`) holds the calibration records' residuals at
the base model's calibration.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from enkf.diagnosis import covariate_trends
from enkf.diagnostics import jsonable

#: ``(column, record_info key)`` of every covariate, in the order of the table's columns.
COVARIATES: tuple[tuple[str, str], ...] = (
    ("strain_rate_per_s", "strain_rate_at_peak_per_s"),
    ("length_to_diameter", "length_to_diameter"),
    ("gas_pressure_Pa", "gas_pressure_Pa"),
    ("striker_velocity_m_s", "striker_velocity_m_s"),
)
#: The residual statistics the trends are computed for by default (columns of :func:`record_covariates`).
RESIDUAL_COLUMNS = ("mean_resid_sd", "rms_resid_sd")


def _number(v) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return math.nan
    return f if math.isfinite(f) else math.nan


def covariate_values(info: Mapping) -> dict[str, float]:
    """``{column: value}`` of every covariate (:data:`COVARIATES`) in one record's information; NaN where
    it is not given. L/D falls back to ``specimen_length_m / specimen_diameter_m``."""
    out = {col: _number(info.get(key)) for col, key in COVARIATES}
    if math.isnan(out["length_to_diameter"]):
        L, D = _number(info.get("specimen_length_m")), _number(info.get("specimen_diameter_m"))
        if D > 0:
            out["length_to_diameter"] = L / D
    return out


def record_covariates(record_info: Mapping[str, Mapping], residuals: Mapping[str, np.ndarray],
                      sigma: Mapping[str, float]) -> pd.DataFrame:
    """Per record (one row each, in the order of ``residuals``): ``record``, one column per covariate
    (:data:`COVARIATES`), ``peak_stress_Pa``, and the mean / RMS of the calibrated model's residual in
    units of the record's noise sd (``mean_resid_sd``, ``rms_resid_sd``)."""
    rows = []
    for rec, r in residuals.items():
        info = record_info.get(rec, {})
        r = np.asarray(r, dtype=float)
        rows.append({"record": rec, **covariate_values(info), "peak_stress_Pa": _number(info.get("peak_stress_Pa")),
                     "mean_resid_sd": float(np.mean(r) / sigma[rec]),
                     "rms_resid_sd": float(np.sqrt(np.mean(r ** 2)) / sigma[rec])})
    return pd.DataFrame(rows, columns=["record", *(c for c, _ in COVARIATES), "peak_stress_Pa", *RESIDUAL_COLUMNS])


def covariate_table_trends(table: pd.DataFrame, columns: Sequence[str] = RESIDUAL_COLUMNS,
                           covariates: Sequence[str] | None = None) -> pd.DataFrame | None:
    """:func:`enkf.diagnosis.covariate_trends` of ``columns`` against every covariate of ``table`` that
    at least three records give and that varies across them. One row per (covariate, column), with a
    ``covariate`` column in front; None when no covariate qualifies."""
    names = [c for c, _ in COVARIATES] if covariates is None else list(covariates)
    parts = []
    for cov in names:
        if cov not in table:
            continue
        x = table[cov].to_numpy(dtype=float)
        ok = np.isfinite(x)
        if ok.sum() < 3 or np.ptp(x[ok]) == 0:
            continue
        t = covariate_trends(table, cov, [c for c in columns if c != cov]).reset_index()
        t.insert(0, "covariate", cov)
        parts.append(t)
    return pd.concat(parts, ignore_index=True) if parts else None


def pointed_at(trends: pd.DataFrame | None, column: str = "mean_resid_sd", alpha: float = 0.01,
               test: str = "p_pearson") -> list[str]:
    """The covariates against which ``column`` trends significantly (``test`` p-value below ``alpha``),
    most significant first."""
    if trends is None:
        return []
    t = trends[(trends["column"] == column) & (trends[test] < alpha)].sort_values(test)
    return t["covariate"].tolist()


#: The check's real-run errors whose trends across the calibration records the report shows.
ERROR_COLUMNS = ("peak_rel_error_before", "peak_rel_error_after")


def peak_error_trends(errors: Mapping[str, Mapping], record_info: Mapping[str, Mapping],
                      records: Sequence[str]) -> dict:
    """The calibration ``records``' relative peak errors of the real cross-validated FDEM runs before and
    after the loop (``errors``: check.json's ``errors_per_record``) against every covariate their sheets
    give, and the trends across them (:func:`covariate_table_trends`, at least three records).

    The peak error is the statistic a rate law or an end-friction confinement moves (a stronger response
    at a higher rate, a shorter specimen); a trend before the loop that is gone after it says the kept
    effect took up that dependence. Held-out records are not in ``records``: their covariates come from
    their own response (the strain rate at their peak)."""
    rows = []
    for rec in records:
        e = errors.get(rec) or {}
        rows.append({"record": rec, **covariate_values(record_info.get(rec, {})),
                     **{f"peak_rel_error_{w}": _number((e.get(w) or {}).get("peak_rel_error"))
                        for w in ("before", "after")}})
    table = pd.DataFrame(rows, columns=["record", *(c for c, _ in COVARIATES), *ERROR_COLUMNS])
    trends = covariate_table_trends(table, ERROR_COLUMNS)
    return jsonable({"records": table.to_dict(orient="records"),
                     "trends": None if trends is None else trends.to_dict(orient="records"),
                     "note": "calibration records only, the relative peak error (model - record) / record of the "
                             "real cross-validated runs; trends need three records whose covariate varies"})
