"""The numbers of the workflow config: finite, inside the simulator's bounds, of a plausible magnitude,
and ensembles large enough for their method when members fail.

A JSON Schema ``minimum`` lets NaN through (every comparison with NaN is false) and knows no units, so
a config could pass validation and fail at its first job with a message naming neither key nor file,
or run for hours on a strength written in MPa where Pa was meant. Checked here, before any job:

* :func:`nonfinite_errors`: NaN or +-inf anywhere in the config;
* :func:`range_errors`: every parameter value (``fixed``, both ends of each ``parameters`` and
  ``sensitivity.parameters`` box, a twin's ``observations.truth``, ``diagnosis.physical_upper``)
  inside the simulator's bounds (:func:`shpb.parameters.bounds`) and, with every other dimensional
  field (time window, sampling, noise levels, lengths, time limits), inside a plausible range; a value
  outside it gets the unit slip that would explain it ("did you mean 160 us = 0.00016 s?");
* :func:`ensemble_size_errors`: each method's smallest ensemble, failed members included.

Each message starts with the key path, so :func:`calibration.config_files.error_origin` can name the
file that set it.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

from shpb.parameters import bounds as simulator_bounds

__all__ = ["nonfinite_errors", "range_errors", "ensemble_size_errors", "PARAM_RANGES", "FIELD_RANGES",
           "survivors_needed", "emulator_min_runs"]

_US, _MS, _NS = (1e-6, "us"), (1e-3, "ms"), (1e-9, "ns")
_MPA, _KPA, _GPA = (1e6, "MPa"), (1e3, "kPa"), (1e9, "GPa")
_UM, _MM = (1e-6, "um"), (1e-3, "mm")

#: Plausible range ``(lo, hi, unit, what, slips)`` of a dimensional simulator parameter [SI]; ``slips``
#: the units a value is likely written in by mistake, tried in order (value x factor inside the range).
#: The simulator's own bounds (shpb.parameters.bounds) are checked first; these catch unit slips.
PARAM_RANGES = {
    # Strengths: rock tensile strengths are 1-30 MPa (Kuru granite 13-17 MPa quasi-static, Saksala et
    # al. 2013, Wessling & Kajberg 2022, and 28 MPa dynamic at 400 GPa/s, shpb.parameters; marble
    # 7-10 MPa), joint shear strengths (cohesion) up to about 100 MPa (the marble box's 120 MPa); 0.1 MPa is below any
    # lithology of shpb/lab/lithologies.csv (the weakest, Savonnieres limestone, has E = 11.5 GPa) and
    # no rock's cohesion or dynamic tensile strength reaches 1 GPa.
    "sigma_n": (1e5, 1e9, "Pa", "a strength", (_MPA, _KPA, _GPA)),
    "sigma_t": (1e5, 1e9, "Pa", "a strength", (_MPA, _KPA, _GPA)),
    # Fracture energies: mode I K_Ic^2 / E with K_Ic 0.2-3 MPa m^0.5 and E 10-50 GPa is 1-800 J/m^2
    # (granite 65-115, shpb.parameters); mode II calibrations go higher (the marble post-peak needs
    # about 26e3 J/m^2 at the fast preset, config/config.yaml). A kJ/m^2 slip falls below 1 J/m^2.
    "E_n": (1.0, 1e6, "J/m^2", "a fracture energy", ((1e3, "kJ/m^2"),)),
    "E_t": (1.0, 1e6, "J/m^2", "a fracture energy", ((1e3, "kJ/m^2"),)),
    # Young's modulus: 11.5-44.8 GPa over shpb/lab/lithologies.csv; 1-200 GPa leaves room for weak
    # sandstones and for the stiffest rocks (below steel's 200 GPa).
    "E": (1e9, 2e11, "Pa", "a Young's modulus", (_GPA, _MPA)),
    # Density: 1,881-2,745 kg/m^3 over shpb/lab/lithologies.csv; a g/cm^3 slip gives 1.9-2.7.
    "rho": (1000.0, 5000.0, "kg/m^3", "a rock density", ((1e3, "g/cm^3"),)),
    # Lengths: the simulator's own bounds (shpb.parameters: gaps up to 2 mm); the slips are um and mm.
    "face_gap.gap_m": (0.0, 2e-3, "m", "a gap", (_UM, _MM)),
    "closure.range_m": (0.0, 2e-3, "m", "a closure range", (_UM, _MM)),
}

#: Plausible ranges of the config's other dimensional fields: ``(path under an experiment, lo, hi,
#: unit, what, slips)``. Windows and steps: SHPB tests last 100-500 us (the disc's window 160 us, the
#: cylinder's 360 us, docs/workflow.md "Windows"); the Freiburg records sample at 1.25 MHz (0.8 us,
#: data/freiburg-rae-rock-shpb/PROVENANCE.md); 10 ms is beyond any bar's pulse train, 1 ns below any useful grid step.
FIELD_RANGES = (
    ("observations.t_start", 0.0, 1e-2, "s", "seconds", (_US, _MS)),
    ("observations.t_end", 1e-6, 1e-2, "s", "seconds", (_US, _MS)),
    ("simulation.t_end", 1e-6, 1e-2, "s", "seconds", (_US, _MS)),
    ("observations.dt", 1e-9, 1e-4, "s", "a time step in seconds", (_US, _NS)),
    ("simulation.sample_dt", 1e-9, 1e-4, "s", "a time step in seconds", (_US, _NS)),
    # noise: a fraction of the reference's peak stress (0.01 = 1 %); above 50 % the data say nothing
    ("observations.noise.relative_sigma", 1e-6, 0.5, "", "a fraction of the peak stress", ((1e-2, "%"),)),
    # the records' pre-trigger noise is 0.02-6 MPa on 10-300 MPa peaks (measured on the shipped
    # Freiburg records: 4-8 mV of pre-trigger noise against 0.3-3.4 V pulses); 1 kPa to 100 MPa
    # covers any stress noise a test could have
    ("observations.noise.sigma_Pa", 1e3, 1e8, "Pa", "a stress noise level", (_MPA, _KPA)),
    # a correlation time longer than the window (10 ms at most, above) would be one offset
    ("observations.noise.corr_time", 0.0, 1e-2, "s", "seconds", (_US, _MS)),
)

#: Wall-time limits [s] of one simulation: a week is beyond any preset (paper: 3-15 min, schema.yaml).
TIME_LIMIT_RANGE = (1.0, 7 * 24 * 3600.0)


def _num(v) -> str:
    return f"{v:.6g}"


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def nonfinite_errors(obj, path: str = "") -> list[str]:
    """``key: nan is not a finite number`` for every NaN or +-inf in ``obj`` (a list item named by its
    list's key and index, since the messages' keys are the mapping keys a config file sets)."""
    errors = []
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            errors += nonfinite_errors(v, f"{path}.{k}" if path else str(k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            if _is_number(v) and not math.isfinite(v):
                errors.append(f"{path or '<top level>'}: item {i} is {_num(v)}, not a finite number "
                              f"(expected a finite number)")
            elif isinstance(v, (Mapping, list)):
                errors += [e.replace(": ", f": item {i}: ", 1) for e in nonfinite_errors(v, path)]
    elif _is_number(obj) and not math.isfinite(obj):
        errors.append(f"{path or '<top level>'}: {_num(obj)} is not a finite number (expected a finite number)")
    return errors


def _slip(v: float, lo: float, hi: float, unit: str, slips) -> str:
    for factor, name in slips:
        if lo <= v * factor <= hi and v * factor != 0:
            return f"; did you mean {_num(v)} {name} = {_num(v * factor)}{' ' + unit if unit else ''}?"
    return ""


def _out_of_range(key: str, v: float, lo: float, hi: float, unit: str, what: str, slips,
                  label: str = "") -> str | None:
    if lo <= v <= hi:
        return None
    u = f" {unit}" if unit else ""
    return (f"{key}: {label}{_num(v)} is outside the plausible range of {what}: expected [{_num(lo)}, {_num(hi)}]{u}"
            f"{_slip(v, lo, hi, unit, slips)}")


def _param_value_error(key: str, name: str, v: float, label: str = "", simulator: bool = True) -> str | None:
    """The simulator's bound of parameter ``name`` (shpb.parameters.bounds), then its plausible range;
    ``simulator=False``: a value outside the simulator's bound is left to the caller's own check."""
    try:
        lo, hi, closed_lo = simulator_bounds(name)
    except KeyError:  # an unknown name is reported by the semantic checks
        return None
    plo, phi, unit, what, slips = PARAM_RANGES.get(name, (lo, hi, "", "", ()))
    if not ((v >= lo if closed_lo else v > lo) and v < hi):
        if not simulator:
            return None
        return (f"{key}: {label}{_num(v)} is outside the simulator's range of {name}: expected "
                f"{'>=' if closed_lo else '>'} {_num(lo)} and < {_num(hi)} (shpb.parameters)"
                f"{_slip(v, max(lo, plo), min(hi, phi), unit, slips)}")
    return _out_of_range(key, v, plo, phi, unit, what, slips, label) if name in PARAM_RANGES else None


def _box_errors(key: str, boxes: Mapping, simulator: bool = True) -> list[str]:
    errors = []
    for name, box in (boxes or {}).items():
        if not (isinstance(box, list) and len(box) == 2 and all(_is_number(b) for b in box)):
            continue  # the schema reports its shape
        for end, v in zip(("lower", "upper"), box):
            e = _param_value_error(f"{key}.{name}", name, v, f"the {end} end of [{_num(box[0])}, {_num(box[1])}], ",
                                   simulator)
            if e:
                errors.append(e)
    return errors


def _values_errors(key: str, values: Mapping) -> list[str]:
    out = [_param_value_error(f"{key}.{name}", name, v) for name, v in (values or {}).items() if _is_number(v)]
    return [e for e in out if e]


def _get(block: Mapping, dotted: str):
    for part in dotted.split("."):
        if not isinstance(block, Mapping):
            return None
        block = block.get(part)
    return block


def experiment_range_errors(where: str, exp: Mapping) -> list[str]:
    """Every number of one experiment block against the simulator's bounds and its plausible range."""
    errors = []
    if isinstance(exp.get("parameters"), Mapping):
        errors += _box_errors(f"{where}.parameters", exp["parameters"])
    errors += _values_errors(f"{where}.fixed", exp.get("fixed"))
    errors += _values_errors(f"{where}.observations.truth", (exp.get("observations") or {}).get("truth"))
    # the sensitivity checks (calibration.sensitivity, run next) name a box end the simulator rejects
    errors += _box_errors(f"{where}.sensitivity.parameters", (exp.get("sensitivity") or {}).get("parameters"), False)
    errors += _values_errors(f"{where}.diagnosis.physical_upper", (exp.get("diagnosis") or {}).get("physical_upper"))
    for path, lo, hi, unit, what, slips in FIELD_RANGES:
        v = _get(exp, path)
        if _is_number(v):
            errors.append(_out_of_range(f"{where}.{path}", v, lo, hi, unit, what, slips))
    for p, windows in (exp.get("localization") or {}).items():
        for window in windows:
            for v in window:
                errors.append(_out_of_range(f"{where}.localization.{p}", v, 0.0, 1e-2, "s", "a time in seconds",
                                            (_US, _MS), "a window end, "))
    return [e for e in errors if e]


