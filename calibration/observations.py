"""Observations of a calibration: the observed specimen stress on a time grid, with its error model.

Two sources (docs/workflow.md, "The loop"):

* **Twin experiments** (paper section 5.2): a reference simulation with known parameters gives the
  "truth" curve; it is sampled on the observation grid and noise drawn from the declared error model is
  added (:func:`twin_observations`). The noise level is a fraction of the truth's peak stress or an
  absolute value in Pa.
* **Measured records**: a Freiburg raw record is reduced (:func:`shpb.lab.reduction.reduce_record`) to the
  back-face specimen stress ``sigma = F_back / A_s`` on the face time axis (0 = incident wave at the
  front face, the simulator's axis too) and sampled on the grid (:func:`measured_observations`). The
  observation error is the record's own noise: ``sigma`` = the pre-trigger standard deviation of the
  stress (``ReducedRecord.noise_std_Pa['stress']``, times a configurable factor), and the AR(1)
  correlation time is estimated from the same pre-trigger samples (:func:`enkf.estimate_noise`).

The workflow reduces each record once (rule ``reduced_record``, :func:`write_reduced_record`: the folder
``results/<experiment>/observations/<record>/`` of :mod:`shpb.lab.reduced_store`) and builds the
observations from those files (:func:`stored_observations`, the same numbers as
:func:`measured_observations`); the Snakefile's check before any job (:func:`cached_check_record`) reads
a record's summary from a cache keyed by its content (:mod:`calibration.record_check`).

Several records are concatenated in one observation vector (record by record, in the config's order);
their errors are independent (``groups`` of :mod:`enkf.covariance`).

Files (``results/<experiment>/observations/``): ``obs.csv`` with columns ``record, time_s, stress_Pa,
sigma_Pa`` (+ ``truth_stress_Pa`` for twins: the noise-free reference), one row per observation in
vector order, and ``obs.json`` with the error model and per-record metadata. :func:`read_observations`
checks both and raises :class:`ObservationFileError` naming the file and the problem.

Member curves are put on the grid by :func:`curve_on_grid` (linear interpolation; NaN where the curve
does not cover the grid, which marks the member as failed) and stacked by :func:`response_matrix`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from .record_check import CACHE_DIR, ObservationFileError, cached_summary, check_summary

if TYPE_CHECKING:  # pragma: no cover
    from enkf.covariance import ObservationError

# enkf (and SciPy under it) is imported where an error model or a noise estimate is made: the Snakefile
# imports this module at parse time (every command, `-n` too), where neither is needed.

__all__ = [
    "OBS_COLUMNS", "UNCORRECTED_COLUMN", "ObservationFileError", "Observations", "observation_grid",
    "curve_on_grid", "read_curve",
    "twin_observations", "reduce_measured_record", "measured_observations", "check_record",
    "read_observations", "response_matrix", "with_approximation_error", "record_validity",
    "record_check_summary", "cached_check_record", "write_reduced_record", "stored_observations",
]

#: Columns of ``obs.csv`` (SI units).
OBS_COLUMNS = ("record", "time_s", "stress_Pa", "sigma_Pa")
#: the stress as observed, beside the corrected ``stress_Pa`` where an approximation error corrected it
UNCORRECTED_COLUMN = "stress_uncorrected_Pa"


# --------------------------------------------------------------------------------------------------
# Grids and curves
# --------------------------------------------------------------------------------------------------
def observation_grid(t_start: float, t_end: float, dt: float) -> np.ndarray:
    """Uniform grid ``t_start, t_start + dt, ...`` up to ``t_end`` (inclusive within 1e-9 dt) [s]."""
    if not (dt > 0 and t_end > t_start):
        raise ValueError(f"observation grid needs dt > 0 and t_end > t_start, got {t_start}, {t_end}, {dt}")
    n = int(math.floor((t_end - t_start) / dt + 1e-9)) + 1
    return t_start + dt * np.arange(n)


def curve_on_grid(time: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear interpolation of a curve onto ``grid``; NaN outside the curve's time span (half a sample
    of slack at each end) and wherever the curve is not finite."""
    t = np.asarray(time, float)
    v = np.asarray(values, float)
    g = np.asarray(grid, float)
    out = np.full(g.shape, np.nan)
    ok = np.isfinite(t) & np.isfinite(v)
    if ok.sum() < 2 or not np.all(np.isfinite(v)):
        return out
    t, v = t[ok], v[ok]
    if np.any(np.diff(t) <= 0):
        raise ValueError("curve time axis must be strictly increasing")
    slack = 0.5 * float(np.median(np.diff(t)))
    inside = (g >= t[0] - slack) & (g <= t[-1] + slack)
    out[inside] = np.interp(g[inside], t, v)
    return out


