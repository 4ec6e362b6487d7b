"""Effect catalogue: switchable model extensions for closing the loop (docs/closing-the-loop.md).

The base model declares none of these. Each effect is a named entry with its parameters (named
``<effect>.<param>``, SI units), a prior box, a null value (the value at which the effect is off and
the model is the base model) and a one-line description with its equation. Two kinds:

* **measurement** effects act on a simulated specimen-stress curve ``s(t)`` in the measurement chain
  and cost no new FDEM run. Applied in this order (all are linear in ``s``; shift, low-pass and gain
  commute, the baseline is added after the gain so the gain does not scale it)::

      y(t) = g * LP_tau[s](t - dt) + offset + drift * (t - t_0)          t_0 = time_s[0]

  ``trigger_shift.dt_s``            dt [s]: a positive dt delays the curve, s(t - dt) by linear
                                    interpolation (held at the first/last value outside the record).
  ``gauge_gain.g``                  g [-]: gauge factor / bridge calibration error, multiplicative.
  ``baseline.offset_Pa``            offset [Pa] and
  ``baseline.drift_Pa_per_s``       drift [Pa/s]: a zero-level error and a linear drift from t_0.
  ``lowpass.tau_s``                 tau = 1 / (2 pi f_c) [s]: a one-pole (RC) amplifier low-pass,
                                    tau y' + y = x, applied causally. Parametrised by tau rather than
                                    f_c so the null (no filter, f_c = infinity) is the finite tau = 0.

  The low-pass is discretised exactly for an input that is linear between samples (first-order hold)
  on a uniform grid of step h, with a = exp(-h / tau)::

      y_k = a y_{k-1} + b0 x_k + b1 x_{k-1},   b0 = 1 - (tau/h)(1 - a),   b1 = (tau/h)(1 - a) - a

  (``scipy.signal.lfilter``; b0 + b1 = 1 - a, so a constant passes unchanged; tau -> 0 gives
  y = x.) The filter starts in steady state at the first sample. Its step response is
  ``1 - exp(-t / tau)``: 63.2% at t = tau. To first order in tau it is a delay by tau
  (``LP_tau[s] ~ s - tau s'``), the same first-order signature as a trigger shift; the two separate
  at second order (the low-pass also rounds the peak), which is why the protocol
  (:func:`enkf.diagnosis.select_effects`) re-calibrates each candidate it tries rather than choosing on
  the linearised score test.

* **physical** effects live in the FDEM engine and need a new simulation. They are declared here
  (name, parameters, box, null, meaning) and passed to the simulator as extra
  ``--param <effect>.<param>=value``; the nulls are the base model's settings:

  ``rate_strength.k``               dynamic increase factor on both joint strengths,
                                    sigma_n,t(rate) = sigma_n,t * DIF, DIF = max(1, 1 + k log10(rate/rate0)),
                                    rate0 = :data:`RATE0_PER_S` = 1 /s (quasi-static; no weakening below it),
                                    rate = the joint's local strain rate, opening (normal) or sliding
                                    (tangential) rate divided by the joint's element size h. k = 0.425
                                    gives DIF = 1.85 at 100 /s, the cap of one published tensile law
                                    (notes/reference-values.md), hence the box [0, 0.6].
  ``damping.beta``                  element viscous damping as a fraction of critical,
                                    eta = 2 h beta sqrt(E rho) (Y lineage; fdem.model.build_model's
                                    damping_beta). Null 0 (the base model is undamped).
  ``interface_friction.mu``         Coulomb friction coefficient of the bar-specimen contact
                                    (fdem.model.ContactParams.friction). Null 0 (frictionless faces).
  ``seating.compliance_m_per_Pa``   seating compliance C of the loaded faces: an extra face closure
                                    delta = C sigma_n in series with the contact penalty, i.e. the
                                    face's normal stiffness per unit area 1 / (1/k_contact + C).
                                    Null 0 (perfect seating). A granite specimen's own compliance L/E
                                    is ~1e-12 m/Pa (50 mm / 35 GPa), a 50 um asperity closure at
                                    50 MPa is 1e-12 m/Pa; box [0, 2e-12].
  ``face_gap.gap_m``                closure [m] the incident bar's face travels before the specimen
                                    takes any load: an initial gap between bar and specimen
                                    (shpb.geometry ``face_gap_m``), closed by contact. Null 0. It is
                                    the large-closure limit of seating, which a penalty layer cannot
                                    carry (a closure of 100 um is a quarter of a fast specimen
                                    element). Where it comes from in a real test: ends not flat or
                                    not parallel, no preload to close the seating, an interlayer; a
                                    gap at the back face acts the same to within the specimen's
                                    inertia (~0.1 kg pushed ahead of the bar). The Freiburg records'
                                    own evidence: the incident bar's face (from incident and
                                    reflected waves) travels 100-270 um while the specimen carries
                                    under 5 % of its peak (README, "Closing the loop"). Box [0, 400 um].
                                    With ``closure`` on, gap_m is the mean of a gap spread across the face.
  ``closure.range_m``               Delta [m]: a **gradual closure** of the loaded face (a non-parallel
                                    or rough front end). The gap between the incident bar's face and
                                    the specimen is not one number: it spreads linearly across the face
                                    over Delta around the mean gap g = ``face_gap.gap_m``, from
                                    g_lo = max(0, g - Delta/2) (first touch) to g_hi = g + Delta/2
                                    (full contact). When the bar's face has advanced by u the contact
                                    covers the fraction a(u) = clip((u - g_lo) / (g_hi - g_lo), 0, 1)
                                    of the face, so the face's contact stiffness rises with closure
                                    instead of jumping. Two forms of the law (tests/test_closure.py
                                    checks the second on the model): quasi-static, on a bed of
                                    independent fibres of stiffness k per unit area and Delta <= 2 g,
                                    F(u) = k A (u - g_lo)^2 / (2 Delta) for g_lo <= u <= g_hi, then
                                    k A (u - g) (quadratic closure, then linear: the hard gap's line);
                                    dynamic, each fibre that touches carries the 1D transmitted force,
                                    so during the specimen's first transit the front force is
                                    F(t) = a(u(t)) 2 Z_s / (Z_s + Z_b) F_I(t) (Z = rho c A of specimen
                                    and bar, F_I the incident force, u(t) = 2 int v_I dt the free face's
                                    travel), rising from zero at u = g_lo without a step. Delta -> 0 is
                                    today's hard gap g, whose force jumps by 2 Z_s / (Z_s + Z_b) F_I(t_c)
                                    at closure (30-40 MPa on the marble records). Null 0 (flat, parallel
                                    ends; the base mesh bit for bit). Box [0, 400 um], the records' face
                                    travel before load. Why this law and this parameterisation: one
                                    parameter, a length; a uniform spread of gap heights over
                                    [g_lo, g_hi] (a rough end's asperities, in the mean) gives the same
                                    a(u) as a tilted flat end; and with g the mean gap the closure nests
                                    the hard gap (a calibration that has fitted ``face_gap`` keeps its g
                                    and only grows Delta from 0). Measured on a fast CaMa_SHPB_004 member
                                    (g 135 um, Delta 150 um, 1.5 % noise, linearised): g and Delta are
                                    correlated +0.14, where first touch and Delta would be -0.82.
                                    A record's measured closure before load (the travel until 2 % of
                                    the peak) is then nearer g_lo than g. Usable with ``face_gap`` (mean gap
                                    g) or without it (g = 0: contact from the start, full at Delta/2).
                                    Implemented as geometry (``shpb.geometry.closure_faces`` and
                                    ``_tilt_front``: the specimen's front face tilted by g_hi - g_lo, the
                                    back face flat), not as a kernel law: the engine's node-to-edge
                                    penalty contact resolves the growing contact itself, so the effect
                                    costs nothing per step and nothing at all at its null. In 2D the face
                                    is a line and the contact width grows linearly with closure; a 3D
                                    tilted circular end would first touch at one rim point (area ~
                                    (u - g_lo)^(3/2) early on).

**Scope.** Every entry says whether it is a property of one test (``per_record``: the seating of that
specimen, the trigger and amplifier settings of that recording) or of the material and model
(``shared``). The protocol (:func:`enkf.diagnosis.select_effects`) estimates a per-record parameter
once per calibration record, as ``<effect>.<param>@<record>`` (:func:`record_param`), each copy acting on
its own record only; a record the calibration has not seen takes its copy from the population of the
calibration records' estimates, never from its own curve. (A record's closure before load,
``ReducedRecord.closure_before_load``, is measured until the *transmitted* stress rises: it reads the
record's answer and sets no face gap.)

Public helpers: :func:`get_effect`, :func:`effects`, :func:`effect_of`, :func:`split_params`,
:func:`apply_measurement`, :func:`bounds`, :func:`null_values`, :func:`candidates`, :func:`record_param`,
:func:`split_record`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

#: Reference strain rate of the rate-strength law [1/s]: DIF = 1 at and below it.
RATE0_PER_S = 1.0

KINDS = ("physical", "measurement")
#: ``per_record``: a property of one test, estimated once per record; ``shared``: of the material / model.
SCOPES = ("per_record", "shared")
#: Separator of a per-record parameter copy's name: ``face_gap.gap_m@CaMa_SHPB_004``.
RECORD_SEP = "@"


@dataclass(frozen=True)
class EffectParam:
    """One parameter of an effect: short name (``dt_s``), prior box, null value, unit."""

    name: str
    lower: float
    upper: float
    null: float
    unit: str

    def __post_init__(self):
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise ValueError(f"parameter {self.name!r}: need finite lower < upper")
        if not self.lower <= self.null <= self.upper:
            raise ValueError(f"parameter {self.name!r}: null {self.null} outside [{self.lower}, {self.upper}]")


@dataclass(frozen=True)
class Effect:
    """A switchable model extension.

    ``apply`` (measurement effects only) maps ``(time_s, stress_Pa, **short_params) -> stress_Pa``.
    ``fdem`` says, for physical effects, what the engine does with the parameters.
    ``scope`` is ``per_record`` or ``shared`` (:data:`SCOPES`, module docstring).
    The attributes ``name``, ``param_names``, ``nulls``, ``scope`` are what
    :func:`enkf.diagnosis.select_effects` reads from a candidate.
    """

    name: str
    kind: str
    params: tuple[EffectParam, ...]
    description: str
    fdem: str = ""
    apply: Callable[..., np.ndarray] | None = field(default=None, repr=False, compare=False)
    scope: str = ""

    def __reduce__(self):
        # a catalogue entry travels by name (its apply functions are lambdas, which pickle cannot carry):
        # the diagnosis hands its selection from one Snakemake job to the next as a pickle
        return (get_effect, (self.name,))

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"effect {self.name!r}: kind must be one of {KINDS}")
        if self.scope not in SCOPES:
            raise ValueError(f"effect {self.name!r}: scope must be one of {SCOPES}, got {self.scope!r}")
        if (self.kind == "measurement") != (self.apply is not None):
            raise ValueError(f"effect {self.name!r}: measurement effects (only) need an apply function")

    @property
    def param_names(self) -> tuple[str, ...]:
        """Full parameter names, ``<effect>.<param>``."""
        return tuple(f"{self.name}.{p.name}" for p in self.params)

    @property
    def nulls(self) -> tuple[float, ...]:
        return tuple(p.null for p in self.params)

    @property
    def lower(self) -> tuple[float, ...]:
        return tuple(p.lower for p in self.params)

    @property
    def upper(self) -> tuple[float, ...]:
        return tuple(p.upper for p in self.params)

    def null_params(self) -> dict[str, float]:
        """``{<effect>.<param>: null}``."""
        return dict(zip(self.param_names, self.nulls))

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"name": self.name, "kind": self.kind, "scope": self.scope, "description": self.description,
                "fdem": self.fdem, "params": {f"{self.name}.{p.name}": {"lower": p.lower, "upper": p.upper,
                                                                         "null": p.null, "unit": p.unit}
                                              for p in self.params}}


# ----------------------------------------------------------------------------------------------
# Measurement-chain operators: (time_s, stress_Pa, parameter) -> stress_Pa
# ----------------------------------------------------------------------------------------------

def _as_curve(time_s, stress_Pa) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(time_s, dtype=float)
    s = np.asarray(stress_Pa, dtype=float)
    if t.ndim != 1 or s.shape != t.shape or t.size < 2:
        raise ValueError(f"time_s and stress_Pa must be 1-D arrays of equal length >= 2, got {t.shape}, {s.shape}")
    if np.any(np.diff(t) <= 0):
        raise ValueError("time_s must be strictly increasing")
    return t, s


def uniform_step(time_s) -> float:
    """The sampling step of a uniform time grid; ValueError if the steps differ by more than 1e-6."""
    t = np.asarray(time_s, dtype=float)
    steps = np.diff(t)
    h = float(np.mean(steps))
    if np.max(np.abs(steps - h)) > 1e-6 * h:
        raise ValueError("the low-pass filter needs a uniform time grid (resample the curve first)")
    return h


def time_shift(time_s, stress_Pa, dt_s: float) -> np.ndarray:
    """``s(t - dt)`` by linear interpolation; a positive ``dt_s`` delays the curve. Outside the record the
    first (before) and last (after) values are held."""
    t, s = _as_curve(time_s, stress_Pa)
    return np.interp(t - float(dt_s), t, s, left=s[0], right=s[-1])


def gain(time_s, stress_Pa, g: float) -> np.ndarray:
    """``g s(t)``."""
    _, s = _as_curve(time_s, stress_Pa)
    return float(g) * s


def baseline(time_s, stress_Pa, offset_Pa: float = 0.0, drift_Pa_per_s: float = 0.0) -> np.ndarray:
    """``s(t) + offset + drift (t - t_0)``, ``t_0`` the first sample time."""
    t, s = _as_curve(time_s, stress_Pa)
    return s + float(offset_Pa) + float(drift_Pa_per_s) * (t - t[0])


def lowpass_coefficients(h: float, tau_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(b, a)`` of the first-order-hold discretisation of ``tau y' + y = x`` with step ``h``."""
    if not (math.isfinite(tau_s) and tau_s >= 0):
        raise ValueError(f"lowpass.tau_s must be finite and >= 0, got {tau_s}")
    if tau_s == 0.0:
        return np.array([1.0, 0.0]), np.array([1.0, 0.0])
    a = math.exp(-h / tau_s)
    c = (tau_s / h) * (-math.expm1(-h / tau_s))  # (tau/h)(1 - a), accurate for small h/tau
    return np.array([1.0 - c, c - a]), np.array([1.0, -a])