def range_errors(config: Mapping) -> list[str]:
    """:func:`experiment_range_errors` of every experiment, the time limits and the ensemble sizes."""
    errors = []
    for preset, v in (config.get("member_time_limit_s") or {}).items():
        errors.append(_out_of_range(f"member_time_limit_s.{preset}", v, *TIME_LIMIT_RANGE, "s",
                                    "a simulation's wall time", ((60.0, "min"), (3600.0, "h"))))
    for name, exp in (config.get("experiments") or {}).items():
        errors += experiment_range_errors(f"experiments.{name}", exp)
        errors += ensemble_size_errors(f"experiments.{name}", exp)
    return [e for e in errors if e]


def survivors_needed(n_members: int, min_alive_fraction: float) -> int:
    """The fewest surviving members an analysis goes on with: ``calibration.experiment.analysis_step``
    (and ``enkf.analysis``) stop with :class:`enkf.EnsembleFailure`, naming the failures, below it."""
    return max(2, math.ceil(min_alive_fraction * n_members - 1e-12))


def emulator_min_runs(n_params: int) -> int:
    """Runs ``enkf.emulated.emulated_esmda_update`` needs: its thin-plate RBF with a linear term has
    ``n + 1`` polynomial coefficients and is refitted leaving each run out, so ``n + 2``."""
    return n_params + 2


