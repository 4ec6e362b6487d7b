"""One calibration process, ask and tell: the paper's EnKF, ES-MDA and emulated ES-MDA behind one interface.

The caller owns the loop (as ``iterative_ensemble_smoother.ESMDA`` leaves it to its user) and the
process owns the state, which is saved between jobs and loaded back (as EnsembleKalmanProcesses'
process is, in one program or between cluster jobs)::

    process = CalibrationProcess(params0, d, FixedError(R), schedule=StepSchedule("esmda"), rng=seed)
    while not process.done:
        Y = forward(process.ask())   # (N, m); a failed member is a NaN row
        process.tell(Y)

``tell(Y)`` after ``k`` analyses, in this order:

1. the failure policy (:class:`FailurePolicy`): the members alive (a finite row the caller did not
   report as failed); fewer than ``max(2, ceil(min_alive_fraction N))`` refuse the step
   (:class:`EnsembleFailure`, naming each failed member's reason);
2. the likelihood's terms for this ensemble (:class:`FixedError`: one error model for everything; the
   workflow's own adds the simulator's variability and the discrepancy estimated on these members) and
   their scores: the misfit recorded and the statistic of the stop test;
3. the stop decision (:class:`StopPolicy`, :func:`enkf.check_stop`), the convergence tests taken only
   where the method's posterior is defined (:meth:`StepSchedule.converges_at`);
4. the analysis the step schedule has at ``k`` (:class:`StepSchedule`): ES-MDA ``alpha_k``, the paper's
   EnKF (``alpha = 1``), or the emulated ES-MDA on every run so far (tempered by ``temper_base^(K-1-k)``),
   computed also after a stop when ``update_on_stop`` (the workflow re-takes the decision from the stored
   numbers with the current rule, so a changed tolerance never invalidates a finished iteration).

Randomness: each analysis ``k`` draws from ``rng``: a Generator shared by every step, or
:class:`SeededSteps` (an independent stream per step, ``SeedSequence(seed, spawn_key=(purpose, k))``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .analysis import EnsembleFailure, enkf_update, esmda_alphas, esmda_update
from .covariance import AR1Error, DenseError, DiagonalError, ObservationError, SquaredExponentialError
from .diagnostics import default_names, jsonable, mean_misfit, member_misfit, posterior_dict
from .stopping import StopCriteria, StopDecision, check_stop
from .transforms import BoxTransform, IdentityTransform

__all__ = ["METHODS", "DEFAULT_INFLATION", "DEFAULT_TRUNCATION", "FailurePolicy", "StepSchedule", "StopPolicy",
           "AnalysisSettings", "EmulatedSettings", "SeededSteps", "FixedError", "Step", "CalibrationProcess",
           "capped_truncation", "all_runs", "register_analysis"]

METHODS = ("enkf", "esmda", "emulated_esmda")
#: Without a stated inflation: the paper's spread floor for its EnKF (eq. 5), none for ES-MDA, whose
#: schedule already inflates the noise.
DEFAULT_INFLATION = {"enkf": "paper", "esmda": None}
#: Without a stated SVD truncation: the exact eq. 4 for the EnKF, 99 % of the singular values for ES-MDA.
DEFAULT_TRUNCATION = {"enkf": 1.0, "esmda": 0.99}
_NAN_ROW = "simulated curve does not cover the observation grid (NaN on the grid)"


@dataclass(frozen=True)
class FailurePolicy:
    """Failed members are left out of the analysis and replaced by it (every member of the next ensemble
    is drawn from the survivors' update); below ``max(2, ceil(min_alive_fraction N))`` survivors the
    update is refused."""

    min_alive_fraction: float = 0.5

    def needed(self, n_members: int) -> int:
        return max(2, math.ceil(self.min_alive_fraction * n_members - 1e-12))

    def failed(self, Y: np.ndarray, ok=None, reasons=None, member_ids=None) -> tuple[np.ndarray, list[dict]]:
        """``(alive, failed)``: alive = finite row and reported ok; one ``{member, reason}`` per failure."""
        N = Y.shape[0]
        ok = np.ones(N, bool) if ok is None else np.asarray(ok, bool)
        alive = ok & np.all(np.isfinite(Y), axis=1)
        ids = np.arange(N) if member_ids is None else np.asarray(member_ids, int)
        failed = [{"member": int(ids[i]), "reason": _NAN_ROW if ok[i] else str((reasons or {}).get(int(i)) or "")}
                  for i in np.flatnonzero(~alive)]
        return alive, failed

    def check(self, alive: np.ndarray, failed: Sequence[Mapping], where: str) -> None:
        N, needed = alive.size, self.needed(alive.size)
        if alive.sum() < needed:
            lines = "\n".join(f"  member {f['member']}: {f['reason']}" for f in failed)
            raise EnsembleFailure(f"{where}: only {int(alive.sum())} of {N} members succeeded (need {needed}, "
                                  f"min_alive_fraction={self.min_alive_fraction}). Failures:\n{lines}")


@dataclass(frozen=True)
class StepSchedule:
    """What each analysis is: ES-MDA's ``alphas`` (default :func:`esmda_alphas` (3), whose length is the
    iteration budget), the EnKF's ``alpha = 1`` every step, or the emulated ES-MDA's tempering
    ``temper_base^(K - 1 - k)`` of its likelihood at analysis ``k`` of ``K``."""

    method: str = "esmda"
    alphas: tuple[float, ...] = ()
    temper_base: float = 4.0

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        alphas = tuple(float(a) for a in self.alphas)
        if self.method == "esmda" and not alphas:
            alphas = tuple(float(a) for a in esmda_alphas(3))
        object.__setattr__(self, "alphas", alphas if self.method == "esmda" else ())

    def alpha(self, k: int) -> float | None:
        """The ES-MDA / EnKF step's noise inflation at analysis ``k`` (None: no such step)."""
        if self.method == "esmda":
            return self.alphas[k] if k < len(self.alphas) else None
        return 1.0 if self.method == "enkf" else None

    def temper(self, k: int, max_iterations: int) -> float:
        return self.temper_base ** max(0, max_iterations - 1 - k)

    def converges_at(self, k: int, max_iterations: int) -> bool:
        """ES-MDA's and the tempered emulated ES-MDA's posterior is defined only at the schedule's end."""
        if self.method == "esmda":
            return k >= len(self.alphas)
        if self.method == "emulated_esmda":
            return k >= max_iterations or self.temper_base == 1.0
        return True

    def criteria(self, criteria: StopCriteria) -> StopCriteria:
        """ES-MDA's schedule is its iteration budget."""
        return replace(criteria, max_iterations=len(self.alphas)) if self.method == "esmda" else criteria