def lowpass(time_s, stress_Pa, tau_s: float) -> np.ndarray:
    """One-pole amplifier low-pass ``tau y' + y = x`` (cutoff ``f_c = 1/(2 pi tau)``), causal, starting in
    steady state at the first sample; ``tau_s = 0`` returns the curve unchanged. Uniform grid only."""
    t, s = _as_curve(time_s, stress_Pa)
    if float(tau_s) == 0.0:
        return s.copy()
    # here, not at the top: the workflow's parse reads the catalogue, and scipy.signal imports SciPy's
    # stats (~1.5 s of every dry run, issue 54)
    from scipy import signal

    b, a = lowpass_coefficients(uniform_step(t), float(tau_s))
    zi = signal.lfilter_zi(b, a) * s[0]
    y, _ = signal.lfilter(b, a, s, zi=zi)
    return y


def cutoff_hz(tau_s: float) -> float:
    """``f_c = 1 / (2 pi tau)`` [Hz]; infinite for ``tau = 0``."""
    return math.inf if tau_s == 0 else 1.0 / (2.0 * math.pi * tau_s)


# ----------------------------------------------------------------------------------------------
# The catalogue
# ----------------------------------------------------------------------------------------------

_P = EffectParam

CATALOGUE: dict[str, Effect] = {e.name: e for e in (
    # measurement chain (order of application: MEASUREMENT_ORDER)
    # per record: each recording is triggered, and its waves aligned, on its own
    Effect("trigger_shift", "measurement", (_P("dt_s", -10e-6, 10e-6, 0.0, "s"),),
           "trigger time shift: y(t) = s(t - dt) (linear interpolation; dt > 0 delays)",
           apply=lambda t, s, dt_s=0.0: time_shift(t, s, dt_s), scope="per_record"),
    Effect("lowpass", "measurement", (_P("tau_s", 0.0, 5e-6, 0.0, "s"),),
           "one-pole amplifier low-pass: tau y' + y = s, tau = 1/(2 pi f_c) (null 0 = no filter; "
           "tau <= 5 us is f_c >= 32 kHz)",
           apply=lambda t, s, tau_s=0.0: lowpass(t, s, tau_s),
           scope="per_record"),  # per record: the amplifier's filter is set for each test
    Effect("gauge_gain", "measurement", (_P("g", 0.8, 1.2, 1.0, "-"),),
           "gauge gain: y(t) = g s(t)",
           apply=lambda t, s, g=1.0: gain(t, s, g),
           scope="per_record"),  # per record: bridge excitation and amplifier gain are set for each test
    Effect("baseline", "measurement",
           (_P("offset_Pa", -5e6, 5e6, 0.0, "Pa"), _P("drift_Pa_per_s", -1e10, 1e10, 0.0, "Pa/s")),
           "baseline offset and drift: y(t) = s(t) + offset + drift (t - t_0)",
           apply=lambda t, s, offset_Pa=0.0, drift_Pa_per_s=0.0: baseline(t, s, offset_Pa, drift_Pa_per_s),
           scope="per_record"),  # per record: zero level and drift of that recording
    # physical (FDEM engine)
    Effect("rate_strength", "physical", (_P("k", 0.0, 0.6, 0.0, "-"),),
           "strain-rate-dependent joint strength: sigma_n,t * DIF, DIF = max(1, 1 + k log10(rate/rate0)), "
           "rate0 = 1 /s",
           fdem="multiplies the tensile (sigma_n) and shear (sigma_t) strength of each joint by the DIF of "
                "the joint's local strain rate (opening or sliding rate / element size h), rate0 = "
                "RATE0_PER_S",
           scope="shared"),  # shared: a law of the rock, the same in every test
    Effect("damping", "physical", (_P("beta", 0.0, 1.0, 0.0, "-"),),
           "element viscous damping: eta = 2 h beta sqrt(E rho), beta a fraction of critical",
           fdem="fdem.model.build_model(damping_beta=beta); the stable time step shrinks by "
                "sqrt(1 + beta^2) - beta",
           scope="shared"),  # shared: a property of the material / the model's discretisation
    Effect("interface_friction", "physical", (_P("mu", 0.0, 0.6, 0.0, "-"),),
           "bar-specimen Coulomb friction: |tau| <= mu sigma_n at the loaded faces",
           fdem="fdem.model.ContactParams(friction=mu) on the bar-specimen contact pairs",
           scope="shared"),  # shared: the same bar faces, rock and lubrication in every test of a series
    Effect("face_gap", "physical", (_P("gap_m", 0.0, 4e-4, 0.0, "m"),),
           "face gap: the incident bar's face travels gap_m before the specimen takes load (ends not flat "
           "or not parallel, seating never closed by a preload, a squeezed interlayer)",
           fdem="initial gap between the incident bar's face and the specimen's front face "
                "(shpb.geometry face_gap_m); contact closes it",
           # per record: every specimen has its own ends and seating
           scope="per_record"),
    Effect("closure", "physical", (_P("range_m", 0.0, 4e-4, 0.0, "m"),),
           "gradual face closure: a non-parallel (or rough) front end, the gap spread across the face over "
           "range_m around the mean gap g = face_gap.gap_m, from max(0, g - range/2) to g + range/2, so the "
           "contact fraction grows linearly with the bar face's advance (no step at closure)",
           fdem="the specimen's front face tilted across its height (shpb.geometry.closure_faces, "
                "closure_range_m; the back face flat); the bar-specimen penalty contact closes it "
                "progressively",
           # per record: every specimen has its own ends
           scope="per_record"),
    Effect("seating", "physical", (_P("compliance_m_per_Pa", 0.0, 2e-12, 0.0, "m/Pa"),),
           "contact seating: extra face closure delta = C sigma_n at the loaded faces",
           fdem="normal stiffness per unit area of the bar-specimen contact 1/(1/k_contact + C), "
                "C = compliance_m_per_Pa, in series with the contact penalty",
           scope="per_record"),  # per record: the contact of that specimen's faces in that test
)}