def read_curve(path: str | Path, column: str = "stress_Pa") -> pd.DataFrame:
    """A simulated curve (``time_s`` and ``column``); an empty frame for a failed member's curve file."""
    path = Path(path)
    try:
        df = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        return pd.DataFrame({"time_s": [], column: []})
    for c in ("time_s", column):
        if c not in df.columns:
            raise ObservationFileError(f"{path}: curve file has no column {c!r} (columns: {list(df.columns)})")
    return df


# --------------------------------------------------------------------------------------------------
# The observation vector
# --------------------------------------------------------------------------------------------------
@dataclass
class Observations:
    """Observation vector ``y_o`` (record by record) with its error model.

    ``frame``: one row per observation, columns :data:`OBS_COLUMNS` (+ ``truth_stress_Pa`` for twins).
    ``error_kind``: ``"diagonal"`` or ``"ar1"``; ``corr_time``: AR(1) correlation time [s] per record.
    ``meta``: JSON-ready description (source files, noise estimates, reduction notes).
    ``added_cov``: a known covariance added to the noise (the approximation error of a coarse model,
    :func:`with_approximation_error`), dense on the whole vector; None: the noise alone.
    """

    frame: pd.DataFrame
    error_kind: str = "diagonal"
    corr_time: dict[str, float] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    added_cov: np.ndarray | None = None

    @property
    def records(self) -> list[str]:
        return list(dict.fromkeys(self.frame["record"].astype(str)))

    @property
    def time(self) -> np.ndarray:
        return self.frame["time_s"].to_numpy(float)

    @property
    def values(self) -> np.ndarray:
        return self.frame["stress_Pa"].to_numpy(float)

    @property
    def sigma(self) -> np.ndarray:
        return self.frame["sigma_Pa"].to_numpy(float)

    @property
    def groups(self) -> np.ndarray:
        order = {r: i for i, r in enumerate(self.records)}
        return self.frame["record"].astype(str).map(order).to_numpy(int)

    @property
    def m(self) -> int:
        return len(self.frame)

    def record_slice(self, record: str) -> slice:
        idx = np.flatnonzero(self.frame["record"].astype(str).to_numpy() == record)
        return slice(int(idx[0]), int(idx[-1]) + 1)

    def grid(self, record: str) -> np.ndarray:
        return self.time[self.record_slice(record)]

    def as_observed(self, record: str) -> np.ndarray | None:
        """The record's stress as observed where an approximation error corrected it, else None (the
        check's plot shows both: how far the coarse mesh's error moved the data)."""
        col = UNCORRECTED_COLUMN
        return self.frame[col].to_numpy(float)[self.record_slice(record)] if col in self.frame else None

    def of_record(self, record: str) -> "Observations":
        """The observations of one record, with its own error model (e.g. to calibrate on it alone)."""
        sl = self.record_slice(record)
        frame = self.frame.iloc[sl].reset_index(drop=True)
        corr = {record: self.corr_time[record]} if record in self.corr_time else {}
        added = None if self.added_cov is None else self.added_cov[sl, sl]
        return Observations(frame, self.error_kind, corr, {}, added)

    def error_model(self) -> ObservationError:
        """The :class:`enkf.covariance.ObservationError` ``R`` of the whole vector (records independent),
        with :attr:`added_cov` added where there is one.

        enkf's AR(1) model takes one correlation time; with several records the mean of theirs is used.
        """
        from enkf import observation_error
        from enkf.covariance import DenseError

        tau = float(np.mean([self.corr_time.get(r, 0.0) for r in self.records])) if self.corr_time else 0.0
        kind = self.error_kind if (self.error_kind != "ar1" or tau > 0) else "diagonal"
        R = observation_error(kind, self.sigma, times=self.time, corr_time=tau, groups=self.groups)
        return R if self.added_cov is None else DenseError(R.dense() + self.added_cov, _symmetric=True)

    def to_meta(self) -> dict:
        return {"error_kind": self.error_kind, "corr_time_s": dict(self.corr_time), "records": self.records,
                "n_obs": self.m, **self.meta}

    def write(self, csv_path: str | Path, json_path: str | Path) -> None:
        from .contracts import atomic_write_csv, atomic_write_json

        atomic_write_csv(self.frame, csv_path)
        atomic_write_json(json_path, _jsonable(self.to_meta()))