@dataclass(frozen=True)
class StopPolicy:
    """The stop decision (:func:`enkf.check_stop`) with the criteria's defaults (:class:`StopCriteria`)."""

    criteria: StopCriteria = field(default_factory=StopCriteria)

    def decide(self, schedule: StepSchedule, k: int, misfit: Mapping, n_obs: int, spread,
               prior_spread) -> StopDecision:
        """``misfit``: ``chi2_per_obs``, ``nrmse`` and the statistic's own ``target`` (None: the default)."""
        c = schedule.criteria(self.criteria)
        return check_stop(k, chi2_per_obs=_nan(misfit.get("chi2_per_obs")), nrmse=_nan(misfit.get("nrmse")),
                          n_obs=n_obs, spread=spread, prior_spread=prior_spread, criteria=c,
                          allow_convergence=schedule.converges_at(k, c.max_iterations),
                          model_target=misfit.get("target"))


@dataclass(frozen=True)
class AnalysisSettings:
    """The Kalman step's options (:func:`enkf.enkf_update`); ``"default"`` / None mean the method's
    default (:data:`DEFAULT_INFLATION`, :data:`DEFAULT_TRUNCATION`); ``max_rank`` caps the singular values
    kept (:func:`capped_truncation`); ``localization`` the paper's mask ``M`` (n x m)."""

    inflation: object = "default"
    truncation: float | None = None
    max_rank: int | None = None
    localization: np.ndarray | None = None

    def resolved(self, method: str) -> tuple[object, float]:
        infl = DEFAULT_INFLATION[method] if self.inflation == "default" else self.inflation
        return infl, DEFAULT_TRUNCATION[method] if self.truncation is None else float(self.truncation)