#: Order in which :func:`apply_measurement` applies the measurement effects.
MEASUREMENT_ORDER = ("trigger_shift", "lowpass", "gauge_gain", "baseline")

_PARAM_INDEX: dict[str, tuple[Effect, EffectParam]] = {
    f"{e.name}.{p.name}": (e, p) for e in CATALOGUE.values() for p in e.params
}


def get_effect(name: str) -> Effect:
    """The catalogue entry ``name``; KeyError naming the known effects otherwise."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; the catalogue has {sorted(CATALOGUE)}") from None


def effects(kind: str | None = None) -> list[Effect]:
    """Catalogue entries, all or of one ``kind`` ("physical" | "measurement")."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS} or None")
    return [e for e in CATALOGUE.values() if kind is None or e.kind == kind]


def record_param(param_name: str, record: str) -> str:
    """The name of ``record``'s copy of a per-record parameter: ``face_gap.gap_m@CaMa_SHPB_004``."""
    if RECORD_SEP in param_name or not record or RECORD_SEP in record:
        raise ValueError(f"cannot name a per-record copy of {param_name!r} for record {record!r}")
    return f"{param_name}{RECORD_SEP}{record}"


def split_record(name: str) -> tuple[str, str | None]:
    """``(parameter, record)`` of a per-record copy's name, ``(name, None)`` for any other name."""
    param, sep, record = name.partition(RECORD_SEP)
    return (param, record) if sep else (name, None)


