r"""A test sheet reduced as a lab reduces it (``python -m shpb reduce SHEET.yaml``): the curves, the
force-balance figure and the checks a lab runs before it trusts a test.

* :func:`reduce_sheet`: the reduction of :mod:`shpb.lab.reduction` with the sheet's bars, specimen and
  settings. A Brazilian disc's stress is the splitting stress :math:`\sigma = 2F/(\pi D t)` of each
  face's force (:func:`brazilian`); its strain rate is the nominal one over the diameter.
* :func:`lab_checks`: force balance around the peak, pulse alignment, noise level, each with its
  number, its limit and ``ok``.
* :func:`write_reduction`: ``curves.csv`` (SI), ``force_balance.png`` and ``checks.json``, atomically.

The checks (limits are the usual SHPB practice; a failed check is reported, never hidden):

1. **Force balance**: :math:`R = 2|F_1-F_2|/(F_1+F_2)` averaged from the first time the specimen stress
   reaches half its peak up to the peak; a test is in dynamic equilibrium when the mean is at most
   0.10 (Zhou et al. 2012, ISRM suggested method: the forces on both faces agree within about 5-10 %).
2. **Pulse alignment**: the shift of :math:`F_2` in time that best matches :math:`F_1` on the loading
   rise (least squares over whole samples, up to 50 us either way). Once the specimen is in
   equilibrium the two forces agree, so with a correct gauge distance and bar wave speed the shift
   stays within the stress wave's transit through the specimen (:math:`L\sqrt{\rho/E}` of the rock, at
   least three samples); a gauge distance wrong by :math:`\Delta x` shows as a shift of about
   :math:`-\Delta x/c_0`.
3. **Noise level**: the standard deviation of the pre-trigger specimen stress over its peak, at most
   2 % for the calibration's observation error to be a small part of the curve.
4. **Stress uniformity**: the loading time from 10 % of the peak stress to the peak, in wave transits
   through the specimen (at least about pi to four: :mod:`shpb.lab.validity`).

From these the test gets a validity class, ``valid``, ``questionable`` or ``invalid``
(:mod:`shpb.lab.validity`, with each threshold's source), written to ``checks.json``.

:func:`reduce_sheet` refuses, as a :class:`~shpb.lab.sheet.SheetError` naming the sheet and its fields,
a record with a non-finite sample on any channel or an implausible sampling interval
(:mod:`shpb.lab.checks`), a record that cannot be reduced (no incident pulse, too short a record: the
message names the sheet fields that set the sign or the window), and, asked to, a sheet whose stated peak
stress or strain rate disagrees with its record beyond :data:`shpb.lab.checks.STATED_TOLERANCE`.
"""
from __future__ import annotations

import io
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import atomic_write_bytes, atomic_write_text
from .checks import raw_problems, stated_problems
from .errors import ReductionError
from .reduction import ReducedRecord, reduce_record
from .validity import classify

__all__ = ["reduce_sheet", "brazilian", "lab_checks", "write_reduction", "REDUCED_COLUMNS",
           "BALANCE_LIMIT", "NOISE_LIMIT"]

#: Columns of ``curves.csv`` (SI units; stresses compression positive).
REDUCED_COLUMNS = ("time_s", "stress_Pa", "stress_front_Pa", "stress_back_Pa", "strain_rate_per_s", "strain",
                   "force_front_N", "force_back_N", "force_balance", "eps_incident", "eps_reflected",
                   "eps_transmitted")
BALANCE_LIMIT = 0.10
NOISE_LIMIT = 0.02
MAX_SHIFT_S = 50.0e-6


def brazilian(red: ReducedRecord, diameter: float, thickness: float) -> ReducedRecord:
    r"""A disc record reduced as a cylinder of the disc's diameter, with its stresses turned into the
    splitting stress :math:`2F/(\pi D t)` (the cylinder's were :math:`F/(\pi D^2/4)`: factor :math:`D/2t`)."""
    k = diameter / (2.0 * thickness)
    return replace(red, stress_front=red.stress_front * k, stress_back=red.stress_back * k,
                   stress_mean=red.stress_mean * k, noise_std_Pa={key: v * k for key, v in red.noise_std_Pa.items()},
                   notes=red.notes + ["Brazilian disc: stress = 2F/(pi D t); strain rate and strain are nominal, "
                                      "over the diameter"])