@dataclass(frozen=True)
class EmulatedSettings:
    """The emulated ES-MDA's inner ensemble and emulator (:func:`enkf.emulated_esmda_update`); ``times`` and
    ``groups`` label the observations for the emulator's AR(1) error."""

    inner_members: int = 400
    inner_steps: int = 8
    smoothing: object = "loo"
    times: np.ndarray | None = None
    groups: np.ndarray | None = None


@dataclass(frozen=True)
class SeededSteps:
    """An independent random stream per analysis: ``default_rng(SeedSequence(seed, spawn_key=(purpose, k)))``."""

    seed: int
    purpose: int = 0

    def __call__(self, k: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence(int(self.seed), spawn_key=(int(self.purpose), int(k))))


class FixedError:
    """The likelihood of a fixed observation error ``R`` for every purpose; the stop test's statistic is
    the median member's chi^2 per observation (the members must fit, not their possibly blurred mean)."""

    def __init__(self, obs_error: ObservationError):
        self.obs_error = obs_error
        self.loo_scale = obs_error.std

    def evaluate(self, Y, d, alive, **extra) -> "FixedError":
        return self

    def assimilation(self, alpha: float = 1.0) -> ObservationError:
        return self.obs_error

    def emulated(self) -> ObservationError:
        return self.obs_error

    def score(self, Y, d, alive) -> tuple[dict, dict]:
        """``(recorded misfit, the stop test's {chi2_per_obs, nrmse, target})``."""
        mean, members = mean_misfit(Y, d, self.obs_error, alive), member_misfit(Y, d, self.obs_error, alive)
        return ({"misfit_mean": mean, "misfit_members": members},
                {"chi2_per_obs": members["median_chi2_per_obs"], "nrmse": members["median_nrmse"], "target": None})

    def to_dict(self) -> dict:
        return {"kind": "fixed", "obs_error": error_to_dict(self.obs_error)}


@dataclass
class Step:
    """One ``tell``: the ensemble simulated, its alive members and failures, the likelihood's terms and
    scores, the spread, the decision and the analysis (``result``, ``next_params``; None without one)."""

    iteration: int
    params: np.ndarray
    responses: np.ndarray
    alive: np.ndarray
    failed: list
    terms: object
    misfit: dict
    stop_misfit: dict
    spread: np.ndarray | None
    prior_spread: np.ndarray
    decision: StopDecision
    alpha: float | None = None
    result: object = None
    next_params: np.ndarray | None = None

    def to_dict(self, names: Sequence[str]) -> dict:
        """The process' ``history`` entry: iteration, n_alive, the misfit, posterior, decision, analysis."""
        out = jsonable({"iteration": self.iteration, "n_alive": int(self.alive.sum()), **self.misfit,
                        "posterior": posterior_dict(self.params, list(names), self.alive),
                        "decision": self.decision.to_dict()})
        if self.result is not None:
            out["analysis"] = self.result.to_dict()
        return out


#: The analysis of each method: ``f(process, step, rng) -> (result, next params)`` (the emulated ES-MDA's
#: is registered by :mod:`enkf.emulated_step`, which builds on the in-process driver this module serves).
_ANALYSES: dict[str, Callable] = {}


def register_analysis(method: str, fn: Callable) -> Callable:
    _ANALYSES[method] = fn
    return fn


def _analysis(method: str) -> Callable:
    if method not in _ANALYSES:
        raise ValueError(f"no analysis registered for method {method!r} (have {sorted(_ANALYSES)}); the "
                         "emulated ES-MDA registers itself when enkf.emulated_step is imported, as "
                         "`from enkf import CalibrationProcess` does")
    return _ANALYSES[method]