def read_observations(csv_path: str | Path, json_path: str | Path) -> Observations:
    """Read ``obs.csv`` + ``obs.json``; :class:`ObservationFileError` names the file and the problem."""
    csv_path, json_path = Path(csv_path), Path(json_path)
    import json

    try:
        df = pd.read_csv(csv_path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ObservationFileError(f"observation file {csv_path}: cannot be read as CSV ({exc})") from exc
    missing = [c for c in OBS_COLUMNS if c not in df.columns]
    if missing:
        raise ObservationFileError(f"observation file {csv_path}: missing column(s) {missing}; "
                                   f"expected {list(OBS_COLUMNS)}")
    if df.empty:
        raise ObservationFileError(f"observation file {csv_path}: no observations")
    for c in ("time_s", "stress_Pa", "sigma_Pa"):
        v = pd.to_numeric(df[c], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(v.to_numpy(float)))
        if bad.size:
            raise ObservationFileError(f"observation file {csv_path}: column {c!r} is not a finite number "
                                       f"in data row(s) {(bad + 1).tolist()[:5]}")
        df[c] = v.astype(float)
    if np.any(df["sigma_Pa"].to_numpy() <= 0):
        raise ObservationFileError(f"observation file {csv_path}: sigma_Pa must be positive")
    df["record"] = df["record"].astype(str)
    for rec, sub in df.groupby("record", sort=False):
        if np.any(np.diff(sub["time_s"].to_numpy()) <= 0):
            raise ObservationFileError(f"observation file {csv_path}: times of record {rec!r} are not "
                                       f"strictly increasing")
    try:
        with open(json_path) as fh:
            meta = json.load(fh)
    except (OSError, ValueError) as exc:
        raise ObservationFileError(f"observation metadata {json_path}: cannot be read as JSON ({exc})") from exc
    kind = meta.get("error_kind", "diagonal")
    if kind not in ("diagonal", "ar1"):
        raise ObservationFileError(f"observation metadata {json_path}: error_kind {kind!r} is not "
                                   f"'diagonal' or 'ar1'")
    corr = {str(k): float(v) for k, v in (meta.get("corr_time_s") or {}).items()}
    extra = {k: v for k, v in meta.items() if k not in ("error_kind", "corr_time_s", "records", "n_obs")}
    obs = Observations(df, kind, corr, extra)
    approx = extra.get("approximation_error") or {}
    if approx.get("sd_Pa"):
        sd = np.asarray(approx["sd_Pa"], float)
        if sd.size != obs.m:
            raise ObservationFileError(f"observation metadata {json_path}: approximation_error.sd_Pa has {sd.size} "
                                       f"values for {obs.m} observations")
        from enkf.covariance import AR1Error

        obs.added_cov = AR1Error(sd, obs.time, float(approx["corr_time_s"]), groups=obs.groups).dense()
    return obs


def with_approximation_error(obs: Observations, offset, M: ObservationError | None, info: Mapping) -> Observations:
    """``obs`` for a coarse model of data from a finer one (:func:`enkf.approximation.approximation_error`):
    the mean resolution error ``offset`` subtracted from the observed stress (the column
    ``stress_uncorrected_Pa`` keeps the data as observed) and its scatter ``M`` added to the error model.
    ``info`` (with ``M``'s ``sd_Pa`` and ``corr_time_s``) goes to the metadata, from which
    :func:`read_observations` rebuilds ``M``."""
    offset = np.asarray(offset, float)
    if offset.shape != (obs.m,) or (M is not None and M.m != obs.m):
        raise ValueError(f"approximation error on {offset.size} times for {obs.m} observations")
    if obs.added_cov is not None:
        raise ValueError("these observations already carry an approximation error")
    frame = obs.frame.copy()
    frame[UNCORRECTED_COLUMN] = frame["stress_Pa"].to_numpy(float)
    frame["stress_Pa"] = frame["stress_Pa"].to_numpy(float) - offset
    return Observations(frame, obs.error_kind, dict(obs.corr_time), {**obs.meta, "approximation_error": dict(info)},
                        None if M is None else M.dense())


# --------------------------------------------------------------------------------------------------
# Twin experiments
# --------------------------------------------------------------------------------------------------
def twin_observations(truth_curve: pd.DataFrame, grid: np.ndarray, *, rng: np.random.Generator,
                      relative_sigma: float | None = 0.01, sigma_Pa: float | None = None,
                      corr_time: float = 0.0, record: str = "synthetic", meta: Mapping | None = None) -> Observations:
    """Synthetic observations: the reference curve on ``grid`` plus noise.

    The noise std is ``sigma_Pa`` if given, else ``relative_sigma`` times the peak ``|stress|`` of the
    reference on the grid. ``corr_time > 0`` draws AR(1)-correlated noise (and declares it), else white.
    The draw is ``L e``, ``e ~ N(0, I)`` from ``rng`` (one call, so a seed fixes it).
    """
    from enkf import observation_error

    truth = curve_on_grid(truth_curve["time_s"], truth_curve["stress_Pa"], grid)
    if not np.all(np.isfinite(truth)):
        raise ValueError(f"the reference simulation covers {truth_curve['time_s'].min():.3g}-"
                         f"{truth_curve['time_s'].max():.3g} s, not the observation grid "
                         f"{grid[0]:.3g}-{grid[-1]:.3g} s (raise simulation.t_end or lower observations.t_end)")
    if sigma_Pa is None:
        if relative_sigma is None or relative_sigma <= 0:
            raise ValueError("give observations.noise.sigma_Pa or a positive relative_sigma")
        sigma_Pa = float(relative_sigma) * float(np.max(np.abs(truth)))
    kind = "ar1" if corr_time > 0 else "diagonal"
    err = observation_error(kind, sigma_Pa, times=grid, corr_time=corr_time)
    noise = err.sample(rng, 1)[0]
    frame = pd.DataFrame({"record": record, "time_s": grid, "stress_Pa": truth + noise,
                          "sigma_Pa": np.full(grid.size, float(sigma_Pa)), "truth_stress_Pa": truth})
    info = {"source": "twin", "sigma_Pa": float(sigma_Pa), "relative_sigma": relative_sigma,
            "peak_truth_Pa": float(np.max(np.abs(truth))), **(meta or {})}
    return Observations(frame, kind, {record: float(corr_time)}, info)


# --------------------------------------------------------------------------------------------------
# Measured records
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Measured:
    """A measured record read, checked and reduced once: the reduction, the sheet's or spreadsheet's
    metadata, the noise estimate of the stress, the lab checks with the validity class and what a
    simulation of the record needs besides its wave (:func:`shpb.lab.reduced_store.simulation_inputs`)."""

    red: object
    meta: dict
    noise: object
    checks: dict
    sim: dict


def _stat_key(path: Path) -> tuple:
    st = path.stat()
    return str(path.resolve()), st.st_mtime_ns, st.st_size


def _record_key(path: Path) -> tuple:
    """(file, mtime, size) of the record, and of a sheet's signals file (a sheet is cheap to parse)."""
    from shpb.lab.sheet import is_sheet, load_sheet

    if not path.is_file():
        raise FileNotFoundError(f"record file not found: {path}")
    if not is_sheet(path):
        return _stat_key(path)
    signals = load_sheet(path).signals_file
    return _stat_key(path) + (_stat_key(signals) if signals.is_file() else (str(signals),))


def _measured(path: Path) -> _Measured:
    """The record's :class:`_Measured`, cached per (file, mtime, size) within a process (tests and tools
    ask for one record several times; the workflow reduces each record once, in its observations stage)."""
    return _measured_cached(_record_key(path), str(path))


@lru_cache(maxsize=64)
def _measured_cached(key: tuple, path_str: str) -> _Measured:
    from enkf import estimate_noise
    from shpb.lab.lab_reduce import lab_checks
    from shpb.lab.reduced_store import pretrigger_stress, simulation_inputs
    from shpb.lab.sheet import is_sheet

    path = Path(path_str)
    if is_sheet(path):
        from shpb.lab.lab_reduce import reduce_sheet, transit_time
        from shpb.lab.sheet_readers import check_sheet

        sheet, raw = check_sheet(path)
        red = reduce_sheet(sheet, raw, check_stated=True)
        spec, transit = dict(sheet.metadata), transit_time(sheet)
        sim = simulation_inputs(path, sheet=sheet)
        thickness = float(sheet.specimen["thickness"]) if sheet.geometry == "brazilian_disc" else None
    else:
        raw, spec, red, transit = _freiburg_record(path)
        sim, thickness = simulation_inputs(path, spec=spec), None
    noise = estimate_noise(pretrigger_stress(raw, red, thickness), raw.dt, model="ar1")
    return _Measured(red, spec, noise, lab_checks(red, transit), sim)


def _freiburg_record(path: Path):
    """A Freiburg raw record with the checks a sheet gets (:mod:`shpb.lab.checks`): (raw, spreadsheet row,
    reduced record, the wave's transit through the specimen [s])."""
    from shpb.lab.checks import freiburg_problems, stated_problems
    from shpb.lab.records import freiburg_specimen, read_freiburg_raw
    from shpb.lab.reduction import FREIBURG_BAR, reduce_record

    raw = read_freiburg_raw(path, bar=FREIBURG_BAR)
    spec = freiburg_specimen(path)
    problems, rock = freiburg_problems(path, spec, FREIBURG_BAR)
    if problems:
        raise ValueError("\n".join(problems))
    L = float(spec["length_m"])
    red = reduce_record(raw, FREIBURG_BAR, L, float(spec["diameter_m"]))
    problems = stated_problems(spec, red, str(path), prefix="spreadsheet ")
    if problems:
        raise ValueError("\n".join(problems))
    return raw, spec, red, L * math.sqrt(rock["rho"] / rock["E"])


def reduce_measured_record(path: str | Path):
    """Read, check and reduce a measured record: a test sheet (``.yaml``, :mod:`shpb.lab.sheet`: its signals,
    bars and specimen) or a Freiburg raw record (its spreadsheet row and the Freiburg bars), both with the
    checks of :mod:`shpb.lab.checks` (finite channels, plausible and fitting specimen, known rock, stated
    peak stress and strain rate against the reduction).

    Returns ``(ReducedRecord, metadata, NoiseEstimate of the stress)``; metadata is the spreadsheet
    row, or the sheet's ``metadata`` block. The noise estimate is taken from the pre-trigger stress of
    the averaged transmitted-bar signal (:func:`shpb.lab.reduced_store.pretrigger_stress`). Cached per
    (file, mtime, size): treat the result as read-only.
    """
    m = _measured(Path(path))
    return m.red, m.meta, m.noise


def record_validity(path: str | Path) -> dict:
    """The record's validity class with its metrics (:func:`shpb.lab.validity.classify`)."""
    return _measured(Path(path)).checks["validity"]


def _read(path: Path) -> _Measured:
    try:
        return _measured(path)
    except (OSError, ValueError, KeyError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)  # KeyError's str() quotes it
        raise ObservationFileError(f"observation file {path}: {msg}") from exc


def record_check_summary(path: str | Path) -> dict:
    """What :func:`check_record` decides on (JSON-ready, the parse-time cache's entry,
    :mod:`calibration.record_check`): the reduced record's ``end_time_s``, whether its specimen stress is
    all finite, its ``validity`` class and reasons. :class:`ObservationFileError` names the file and the
    problem when it cannot be read, checked or reduced."""
    red = _read(Path(path)).red
    v = _measured(Path(path)).checks["validity"]
    return {"end_time_s": float(red.time[-1]), "stress_finite": bool(np.all(np.isfinite(red.stress))),
            "validity": {"class": str(v["class"]), "reasons": [str(r) for r in v["reasons"]]}}


def check_record(path: str | Path, t_end: float | None = None, *, refuse_invalid: bool = False) -> None:
    """Read, check and reduce a measured record; :class:`ObservationFileError` names the file and the
    problem (unreadable or malformed file, non-finite samples, implausible or contradictory values, no
    spreadsheet row, no pulse, window shorter than ``t_end``). ``refuse_invalid``: a test of validity class
    ``invalid`` is refused too (a calibration record, unless the experiment sets
    ``observations.allow_invalid: true``)."""
    check_summary(path, record_check_summary(path), t_end, refuse_invalid=refuse_invalid)


def cached_check_record(path: str | Path, t_end: float | None = None, *, refuse_invalid: bool = False,
                        cache_dir: str | Path = CACHE_DIR, code: bytes | None = None) -> dict:
    """:func:`check_record` on the record's summary kept in ``cache_dir`` under the SHA-256 of what its
    reduction reads (:mod:`calibration.record_check`; the Snakefile's check before any job): the record is
    reduced only when that content has no valid entry. Returns the summary."""
    summary = cached_summary(path, code, cache_dir, record_check_summary)
    check_summary(path, summary, t_end, refuse_invalid=refuse_invalid)
    return summary


def _record_entry(path: Path) -> dict:
    """One record's part of the observations, JSON-ready: its reduced record's scalars, noise, checks and
    test covariates (``record.json``'s ``observation``, :func:`write_reduced_record`)."""
    m = _read(path)
    red, spec, noise = m.red, m.meta, m.noise
    v = m.checks["validity"]
    return {"noise_std_Pa": red.noise_std_Pa["stress"], "noise_estimate": noise.to_dict(),
            "peak_stress_Pa": red.peak_stress, "peak_time_s": red.peak_time,
            "strain_rate_at_peak_per_s": red.strain_rate_at_peak,
            "force_balance_at_peak": red.force_balance_at_peak, "notes": list(red.notes),
            "validity": v["class"], "validity_reasons": list(v["reasons"]),
            "specimen_length_m": red.specimen_length, "specimen_diameter_m": red.specimen_diameter,
            "spreadsheet_strength_Pa": _float_or_none(spec.get("reference_stress_Pa")),
            # the incident bar face's travel before the specimen carries 2 % of its peak: the
            # record's own measure of the face gap (prior centre of its face_gap.gap_m)
            "closure_before_load_m": _closure_or_none(red),
            # test covariates for the residual's trends across records (calibration.covariates)
            **_test_covariates(red, spec),
            "corr_time_s": noise.corr_time, "dt_s": red.dt, "check": record_check_summary(path)}


def write_reduced_record(path: str | Path, folder: str | Path) -> Path:
    """Reduce a measured record once and store it (``folder``: ``results/<exp>/observations/<record>/``,
    :mod:`shpb.lab.reduced_store`): its incident wave and set-up for the simulations, its reduced curves,
    noise and checks for :func:`stored_observations`. Returns the ``record.json`` written."""
    from shpb.lab.reduced_store import write_reduced

    path = Path(path)
    entry = _record_entry(path)
    m = _measured(path)
    return write_reduced(folder, m.red, source=path, simulation=m.sim, observation=entry)


def _assemble(parts, *, t_start, t_end, dt, error_kind, sigma_scale) -> Observations:
    """Observations from ``(name, source, time, stress, entry)`` per record (entry: :func:`_record_entry`)."""
    frames, corr, info = [], {}, {}
    for name, source, time, stress, e in parts:
        check_summary(source, e["check"], t_end)
        grid = observation_grid(t_start, t_end, dt if dt is not None else e["dt_s"])
        values = curve_on_grid(time, stress, grid)
        sigma = sigma_scale * e["noise_std_Pa"]
        frames.append(pd.DataFrame({"record": name, "time_s": grid, "stress_Pa": values,
                                    "sigma_Pa": np.full(grid.size, sigma)}))
        corr[name] = e["corr_time_s"]
        info[name] = {"source": str(source), "sigma_Pa": sigma,
                      **{k: v for k, v in e.items() if k not in ("corr_time_s", "dt_s", "check")}}
    return Observations(pd.concat(frames, ignore_index=True), error_kind, corr,
                        {"source": "measured", "sigma_scale": sigma_scale, "record_info": info})


def measured_observations(records: Mapping[str, str | Path], *, t_start: float, t_end: float, dt: float | None,
                          error_kind: str = "ar1", sigma_scale: float = 1.0) -> tuple[Observations, dict]:
    """Observations from measured records (``{name: raw file}``), concatenated in the given order.

    The grid of each record is ``t_start..t_end`` with step ``dt`` (default: the record's sample
    interval). Returns the observations and ``{name: ReducedRecord}`` (for plots and the summary).
    """
    parts, reduced = [], {}
    for name, path in records.items():
        e = _record_entry(Path(path))
        red = _measured(Path(path)).red
        parts.append((name, path, red.time, red.stress, e))
        reduced[name] = red
    obs = _assemble(parts, t_start=t_start, t_end=t_end, dt=dt, error_kind=error_kind, sigma_scale=sigma_scale)
    return obs, reduced


def stored_observations(folders: Mapping[str, str | Path], *, t_start: float, t_end: float, dt: float | None,
                        error_kind: str = "ar1", sigma_scale: float = 1.0) -> Observations:
    """:func:`measured_observations` from the records stored by :func:`write_reduced_record`
    (``{name: folder}``), read and not reduced again: the same observations, number for number."""
    from shpb.lab.reduced_store import read_curves, read_reduced

    parts = []
    for name, folder in folders.items():
        try:
            doc, curves = read_reduced(folder), read_curves(folder)
        except ValueError as exc:
            raise ObservationFileError(str(exc)) from None
        parts.append((name, doc["source"], curves["time_s"], curves["stress_Pa"], doc["observation"]))
    return _assemble(parts, t_start=t_start, t_end=t_end, dt=dt, error_kind=error_kind, sigma_scale=sigma_scale)


# --------------------------------------------------------------------------------------------------
# Member responses
# --------------------------------------------------------------------------------------------------
def response_matrix(curves: Sequence[Mapping[str, pd.DataFrame]], obs: Observations,
                    column: str = "stress_Pa") -> np.ndarray:
    """Stack member curves on the observation grid: ``curves[i][record]`` -> row ``i`` of ``(N, m)``.

    A record's block is NaN when the member's curve for it is empty (failed) or does not cover the grid.
    """
    Y = np.full((len(curves), obs.m), np.nan)
    for i, member in enumerate(curves):
        for rec in obs.records:
            sl = obs.record_slice(rec)
            df = member.get(rec)
            if df is None or len(df) < 2:
                continue
            Y[i, sl] = curve_on_grid(df["time_s"].to_numpy(float), df[column].to_numpy(float), obs.time[sl])
    return Y


def _float_or_none(v):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _test_covariates(red, spec) -> dict:
    """The covariates of a test that its sheet or spreadsheet row gives, beside the strain rate: the
    specimen's ``length_to_diameter`` [-], the gas (striker) pressure ``gas_pressure_Pa`` (the Freiburg
    spreadsheet's "P (bar)", or a sheet's metadata) and the ``striker_velocity_m_s`` (a sheet's metadata);
    None where not given."""
    get = spec.get if hasattr(spec, "get") else (lambda k, d=None: d)
    D = _float_or_none(red.specimen_diameter)
    L = _float_or_none(red.specimen_length)
    return {"length_to_diameter": L / D if (L is not None and D) else None,
            "gas_pressure_Pa": _float_or_none(get("gas_pressure_Pa")),
            "striker_velocity_m_s": _float_or_none(get("striker_velocity_m_s"))}


def _closure_or_none(red, level: float = 0.02):
    """``red.closure_before_load(level)`` [m], None where the record does not give it."""
    try:
        return _float_or_none(red.closure_before_load(level))
    except (IndexError, ValueError):
        return None


def _jsonable(obj):
    from enkf import jsonable

    return jsonable(obj)