def effect_of(param_name: str) -> Effect | None:
    """The effect a parameter (or a per-record copy of one, :func:`record_param`) belongs to; ``None``
    for a base parameter (no dot). A dotted name that is not in the catalogue raises KeyError (typos
    should not pass silently as base parameters)."""
    param_name = split_record(param_name)[0]
    if "." not in param_name:
        return None
    try:
        return _PARAM_INDEX[param_name][0]
    except KeyError:
        raise KeyError(f"unknown effect parameter {param_name!r}; known: {sorted(_PARAM_INDEX)}") from None


def split_params(params: Mapping[str, float]) -> tuple[dict, dict, dict]:
    """Split a parameter mapping into ``(base, physical, measurement)`` dicts (order kept).

    Physical parameters go to the simulator together with the base ones; measurement ones to
    :func:`apply_measurement`.
    """
    base, physical, measurement = {}, {}, {}
    for name, value in params.items():
        e = effect_of(name)
        (base if e is None else physical if e.kind == "physical" else measurement)[name] = value
    return base, physical, measurement


def apply_measurement(curve_time, curve_stress, params: Mapping[str, float]) -> np.ndarray:
    """Apply the measurement chain to a simulated curve: ``y = g LP_tau[s](t - dt) + offset + drift (t - t_0)``.

    ``params`` may hold any parameters (base and physical ones are ignored); missing measurement
    parameters take their null values, so ``apply_measurement(t, s, {})`` returns ``s`` unchanged.
    """
    t, s = _as_curve(curve_time, curve_stress)
    _, _, meas = split_params(params)
    copies = [n for n in meas if split_record(n)[1] is not None]
    if copies:
        raise ValueError(f"per-record parameters {copies}: give the chain one record's values under their plain "
                         "names (calibration.diagnose.record_params)")
    by_effect: dict[str, dict[str, float]] = {}
    for name, value in meas.items():
        effect, p = _PARAM_INDEX[name]
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{name} = {value!r} is not finite")
        by_effect.setdefault(effect.name, {})[p.name] = v
    y = s.copy()
    for name in MEASUREMENT_ORDER:
        if name in by_effect:
            y = CATALOGUE[name].apply(t, y, **by_effect[name])
    return y


