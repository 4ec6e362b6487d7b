"""``python -m shpb init-config SHEET... --out my.yaml``: a calibration experiment written from a lab's
test sheets (docs/own-data.md), every choice with a YAML comment giving its reason.

* geometry: the sheets' ``specimen.geometry`` (all sheets must share it and the rock; mixed sets are
  refused, since one experiment calibrates one parameter set of one model);
* window: each record is reduced as ``python -m shpb reduce`` does (:func:`~shpb.lab.lab_reduce.reduce_sheet`);
  its onset (:data:`ONSET_FRACTION` of its peak), peak and fall (the first time after the peak where the
  stress is down to :data:`FALL_FRACTION` of it) are found, and the window runs from 0 (the incident
  wave at the specimen's front face) to the latest fall plus a margin, rounded up to :data:`ROUND_S`;
* ``dt``: a round step giving :data:`N_OBS_RANGE` observations in the window, nearest :data:`N_OBS_TARGET`;
* prior box: from the rock class of the sheets' lithology (:data:`ROCK_CLASSES`), else a stated wide
  default; ``E_t``'s box depends on the geometry (a compression cylinder's post-peak at ``fast`` needs an
  order of magnitude more mode II energy than a disc's);
* method and ensemble: ``config/own_data.yaml``'s for a calibration, ``config/diagnosis.yaml``'s with
  ``--diagnosis`` (then one record, the last by test order or ``--heldout``, is held out).

This module reads sheets and writes YAML only; the workflow validates the file
(``calibration.config_check.validate_config``) when it runs.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .lab_reduce import lab_checks, reduce_sheet, transit_time
from .sheet_readers import check_sheet

__all__ = ["RockClass", "ROCK_CLASSES", "WIDE_DEFAULT", "RecordTimes", "record_times", "choose_window",
           "choose_dt", "rock_box", "init_config", "InitConfigError"]

#: A record's onset: the first time its stress reaches this fraction of its peak.
ONSET_FRACTION = 0.05
#: A record's fall: the first time after its peak where its stress is down to this fraction of the peak
#: (the post-peak softening that E_t controls is then inside the window).
FALL_FRACTION = 0.5
#: Margin after the latest fall: this fraction of it, at least :data:`MIN_MARGIN_S`.
MARGIN_FRACTION = 0.10
MIN_MARGIN_S = 10.0e-6
#: Windows are rounded up to a multiple of this [s].
ROUND_S = 10.0e-6
#: Observations in the window: a range, and the count preferred inside it (enough points for the
#: rise, peak and fall; few enough that the misfit's dense covariance stays cheap).
N_OBS_RANGE = (100, 200)
N_OBS_TARGET = 150
#: Round steps (times a power of ten) the observation grid may take.
NICE_STEPS = (1.0, 2.0, 2.5, 5.0)
#: The simulator's output interval in the shipped configs [s].
SAMPLE_DT = 5.0e-7


class InitConfigError(ValueError):
    """A set of sheets that cannot make one experiment (mixed rocks or geometries, too few for a held-out
    record, a window no record covers)."""


@dataclass(frozen=True)
class RockClass:
    """Prior boxes of the model's joint shear strength ``sigma_t`` [Pa] and mode II energy ``E_t``
    [J/m^2] for one rock class at the ``fast`` preset, with where they come from."""

    sigma_t: tuple[float, float]
    E_t_disc: tuple[float, float]
    E_t_cylinder: tuple[float, float]
    sigma_t_source: str
    E_t_cylinder_source: str


_DISC_BOX = "the seed paper's Table 2 box of the granite disc (config/own_data.yaml)"
_CYL_E_T = ("a compression cylinder's post-peak at `fast` needs ~26 kJ/m^2 for the Carrara marble "
            "(docs/closing-the-loop.md; config/config.yaml marble_loop)")
#: Rock classes, matched by a word of the lithology's name (shpb/lab/lithologies.csv or the sheet's).
#: sigma_t is the joint's shear strength (cohesion), E_t the mode II energy (shpb/parameters.py): model
#: parameters at the `fast` mesh, not handbook values, so the boxes are the ones the shipped
#: calibrations chose and converged inside, widened where only one rock was tried (no handbook table
#: is used: a joint's strength at a mesh is not a handbook rock strength).
ROCK_CLASSES: dict[str, RockClass] = {
    "granite": RockClass((4.0e6, 6.0e7), (200.0, 2400.0), (100.0, 5.0e4), _DISC_BOX,
                         f"no granite cylinder was calibrated; the marble's box: {_CYL_E_T}"),
    "marble": RockClass((1.0e7, 1.2e8), (200.0, 2400.0), (100.0, 5.0e4),
                        "the marble cylinder's box of config/config.yaml and config/diagnosis.yaml", _CYL_E_T),
    "sandstone": RockClass((4.0e6, 6.0e7), (200.0, 2400.0), (100.0, 5.0e4),
                           "config/diagnosis.yaml sandstone_loro",
                           f"widened from sandstone_loro's 5 kJ/m^2 to the marble's 50 kJ/m^2: {_CYL_E_T}"),
}
#: Any other rock (no lithology, or a limestone, quartzite, gneiss, ... that no shipped run calibrated):
#: the union of the classes' boxes, wide on purpose; narrow it once a first run shows where the rock sits.
#: Its sigma_t box applies only without records (init-config sets it from their peaks: :data:`PEAK_MULTIPLES`).
WIDE_DEFAULT = RockClass((4.0e6, 1.2e8), (200.0, 2400.0), (100.0, 5.0e4),
                         "no rock class known: the union of the shipped classes' boxes (shpb/lab/init_config.py)",
                         f"the widest shipped box: {_CYL_E_T}")


@dataclass(frozen=True)
class RecordTimes:
    """Times of one reduced record on the face axis [s]; ``fall`` None when the stress does not fall to
    :data:`FALL_FRACTION` of its peak before ``end`` (the reduced record's last time)."""

    name: str
    path: Path
    onset: float
    peak: float
    peak_stress: float
    fall: float | None
    end: float
    validity: str = "valid"
    reasons: tuple[str, ...] = ()


def record_times(name: str, path: Path, time: np.ndarray, stress: np.ndarray) -> RecordTimes:
    """Onset, peak and fall of one reduced stress curve (see the module's docstring)."""
    stress = np.nan_to_num(np.asarray(stress, float), nan=-np.inf)
    i = int(np.argmax(stress))
    peak = float(stress[i])
    onset = float(time[int(np.argmax(stress >= ONSET_FRACTION * peak))])
    after = np.flatnonzero(stress[i:] <= FALL_FRACTION * peak)
    fall = float(time[i + after[0]]) if after.size else None
    return RecordTimes(name, path, onset, float(time[i]), peak, fall, float(time[-1]))


def choose_window(times: list[RecordTimes], heldout: str | None = None) -> tuple[float, str]:
    """``(t_end, reason)``: from 0 to the latest fall of the calibration records plus the margin, rounded
    up, and no later than the shortest reduced record, held-out one included (the workflow refuses a window
    a record does not cover). A held-out record's response (its peak, its fall) never sets the window:
    what it is predicted on is chosen from the calibration records alone; its reduced length comes from
    its bars (2 x_I / c0), not from its response."""
    every = times
    times = [t for t in every if t.name != heldout]
    falls = [t.fall if t.fall is not None else t.end for t in times]
    latest = max(range(len(times)), key=lambda k: falls[k])
    t_fall = falls[latest]
    want = math.ceil((t_fall + max(MARGIN_FRACTION * t_fall, MIN_MARGIN_S)) / ROUND_S - 1e-9) * ROUND_S
    shortest = min(every, key=lambda t: t.end)
    cap = math.floor(shortest.end / ROUND_S + 1e-9) * ROUND_S
    if cap < max(t.peak for t in times):
        raise InitConfigError(f"{shortest.path}: the reduced record ends at {shortest.end * 1e6:.0f} us, before "
                              f"the peak of another record; set reduction.window_s longer in its sheet")
    unseen = [t.name for t in times if t.fall is None]
    why = (f"0 to the latest fall ({times[latest].name}: down to {FALL_FRACTION:.0%} of its peak at "
           f"{t_fall * 1e6:.0f} us) + {MARGIN_FRACTION:.0%} (at least {MIN_MARGIN_S * 1e6:.0f} us), rounded up to "
           f"{ROUND_S * 1e6:.0f} us; holds every calibration record's onset, peak and fall"
           + (f" ({heldout}, held out, is not read)" if heldout else ""))
    if unseen:
        why += f"; {unseen} do not fall that far before their reduced window ends"
    if want > cap:
        why += (f"; cut to {cap * 1e6:.0f} us, where {shortest.name}'s reduced record ends (a longer "
                f"reduction.window_s in its sheet lets the window grow)")
        want = cap
    return want, why


def choose_dt(window: float) -> float:
    """The round step (:data:`NICE_STEPS`) giving a count in :data:`N_OBS_RANGE` nearest :data:`N_OBS_TARGET`."""
    decade = 10.0 ** math.floor(math.log10(window / N_OBS_TARGET))
    steps = [m * decade * f for f in (0.1, 1.0, 10.0) for m in NICE_STEPS]
    lo, hi = N_OBS_RANGE
    ok = [s for s in steps if lo <= window / s <= hi]
    return min(ok or steps, key=lambda s: abs(window / s - N_OBS_TARGET))


def rock_class(lithology: str | None) -> tuple[str | None, RockClass]:
    """``(class name, boxes)`` of a lithology name by a word of it; ``(None, WIDE_DEFAULT)`` when none matches."""
    words = set(re.split(r"[^a-z]+", (lithology or "").lower()))
    for name, cls in ROCK_CLASSES.items():
        if name in words:
            return name, cls
    return None, WIDE_DEFAULT


#: A rock of no class: sigma_t's box as multiples of the highest calibration record's peak stress. The
#: shipped calibrations put the joint's shear strength at about 0.2 of a compression cylinder's peak (the
#: Carrara marble: ~40 MPa for 170-200 MPa peaks) and about 1.4 times a disc's splitting peak (the granite
#: disc: 45 MPa for 33 MPa); each box spans about four times either way. A fixed box failed a weak rock: the
#: Savonnieres limestone's 27-29 MPa peaks put sigma_t against the 4 MPa end of the union box (box_limited).
PEAK_MULTIPLES = {"cylinder": (0.05, 1.0), "brazilian_disc": (0.25, 5.0)}


def _round2(x: float) -> float:
    return float(f"{x:.2g}")


def rock_box(lithology: str | None, geometry: str, peak_stress: float | None = None
             ) -> tuple[dict[str, list[float]], dict[str, str]]:
    """Prior boxes ``{sigma_t, E_t}`` and a reason for each; ``peak_stress``: the highest calibration
    record's peak [Pa], which sets sigma_t's box of a rock of no class (:data:`PEAK_MULTIPLES`)."""
    name, cls = rock_class(lithology)
    label = f"rock class {name} (lithology {lithology})" if name else f"lithology {lithology or 'not given'}"
    e_t = cls.E_t_cylinder if geometry == "cylinder" else cls.E_t_disc
    boxes = {"sigma_t": [*cls.sigma_t], "E_t": [*e_t]}
    sigma_why = cls.sigma_t_source
    if name is None and peak_stress is not None:
        lo, hi = PEAK_MULTIPLES[geometry]
        boxes["sigma_t"] = [_round2(lo * peak_stress), _round2(hi * peak_stress)]
        sigma_why = (f"no rock class known: {lo:g}-{hi:g} x the highest calibration peak "
                     f"({peak_stress / 1e6:.1f} MPa), around the shipped {geometry}'s ratio (shpb/lab/init_config.py)")
    reasons = {"sigma_t": f"joint shear strength [Pa], {label}: {sigma_why}",
               "E_t": f"mode II energy [J/m^2] of a {geometry} at `fast`, {label}: "
                      f"{cls.E_t_cylinder_source if geometry == 'cylinder' else _DISC_BOX}"}
    return boxes, reasons


def _test_order(name: str) -> tuple:
    """Natural order of test names (CaMa_SHPB_9 before CaMa_SHPB_10)."""
    return tuple(int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name))