#: Where a sheet sets each field a reduction error names (:class:`~shpb.lab.errors.ReductionError`).
_SHEET_FIELDS = {"E": "bars.E", "rho": "bars.rho", "gauge_distance_incident": "bars.gauge_distance_incident",
                 "gauge_distance_transmitted": "bars.gauge_distance_transmitted", "window_s": "reduction.window_s"}


def _sheet_fields(sheet, fields: tuple[str, ...]) -> str:
    csv = sheet.format == "csv"
    names = {**_SHEET_FIELDS,
             "compression_sign": "signals.compression_sign" if csv else f"signals.format ({sheet.format}: its sign)",
             "time": "signals.time.unit" if csv else "signals.file (its time axis)"}
    return ", ".join(names[f] for f in fields if f in names) or "signals.file"


def reduce_sheet(sheet, raw=None, *, check_stated: bool = False, **overrides) -> ReducedRecord:
    """Reduce a sheet's record (``raw``: its :func:`~shpb.lab.sheet_readers.read_sheet_record`, read if None)
    with the sheet's bars, specimen and ``reduction`` settings (``overrides`` win); with
    ``dispersion_correction: true`` the bar signals are corrected for Pochhammer-Chree dispersion with the
    bars' Poisson ratio (:mod:`shpb.lab.dispersion`). Every problem is a :class:`~shpb.lab.sheet.SheetError`
    naming the sheet (module docstring); ``check_stated``: refuse a sheet whose metadata disagree with the
    result (``python -m shpb reduce`` and a calibration's check do; off for a study of a changed sheet)."""
    from .sheet import SheetError

    if raw is None:
        from .sheet_readers import read_sheet_record

        raw = read_sheet_record(sheet)
    where = str(sheet.path)
    problems = raw_problems(raw, where, "signals.time.unit" if sheet.format == "csv" else "signals.file")
    if problems:
        raise SheetError(problems)
    try:
        red = _reduce(sheet, raw, overrides)
    except ReductionError as exc:
        raise SheetError([f"{where}: {_sheet_fields(sheet, exc.fields)}: {exc} (signals file {sheet.signals_file})"]
                         ) from None
    except ValueError as exc:
        raise SheetError([f"{where}: {exc} (signals file {sheet.signals_file})"]) from None
    problems = stated_problems(sheet.metadata, red, where) if check_stated else []
    if problems:
        raise SheetError(problems)
    return red


def _reduce(sheet, raw, overrides: dict) -> ReducedRecord:
    opts = {"window_s": sheet.reduction.get("window_s"),
            "exclude_channels": tuple(sheet.reduction.get("exclude_channels", ())),
            "dispersion_nu": sheet.bar_nu if sheet.reduction.get("dispersion_correction", False) else None,
            **overrides}
    D = sheet.specimen_diameter
    if sheet.geometry == "cylinder":
        return reduce_record(raw, raw.bar, sheet.specimen_length, D, **opts)
    return brazilian(reduce_record(raw, raw.bar, D, D, **opts), D, float(sheet.specimen["thickness"]))


def _best_shift(red: ReducedRecord, rise: slice) -> float:
    """Time shift [s] of F_back that best matches F_front over ``rise`` (least squares, whole samples)."""
    F1, F2, dt = red.force_front, red.force_back, red.dt
    m = int(round(MAX_SHIFT_S / dt))
    idx = np.arange(rise.start, rise.stop)
    best, best_err = 0, math.inf
    for s in range(-m, m + 1):
        j = idx + s
        ok = (j >= 0) & (j < F2.size)
        if ok.sum() < 0.5 * idx.size:
            continue
        err = float(np.mean((F1[idx[ok]] - F2[j[ok]]) ** 2))
        if err < best_err:
            best, best_err = s, err
    return best * dt