class CalibrationProcess:
    """The calibration's state and its step (module docstring). ``iteration``, ``runs`` (the ``(P, Y)`` of
    iterations ``0 .. k-1``) and ``prior_spread`` restore a process at analysis ``k`` (the workflow's jobs,
    :meth:`load`); ``label`` names it in errors."""

    def __init__(self, params, obs, likelihood, *, rng, schedule: StepSchedule | None = None,
                 stop: StopPolicy | None = None, failure: FailurePolicy | None = None,
                 analysis: AnalysisSettings | None = None, emulated: EmulatedSettings | None = None,
                 transform: BoxTransform | IdentityTransform | None = None, names: Sequence[str] | None = None,
                 iteration: int = 0, runs: Sequence[tuple[np.ndarray, np.ndarray]] = (), prior_spread=None,
                 update_on_stop: bool = True, label: str = "calibration"):
        self.params = np.array(params, dtype=float, ndmin=2)
        self.obs = np.asarray(obs, dtype=float)
        self.likelihood = likelihood
        self.rng = rng
        self.schedule = schedule or StepSchedule()
        self.stop = stop or StopPolicy()
        self.failure = failure or FailurePolicy()
        self.analysis = analysis or AnalysisSettings()
        self.emulated = emulated or EmulatedSettings()
        self.transform = IdentityTransform() if transform is None else transform
        self.names = default_names(self.params.shape[1], names)
        self.iteration = int(iteration)
        self.runs = [(np.asarray(p, float), np.asarray(y, float)) for p, y in runs]
        self.prior_spread = (self.transform.to_unbounded(self.params).std(axis=0, ddof=1) if prior_spread is None
                             else np.asarray(prior_spread, float))
        self.update_on_stop = bool(update_on_stop)
        self.label = label
        self.decision: StopDecision | None = None
        # each tell's entry: its Step until first read, then the Step's dict (a summary of the ensemble with
        # quantiles, a fifth of a tell's time, that the in-process loops of the diagnosis never read)
        self._history: list = []
        self.n_simulations = 0

    @property
    def history(self) -> list[dict]:
        """One dict per ``tell``: iteration, n_alive, the misfit, posterior, decision and analysis."""
        for i, entry in enumerate(self._history):
            if isinstance(entry, Step):
                self._history[i] = entry.to_dict(self.names)
        return self._history

    @history.setter
    def history(self, entries) -> None:
        self._history = list(entries)

    @property
    def criteria(self) -> StopCriteria:
        return self.schedule.criteria(self.stop.criteria)

    @property
    def done(self) -> bool:
        return self.decision is not None and self.decision.stop

    def ask(self) -> np.ndarray:
        """The ensemble to simulate next, ``(N, n)``, one row per member."""
        if self.done:
            raise RuntimeError(f"{self.label}: the process has stopped ({self.decision.reason}); nothing to ask")
        return self.params.copy()

    def _rng(self, k: int) -> np.random.Generator:
        return self.rng(k) if callable(self.rng) else self.rng

    def tell(self, responses, *, ok=None, reasons: Mapping[int, str] | None = None, member_ids=None,
             **extra) -> Step:
        """Take the responses ``(N, m)`` of :meth:`ask`'s ensemble (a failed member: a NaN row, or
        ``ok[i]`` False with ``reasons[i]``), analyse and decide. ``extra`` goes to the likelihood's
        ``evaluate`` (the workflow's replicate runs)."""
        if self.done:
            raise RuntimeError(f"{self.label}: the process has stopped; nothing to tell")
        k, P, d = self.iteration, self.params, self.obs
        Y = np.array(responses, dtype=float, ndmin=2)
        if Y.shape != (P.shape[0], d.size):
            raise ValueError(f"responses have shape {Y.shape}, expected ({P.shape[0]}, {d.size})")
        alive, failed = self.failure.failed(Y, ok, reasons, member_ids)
        self.failure.check(alive, failed, f"{self.label}, iteration {k}")
        terms = self.likelihood.evaluate(Y, d, alive, **extra)
        misfit, stop_misfit = terms.score(Y, d, alive)
        spread = self.transform.to_unbounded(P[alive]).std(axis=0, ddof=1) if alive.sum() > 1 else None
        decision = self.stop.decide(self.schedule, k, stop_misfit, d.size, spread, self.prior_spread)
        step = Step(k, P, Y, alive, failed, terms, misfit, stop_misfit, spread, self.prior_spread, decision,
                    alpha=self.schedule.alpha(k))
        spent = self.schedule.method == "esmda" and step.alpha is None  # then the decision above stopped
        if not spent and (not decision.stop or self.update_on_stop):
            step.result, step.next_params = _analysis(self.schedule.method)(self, step, self._rng(k))
        self.n_simulations += P.shape[0]
        self._history.append(step)
        self.decision = decision
        if not decision.stop:
            if step.next_params is None:
                raise RuntimeError(f"{self.label}, iteration {k}: the schedule has no analysis to continue with")
            self.runs.append((P, Y))
            self.params = np.asarray(step.next_params, float)
            self.iteration = k + 1
        return step

    # ------------------------------------------------------------------ saved state
    def to_dict(self) -> dict:
        """Settings and state (NaN kept, so the runs' failures survive); the likelihood where it is a
        :class:`FixedError`, else the caller passes it to :meth:`load`."""
        tr = self.transform
        rng = (asdict(self.rng) if isinstance(self.rng, SeededSteps)
               else {"bit_generator": type(self.rng.bit_generator).__name__, "state": self.rng.bit_generator.state})
        return {"version": 1, "label": self.label, "names": list(self.names), "obs": self.obs.tolist(),
                "likelihood": self.likelihood.to_dict() if isinstance(self.likelihood, FixedError) else None,
                "rng": rng, "schedule": asdict(self.schedule), "stop": self.stop.criteria.to_dict(),
                "failure": asdict(self.failure), "analysis": _arrays(asdict(self.analysis)),
                "emulated": _arrays(asdict(self.emulated)),
                "transform": None if isinstance(tr, IdentityTransform) else
                {"lower": tr.lower.tolist(), "upper": tr.upper.tolist(), "kind": tr.kind},
                "update_on_stop": self.update_on_stop, "iteration": self.iteration, "params": self.params.tolist(),
                "prior_spread": self.prior_spread.tolist(), "runs": [[p.tolist(), y.tolist()] for p, y in self.runs],
                "decision": None if self.decision is None else asdict(self.decision), "history": self.history,
                "n_simulations": self.n_simulations}

    def save(self, folder) -> Path:
        """``folder/process.json`` (written whole, then renamed into place)."""
        path = Path(folder) / "process.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self.to_dict()))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, folder, likelihood=None) -> "CalibrationProcess":
        """The process :meth:`save` left in ``folder``; ``likelihood`` where it was not a :class:`FixedError`."""
        s = json.loads((Path(folder) / "process.json").read_text())
        if likelihood is None:
            if s["likelihood"] is None:
                raise ValueError(f"{folder}: the process' likelihood is not saved; pass it to load()")
            likelihood = FixedError(error_from_dict(s["likelihood"]["obs_error"]))
        r = s["rng"]
        if "seed" in r:
            rng = SeededSteps(**r)
        else:
            rng = np.random.Generator(getattr(np.random, r["bit_generator"])())
            rng.bit_generator.state = r["state"]
        a, e, t = s["analysis"], s["emulated"], s["transform"]
        p = cls(s["params"], s["obs"], likelihood, rng=rng, schedule=StepSchedule(**s["schedule"]),
                stop=StopPolicy(StopCriteria(**s["stop"])), failure=FailurePolicy(**s["failure"]),
                analysis=AnalysisSettings(**{**a, "localization": _array(a["localization"])}),
                emulated=EmulatedSettings(**{**e, "times": _array(e["times"]), "groups": _array(e["groups"])}),
                transform=None if t is None else BoxTransform(np.array(t["lower"]), np.array(t["upper"]), t["kind"]),
                names=s["names"], iteration=s["iteration"], runs=[(np.array(p), np.array(y)) for p, y in s["runs"]],
                prior_spread=s["prior_spread"], update_on_stop=s["update_on_stop"], label=s["label"])
        p.decision = None if s["decision"] is None else StopDecision(**s["decision"])
        p.history, p.n_simulations = s["history"], s["n_simulations"]
        return p