def read_sheets(paths: list[str | Path]) -> tuple[list, list[RecordTimes]]:
    """The sheets in test order and each record's times; :class:`InitConfigError` for a mixed set."""
    loaded = []
    for p in paths:
        sheet, raw = check_sheet(p)
        red = reduce_sheet(sheet, raw)
        grade = lab_checks(red, transit_time(sheet))["validity"]
        times = record_times(Path(p).stem, Path(p), red.time, red.stress)
        loaded.append((sheet, replace(times, validity=grade["class"], reasons=tuple(grade["reasons"]))))
    loaded.sort(key=lambda st: _test_order(st[1].name))
    for key, what in ((lambda s: s.geometry, "specimen.geometry"),
                      (lambda s: (s.rock.get("lithology") or "").lower() or None, "rock.lithology")):
        kinds = {}
        for sheet, _ in loaded:
            kinds.setdefault(key(sheet), []).append(str(sheet.path))
        if len(kinds) > 1:
            raise InitConfigError(f"the sheets mix {what} values {sorted(map(str, kinds))} ({kinds}); one experiment "
                                  f"calibrates one model of one rock: run init-config once per rock and geometry")
    return [s for s, _ in loaded], [t for _, t in loaded]


def init_config(paths: list[str | Path], *, name: str | None = None, diagnosis: bool = False,
                heldout: str | None = None, seed: int = 31, allow_invalid: bool = False,
                approximation_error: bool = True) -> tuple[str, dict]:
    """``(YAML text with comments, the same document as a dict)``: one calibration experiment from ``paths``.

    The rock is compared by the sheets' ``rock.lithology``; sheets that give only E, nu, rho are taken
    as one rock of no class (the wide default box)."""
    from .init_config_yaml import experiment_yaml

    if not paths:
        raise InitConfigError("give at least one test sheet")
    sheets, times = read_sheets(paths)
    geometry = sheets[0].geometry
    lithology = sheets[0].rock.get("lithology")
    name = name or re.sub(r"[^A-Za-z0-9_-]", "_", f"{lithology or sheets[0].name}_{geometry}".lower())
    if not re.match(r"^[A-Za-z][A-Za-z0-9_-]*$", name):
        raise InitConfigError(f"--name: expected letters, digits, '_' or '-' starting with a letter (it becomes "
                              f"a folder name), got {name!r}")
    held = None
    if diagnosis:
        if len(times) < 3:
            raise InitConfigError(f"--diagnosis: expected at least 3 sheets (one held out, two or more calibrated: "
                                  f"the protocol cross-validates within the calibration records), got {len(times)}")
        names = [t.name for t in times]
        if heldout is not None and heldout not in names:
            raise InitConfigError(f"--heldout: expected the file stem of one of the sheets {names}, got {heldout!r}")
        held = heldout or names[-1]
    elif heldout is not None:
        raise InitConfigError("--heldout: only with --diagnosis (a plain calibration holds no record out)")
    invalid = [t for t in times if t.validity == "invalid" and t.name != held]
    if invalid and not allow_invalid:
        # the workflow refuses them before any job (issue 56); saying so here saves the user a dry run
        raise InitConfigError(
            "invalid as calibration records (python -m shpb reduce SHEET shows the checks): "
            + "; ".join(f"{t.path}: {', '.join(t.reasons)}" for t in invalid)
            + ". Leave them out, fix their sheets, or give --allow-invalid to calibrate on them anyway "
              "(written as observations.allow_invalid: true)")
    window, why_window = choose_window(times, held)
    boxes, why_box = rock_box(lithology, geometry, max(t.peak_stress for t in times if t.name != held))
    return experiment_yaml(name=name, geometry=geometry, lithology=lithology, times=times, window=window,
                           why_window=why_window, dt=choose_dt(window), boxes=boxes, why_box=why_box,
                           heldout=held, seed=seed, invalid=[t.name for t in invalid], approximation=approximation_error)