def lab_checks(red: ReducedRecord, transit_s: float) -> dict:
    """The checks of the module docstring and the test's validity class (:func:`shpb.lab.validity.classify`,
    under ``validity``). ``transit_s``: the wave's transit through the specimen [s]."""
    i_pk = red.peak_index
    half = np.flatnonzero(red.stress_back[: i_pk + 1] >= 0.5 * red.peak_stress)
    i0 = int(half[0]) if half.size else i_pk
    R = red.force_balance[i0: i_pk + 1]
    R = R[np.isfinite(R)]
    mean_R = float(np.mean(R)) if R.size else float("nan")
    rise0 = int(np.flatnonzero(red.stress_back[: i_pk + 1] >= 0.1 * red.peak_stress)[0])
    shift = _best_shift(red, slice(rise0, i_pk + 1))
    shift_limit = max(transit_s, 3.0 * red.dt)
    noise = red.noise_std_Pa["stress"] / red.peak_stress
    rise_time = red.peak_time - float(red.time[rise0])
    checks = {
        "force_balance": {"mean_R_half_peak_to_peak": mean_R, "R_at_peak": red.force_balance_at_peak,
                          "from_s": float(red.time[i0]), "to_s": red.peak_time, "limit": BALANCE_LIMIT,
                          "ok": bool(mean_R <= BALANCE_LIMIT)},
        "pulse_alignment": {"best_shift_back_s": shift, "transit_s": transit_s, "limit_s": shift_limit,
                            "ok": bool(abs(shift) <= shift_limit)},
        "noise": {"stress_noise_Pa": red.noise_std_Pa["stress"], "peak_stress_Pa": red.peak_stress,
                  "noise_over_peak": noise, "limit": NOISE_LIMIT, "ok": bool(noise <= NOISE_LIMIT)},
        "stress_uniformity": {"transits_to_peak": rise_time / transit_s if transit_s > 0 else float("nan"),
                              "from_s": float(red.time[rise0]), "to_s": red.peak_time, "transit_s": transit_s},
        "peak_stress_Pa": red.peak_stress, "peak_time_s": red.peak_time,
        "strain_rate_at_peak_per_s": red.strain_rate_at_peak,
        "strain_rate_loading_per_s": red.mean_strain_rate_loading(), "notes": list(red.notes),
    }
    checks["validity"] = classify(checks)
    return checks


def transit_time(sheet) -> float:
    """Time [s] the rock's bar wave takes across the specimen (length, or a disc's diameter)."""
    size = sheet.specimen_length if sheet.geometry == "cylinder" else sheet.specimen_diameter
    return float(size * math.sqrt(sheet.rock["rho"] / sheet.rock["E"]))


def _figure_png(red: ReducedRecord, checks: dict, title: str) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6))
    FigureCanvasAgg(fig)
    ax, axr = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    t = red.time * 1e6
    ax.plot(t, red.force_front / 1e3, label="front face F1 (incident + reflected)")
    ax.plot(t, red.force_back / 1e3, label="back face F2 (transmitted)")
    ax.axvline(red.peak_time * 1e6, color="k", lw=0.6, ls=":")
    ax.set_ylabel("force [kN]")
    ax.legend(fontsize=8)
    fb = checks["force_balance"]
    ax.set_title(f"{title}: peak {red.peak_stress / 1e6:.1f} MPa, mean R {fb['mean_R_half_peak_to_peak']:.3f} "
                 f"({'ok' if fb['ok'] else 'NOT balanced'})", fontsize=9)
    axr.plot(t, red.force_balance, color="tab:red")
    axr.axhline(BALANCE_LIMIT, color="k", lw=0.6, ls="--")
    axr.axvspan(fb["from_s"] * 1e6, fb["to_s"] * 1e6, color="0.9")
    axr.set_ylim(0, 1)
    axr.set_ylabel("R = 2|F1-F2|/(F1+F2)")
    axr.set_xlabel("time at the specimen faces [us]")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    return buf.getvalue()


def reduced_frame(red: ReducedRecord) -> pd.DataFrame:
    return pd.DataFrame({
        "time_s": red.time, "stress_Pa": red.stress_back, "stress_front_Pa": red.stress_front,
        "stress_back_Pa": red.stress_back, "strain_rate_per_s": red.strain_rate, "strain": red.strain,
        "force_front_N": red.force_front, "force_back_N": red.force_back, "force_balance": red.force_balance,
        "eps_incident": red.eps_incident, "eps_reflected": red.eps_reflected, "eps_transmitted": red.eps_transmitted,
    }, columns=list(REDUCED_COLUMNS))


def write_reduction(red: ReducedRecord, checks: dict, out_dir: str | Path, title: str = "") -> dict[str, Path]:
    """``curves.csv``, ``force_balance.png``, ``checks.json`` in ``out_dir``, each written atomically."""
    out = Path(out_dir)
    paths = {"curves": out / "curves.csv", "figure": out / "force_balance.png", "checks": out / "checks.json"}
    atomic_write_text(paths["curves"], reduced_frame(red).to_csv(index=False, float_format="%.9g"))
    atomic_write_bytes(paths["figure"], _figure_png(red, checks, title or red.name))
    clean = json.loads(json.dumps(checks, default=float).replace("NaN", "null"))
    atomic_write_text(paths["checks"], json.dumps(clean, indent=2) + "\n")
    return paths