def ensemble_size_errors(where: str, exp: Mapping) -> list[str]:
    """emulated_esmda: its first analysis has only the prior's surviving members to build the emulator
    on, so the ensemble, and the fewest survivors the failed-member policy goes on with, must give
    :func:`emulator_min_runs`; otherwise a failed member could stop the run with a bare error. (ES-MDA
    and the EnKF need 2 survivors, which the policy's floor guarantees, and members spanning the
    parameters, checked with the prior box.)"""
    if exp.get("method") != "emulated_esmda" or not _is_number(exp.get("ensemble_size")):
        return []
    params = exp.get("parameters")
    # parameters: auto calibrates at least one of the sensitivity block's parameters
    n = len(params) if isinstance(params, Mapping) else 1
    need = emulator_min_runs(n)
    size, fraction = int(exp["ensemble_size"]), float(exp.get("min_alive_fraction", 0.5))
    # the smallest ensemble whose fewest survivors still build the emulator (fraction > 0: the schema)
    smallest = next(s for s in range(need, math.ceil(need / fraction) + 2) if survivors_needed(s, fraction) >= need)
    if size < need:
        return [f"{where}.ensemble_size: {size} members give emulated_esmda's first analysis at most {size} runs, "
                f"but its emulator needs at least {need} (n_params + 2 = {n} + 2: a thin-plate RBF with a linear "
                f"term, refitted leaving each run out); expected ensemble_size >= {smallest} with min_alive_fraction "
                f"{_num(fraction)} (which lets the analysis go on with {survivors_needed(smallest, fraction)} of "
                f"{smallest} members)"]
    survivors = survivors_needed(size, fraction)
    if survivors >= need:
        return []
    return [f"{where}.ensemble_size: {size} members with min_alive_fraction {_num(fraction)} let the first "
            f"analysis go on with as few as {survivors} surviving members, but emulated_esmda's emulator needs "
            f"{need} runs (n_params + 2), so {size - need + 1} or more failed members would stop the run without "
            f"saying why; expected ensemble_size >= {smallest}, or min_alive_fraction >= {_num(need / size)}"]
