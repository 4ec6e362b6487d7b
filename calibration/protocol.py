"""The frozen protocol of :mod:`enkf.diagnosis.protocol` on SHPB records (issue 32): effects chosen by
cross-validation within the calibration records on the emulated FDEM curves
(:class:`calibration.diagnose.EmulatedSHPB`), confirmed on real FDEM runs at the cross-validation points,
and only then the held-out records' curves read.

Its rules on SHPB records:

* **No record's own measurement of a per-record effect** is used. A record's face closure before load
  (``closure_before_load_m``) is measured until the *transmitted* stress reaches 2 % of its peak, so it
  reads the record's own answer: it neither centres a box nor gives any record a value
  (:class:`calibration.diagnose.EmulatedSHPB` has no way to take one). A record the calibration has not
  seen takes its per-record values from the population of the calibration records' estimates
  (:mod:`enkf.diagnosis.population`); each record's forward model must be given its own copy of every
  per-record parameter (:class:`ProtocolModel` refuses a record without one).
* **The emulator's error is time-correlated**: per-time rms of the leave-one-out residuals with an
  AR(1) correlation (:func:`emulator_errors`, :func:`enkf.emulated.emulator_error_model`), never a
  diagonal term.
* The gates are the protocol's: cross-validated error against its own uncertainty, Holm-corrected, and
  the real-run confirmation walk.

Workflow (:mod:`calibration.closing`, in this order): build the emulators from the FDEM design
(:func:`calibration.diagnose.emulators_from_design`) and ``EmulatedSHPB``; the workflow's reported posterior
as the base model (:func:`workflow_base`: one base posterior per run, never re-fitted on the emulator);
:func:`select` with the calibration records' observations only; :func:`check_runs` lists the FDEM runs (per step and calibration
record the cross-validation point, per step and held-out record its prediction point); run them;
:func:`real_curves` turns them into curves through the measurement chain; :func:`confirm` walks the steps;
:func:`enkf.diagnosis.heldout_evaluation` (``final`` = the confirmed step, ``real`` = the held-out runs)
reads the held-out records last.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from enkf.covariance import ObservationError
from enkf.diagnosis import (Fit, RecordErrors, Selection, confirm_additions, given_fit, real_identification,
                            select_effects)
from enkf.emulated import emulator_error_model
from shpb import effects as fx

from .diagnose import EmulatedSHPB, interpolation_matrix, measured_curve, record_params, workflow_sample

__all__ = ["MAX_BASE_DRAWS", "ProtocolModel", "check_runs", "confirm", "emulator_axis_errors", "emulator_errors",
           "protocol_model", "real_curves", "real_group", "record_errors", "select", "workflow_base"]

#: At most this many of the workflow's posterior draws predict with the base model (evenly spaced through
#: the sample): an MCMC sample holds tens of thousands, and the 5 % and 95 % quantiles of a band from
#: 2,000 draws are off by at most about 0.5 % in probability (binomial sd sqrt(0.05 * 0.95 / 2000)).
MAX_BASE_DRAWS = 2000


@dataclass
class ProtocolModel:
    """An :class:`EmulatedSHPB` as the protocol's :class:`enkf.diagnosis.ForwardModel`: boxes are the
    design's and the catalogue's, and a record whose per-record copy is missing from the names is an
    error (where :class:`EmulatedSHPB` would read the null), never a value from elsewhere."""

    emulated: EmulatedSHPB

    def box(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        return self.emulated.box(list(names))

    def forward(self, names: Sequence[str], records: Sequence[str]):
        names = list(names)
        per = {fx.split_record(n)[0] for n in names if fx.split_record(n)[1] is not None}
        for r in records:
            missing = [p for p in sorted(per) if fx.record_param(p, r) not in names]
            if missing:
                raise ValueError(f"record {r} has no copy of {missing}: the protocol gives every record its own "
                                 "(fitted, or drawn from the population), never its measured value")
        return self.emulated.forward(names, records)


def protocol_model(model: EmulatedSHPB) -> ProtocolModel:
    """``model`` as the protocol's forward model (:class:`ProtocolModel`)."""
    return ProtocolModel(model)


def emulator_errors(model: EmulatedSHPB, records: Sequence[str]) -> dict[str, ObservationError]:
    """Per record, its surrogate's error at the record's observation times: the leave-one-out residuals
    of its runs (:meth:`enkf.emulator.CurveEmulator.loo_residuals`, or along each axis for the anchored
    model, :meth:`enkf.emulator.AnchoredEmulator.loo_residuals`) interpolated to those times, as
    per-time rms with AR(1) correlation (:func:`enkf.emulated.emulator_error_model`)."""
    out = {}
    for r in records:
        err = _error_at_obs(model, r, model.emulators[r].loo_residuals())
        if err is None:
            raise ValueError(f"the emulator of {r} has no leave-one-out residuals")
        out[r] = err
    return out