def _kalman(process: CalibrationProcess, step: Step, rng) -> tuple[object, np.ndarray]:
    """ES-MDA step ``alpha_k`` or the paper's EnKF, with the error the likelihood assimilates at ``alpha``."""
    method = process.schedule.method
    infl, base = process.analysis.resolved(method)
    total = step.terms.assimilation(step.alpha)
    truncation = capped_truncation(step.responses, step.alive, total, base, process.analysis.max_rank)
    common = dict(rng=rng, transform=process.transform, localization=process.analysis.localization,
                  inflation=infl, prior_std=process.prior_spread, alive=step.alive,
                  min_alive_fraction=process.failure.min_alive_fraction, truncation=truncation, names=process.names)
    if method == "esmda":
        res = esmda_update(step.params, step.responses, process.obs, total, alpha=step.alpha, **common)
    else:
        res = enkf_update(step.params, step.responses, process.obs, total, **common)
    return res, res.params


register_analysis("esmda", _kalman)
register_analysis("enkf", _kalman)


def capped_truncation(Y: np.ndarray, alive: np.ndarray, err: ObservationError, base: float,
                      max_rank: int | None) -> float:
    """The ``truncation`` argument of :func:`enkf.esmda_update` / :func:`enkf.enkf_update` that keeps at
    most ``max_rank`` singular values of the whitened response anomalies (and never more than ``base``).

    Same anomalies as the analysis: ``S = L^{-1} (Y_alive - mean)^T / sqrt(N_alive - 1)``; the
    returned fraction sits just below the cumulative singular-value fraction of the ``max_rank``-th
    value, so :func:`enkf.truncation_rank` keeps exactly ``min(rank(base), max_rank)`` values.
    """
    if max_rank is None:
        return base
    Ya = np.asarray(Y, float)[np.asarray(alive, bool)]
    if Ya.shape[0] < 2:
        return base
    S = err.whiten((Ya - Ya.mean(axis=0)).T) / math.sqrt(Ya.shape[0] - 1)
    s = np.linalg.svd(S, compute_uv=False)
    if s.size == 0 or s[0] <= 0:
        return base
    frac = np.cumsum(s) / np.sum(s)
    r = min(int(max_rank), int(np.count_nonzero(s > s[0] * 1e-12)))
    if r >= s.size or frac[r - 1] >= base:
        return base
    return float(frac[r - 1]) - 1e-12


