"""The emulated FDEM model of SHPB records and its design, for the frozen protocol
(:mod:`calibration.protocol`, :mod:`calibration.closing`).

The protocol re-calibrates the model many times (once per cross-validation fold and candidate effect),
each time with an ensemble of about a hundred members, which FDEM cannot afford. So it runs on an
emulator of the FDEM curves (:class:`enkf.emulator.CurveEmulator`), built from a design of FDEM runs that
spans the base parameters near their calibrated values (:func:`base_design_box`) and every physical
candidate's parameters from their null value up (:func:`physical_design_ranges`, :func:`design_points`).
Measurement effects need no design dimension: they act on the emulated curve through the measurement
chain (:func:`shpb.effects.apply_measurement`), exactly as on a simulated one. The emulator's own error
is the protocol's, time-correlated (:func:`calibration.protocol.emulator_errors`).

Conventions: every record's curve is emulated on one model time grid (:func:`model_grid`, the
simulation's sampling), the measurement chain is applied on that grid, and the result is interpolated
linearly to the record's observation times; records are concatenated in the order given.

Per-record parameters are named ``<effect>.<param>@<record>`` (:func:`shpb.effects.record_param`), and
record A's curve reads only A's copies (:meth:`EmulatedSHPB.forward`). Nothing here reads a record's own
measurement of an effect (its closure before load is measured until the *transmitted* stress rises, so
it reads the record's own answer): a record's per-record value is fitted on it or, for a record the
calibration has not seen, predicted from the calibration records' population
(:mod:`enkf.diagnosis.population`); :class:`calibration.protocol.ProtocolModel` refuses a record without
its own copy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.stats import qmc

from enkf.emulator import AnchoredEmulator, CurveEmulator
from shpb import effects as fx

from .observations import curve_on_grid

__all__ = ["EmulatedSHPB", "anchored_design", "anchored_emulators", "base_design_box", "curve_on_model_grid", "design_points", "emulators_from_design",
           "interpolation_matrix", "measured_curve", "model_grid", "physical_design_ranges", "record_params",
           "workflow_sample"]


def design_points(base_lower, base_upper, physical_lower, physical_upper, n: int, *, seed: int,
                  null_fraction: float = 0.25, physical_nulls=None) -> np.ndarray:
    """``(n, n_base + n_phys)`` design: a Latin hypercube over the whole box for ``(1 - null_fraction) n``
    points and one over the base box with every physical parameter at its null for the rest (the base
    calibration lives on that face, so the emulator is made most accurate there)."""
    bl, bu = np.asarray(base_lower, float), np.asarray(base_upper, float)
    pl, pu = np.asarray(physical_lower, float), np.asarray(physical_upper, float)
    nulls = pl if physical_nulls is None else np.asarray(physical_nulls, float)
    n_null = int(round(null_fraction * n)) if pl.size else n
    n_full = n - n_null
    lo, hi = np.concatenate([bl, pl]), np.concatenate([bu, pu])
    rng = np.random.default_rng(seed)
    full = lo + qmc.LatinHypercube(d=lo.size, seed=rng).random(n_full) * (hi - lo) if n_full else np.zeros((0, lo.size))
    face = bl + qmc.LatinHypercube(d=bl.size, seed=rng).random(n_null) * (bu - bl)
    face = np.column_stack([face, np.broadcast_to(nulls, (n_null, pl.size))])
    return np.vstack([full, face])


def interpolation_matrix(src_times, dst_times) -> np.ndarray:
    """``W`` with ``W @ y`` = ``np.interp(dst_times, src_times, y)`` (dst inside the source range)."""
    src, dst = np.asarray(src_times, float), np.asarray(dst_times, float)
    if dst.min() < src[0] - 1e-12 or dst.max() > src[-1] + 1e-12:
        raise ValueError("observation times outside the model's time grid")
    j = np.clip(np.searchsorted(src, dst, side="right") - 1, 0, src.size - 2)
    w = np.clip((dst - src[j]) / (src[j + 1] - src[j]), 0.0, 1.0)
    W = np.zeros((dst.size, src.size))
    W[np.arange(dst.size), j] = 1.0 - w
    W[np.arange(dst.size), j + 1] += w
    return W


@dataclass
class EmulatedSHPB:
    """Forward model of the protocol: emulated FDEM curves -> measurement chain -> observation times.

    emulators : per record, a :class:`CurveEmulator` over ``input_names`` (the base parameters followed
        by the physical candidates' parameters) whose outputs are the curve on ``model_times``.
    obs_times : per record, the observation times (inside ``model_times``).

    Parameter names are base / effect parameters (one value for every record) or per-record copies
    ``<param>@<record>`` (:func:`shpb.effects.record_param`), which only ``<record>``'s curve reads; a
    parameter a record has no column for is at its null (the contract of
    :class:`enkf.diagnosis.ForwardModel`).
    """

    emulators: Mapping[str, CurveEmulator]
    input_names: Sequence[str]
    model_times: np.ndarray
    obs_times: Mapping[str, np.ndarray]
    _W: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        self.input_names = list(self.input_names)
        self.model_times = np.asarray(self.model_times, float)
        for rec, emu in self.emulators.items():
            if emu.m != self.model_times.size or emu.n_params != len(self.input_names):
                raise ValueError(f"emulator of {rec}: {emu.n_params} inputs x {emu.m} outputs, expected "
                                 f"{len(self.input_names)} x {self.model_times.size}")
        self._W = {rec: interpolation_matrix(self.model_times, t) for rec, t in self.obs_times.items()}

    def _plain_box(self, n: str) -> tuple[float, float]:
        if n in self.input_names:
            emu = next(iter(self.emulators.values()))
            i = self.input_names.index(n)
            return float(emu.lower[i]), float(emu.upper[i])
        effect = fx.effect_of(n)
        if effect is None or effect.kind != "measurement":
            raise ValueError(f"{n} is neither an emulator input nor a measurement effect parameter")
        a, b = fx.bounds([n])
        return float(a[0]), float(b[0])

    def box(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``names`` (a per-record copy: its parameter's): the emulator's box for its inputs, the
        catalogue's for measurement effects."""
        bounds = [self._plain_box(fx.split_record(n)[0]) for n in names]
        return np.array([b[0] for b in bounds], dtype=float), np.array([b[1] for b in bounds], dtype=float)

    @staticmethod
    def _columns(names: Sequence[str], rec: str) -> dict[str, int]:
        """``{plain parameter: column of names}`` record ``rec`` reads: shared names and its own copies."""
        return {fx.split_record(n)[0]: j for j, n in enumerate(names) if fx.split_record(n)[1] in (None, rec)}

    def forward(self, names: Sequence[str], records: Sequence[str]) -> Callable[[np.ndarray], np.ndarray]:
        names = list(names)
        cols = {rec: self._columns(names, rec) for rec in records}
        nulls = {n: fx.null_values([n])[n] for n in self.input_names if "." in n}

        def f(P):
            P = np.array(P, dtype=float, ndmin=2)
            out = []
            for rec in records:
                c = cols[rec]
                X = np.column_stack([P[:, c[n]] if n in c else np.full(P.shape[0], nulls[n])
                                     for n in self.input_names])
                Y = self.emulators[rec](X)
                meas = {p: P[:, j] for p, j in c.items() if p not in self.input_names}
                if meas:
                    Y = np.array([fx.apply_measurement(self.model_times, Y[i], {p: v[i] for p, v in meas.items()})
                                  for i in range(Y.shape[0])])
                out.append(Y @ self._W[rec].T)
            return np.hstack(out)
        return f


def workflow_sample(posterior, names: Sequence[str]) -> np.ndarray:
    """``(N, len(names))``: the workflow's reported posterior sample from ``posterior.csv`` (a frame): an
    ensemble's alive members (its ``alive`` column), or every row of an MCMC sample (no such column).
    These are the draws ``summary.json``'s ``posterior`` summarises."""
    keep = np.asarray(posterior["alive"], bool) if "alive" in posterior else np.ones(len(posterior), bool)
    return np.column_stack([np.asarray(posterior[n], float)[keep] for n in names])


def base_design_box(posterior, names: Sequence[str], prior_lower, prior_upper, *, width_sd: float,
                    min_rel_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Design box of the base parameters: the calibrated posterior's mean +- ``width_sd`` sd, at least
    +- ``min_rel_width`` of the mean (the effects a base calibration absorbed move it that far), widened
    to hold every draw of the posterior (the protocol's base model predicts with those draws on the
    emulator, which is not evaluated outside its design), clipped to the prior box. ``posterior``:
    ``posterior.csv`` (one column per name; :func:`workflow_sample`)."""
    P = workflow_sample(posterior, names)
    mean, sd = P.mean(axis=0), P.std(axis=0, ddof=1)
    half = np.maximum(width_sd * sd, min_rel_width * np.abs(mean))
    lo = np.maximum(np.asarray(prior_lower, float), np.minimum(mean - half, P.min(axis=0)))
    hi = np.minimum(np.asarray(prior_upper, float), np.maximum(mean + half, P.max(axis=0)))
    if np.any(hi <= lo):
        raise ValueError(f"empty design box for {list(names)}: {lo} .. {hi}")
    return lo, hi


def physical_design_ranges(effect_names: Sequence[str], upper_override: Mapping[str, float] | None = None):
    """(param names, nulls, uppers) of the physical candidates' parameters: null value to the catalogue's
    upper bound (or ``upper_override[param]``)."""
    names, lo, hi = [], [], []
    for e in effect_names:
        eff = fx.get_effect(e)
        if eff.kind != "physical":
            continue
        for p in eff.params:
            full = f"{eff.name}.{p.name}"
            top = float((upper_override or {}).get(full, p.upper))
            if not top > p.null:
                raise ValueError(f"diagnosis.physical_upper.{full} = {top:g} must exceed the null value {p.null:g}")
            names.append(full), lo.append(p.null), hi.append(top)
    return names, np.array(lo), np.array(hi)


def model_grid(simulation: Mapping) -> np.ndarray:
    """The model time grid of an experiment's ``simulation`` settings (``t_end``, ``sample_dt``, default
    0.5 us): where emulated and checked curves are compared and the measurement chain acts."""
    dt = simulation.get("sample_dt") or 5.0e-7
    return np.arange(0.0, simulation["t_end"] + 1e-12, dt)


def curve_on_model_grid(curve, model_times) -> np.ndarray | None:
    """A simulated curve (DataFrame with ``time_s``, ``stress_Pa``) on ``model_times``
    (:func:`calibration.observations.curve_on_grid`, the workflow's rule); None when it failed or does not
    cover the grid."""
    if curve is None or len(curve) < 2:
        return None
    y = curve_on_grid(curve["time_s"].to_numpy(float), curve["stress_Pa"].to_numpy(float), model_times)
    return None if np.any(np.isnan(y)) else y


def emulators_from_design(X, curves: Mapping[str, Sequence], model_times, lower, upper, names: Sequence[str],
                          *, label: str = "diagnosis") -> tuple[dict, dict]:
    """One :class:`CurveEmulator` per record from the design ``X`` (points x parameters) and, per record,
    the design runs' curves (DataFrames or None for a failed run), in the order of ``X``. Failed runs
    and runs that do not cover ``model_times`` are left out; returns ``(emulators, n_failed)``.
    Raises ``RuntimeError`` when a record has fewer than ``len(names) + 2`` usable runs."""
    X = np.asarray(X, dtype=float)
    emulators, n_failed = {}, {}
    for rec, runs in curves.items():
        Y = [curve_on_model_grid(c, model_times) for c in runs]
        ok = np.array([y is not None for y in Y], dtype=bool)
        n_failed[rec] = int((~ok).sum())
        if ok.sum() < len(names) + 2:
            raise RuntimeError(f"{label}: only {int(ok.sum())} of {len(Y)} design runs of {rec} succeeded; "
                               f"the emulator needs at least {len(names) + 2}")
        emulators[rec] = CurveEmulator(X[ok], np.array([y for y in Y if y is not None]), lower, upper,
                                       names=list(names))
    return emulators, n_failed


def anchored_design(base_anchor, base_lower, base_upper, physical_nulls, physical_upper, *, base_step: float,
                    sweep: int, cross: Sequence[int] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(X, axis, pair)``: the one-at-a-time design of the anchored selection model
    (:class:`enkf.emulator.AnchoredEmulator`). Row 0 is the anchor: the base parameters at
    ``base_anchor`` (the workflow's posterior mean), every physical effect at its null. Then each base
    parameter moved by ``-+ base_step`` of its design box's width (kept inside the box), and each
    physical parameter moved from its null to ``k / (sweep + 1)`` of its range, ``k = 1..sweep`` (evenly
    spaced inside it: some upper bounds are open), the others at the anchor. ``axis[r]`` is the parameter
    row ``r`` moves (-1 for the anchor).

    ``cross`` (base parameter indices): for each, the physical parameters' runs again with that base
    parameter at its lower step (the emulator's second-order terms: an effect whose size depends on the
    strength, an end friction or a rate law, is measured at a second strength). Those rows have ``axis``
    the physical parameter and ``pair`` the base one; every other row's ``pair`` is -1."""
    a = np.asarray(base_anchor, float)
    bl, bu = np.asarray(base_lower, float), np.asarray(base_upper, float)
    pn, pu = np.asarray(physical_nulls, float), np.asarray(physical_upper, float)
    if not 0.0 < base_step <= 0.5 or int(sweep) < 1:
        raise ValueError(f"base_step must lie in (0, 0.5] and sweep be >= 1, got {base_step}, {sweep}")
    if np.any(a <= bl) or np.any(a >= bu):
        raise ValueError(f"the anchor {a} is not inside the base design box {bl} .. {bu}")
    if any(not 0 <= int(i) < a.size for i in cross) or len(set(cross)) < len(cross):
        raise ValueError(f"cross must list distinct base parameter indices below {a.size}, got {list(cross)}")
    x0 = np.concatenate([a, pn])
    rows, axis, pair = [x0], [-1], [-1]
    low = {}
    for j in range(a.size):
        h = base_step * (bu[j] - bl[j])
        low[j] = max(a[j] - h, 0.5 * (bl[j] + a[j]))
        for v in (low[j], min(a[j] + h, 0.5 * (a[j] + bu[j]))):
            rows.append(np.where(np.arange(x0.size) == j, v, x0)), axis.append(j), pair.append(-1)
    for i in (-1, *(int(c) for c in cross)):
        base = x0 if i < 0 else np.where(np.arange(x0.size) == i, low[i], x0)
        for j in range(pn.size):
            for k in range(1, int(sweep) + 1):
                v = pn[j] + k / (int(sweep) + 1) * (pu[j] - pn[j])  # inside the range: some bounds are open
                rows.append(np.where(np.arange(x0.size) == a.size + j, v, base))
                axis.append(a.size + j), pair.append(i)
    return np.array(rows), np.array(axis, dtype=int), np.array(pair, dtype=int)


def anchored_emulators(X, axis, curves: Mapping[str, Sequence], model_times, lower, upper, names: Sequence[str],
                       *, label: str = "diagnosis", pair=None) -> tuple[dict, dict]:
    """One :class:`enkf.emulator.AnchoredEmulator` per record from the one-at-a-time design ``(X, axis,
    pair)`` (:func:`anchored_design`; ``pair`` None: no cross runs) and, per record, its runs' curves in
    the order of ``X``; a failed run is left out of its axis or pair (an axis with none left is held at the
    anchor, a pair then dropped). Returns ``(emulators, n_failed)``; RuntimeError when a record's anchor
    run failed."""
    X, axis = np.asarray(X, float), np.asarray(axis, int)
    pair = np.full(axis.size, -1) if pair is None else np.asarray(pair, int)
    if axis[0] != -1 or np.any(axis[1:] < 0) or pair.shape != axis.shape:
        raise ValueError("the anchored design's first row must be its anchor and only that row, and pair "
                         "must give one entry per row")
    emulators, n_failed = {}, {}
    for rec, runs in curves.items():
        Y = [curve_on_model_grid(c, model_times) for c in runs]
        n_failed[rec] = sum(y is None for y in Y)
        if Y[0] is None:
            raise RuntimeError(f"{label}: the anchor run of {rec} failed; the anchored model needs it")
        axes, pairs = {}, {}
        for j in sorted(set(axis[1:][pair[1:] < 0].tolist())):
            ok = [r for r in np.flatnonzero((axis == j) & (pair < 0)) if Y[r] is not None]
            axes[j] = (X[ok, j], [Y[r] for r in ok])
        for i, j in sorted({(int(i), int(j)) for i, j in zip(pair, axis) if i >= 0}):
            ok = [r for r in np.flatnonzero((axis == j) & (pair == i)) if Y[r] is not None]
            if ok and all(k in axes and len(axes[k][0]) for k in (i, j)):  # a pair needs both axes' runs
                pairs[(i, j)] = (float(X[ok[0], i]), X[ok, j], [Y[r] for r in ok])
        emulators[rec] = AnchoredEmulator(X[0], Y[0], axes, lower, upper, names=list(names), pairs=pairs)
    return emulators, n_failed


def record_params(values: Mapping[str, float], record: str | None) -> dict[str, float]:
    """One record's parameters from a set with per-record copies: shared ones as they are, the record's own
    copies ``<param>@<record>`` under their plain name, other records' copies dropped. ValueError when a
    per-record parameter has no copy for ``record`` (or ``record`` is None): its value is never filled in
    from elsewhere."""
    out, own, others = {}, {}, set()
    for n, v in values.items():
        p, r = fx.split_record(n)
        if r is None:
            out[n] = v
        elif r == record:
            own[p] = v
        else:
            others.add(p)
    missing = sorted(others - set(own))
    if missing:
        raise ValueError(f"{missing[0]} is estimated per record and has no value for record {record!r}")
    out.update(own)
    return out


def measured_curve(curve, model_times, posterior: Mapping[str, Mapping[str, float]], obs_times,
                   record: str | None = None) -> np.ndarray | None:
    """An FDEM run's curve as the emulated model sees it: on ``model_times``, through the measurement chain
    of ``posterior``'s measurement parameters (``{name: {"mean": value}}``, at their means; per-record ones
    ``record``'s own, :func:`record_params`), at ``obs_times``; None for a failed run. The real runs of the
    protocol's check (:func:`calibration.protocol.real_curves`) are compared with the data this way."""
    y = curve_on_model_grid(curve, model_times)
    if y is None:
        return None
    means = record_params({n: float(v["mean"]) for n, v in posterior.items()}, record)
    meas = {n: v for n, v in means.items() if fx.effect_of(n) is not None and fx.effect_of(n).kind == "measurement"}
    return interpolation_matrix(model_times, obs_times) @ fx.apply_measurement(model_times, y, meas)