def _param(name: str) -> EffectParam:
    effect_of(name) or _raise_base(name)
    return _PARAM_INDEX[split_record(name)[0]][1]


def bounds(param_names: Iterable[str]) -> tuple[np.ndarray, np.ndarray]:
    """Prior box ``(lower, upper)`` of the named effect parameters (a per-record copy: its effect's box)."""
    ps = [_param(n) for n in param_names]
    return np.array([p.lower for p in ps]), np.array([p.upper for p in ps])


def catalogue_edge(param_name: str, value: float, tol_fraction: float = 0.0) -> str | None:
    """``"lower"`` or ``"upper"`` where ``value`` of an effect parameter (or a per-record copy) lies within
    ``tol_fraction`` of its box's width from that end of the catalogue's range and the end is not its null
    (an effect taken as far as the catalogue allows); else None (inside, or on the null, where "no effect"
    sits)."""
    p = _param(param_name)
    side = box_end(value, p.lower, p.upper, tol_fraction)
    tol = float(tol_fraction) * (p.upper - p.lower)
    edge = p.lower if side == "lower" else p.upper
    return side if side is not None and abs(edge - p.null) > tol else None


def box_end(value: float, lower: float, upper: float, tol_fraction: float = 0.0) -> str | None:
    """``"lower"`` or ``"upper"`` where ``value`` lies within ``tol_fraction`` of the box's width from that end of
    ``[lower, upper]``; else None."""
    tol = float(tol_fraction) * (float(upper) - float(lower))
    for side, edge in (("lower", lower), ("upper", upper)):
        if abs(float(value) - float(edge)) <= tol:
            return side
    return None


def null_values(param_names: Iterable[str] | None = None) -> dict[str, float]:
    """``{param: null}`` for the named effect parameters or per-record copies (all of the catalogue by
    default)."""
    names = list(_PARAM_INDEX) if param_names is None else list(param_names)
    return {n: _param(n).null for n in names}


def candidates(names: Iterable[str] | None = None, kind: str | None = None) -> list[Effect]:
    """The effects to offer the protocol: the named ones, or all (of a ``kind``)."""
    if names is not None:
        return [get_effect(n) for n in names]
    return effects(kind)


def _raise_base(name: str):
    raise KeyError(f"{name!r} is a base parameter, not an effect parameter")