def _error_at_obs(model: EmulatedSHPB, record: str, residuals) -> ObservationError | None:
    """Residual curves on the model grid as an error at ``record``'s observation times: per-time rms,
    AR(1) (:func:`enkf.emulated.emulator_error_model`); None without residuals."""
    W = interpolation_matrix(model.model_times, model.obs_times[record])
    return emulator_error_model(np.asarray(residuals) @ W.T, model.obs_times[record])[0]


def emulator_axis_errors(model: EmulatedSHPB, records: Sequence[str]) -> dict[str, dict[str, ObservationError]]:
    """Per record whose surrogate is additive over its parameters (the anchored model), the error of each
    parameter's own term: that axis's leave-one-out residuals
    (:meth:`enkf.emulator.AnchoredEmulator.loo_residuals_by_axis`) at the record's observation times,
    per-time rms with AR(1) correlation. A parameter without runs has no term (none is added for it).
    Records with another surrogate are left out (their pooled error applies)."""
    out = {}
    for r in records:
        emu = model.emulators[r]
        if not hasattr(emu, "loo_residuals_by_axis"):
            continue
        axes = {name: _error_at_obs(model, r, res) for name, res in emu.loo_residuals_by_axis().items()}
        out[r] = {name: err for name, err in axes.items() if err is not None}
    return out


def record_errors(model: EmulatedSHPB, noise: Mapping[str, ObservationError], *,
                  simulator: Mapping[str, ObservationError] | None = None,
                  model_correlation: float = 0.0, simulator_correlation: float = 0.0,
                  per_model: bool = False) -> RecordErrors:
    """The protocol's error model per record: instrument ``noise`` (e.g. ``Observations.of_record(r).
    error_model()``), the emulator's time-correlated error (:func:`emulator_errors`) and the FDEM runs'
    variability ``simulator`` if known (e.g. the scatter of runs with different mesh seeds), with the
    correlations of two predictions' errors (:class:`enkf.diagnosis.RecordErrors`). ``per_model``: on an
    additive surrogate, each model's own error from the axes it moves (:func:`emulator_axis_errors`)."""
    records = list(noise)
    return RecordErrors(dict(noise), emulator_errors(model, records), dict(simulator or {}), model_correlation,
                        simulator_correlation, emulator_axis_errors(model, records) if per_model else {})


def select(model: EmulatedSHPB, *, base_names: Sequence[str], candidates: Sequence, calib_records: Sequence[str],
           obs: Mapping[str, np.ndarray], noise: Mapping[str, ObservationError], heldout_records: Sequence[str] = (),
           simulator: Mapping[str, ObservationError] | None = None, model_correlation: float = 0.0,
           simulator_correlation: float = 0.0, scopes: Mapping[str, str] | None = None, per_model: bool = False,
           **select_kw) -> Selection:
    """:func:`enkf.diagnosis.select_effects` on the emulated records (module docstring). ``obs`` is read for
    the calibration records only; ``noise`` must cover calibration and held-out records (the held-out
    record's noise sets its predictive band, never its prediction). Physical candidates must be emulator
    inputs (ValueError otherwise); per-record scopes come from the catalogue unless ``scopes`` says;
    ``per_model``: each model its own surrogate error (:func:`record_errors`)."""
    pm = protocol_model(model)
    for c in candidates:
        pm.box(list(c.param_names))  # raises for a physical candidate the emulator does not cover
    errors = record_errors(model, noise, simulator=simulator, model_correlation=model_correlation,
                           simulator_correlation=simulator_correlation, per_model=per_model)
    return select_effects(pm, base_names=base_names, candidates=candidates, calib_records=calib_records,
                          heldout_records=heldout_records, obs=obs, errors=errors, scopes=scopes, **select_kw)


def workflow_base(model: EmulatedSHPB, base_names: Sequence[str], calib_records: Sequence[str], posterior,
                  summary: Mapping, *, file: str, max_draws: int = MAX_BASE_DRAWS) -> Fit:
    """The workflow's reported posterior as the protocol's base model on the calibration records
    (:func:`enkf.diagnosis.given_fit`): its draws are ``posterior.csv``'s (``posterior``, a frame;
    :func:`calibration.diagnose.workflow_sample`, at most ``max_draws`` evenly spaced), its estimates
    ``summary.json``'s ``posterior`` block as printed there (``summary``: that file's dict). The base is
    then not re-calibrated on the emulator; ``info`` names the file and the method (``posterior_method``)."""
    names = list(base_names)
    P = workflow_sample(posterior, names)
    n = P.shape[0]
    if n > max_draws:
        P = P[np.unique(np.round(np.linspace(0, n - 1, max_draws)).astype(int))]
    method = str(summary.get("posterior_method", "ensemble"))
    info = {"source": "workflow", "file": str(file), "method": method, "draws": int(n), "draws_used": int(P.shape[0]),
            "iteration": summary.get("posterior_iteration")}
    return given_fit(protocol_model(model), names, list(calib_records), P, summary=summary["posterior"], info=info)


