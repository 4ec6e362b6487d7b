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
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.stats import qmc

from enkf import BoxTransform, assimilate, esmda_alphas, latin_hypercube
from enkf.covariance import ObservationError
from enkf.diagnosis import CalibrationResult, curve_errors, diagnose_loop, finite_difference_sensitivity
from enkf.emulator import CurveEmulator, with_emulator_error

from shpb import effects as fx
from .observations import curve_on_grid

__all__ = ["design_points", "interpolation_matrix", "EmulatedSHPB", "diagnose", "emulators_from_design",
           "errors_per_record", "model_grid", "simulator_params", "measured_curve", "check_errors", "record_calibrations"]


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

    def box(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``names``: the emulator's box for its inputs, the catalogue's for measurement effects."""
        emu = next(iter(self.emulators.values()))
        lo, hi = [], []
        for n in names:
            if n in self.input_names:
                i = self.input_names.index(n)
                lo.append(emu.lower[i]), hi.append(emu.upper[i])
            else:
                effect = fx.effect_of(n)
                if effect is None or effect.kind != "measurement":
                    raise ValueError(f"{n} is neither an emulator input nor a measurement effect parameter")
                a, b = fx.bounds([n])
                lo.append(a[0]), hi.append(b[0])
        return np.array(lo), np.array(hi)

    def forward(self, names: Sequence[str], records: Sequence[str]) -> Callable[[np.ndarray], np.ndarray]:
        names = list(names)
        meas = [n for n in names if n not in self.input_names]
        nulls = {n: fx.null_values([n])[n] for n in self.input_names if n not in names}

        def f(P):
            P = np.array(P, dtype=float, ndmin=2)
            cols = {n: P[:, j] for j, n in enumerate(names)}
            X = np.column_stack([cols[n] if n in cols else np.full(P.shape[0], nulls[n]) for n in self.input_names])
            out = []
            for rec in records:
                Y = self.emulators[rec](X)
                if meas:
                    Y = np.array([fx.apply_measurement(self.model_times, Y[i], {n: cols[n][i] for n in meas})
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


def diagnose(model: EmulatedSHPB, *, base_names: Sequence[str], candidates: Sequence, calib_records: Sequence[str],
             obs, obs_error: ObservationError, times, heldout_records: Sequence[str] = (), heldout_obs=None,
             heldout_times=None, heldout_error: ObservationError | None = None, seed: int = 0,
             n_members: int = 100, esmda_steps: int = 4, fd_fraction: float = 1e-3, **loop_kw) -> dict:
    """Run :func:`enkf.diagnosis.diagnose_loop` with ES-MDA re-calibrations on the emulated model.

    ``obs_error`` is the observation error of ``obs`` (calibration records, concatenated); the emulator's
    leave-one-out error is added to it. Physical candidates must be emulator inputs; measurement
    candidates need nothing. Returns the loop's report with ``emulator`` (its error) added.
    """
    calib_records, heldout_records = list(calib_records), list(heldout_records)
    err = with_emulator_error(obs_error, model.emulator_std(calib_records))
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
        lo, hi = model.box(names)
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


def simulator_params(posterior: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
    """The parameters an FDEM run needs from a loop posterior (``params_before``/``params_after`` of the
    report: ``{name: {"mean": ...}}``): base and physical effect parameters at their posterior mean;
    measurement effects are left to :func:`measured_curve`."""
    return {n: float(v["mean"]) for n, v in posterior.items()
            if (fx.effect_of(n) is None or fx.effect_of(n).kind != "measurement")}


def measured_curve(curve, model_times, posterior: Mapping[str, Mapping[str, float]], obs_times) -> np.ndarray | None:
    """An FDEM run's curve as the loop's model sees it: on ``model_times``, through the measurement chain
    of the posterior's measurement parameters (at their means), at ``obs_times``; None for a failed run.
    The FDEM check of a loop answer (rules/diagnosis.smk) compares it with the data."""
    y = curve_on_model_grid(curve, model_times)
    if y is None:
        return None
    meas = {n: float(v["mean"]) for n, v in posterior.items()
            if fx.effect_of(n) is not None and fx.effect_of(n).kind == "measurement"}
    return interpolation_matrix(model_times, obs_times) @ fx.apply_measurement(model_times, y, meas)


def check_errors(sets, runs: Mapping[str, Mapping], model_times,
                 posteriors: Mapping[str, Mapping]) -> tuple[dict, dict]:
    """The FDEM check of a loop answer: per record, the errors (:func:`enkf.diagnosis.curve_errors`) of
    real runs at the posterior means against the data.

    ``sets``: ``(data_label, Observations)`` pairs (calibration, held-out); ``runs[which][record]``: the
    run's curve (DataFrame) for each ``which`` of ``posteriors`` (e.g. ``"before"``, ``"after"``, the
    report's ``params_before`` / ``params_after``). Returns ``(errors, curves)``:
    ``errors[rec] = {"data": label, which: curve_errors or None for a failed run}`` and
    ``curves[rec] = {"data", "time", "obs", which: the run seen through the chain (or None)}``."""
    errors, curves = {}, {}
    for label, o in sets:
        for r in o.records:
            s = o.record_slice(r)
            t, y = o.time[s], o.values[s]
            errors[r], curves[r] = {"data": label}, {"data": label, "time": t, "obs": y}
            for which, post in posteriors.items():
                sim = measured_curve(runs[which][r], model_times, post, t)
                curves[r][which] = sim
                errors[r][which] = None if sim is None else curve_errors(t, sim, y)
    return errors, curves


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
