"""The discrepancy loop (:func:`enkf.diagnosis.diagnose_loop`) on SHPB experiments.

The loop re-calibrates the model once per candidate effect it tries, each time with an ensemble of
about a hundred members, which FDEM cannot afford per candidate. So the re-calibrations run on an
emulator of the FDEM curves (:class:`enkf.emulator.CurveEmulator`), built from a design of FDEM runs
that spans the base parameters near their calibrated values and every physical candidate's parameters
from their null value up (:func:`design_points`). Measurement effects need no design dimension: they act
on the emulated curve through the measurement chain (:func:`shpb.effects.apply_measurement`), exactly
as on a simulated one. The emulator's own leave-one-out error is added to the observation error as an
independent term (:func:`enkf.emulator.with_emulator_error`), so interpolation error is not read as
structure; the report states it.

Conventions: every record's curve is emulated on one model time grid (the simulation's sampling),
the measurement chain is applied on that grid, and the result is interpolated linearly to the record's
observation times; records are concatenated in the order given.

Scopes (:data:`shpb.effects.SCOPES`): a ``per_record`` candidate is offered to the loop with one copy of
each parameter per calibration record, ``<effect>.<param>@<record>`` (:func:`record_candidates`), and
the forward model of record A reads only A's copies (:meth:`EmulatedSHPB.forward`); the score test
therefore has ``k`` = parameters x records degrees of freedom. A held-out record has no copy: it takes
its prior centre where its own waves measure the effect (``record_prior``, e.g. the face closure before
load for ``face_gap``), else the null, and the report says which (``per_record`` in the report).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.stats import qmc

from enkf import BoxTransform, assimilate, esmda_alphas, latin_hypercube
from enkf.covariance import ObservationError
from enkf.diagnosis import Candidate, CalibrationResult, curve_errors, diagnose_loop, finite_difference_sensitivity
# the report writers and the effect catalogue, for the workflow's diagnosis step (scripts/ reach enkf
# and shpb through calibration only)
from enkf.diagnosis import covariate_trends, report_to_json, write_report  # noqa: F401
from shpb.effects import get_effect  # noqa: F401
from enkf.emulator import CurveEmulator, with_emulator_error

from shpb import effects as fx
from .observations import curve_on_grid

__all__ = ["design_points", "interpolation_matrix", "EmulatedSHPB", "diagnose", "emulators_from_design",
           "errors_per_record", "fdem_confirmation", "model_grid", "simulator_params", "measured_curve", "check_errors", "record_calibrations",
           "record_candidates", "record_params", "record_prior_centres", "heldout_fill"]


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
    """Forward model for the loop: emulated FDEM curves -> measurement chain -> observation times.

    emulators : per record, a :class:`CurveEmulator` over ``input_names`` (the base parameters followed
        by the physical candidates' parameters) whose outputs are the curve on ``model_times``.
    obs_times : per record, the observation times (inside ``model_times``).
    record_centres : per record, ``{param: value}`` the record's own measurement of a per-record parameter
        (:func:`record_prior_centres`): the centre of that record's prior box (:func:`shpb.effects.centred_box`)
        and a held-out record's value.

    Parameter names are base / effect parameters (one value for every record) or per-record copies
    ``<param>@<record>`` (:func:`shpb.effects.record_param`), which only ``<record>``'s curve reads.
    """

    emulators: Mapping[str, CurveEmulator]
    input_names: Sequence[str]
    model_times: np.ndarray
    obs_times: Mapping[str, np.ndarray]
    record_centres: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
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

    def prior_centre(self, param: str, record: str) -> float | None:
        """The record's measured centre of ``param`` clipped to its box, None where it measures none."""
        c = self.record_centres.get(record, {}).get(param)
        return None if c is None else fx.centred_box(param, c, within=self._plain_box(param))[0]

    def box(self, names: Sequence[str], *, centred: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``names``: the emulator's box for its inputs, the catalogue's for measurement effects;
        a per-record copy whose record measures its value (``record_centres``) gets the box centred on it
        (:func:`shpb.effects.centred_box`, inside the former) unless ``centred`` is False."""
        lo, hi = [], []
        for n in names:
            p, rec = fx.split_record(n)
            a, b = self._plain_box(p)
            c = self.record_centres.get(rec, {}).get(p) if rec is not None and centred else None
            if c is not None:
                _, a, b = fx.centred_box(p, c, within=(a, b))
            lo.append(a), hi.append(b)
        return np.array(lo), np.array(hi)

    def record_value(self, param: str, record: str) -> tuple[float, str]:
        """``(value, source)`` of a per-record parameter for a record that has no copy of its own (a
        held-out record): its prior centre where its waves measure it, else the null."""
        c = self.prior_centre(param, record)
        if c is not None:
            keys = dict(fx.effect_of(param).record_prior)
            return c, f"prior centre: the record's own {keys.get(param.split('.', 1)[1], 'measurement')}"
        return fx.null_values([param])[param], "null (the record does not measure it)"

    def _sources(self, names: list[str], rec: str) -> dict:
        """Where record ``rec`` takes each effect parameter from: a column of ``names`` (shared, or its own
        copy) or a value (a per-record effect in ``names`` of which ``rec`` has no copy)."""
        src, copied = {}, set()
        for j, n in enumerate(names):
            p, r = fx.split_record(n)
            if r is None or r == rec:
                src[p] = ("col", j)
            else:
                copied.add(p)
        for p in copied - set(src):
            src[p] = ("val", self.record_value(p, rec)[0])
        return src

    def forward(self, names: Sequence[str], records: Sequence[str]) -> Callable[[np.ndarray], np.ndarray]:
        names = list(names)
        plans = {rec: self._sources(names, rec) for rec in records}
        nulls = {n: fx.null_values([n])[n] for n in self.input_names if "." in n}

        def value(src, p, P):
            kind, v = src[p]
            return P[:, v] if kind == "col" else np.full(P.shape[0], v)

        def f(P):
            P = np.array(P, dtype=float, ndmin=2)
            out = []
            for rec in records:
                src = plans[rec]
                X = np.column_stack([value(src, n, P) if n in src else np.full(P.shape[0], nulls[n])
                                     for n in self.input_names])
                Y = self.emulators[rec](X)
                meas = {p: value(src, p, P) for p in src if p not in self.input_names}
                if meas:
                    Y = np.array([fx.apply_measurement(self.model_times, Y[i], {p: v[i] for p, v in meas.items()})
                                  for i in range(Y.shape[0])])
                out.append(Y @ self._W[rec].T)
            return np.hstack(out)
        return f

    def emulator_std(self, records: Sequence[str]) -> np.ndarray:
        """Leave-one-out emulator error at the observation times of ``records``, concatenated."""
        return np.concatenate([np.sqrt(self._W[r] ** 2 @ self.emulators[r].error_std() ** 2) for r in records])


def _seed_for(seed: int, names: Sequence[str]) -> int:
    """A calibration's seed from the run's seed and its parameter names (independent of call order)."""
    return (int(seed) * 1_000_003 + zlib.crc32(",".join(names).encode())) % (2 ** 32)


def _emulated_esmda(model: EmulatedSHPB, names: Sequence[str], records: Sequence[str], obs, err: ObservationError,
                    seed: int, n_members: int, esmda_steps: int):
    """ES-MDA of ``names`` against ``obs`` of ``records`` on the emulator, from a Latin hypercube over the
    emulator's box; returns ``(result, forward, lower, upper)``."""
    names = list(names)
    lo, hi = model.box(names)
    f = model.forward(names, records)
    rng = np.random.default_rng(seed)
    res = assimilate(f, latin_hypercube(lo, hi, n_members, rng), obs, err, rng=rng, method="esmda",
                     alphas=esmda_alphas(esmda_steps), transform=BoxTransform(lo, hi), names=names)
    return res, f, lo, hi


def _scope(c, scopes: Mapping[str, str] | None) -> str:
    s = (scopes or {}).get(c.name, getattr(c, "scope", "shared"))
    if s not in fx.SCOPES:
        raise ValueError(f"scope of {c.name}: {s!r} is not one of {fx.SCOPES}")
    return s


def record_candidates(candidates: Sequence, records: Sequence[str], scopes: Mapping[str, str] | None = None) -> list:
    """The candidates as the loop sees them: a ``per_record`` effect (``scope``, or ``scopes[name]`` where
    given) becomes a :class:`enkf.diagnosis.Candidate` of the same name with one copy of each parameter per
    record, ``<effect>.<param>@<record>`` (record by record), the effect's nulls and box repeated; ``shared``
    effects and candidates without a scope (generic :class:`enkf.diagnosis.Candidate`) are returned as they
    are."""
    out = []
    for c in candidates:
        if _scope(c, scopes) != "per_record":
            out.append(c)
            continue
        k = len(records)
        out.append(Candidate(c.name, tuple(fx.record_param(p, r) for r in records for p in c.param_names),
                             tuple(c.nulls) * k, tuple(c.lower) * k, tuple(c.upper) * k))
    return out


def record_prior_centres(record_info: Mapping[str, Mapping], candidates: Sequence) -> dict[str, dict[str, float]]:
    """Per record, the prior centres its own measurements give the candidates' per-record parameters:
    ``{record: {<effect>.<param>: record_info[record][key]}}`` for the catalogue's ``record_prior`` pairs
    (``face_gap.gap_m`` <- ``closure_before_load_m``); records without the value are left out."""
    out: dict[str, dict[str, float]] = {}
    for c in candidates:
        eff = fx.get_effect(c if isinstance(c, str) else c.name)
        for short, key in eff.record_prior:
            for rec, info in record_info.items():
                v = info.get(key)
                if v is not None and np.isfinite(float(v)):
                    out.setdefault(rec, {})[f"{eff.name}.{short}"] = float(v)
    return out


def _per_record_report(model: EmulatedSHPB, candidates: Sequence, calib_records: list, heldout_records: list,
                       added: Sequence[str], scopes: Mapping[str, str] | None) -> dict:
    per = [c for c in candidates if _scope(c, scopes) == "per_record"]
    centres = {}
    for rec in calib_records + heldout_records:
        for c in per:
            for p in c.param_names:
                cen = model.prior_centre(p, rec)
                if cen is not None:
                    lo, hi = model.box([fx.record_param(p, rec)])
                    centres.setdefault(rec, {})[p] = {"centre": cen, "measured": model.record_centres[rec][p],
                                                      "box": [float(lo[0]), float(hi[0])]}
    heldout = {rec: {p: dict(zip(("value", "source"), model.record_value(p, rec)), used=c.name in added)
                     for c in per for p in c.param_names} for rec in heldout_records}
    return {"scopes": {c.name: _scope(c, scopes) for c in candidates}, "records": calib_records,
            "naming": "<effect>.<param>@<record>: the record's own copy of a per-record parameter",
            "prior_centres": centres, "heldout": heldout,
            "note": "a held-out record has no copy of a per-record parameter (the calibration cannot know it); "
                    "it takes its prior centre where its own waves measure the effect, else the null ('source')"}


def heldout_fill(report: Mapping, record: str) -> dict[str, float]:
    """``{param: value}`` a record without copies of the per-record parameters takes (the report's
    ``per_record.heldout``; empty for a calibration record or a report without per-record effects)."""
    return {p: float(v["value"]) for p, v in (report.get("per_record") or {}).get("heldout", {}).get(record, {}).items()}


def diagnose(model: EmulatedSHPB, *, base_names: Sequence[str], candidates: Sequence, calib_records: Sequence[str],
             obs, obs_error: ObservationError, times, heldout_records: Sequence[str] = (), heldout_obs=None,
             heldout_times=None, heldout_error: ObservationError | None = None, seed: int = 0,
             n_members: int = 100, esmda_steps: int = 4, fd_fraction: float = 1e-3,
             scopes: Mapping[str, str] | None = None, **loop_kw) -> dict:
    """Run :func:`enkf.diagnosis.diagnose_loop` with ES-MDA re-calibrations on the emulated model.

    ``obs_error`` is the observation error of ``obs`` (calibration records, concatenated); the emulator's
    leave-one-out error is added to it. Physical candidates must be emulator inputs; measurement
    candidates need nothing. A ``per_record`` candidate is estimated per calibration record
    (:func:`record_candidates`; module docstring); ``scopes`` overrides the catalogue's scope by effect name
    (e.g. ``{"gauge_gain": "shared"}`` for records known to share their gauges' calibration). Returns the loop's report with ``emulator`` (its
    error) and ``per_record`` (scopes, prior centres and boxes, held-out values and their source) added.
    """
    calib_records, heldout_records = list(calib_records), list(heldout_records)
    err = with_emulator_error(obs_error, model.emulator_std(calib_records))
    offered = list(candidates)
    candidates = record_candidates(offered, calib_records, scopes)
    for c in candidates:
        for n in c.param_names:
            model.box([n])  # raises for a physical candidate the emulator does not cover

    def calibrate(names):
        res, f, lo, hi = _emulated_esmda(model, names, calib_records, obs, err, _seed_for(seed, names),
                                         n_members, esmda_steps)
        mean = res.params[res.alive].mean(axis=0)
        held = model.forward(names, heldout_records)(mean)[0] if heldout_records else None
        return CalibrationResult(names, res.params[res.alive], f(mean)[0], heldout=held,
                                 responses=res.responses[res.alive],
                                 info={"stop_reason": res.decision.reason, "n_members": n_members,
                                       "esmda_steps": esmda_steps}, lower=lo, upper=hi)

    def sensitivities(result, names):
        mean = result.mean()
        x0 = np.array([mean[n] if n in mean else fx.null_values([n])[n] for n in names])
        lo, hi = model.box(names, centred=False)  # the nulls lie in it
        return finite_difference_sensitivity(model.forward(names, calib_records), x0, fd_fraction * (hi - lo),
                                             lower=lo, upper=hi)

    report = diagnose_loop(calibrate, sensitivities, base_names=list(base_names), candidates=list(candidates),
                           obs=obs, obs_error=err, times=times,
                           heldout_obs=heldout_obs if heldout_records else None,
                           heldout_times=heldout_times if heldout_records else None, **loop_kw)
    s = model.emulator_std(calib_records)
    report["emulator"] = {"loo_rms_Pa": float(np.sqrt(np.mean(s ** 2))), "loo_max_Pa": float(s.max()),
                          "obs_sigma_rms_Pa": float(np.sqrt(np.mean(obs_error.std ** 2))),
                          "design_points": {r: int(model.emulators[r].X.shape[0]) for r in model.emulators}}
    report["per_record"] = _per_record_report(model, offered, calib_records, heldout_records, report["added"], scopes)
    return report


def record_calibrations(model: EmulatedSHPB, base_names: Sequence[str], observation_sets, *, seed: int = 0,
                        n_members: int = 100, esmda_steps: int = 4):
    """The base model calibrated on each record alone (ES-MDA on the emulator, its leave-one-out error
    added, as in :func:`diagnose`): one row per record with ``<param>_mean`` and ``<param>_sd``, for the
    fitted-parameters-against-covariates check (a strength that rises with the strain rate across
    records is a rate effect the model lacks). ``observation_sets``: :class:`calibration.observations.Observations`
    whose records the emulator covers."""
    import pandas as pd

    names = list(base_names)
    rows = []
    for o in observation_sets:
        for r in o.records:
            sub = o.of_record(r)
            err = with_emulator_error(sub.error_model(), model.emulator_std([r]))
            res, *_ = _emulated_esmda(model, names, [r], sub.values, err, _seed_for(seed, [r, *names]),
                                      n_members, esmda_steps)
            P = res.params[res.alive]
            row = {"record": r}
            for j, n in enumerate(names):
                row[f"{n}_mean"], row[f"{n}_sd"] = float(P[:, j].mean()), float(P[:, j].std(ddof=1))
            rows.append(row)
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------------
# The workflow's diagnosis stage (rules/diagnosis.smk)
# --------------------------------------------------------------------------------------------------
def base_design_box(posterior, names: Sequence[str], prior_lower, prior_upper, *, width_sd: float,
                    min_rel_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Design box of the base parameters: the calibrated posterior's mean +- ``width_sd`` sd, at least
    +- ``min_rel_width`` of the mean (the effects a base calibration absorbed move it that far), clipped
    to the prior box. ``posterior``: the final ensemble (one column per name)."""
    P = np.column_stack([np.asarray(posterior[n], float) for n in names])
    mean, sd = P.mean(axis=0), P.std(axis=0, ddof=1)
    half = np.maximum(width_sd * sd, min_rel_width * np.abs(mean))
    lo = np.maximum(np.asarray(prior_lower, float), mean - half)
    hi = np.minimum(np.asarray(prior_upper, float), mean + half)
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


def record_params(values: Mapping[str, float], record: str | None,
                  fill: Mapping[str, float] | None = None) -> dict[str, float]:
    """One record's parameters from a set with per-record copies: shared ones as they are, the record's own
    copies ``<param>@<record>`` under their plain name, other records' copies dropped; a per-record
    parameter of which ``record`` has no copy (a held-out record) takes ``fill[param]`` (:func:`heldout_fill`).
    ValueError when a per-record parameter has no value for the record (or ``record`` is None)."""
    out, own, others = {}, {}, set()
    for n, v in values.items():
        p, r = fx.split_record(n)
        if r is None:
            out[n] = v
        elif r == record:
            own[p] = v
        else:
            others.add(p)
    out.update(own)
    for p in sorted(others - set(own)):
        if fill is None or p not in fill:
            raise ValueError(f"{p} is estimated per record and has no value for record {record!r}")
        out[p] = float(fill[p])
    return out


def simulator_params(posterior: Mapping[str, Mapping[str, float]], record: str | None = None,
                     fill: Mapping[str, float] | None = None) -> dict[str, float]:
    """The parameters an FDEM run of ``record`` needs from a loop posterior (``params_before``/``params_after``
    of the report: ``{name: {"mean": ...}}``): base and physical effect parameters at their posterior mean,
    per-record ones the record's own (:func:`record_params`, ``fill`` for a held-out record); measurement
    effects are left to :func:`measured_curve`."""
    means = record_params({n: float(v["mean"]) for n, v in posterior.items()}, record, fill)
    return {n: v for n, v in means.items() if (fx.effect_of(n) is None or fx.effect_of(n).kind != "measurement")}


def measured_curve(curve, model_times, posterior: Mapping[str, Mapping[str, float]], obs_times,
                   record: str | None = None, fill: Mapping[str, float] | None = None) -> np.ndarray | None:
    """An FDEM run's curve as the loop's model sees it: on ``model_times``, through the measurement chain
    of the posterior's measurement parameters (at their means; per-record ones ``record``'s, as in
    :func:`simulator_params`), at ``obs_times``; None for a failed run. The FDEM check of a loop answer
    (rules/diagnosis.smk) compares it with the data."""
    y = curve_on_model_grid(curve, model_times)
    if y is None:
        return None
    means = record_params({n: float(v["mean"]) for n, v in posterior.items()}, record, fill)
    meas = {n: v for n, v in means.items() if fx.effect_of(n) is not None and fx.effect_of(n).kind == "measurement"}
    return interpolation_matrix(model_times, obs_times) @ fx.apply_measurement(model_times, y, meas)


def check_errors(sets, runs: Mapping[str, Mapping], model_times, posteriors: Mapping[str, Mapping],
                 fills: Mapping[str, Mapping[str, float]] | None = None) -> tuple[dict, dict]:
    """The FDEM check of a loop answer: per record, the errors (:func:`enkf.diagnosis.curve_errors`) of
    real runs at the posterior means against the data.

    ``sets``: ``(data_label, Observations)`` pairs (calibration, held-out); ``runs[which][record]``: the
    run's curve (DataFrame) for each ``which`` of ``posteriors`` (e.g. ``"before"``, ``"after"``, the
    report's ``params_before`` / ``params_after``); ``fills[record]``: a held-out record's values of the
    per-record parameters (:func:`heldout_fill`). Returns ``(errors, curves)``:
    ``errors[rec] = {"data": label, which: curve_errors or None for a failed run}`` and
    ``curves[rec] = {"data", "time", "obs", which: the run seen through the chain (or None)}``."""
    errors, curves = {}, {}
    for label, o in sets:
        for r in o.records:
            s = o.record_slice(r)
            t, y = o.time[s], o.values[s]
            errors[r], curves[r] = {"data": label}, {"data": label, "time": t, "obs": y}
            for which, post in posteriors.items():
                sim = measured_curve(runs[which][r], model_times, post, t, record=r, fill=(fills or {}).get(r))
                curves[r][which] = sim
                errors[r][which] = None if sim is None else curve_errors(t, sim, y)
    return errors, curves


def fdem_confirmation(errors: Mapping[str, Mapping], added: Sequence[str]) -> dict:
    """Does the FDEM check confirm the loop's answer on the records it was not calibrated on?

    ``errors``: :func:`check_errors`' first result. The emulator the loop ran on can be wrong where the
    design is thin, so the answer stands only if real runs agree: ``confirmed`` when every held-out
    record's FDEM RMSE falls from before to after, ``refuted`` when any rises (or its after run failed),
    ``nothing_added`` / ``no_heldout`` otherwise; with the RMSE of each record before and after."""
    rmse = {r: {w: (None if e.get(w) is None else float(e[w]["rmse"])) for w in ("before", "after")}
            for r, e in errors.items()}
    held = [r for r, e in errors.items() if e["data"] == "heldout"]
    if not added:
        status = "nothing_added"
    elif not held:
        status = "no_heldout"
    elif all(rmse[r]["after"] is not None and rmse[r]["before"] is not None and rmse[r]["after"] < rmse[r]["before"]
             for r in held):
        status = "confirmed"
    else:
        status = "refuted"
    words = {"confirmed": "real FDEM runs confirm it: the held-out error falls",
             "refuted": "real FDEM runs refute it: the held-out error does not fall (the emulator the loop "
                        "ran on is wrong there; a denser design around the answer is needed)",
             "nothing_added": "nothing was added", "no_heldout": "no held-out record to confirm it on"}[status]
    detail = "; ".join(f"{r} {_mpa(rmse[r]['before'])} -> {_mpa(rmse[r]['after'])} MPa" for r in held)
    return {"status": status, "added": list(added), "rmse_Pa": rmse,
            "text": f"{', '.join(added) or 'no effect'}: {words}" + (f" ({detail})" if detail else "")}


def _mpa(v):
    return "failed" if v is None else f"{v / 1e6:.1f}"


def errors_per_record(sets) -> tuple[dict, dict, dict]:
    """Per record, the error of the model before and after the loop (:func:`enkf.diagnosis.curve_errors`).

    ``sets``: iterable of ``(data_label, observations, fitted_before, fitted_after)`` with the curves on the
    observations' vector (``observations`` None to skip the set). Returns ``(errors, residuals, sigma)``:
    ``errors[rec] = {"data", "before", "after"}``, the residual ``data - before`` and the record's RMS
    observation sd, the inputs of :func:`record_covariates`."""
    errors, resid, sigma = {}, {}, {}
    for label, o, before, after in sets:
        if o is None:
            continue
        for r in o.records:
            s = o.record_slice(r)
            t, y = o.time[s], o.values[s]
            errors[r] = {"data": label, "before": curve_errors(t, before[s], y),
                         "after": curve_errors(t, after[s], y)}
            resid[r] = y - before[s]
            sigma[r] = float(np.sqrt(np.mean(o.sigma[s] ** 2)))
    return errors, resid, sigma


def record_covariates(record_info: Mapping[str, Mapping], residuals: Mapping[str, np.ndarray],
                      sigma: Mapping[str, float]):
    """Per record: strain rate at peak, peak stress, and the mean / RMS of the calibrated model's residual
    in units of the record's noise sd (the table :func:`enkf.diagnosis.covariate_trends` reads)."""
    import pandas as pd
    rows = []
    for rec, r in residuals.items():
        info = record_info.get(rec, {})
        rows.append({"record": rec, "strain_rate_per_s": info.get("strain_rate_at_peak_per_s", np.nan),
                     "peak_stress_Pa": info.get("peak_stress_Pa", np.nan),
                     "mean_resid_sd": float(np.mean(r) / sigma[rec]),
                     "rms_resid_sd": float(np.sqrt(np.mean(r ** 2)) / sigma[rec])})
    return pd.DataFrame(rows)