def check_runs(selection: Selection, replicates: int = 1) -> list[dict]:
    """The real FDEM runs the confirmation and the held-out evaluation need: per step and calibration
    record its cross-validation point (``role`` "cv"), per step and held-out record its prediction point
    ("heldout"), each ``replicates`` times (``replicate`` k: the record's k-th mesh realization, the same
    for every step, so that two steps are compared on common meshes); the rounds' alternatives too
    (:attr:`enkf.diagnosis.Selection.alternatives`). ``simulator``: the parameters of
    the run (base and physical effects, the record's own copies under their plain names);
    ``measurement``: the chain applied to the run's curve afterwards."""
    if int(replicates) < 1:
        raise ValueError(f"check replicates must be >= 1, got {replicates}")
    rows = []
    for step in (*selection.steps, *selection.alternatives):
        pts = step.check_points()
        for role in ("cv", "heldout"):
            for rec, point in pts[role].items():
                plain = record_params(point, rec)
                base, phys, meas = fx.split_params(plain)
                for k in range(int(replicates)):
                    rows.append({"step": step.index, "model": step.spec.label(), "role": role, "record": rec,
                                 "replicate": k, "simulator": {**base, **phys}, "measurement": meas,
                                 "point": dict(point)})
    return rows


def real_curves(rows: Sequence[Mapping], runs: Sequence, model: EmulatedSHPB) -> dict[str, dict[int, dict]]:
    """``{"cv": {step: {record: curve}}, "heldout": {...}}`` from the FDEM runs of :func:`check_runs`'s rows
    (``runs[i]``: the run of ``rows[i]``, a DataFrame with ``time_s``, ``stress_Pa``, or None for a failed
    run): each run on the model grid, through its row's measurement chain, at the record's observation
    times (:func:`calibration.diagnose.measured_curve`). One run per point gives a curve; replicated
    runs a ``(K, m)`` array, row k the k-th realization. None if a run of the point failed."""
    runs_of: dict[tuple, dict[int, np.ndarray | None]] = {}
    for row, run in zip(rows, runs):
        post = {n: {"mean": v} for n, v in row["point"].items()}
        curve = measured_curve(run, model.model_times, post, model.obs_times[row["record"]], record=row["record"])
        runs_of.setdefault((row["role"], row["step"], row["record"]), {})[int(row.get("replicate", 0))] = curve
    out: dict[str, dict[int, dict]] = {"cv": {}, "heldout": {}}
    for (role, step, rec), reps in runs_of.items():
        curves = [reps[k] for k in sorted(reps)]
        if any(c is None for c in curves):
            value = None
        else:
            value = curves[0] if len(curves) == 1 else np.vstack(curves)
        out[role].setdefault(step, {})[rec] = value
    return out


def real_group(selection: Selection, real_cv: Mapping[int, Mapping[str, np.ndarray | None]],
               obs: Mapping[str, np.ndarray], noise: Mapping[str, ObservationError], step: int, *,
               simulator: Mapping[str, ObservationError] | None = None,
               weights: Mapping[str, np.ndarray] | None = None) -> list[dict]:
    """:func:`enkf.diagnosis.real_identification` with the error terms and weights of :func:`confirm`: the
    kept step against the other models of its round that have real runs."""
    return real_identification(selection, real_cv, obs, _real_errors(noise, simulator), step, weights=weights)


def _real_errors(noise: Mapping[str, ObservationError], simulator: Mapping[str, ObservationError] | None) -> RecordErrors:
    # real runs: no surrogate error, the runs' variability where given
    return RecordErrors(dict(noise), {}, dict(simulator or {}))


def confirm(selection: Selection, real_cv: Mapping[int, Mapping[str, np.ndarray | None]],
            obs: Mapping[str, np.ndarray], noise: Mapping[str, ObservationError], *,
            simulator: Mapping[str, ObservationError] | None = None, alpha: float | None = None,
            weights: Mapping[str, np.ndarray] | None = None) -> dict:
    """:func:`enkf.diagnosis.confirm_additions` on real FDEM curves at the cross-validation points
    (:func:`real_curves`' ``"cv"``): uncertainty = instrument noise and the runs' variability (measured on
    the paired replicates where there are several, else ``simulator`` on each run); ``weights`` per time
    (:func:`enkf.diagnosis.walk_weights`)."""
    return confirm_additions(selection, real_cv, obs, _real_errors(noise, simulator), alpha=alpha, weights=weights)