def all_runs(params: Sequence[np.ndarray], responses: Sequence[np.ndarray], last_alive):
    """Every successful run of iterations ``0..K``: ``(X (k, n), Y (k, m), latest (k,) bool)``, where a run
    counts if its curve is finite on the grid (and, in iteration ``K``, its member is alive)."""
    runs = [(np.asarray(p, float), np.asarray(y, float)) for p, y in zip(params, responses)]
    ok = [np.all(np.isfinite(y), axis=1) for _, y in runs]
    ok[-1] = ok[-1] & np.asarray(last_alive, bool)
    X = np.vstack([p[o] for (p, _), o in zip(runs, ok)])
    Y = np.vstack([y[o] for (_, y), o in zip(runs, ok)])
    latest = np.concatenate([np.full(int(o.sum()), i == len(runs) - 1) for i, o in enumerate(ok)])
    return X, Y, latest


def error_to_dict(err: ObservationError) -> dict:
    """The error models a saved :class:`FixedError` can hold, by their defining numbers."""
    if isinstance(err, DiagonalError):
        return {"kind": "diagonal", "sigma": err.std.tolist()}
    if isinstance(err, AR1Error):
        return {"kind": "ar1", "sigma": err.std.tolist(), "times": err.times.tolist(), "corr_time": err.corr_time,
                "groups": err.groups.tolist()}
    if isinstance(err, SquaredExponentialError):
        return {"kind": "sqexp", "sigma": err.std.tolist(), "times": err.times.tolist(), "corr_time": err.corr_time,
                "groups": err.groups.tolist(), "nugget": err.nugget}
    if isinstance(err, DenseError):
        return {"kind": "dense", "matrix": err.dense().tolist()}
    raise TypeError(f"cannot save an observation error of kind {err.kind!r}")


def error_from_dict(e: Mapping) -> ObservationError:
    kind = e["kind"]
    if kind == "diagonal":
        return DiagonalError(np.array(e["sigma"]))
    if kind == "ar1":
        return AR1Error(np.array(e["sigma"]), np.array(e["times"]), e["corr_time"], np.array(e["groups"]))
    if kind == "sqexp":
        return SquaredExponentialError(np.array(e["sigma"]), np.array(e["times"]), e["corr_time"],
                                       np.array(e["groups"]), e["nugget"])
    return DenseError(np.array(e["matrix"]))


def _arrays(d: dict) -> dict:
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in d.items()}


def _array(v):
    return None if v is None else np.asarray(v)


def _nan(v) -> float:
    return math.nan if v is None else float(v)
