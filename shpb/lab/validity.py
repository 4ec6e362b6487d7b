r"""Validity class of a reduced SHPB test: ``valid``, ``questionable`` or ``invalid``, from the lab checks of
:func:`shpb.lab.lab_reduce.lab_checks`, each metric with its thresholds and where they come from.

A test is as good as its worst metric:

=====================  ==================================  =============  ==============
metric                 number                              valid          invalid
=====================  ==================================  =============  ==============
force balance          mean R = 2|F1-F2|/(F1+F2), half     <= 0.05        > 0.10
                       peak to peak (the loading phase)
stress uniformity      loading time to the peak in         >= 4           < pi
                       specimen wave transits
pulse alignment        best shift of F2 onto F1            <= limit       > limit
noise                  pre-trigger stress sd / peak        <= 0.02        > 0.05
=====================  ==================================  =============  ==============

and ``questionable`` in between. Sources: force balance, Zhou et al. (2012), ISRM suggested methods for
the dynamic strength of rock (Rock Mech. Rock Eng. 45): the forces on the specimen's faces agree within
about 5 % in the loading phase; 0.10 is the lab check's limit (:data:`shpb.lab.lab_reduce.BALANCE_LIMIT`)
beyond which the test failed it; the Brazilian formula
:math:`2F/(\pi D t)` holds only under force balance (Dai et al. 2010, Int. J. Rock Mech. Min. Sci. 47).
Stress uniformity: Davies & Hunter (1963, J. Mech. Phys. Solids 11) found a specimen's stress uniform
after about :math:`\pi` wave transits, Ravichandran & Subhash (1994, J. Am. Ceram. Soc. 77) asked for
about four. Pulse alignment: a shift beyond the wave's transit through the specimen means a wrong gauge
distance or bar wave speed (:mod:`shpb.lab.lab_reduce`): the reduced stress is then wrong in time.
Noise: the project's own criteria (no literature value): the calibration's observation error is the
pre-trigger noise, 2 % keeps it a small part of the curve, above 5 % it dominates the fit.
"""
from __future__ import annotations

import math

__all__ = ["CLASSES", "THRESHOLDS", "classify"]

CLASSES = ("valid", "questionable", "invalid")
#: metric -> (valid up to / from, invalid beyond / below, source). Ranges are inclusive on the valid side.
THRESHOLDS = {
    "force_balance": (0.05, 0.10, "Zhou et al. 2012 (ISRM suggested method): forces within ~5 % in the loading "
                                  "phase; above 0.10 the lab check fails"),
    "stress_uniformity": (4.0, math.pi, "Davies & Hunter 1963: uniform after ~pi transits; Ravichandran & "
                                        "Subhash 1994: about 4"),
    "pulse_alignment": (1.0, 1.0, "shift beyond the specimen transit: wrong gauge distance or bar wave speed"),
    "noise": (0.02, 0.05, "project criterion: the observation error is the pre-trigger noise"),
}

#: The short citation a reason line carries (the full one is in ``metrics``).
_CITE = {"force_balance": "Zhou et al. 2012, ISRM", "stress_uniformity": "Davies & Hunter 1963",
         "pulse_alignment": "gauge distance or bar wave speed", "noise": "project criterion"}


def _grade(value: float, valid: float, invalid: float, higher_is_better: bool) -> str:
    if not math.isfinite(value):
        return "invalid"
    if higher_is_better:
        return "valid" if value >= valid else ("questionable" if value >= invalid else "invalid")
    return "valid" if value <= valid else ("questionable" if value <= invalid else "invalid")


def classify(checks: dict) -> dict:
    """``{"class", "reasons", "metrics"}`` from :func:`shpb.lab.lab_reduce.lab_checks`' dict: each metric's
    value, thresholds, source and grade; ``reasons``: one line per metric graded below ``valid``."""
    fb, al, nz, su = (checks["force_balance"], checks["pulse_alignment"], checks["noise"],
                      checks["stress_uniformity"])
    values = {
        "force_balance": (fb["mean_R_half_peak_to_peak"], False, "mean R from half peak to peak"),
        "stress_uniformity": (su["transits_to_peak"], True, "wave transits through the specimen up to the peak"),
        "pulse_alignment": (abs(al["best_shift_back_s"]) / al["limit_s"], False,
                            "|best shift of F2| over its limit (the specimen transit)"),
        "noise": (nz["noise_over_peak"], False, "pre-trigger stress noise over the peak"),
    }
    metrics, reasons = {}, []
    for name, (value, higher, what) in values.items():
        valid, invalid, source = THRESHOLDS[name]
        grade = _grade(float(value), valid, invalid, higher)
        metrics[name] = {"value": float(value), "what": what, "valid": valid, "invalid": invalid,
                         "higher_is_better": higher, "source": source, "class": grade}
        if grade != "valid":
            op = "<" if higher else ">"
            bound = invalid if grade == "invalid" else valid
            reasons.append(f"{name} {grade}: {what} {float(value):.3g} {op} {bound:.3g} ({_CITE[name]})")
    worst = max((CLASSES.index(m["class"]) for m in metrics.values()), default=0)
    return {"class": CLASSES[worst], "reasons": reasons, "metrics": metrics}
