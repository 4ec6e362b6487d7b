"""Leave-one-calibration-record-out cross-validation of a model (base parameters + a set of effects)
and the test of a difference of two models' cross-validated errors (:mod:`enkf.diagnosis`, the frozen
protocol).

**The model** the protocol sees (:class:`ForwardModel`): ``model.forward(names, records)`` maps
``(N, n)`` parameter rows to the ``(N, m)`` concatenated curves of ``records`` (record ``r`` reads shared
names and its own per-record copies ``<param>@r``; a parameter not named is at its null), and
``model.box(names)`` gives ``(lower, upper)`` for names and plain parameter names. What a record's curve
depends on besides the parameters (its incident wave, its test sheet, its loading rate) is the model's
business; its observed curve is not part of the model.

**A model** is a :class:`ModelSpec`: base names and effects; an effect is ``shared`` (one value for every
record) or ``per_record`` (one copy per record: estimated on every calibration record, predicted for an
unseen one from the population of the others, :mod:`.population`; each parameter of a per-record effect
with several, e.g. a baseline's offset and drift, has its own population, their correlation is not
modelled).

**Cross-validation** (:func:`cross_validate`): for each calibration record ``j``, ES-MDA of the model on
the other calibration records (:func:`calibrate`), the populations of its per-record parameters from
those records, and the prediction of ``j`` (:func:`predict_record`) at the point (shared parameters at
their posterior mean, per-record ones at the population's predictive median) that a real-simulator
check can run, with a band from draws (posterior members x population draws). Scored by the squared
error and the log predictive density (a mixture over the draws, error covariance = noise + model error
+ simulator variability). Record ``j``'s observations are read only to score it.

**The difference of two models' errors** (:func:`squared_error_difference`). For one record with data
``y``, predictions ``a`` (current model) and ``b`` (candidate), ``u = y - a``, ``v = y - b``, ``d = b - a``,
``Delta = |u|^2 - |v|^2`` (> 0: the candidate predicts better). Perturb with independent Gaussian errors:
``y`` by ``e ~ N(0, R)`` (instrument noise), ``a`` and ``b`` by model errors ``alpha``, ``beta`` with
``Cov(alpha) = A_a``, ``Cov(beta) = A_b``, ``A = E + S`` (emulator/model error ``E`` plus simulator
variability ``S``, plus optionally each prediction's own calibration spread ``P``, below) and
``Cov(alpha, beta) = C = rho E + rho_S S`` (``rho``: how alike the model errors of two nearby predictions
are; 0, the default, treats them as independent, the cautious choice; ``rho_S`` likewise for the
simulator's variability: 1 where both predictions interpolate runs on one mesh realization, as the
anchored selection model's do, so that its departure is common to both and enters like the noise,
``4 d'Sd``). Then ``u' = u + e - alpha``,
``v' = v + e - beta`` and

    Delta' = Delta + [2 d.e - 2 u.alpha + 2 v.beta] + [|alpha|^2 - |beta|^2 - 2 e.(alpha - beta)]

The first bracket is linear, the second quadratic, and they are uncorrelated (odd moments of zero-mean
Gaussians vanish), so

    Var(Delta) = 4 d'Rd + 4 (u'A_a u + v'A_b v - 2 u'Cv) + 2 tr(A_a^2) + 2 tr(A_b^2) - 4 tr(C^2)
                 + 4 tr(R (A_a + A_b - 2C))

(``Var |alpha|^2 = 2 tr A_a^2``, ``Cov(|alpha|^2, |beta|^2) = 2 tr C^2``; the mean is ``Delta + tr A_a - tr
A_b``, ``Delta`` when the two error models are alike). With only instrument noise the
quadratic terms of ``y`` cancel exactly: ``Delta`` is linear in ``e`` and ``Var = 4 d'Rd`` exactly. Records
are independent, so the variances of the per-record differences add. Checked by simulation in the tests.

What this leaves out by default: the scatter of the predictions themselves, from the noise of the
training records and the ensemble's sampling (the calibrations shared between folds are not counted
either, the usual approximation of cross-validation). Measured on the stand-in, the z of null
candidates then has sd 1.0-1.7 and mean -0.5 to -1.1; the level holds because a null candidate's
prediction is on average worse, not better. ``prediction_spread=True`` (:func:`compare_cv`) adds each
prediction's spread over its posterior members (per-record values at the point), ``P_a`` and ``P_b``,
as independent terms: null z then has sd 0.2, and a real rate law's z falls from 18 to 13.

The calibration's own error model (for ES-MDA and the whitened residual) is the sum of the same parts,
block-diagonal over records; the model error must be time-correlated (``enkf.emulated.
emulator_error_model``, per-time rms with AR(1)): a diagonal model-error term is refused, because it
counts every time as independent evidence.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy import special, stats

from ..analysis import esmda_alphas
from ..covariance import DenseError, ObservationError
from ..diagnostics import posterior_dict
from ..loop import assimilate
from ..sampling import latin_hypercube
from ..transforms import BoxTransform
from .population import Population, fit_population, record_name, split_name

__all__ = ["CVResult", "Fit", "ForwardModel", "ModelSpec", "Prediction", "RecordErrors", "calibrate",
           "compare_cv", "compare_replicated", "cross_validate", "fit_populations", "given_fit", "holm", "predict_record",
           "box_draws",
           "scope_of", "seed_for", "squared_error_difference"]

SCOPES = ("per_record", "shared")


class ForwardModel(Protocol):
    def forward(self, names: Sequence[str], records: Sequence[str]) -> Callable[[np.ndarray], np.ndarray]: ...

    def box(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]: ...


def seed_for(seed: int, *parts) -> int:
    """A seed from the run's seed and labels (independent of call order: a fold gives the same numbers
    whichever candidates ran before it)."""
    return (int(seed) * 1_000_003 + zlib.crc32("|".join(map(str, parts)).encode())) % (2 ** 32)


def scope_of(candidate, scopes: Mapping[str, str] | None = None) -> str:
    """``scopes[name]``, else the candidate's ``scope`` attribute, else ``shared``."""
    s = (scopes or {}).get(candidate.name, getattr(candidate, "scope", "") or "shared")
    if s not in SCOPES:
        raise ValueError(f"scope of {candidate.name}: {s!r} is not one of {SCOPES}")
    return s


@dataclass(frozen=True)
class ModelSpec:
    """Base names and the effects added (candidates with ``name``, ``param_names``, ``nulls``), with their
    scopes resolved (``scopes`` overrides a candidate's own)."""

    base: tuple[str, ...]
    effects: tuple = ()
    scopes: tuple[tuple[str, str], ...] = ()

    @classmethod
    def of(cls, base: Sequence[str], effects: Sequence = (), scopes: Mapping[str, str] | None = None):
        return cls(tuple(base), tuple(effects), tuple((e.name, scope_of(e, scopes)) for e in effects))

    def add(self, effect, scopes: Mapping[str, str] | None = None) -> "ModelSpec":
        return ModelSpec(self.base, self.effects + (effect,), self.scopes + ((effect.name, scope_of(effect, scopes)),))

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def shared(self) -> list[str]:
        sc = dict(self.scopes)
        return list(self.base) + [p for e in self.effects if sc[e.name] == "shared" for p in e.param_names]

    @property
    def per_record(self) -> list[str]:
        sc = dict(self.scopes)
        return [p for e in self.effects if sc[e.name] == "per_record" for p in e.param_names]

    def names(self, records: Sequence[str]) -> list[str]:
        """The calibrated names on ``records``: shared ones, then each record's copies (record by record)."""
        return self.shared + [record_name(p, r) for r in records for p in self.per_record]

    def label(self) -> str:
        return "base" + "".join(f" + {e.name}" for e in self.effects)


@dataclass
class RecordErrors:
    """The error model per record: instrument ``noise``, ``model`` error (the emulator's, time-correlated)
    and ``simulator`` variability (run-to-run scatter of the real model at a point), each an
    :class:`~enkf.covariance.ObservationError` on the record's observation times (absent: zero).
    ``model_correlation``, ``simulator_correlation``: correlation of two predictions' model errors and of
    their simulator variability (module docstring).

    ``model_axes``: per record, the model error of each parameter's own term (``{record: {param:
    error}}``, an additive surrogate's error along each axis, e.g. the anchored model's leave-one-out
    residuals along that axis). Where a record has them, a model's error of it is the sum over the
    parameters the model moves (its names, per-record copies read as their parameter), so a model that
    moves fewer parameters carries less surrogate error; and two models' errors share the terms of the
    parameters both move (both read the same axis term of one surrogate: correlation 1) and nothing else
    (``model_correlation`` is then not used). Without names, or for a record without them, ``model``
    (the pooled error) is used. The dense matrices are cached on first use: build a new one rather than
    change its parts."""

    noise: Mapping[str, ObservationError]
    model: Mapping[str, ObservationError] = field(default_factory=dict)
    simulator: Mapping[str, ObservationError] = field(default_factory=dict)
    model_correlation: float = 0.0
    simulator_correlation: float = 0.0
    model_axes: Mapping[str, Mapping[str, ObservationError]] = field(default_factory=dict)
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        terms = [(rec, e) for rec, e in self.model.items()]
        terms += [(f"{rec} ({a})", e) for rec, axes in self.model_axes.items() for a, e in axes.items()]
        for rec, e in terms:
            if getattr(e, "kind", "") == "diagonal" and e.m > 1:
                raise ValueError(f"model error of {rec} is diagonal: give a time-correlated one "
                                 "(enkf.emulated.emulator_error_model)")
        if not 0.0 <= self.model_correlation <= 1.0 or not 0.0 <= self.simulator_correlation <= 1.0:
            raise ValueError("model_correlation and simulator_correlation must lie in [0, 1]")

    def scaled(self, factor: float) -> "RecordErrors":
        """Every term (noise, pooled and per-axis model errors, simulator) times ``factor``, the
        correlations unchanged: the error model of a likelihood whose variance scale is ``factor``."""
        def times(terms):
            return {k: DenseError(factor * e.dense(), _symmetric=True) for k, e in terms.items()}
        return RecordErrors(times(self.noise), times(self.model), times(self.simulator), self.model_correlation,
                            self.simulator_correlation, {r: times(a) for r, a in self.model_axes.items()})

    def axes(self, rec: str, names: Sequence[str] | None) -> tuple[str, ...] | None:
        """The parameters of ``names`` with an own error term for ``rec`` (None: the pooled error applies)."""
        if names is None or rec not in self.model_axes:
            return None
        plain = {split_name(n)[0] for n in names}
        return tuple(sorted(a for a in self.model_axes[rec] if a in plain))

    def _model_dense(self, rec: str, axes: tuple[str, ...] | None, m: int) -> np.ndarray:
        key = ("model", rec, axes)
        if key not in self._cache:
            if axes is None:
                E = self.model[rec].dense() if rec in self.model else np.zeros((m, m))
            else:
                E = sum((self.model_axes[rec][a].dense() for a in axes), np.zeros((m, m)))
            self._cache[key] = E
        return self._cache[key]

    def parts(self, rec: str, names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Dense ``(R, E, S)`` of record ``rec`` for a model of ``names`` (class docstring)."""
        key = ("parts", rec)
        if key not in self._cache:
            R = self.noise[rec].dense()
            S = self.simulator[rec].dense() if rec in self.simulator else np.zeros_like(R)
            self._cache[key] = (R, S)
        R, S = self._cache[key]
        return R, self._model_dense(rec, self.axes(rec, names), R.shape[0]), S

    def pair(self, rec: str, names_a: Sequence[str] | None,
             names_b: Sequence[str] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(R, E_a, E_b, C, S)`` for two models' predictions of ``rec``: their model errors and the
        covariance ``C`` of the two (the shared axes' terms, or ``model_correlation`` times the pooled
        error)."""
        R, Ea, S = self.parts(rec, names_a)
        _, Eb, _ = self.parts(rec, names_b)
        ax_a, ax_b = self.axes(rec, names_a), self.axes(rec, names_b)
        if ax_a is None or ax_b is None:
            return R, Ea, Eb, self.model_correlation * self._model_dense(rec, None, R.shape[0]), S
        common = tuple(a for a in ax_a if a in ax_b)
        return R, Ea, Eb, self._model_dense(rec, common, R.shape[0]), S

    def total(self, rec: str, names: Sequence[str] | None = None) -> DenseError:
        key = ("total", rec, self.axes(rec, names))
        if key not in self._cache:
            self._cache[key] = DenseError(sum(self.parts(rec, names)), _symmetric=True)
        return self._cache[key]

    def calibration_error(self, records: Sequence[str], names: Sequence[str] | None = None) -> DenseError:
        """``R + E + S`` block-diagonal over ``records`` (errors of different records are independent),
        ``E`` that of a model of ``names``."""
        key = ("calib", tuple(records), tuple(self.axes(r, names) for r in records))
        if key not in self._cache:
            blocks = [sum(self.parts(r, names)) for r in records]
            n = sum(b.shape[0] for b in blocks)
            C, i = np.zeros((n, n)), 0
            for b in blocks:
                C[i:i + b.shape[0], i:i + b.shape[0]] = b
                i += b.shape[0]
            self._cache[key] = DenseError(C, _symmetric=True)
        return self._cache[key]


@dataclass
class Fit:
    """A posterior sample ``params`` (rows: draws, e.g. an ES-MDA's alive members) over ``names``.

    ``summary``: the posterior as its source reported it (``{name: {mean, q05, q95, ...}}``) when the
    sample was not fitted here (:func:`given_fit`: the workflow's posterior), so that the protocol
    reports the very numbers the workflow does; None: the sample's own summary. ``info["source"]``
    names where the sample came from (``"emulator"``: :func:`calibrate`)."""

    names: list[str]
    records: tuple[str, ...]
    params: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    info: dict = field(default_factory=dict)
    summary: dict | None = None

    def column(self, name: str) -> np.ndarray:
        return self.params[:, self.names.index(name)]

    def mean(self) -> dict[str, float]:
        return dict(zip(self.names, self.params.mean(axis=0).tolist()))

    def posterior(self) -> dict:
        if self.summary is not None:
            return {n: dict(self.summary[n]) for n in self.names}
        return posterior_dict(self.params, self.names)

    @property
    def source(self) -> str:
        return str(self.info.get("source", "emulator"))


def given_fit(model: ForwardModel, names: Sequence[str], records: Sequence[str], params, *, summary: Mapping,
              info: Mapping | None = None) -> Fit:
    """A posterior fitted elsewhere (the workflow's on the real simulator) as the protocol's :class:`Fit` of
    ``names`` on ``records``: its draws ``params`` (rows) predict, ``summary`` (every name) is what it
    reports. Every draw must lie inside ``model.box(names)`` (an emulator is not evaluated outside its
    design): ValueError otherwise, never a clipped draw."""
    names = list(names)
    P = np.array(params, dtype=float, ndmin=2)
    if P.shape[1] != len(names) or P.shape[0] < 2 or not np.all(np.isfinite(P)):
        raise ValueError(f"a given posterior needs >= 2 finite draws of {names}, got shape {P.shape}")
    missing = [n for n in names if n not in summary]
    if missing:
        raise ValueError(f"the given posterior's summary has no {missing}")
    lo, hi = (np.asarray(v, float) for v in model.box(names))
    out = (P < lo) | (P > hi)
    if np.any(out):
        j = int(np.nonzero(out.any(axis=0))[0][0])
        raise ValueError(f"{int(out.any(axis=1).sum())} of {P.shape[0]} draws of the given posterior lie outside the "
                         f"model's box, e.g. {names[j]} outside [{lo[j]:g}, {hi[j]:g}]: widen the design box to hold them")
    return Fit(names, tuple(records), P, lo, hi, {"source": "given", **dict(info or {})},
               {n: dict(summary[n]) for n in names})


def calibrate(model: ForwardModel, names: Sequence[str], records: Sequence[str], obs: Mapping[str, np.ndarray],
              errors: RecordErrors, *, seed: int, n_members: int = 80, esmda_steps: int = 4) -> Fit:
    """ES-MDA of ``names`` on ``records`` (their observations concatenated, the block-diagonal error of
    :meth:`RecordErrors.calibration_error`) from a Latin hypercube over ``model.box(names)``."""
    names, records = list(names), tuple(records)
    lo, hi = model.box(names)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    y = np.concatenate([np.asarray(obs[r], dtype=float) for r in records])
    rng = np.random.default_rng(seed_for(seed, "calibrate", *records, *names))
    res = assimilate(model.forward(names, records), latin_hypercube(lo, hi, n_members, rng), y,
                     errors.calibration_error(records, names), rng=rng, method="esmda", alphas=esmda_alphas(esmda_steps),
                     transform=BoxTransform(lo, hi), names=names)
    return Fit(names, records, res.params[res.alive], lo, hi,
               {"source": "emulator", "stop_reason": res.decision.reason, "n_members": n_members,
                "esmda_steps": esmda_steps})


def fit_populations(model: ForwardModel, spec: ModelSpec, fit: Fit, *, scales: Mapping[str, str] | None = None,
                    **population_kw) -> dict[str, Population]:
    """The population of each per-record parameter of ``spec`` from its copies in ``fit``."""
    out = {}
    for p in spec.per_record:
        lo, hi = model.box([p])
        out[p] = fit_population({r: fit.column(record_name(p, r)) for r in fit.records}, param=p,
                                lower=float(lo[0]), upper=float(hi[0]), scale=(scales or {}).get(p, "linear"),
                                **population_kw)
    return out


@dataclass
class Prediction:
    """A record's prediction: the ``point`` (names and values a real-simulator run takes), its ``curve``,
    the draws' curves ``draws`` (shared members x population draws) and their central band, and
    ``spread``: the covariance of the curves over the posterior members with the per-record values at the
    point (the calibration's own uncertainty, without the population's)."""

    record: str
    point: dict[str, float]
    curve: np.ndarray
    draws: np.ndarray
    band_level: float
    populations: dict[str, Population]
    spread: np.ndarray | None = None

    @property
    def band(self) -> tuple[np.ndarray, np.ndarray]:
        q = 0.5 * (1.0 - self.band_level)
        return np.quantile(self.draws, q, axis=0), np.quantile(self.draws, 1.0 - q, axis=0)

    def intervals(self, level: float | None = None) -> dict[str, tuple[float, float]]:
        """The predictive interval of each per-record value of the record."""
        return {record_name(p, self.record): pop.interval(level or self.band_level)
                for p, pop in self.populations.items()}

    def summary(self) -> dict:
        lo, hi = self.band
        return {"record": self.record, "point": dict(self.point),
                "intervals": {k: list(v) for k, v in self.intervals().items()},
                "populations": {p: pop.to_dict(self.band_level) for p, pop in self.populations.items()},
                "band_level": self.band_level, "band_width_rms": float(np.sqrt(np.mean((hi - lo) ** 2)))}


def predict_record(model: ForwardModel, spec: ModelSpec, fit: Fit, record: str, populations: Mapping[str, Population],
                   *, seed: int, band_level: float = 0.90) -> Prediction:
    """Predict ``record`` from the shared parameters of ``fit`` and the populations alone (never its data)."""
    shared, per = spec.shared, spec.per_record
    names = shared + [record_name(p, record) for p in per]
    mean = fit.mean()
    point = {n: mean[n] for n in shared}
    point.update({record_name(p, record): populations[p].median() for p in per})
    f = model.forward(names, [record])
    curve = np.asarray(f(np.array([point[n] for n in names]))[0], dtype=float)
    rng = np.random.default_rng(seed_for(seed, "draws", record, *names))
    N = fit.params.shape[0]
    X = np.column_stack([fit.column(n) for n in shared] + [populations[p].draw(rng, N) for p in per])
    Xs = np.column_stack([fit.column(n) for n in shared] + [np.full(N, point[record_name(p, record)]) for p in per])
    spread = np.atleast_2d(np.cov(np.asarray(f(Xs), dtype=float).T))
    return Prediction(record, point, curve, np.asarray(f(X), dtype=float), band_level, dict(populations), spread)


def box_draws(model: ForwardModel, spec: ModelSpec, record: str, n: int, *, seed: int) -> np.ndarray:
    """``(n, m)`` curves of ``record`` with every parameter of ``spec`` uniform over ``model``'s box (an
    emulated model's: its design box): what knowing only that box predicts, against which a prediction's
    band must score better to say more than the box (:func:`enkf.diagnosis.band.informative`)."""
    names = spec.shared + [record_name(p, record) for p in spec.per_record]
    lo, hi = model.box(names)
    rng = np.random.default_rng(seed_for(seed, "box draws", record, *names))
    X = lo + (hi - lo) * rng.random((int(n), len(names)))
    return np.asarray(model.forward(names, [record])(X), dtype=float)


def score_prediction(pred: Prediction, y: np.ndarray, errors: RecordErrors) -> dict:
    """Squared error and RMSE of the point curve; log predictive density of ``y`` (the mixture of
    ``N(draw, R + E + S)`` over the draws, and at the point curve alone)."""
    y = np.asarray(y, dtype=float)
    C = errors.total(pred.record, list(pred.point))
    logdet = 2.0 * float(np.sum(np.log(np.diag(C.cholesky))))
    const = -0.5 * (logdet + y.size * math.log(2.0 * math.pi))
    chi_draws = C.chi2((y[None, :] - pred.draws).T)
    chi_point = float(C.chi2(y - pred.curve))
    r = y - pred.curve
    sq = float(r @ r)
    return {"sq_error": sq, "rmse": math.sqrt(sq / y.size), "n": int(y.size),
            "lpd": float(special.logsumexp(-0.5 * chi_draws) - math.log(chi_draws.size) + const),
            "lpd_point": -0.5 * chi_point + const}


@dataclass
class CVResult:
    """Cross-validation of one model: per calibration record its fold (``folds[j]``: the training
    records, the prediction and its score) and the totals."""

    spec: ModelSpec
    folds: dict[str, dict]

    @property
    def sq_error(self) -> float:
        return float(sum(f["score"]["sq_error"] for f in self.folds.values()))

    @property
    def rmse(self) -> float:
        return math.sqrt(self.sq_error / sum(f["score"]["n"] for f in self.folds.values()))

    @property
    def lpd(self) -> float:
        return float(sum(f["score"]["lpd"] for f in self.folds.values()))

    def curve(self, record: str) -> np.ndarray:
        return self.folds[record]["prediction"].curve

    def spread(self, record: str) -> np.ndarray:
        return self.folds[record]["prediction"].spread

    def points(self) -> dict[str, dict[str, float]]:
        """Per calibration record, the parameter point its CV prediction was made at."""
        return {j: dict(f["prediction"].point) for j, f in self.folds.items()}

    def summary(self) -> dict:
        return {"model": self.spec.label(), "effects": self.spec.effect_names, "cv_rmse": self.rmse,
                "cv_sq_error": self.sq_error, "cv_lpd": self.lpd,
                "folds": {j: {"train": list(f["train"]), **f["score"], **f["prediction"].summary()}
                          for j, f in self.folds.items()}}


def cross_validate(model: ForwardModel, spec: ModelSpec, records: Sequence[str], obs: Mapping[str, np.ndarray],
                   errors: RecordErrors, *, seed: int, n_members: int = 80, esmda_steps: int = 4,
                   scales: Mapping[str, str] | None = None, band_level: float = 0.90,
                   population_kw: Mapping | None = None) -> CVResult:
    """Leave-one-record-out cross-validation of ``spec`` over ``records`` (module docstring)."""
    records = list(records)
    if len(records) < 2:
        raise ValueError("cross-validation needs at least two calibration records")
    folds = {}
    for j in records:
        train = [r for r in records if r != j]
        fit = calibrate(model, spec.names(train), train, obs, errors, seed=seed, n_members=n_members,
                        esmda_steps=esmda_steps)
        pops = fit_populations(model, spec, fit, scales=scales, **(population_kw or {}))
        pred = predict_record(model, spec, fit, j, pops, seed=seed, band_level=band_level)
        folds[j] = {"train": tuple(train), "fit": fit, "prediction": pred,
                    "score": score_prediction(pred, obs[j], errors)}
    return CVResult(spec, folds)


def squared_error_difference(y, a, b, R, E=None, S=None, correlation: float = 0.0, Pa=None,
                             Pb=None, simulator_correlation: float = 0.0, *, Eb=None,
                             Ec=None) -> tuple[float, float]:
    """``(Delta, Var Delta)`` of ``Delta = |y - a|^2 - |y - b|^2`` under the Gaussian errors of the module
    docstring: noise ``R`` on ``y``; model error ``E`` (correlation ``correlation`` between the two
    predictions) plus simulator variability ``S`` (correlation ``simulator_correlation``: 1 when both
    predictions come from runs on one mesh realization) on each prediction, and each prediction's own
    spread ``Pa``, ``Pb`` (independent) if given. Two models with different model errors: ``E`` is
    ``a``'s, ``Eb`` ``b``'s and ``Ec`` the covariance of the two (``correlation`` is then not used)."""
    y, a, b = (np.asarray(v, dtype=float) for v in (y, a, b))
    R = np.asarray(R, dtype=float)
    Ea = np.zeros_like(R) if E is None else np.asarray(E, dtype=float)
    S = np.zeros_like(R) if S is None else np.asarray(S, dtype=float)
    if Eb is None:
        Eb, CE = Ea, correlation * Ea
    else:
        Eb = np.asarray(Eb, dtype=float)
        CE = np.zeros_like(R) if Ec is None else np.asarray(Ec, dtype=float)
    u, v, d = y - a, y - b, b - a
    C = CE + simulator_correlation * S
    Aa = Ea + S if Pa is None else Ea + S + Pa
    Ab = Eb + S if Pb is None else Eb + S + Pb
    delta = float(u @ u - v @ v)
    var = (4.0 * d @ R @ d + 4.0 * (u @ Aa @ u + v @ Ab @ v - 2.0 * u @ C @ v)
           + 2.0 * np.sum(Aa * Aa) + 2.0 * np.sum(Ab * Ab) - 4.0 * np.sum(C * C) + 4.0 * np.sum(R * (Aa + Ab - 2 * C)))
    return delta, float(max(var, 0.0))


def compare_cv(y: Mapping[str, np.ndarray], current: Mapping[str, np.ndarray], candidate: Mapping[str, np.ndarray],
               errors: RecordErrors, *, use_model_error: bool = True, spread_current: Mapping | None = None,
               spread_candidate: Mapping | None = None, names_current: Sequence[str] | None = None,
               names_candidate: Sequence[str] | None = None) -> dict:
    """The difference of two sets of per-record predictions' squared errors, summed over the records of
    ``current``: ``delta`` (> 0: the candidate is better), its ``sd``, ``z = delta / sd`` and the one-sided
    ``p = 1 - Phi(z)``; per record the same. ``use_model_error=False`` leaves out the model (emulator)
    error, for predictions by the real simulator; ``spread_current`` / ``spread_candidate``: per record the
    predictions' own spread (:attr:`Prediction.spread`, module docstring); ``names_current`` /
    ``names_candidate``: the two models' names, for an error per model (:class:`RecordErrors`'
    ``model_axes``)."""
    per, tot, var = {}, 0.0, 0.0
    for j in current:
        R, Ea, Eb, Ec, S = errors.pair(j, names_current, names_candidate)
        if not use_model_error:
            Ea = Eb = Ec = None
        d, v = squared_error_difference(y[j], current[j], candidate[j], R, Ea, S, Pa=(spread_current or {}).get(j),
                                        Pb=(spread_candidate or {}).get(j),
                                        simulator_correlation=errors.simulator_correlation, Eb=Eb, Ec=Ec)
        per[j] = {"delta": d, "sd": math.sqrt(v)}
        tot += d
        var += v
    sd = math.sqrt(var)
    z = tot / sd if sd > 0 else (math.inf if tot > 0 else -math.inf if tot < 0 else 0.0)
    return {"delta": tot, "sd": sd, "z": z, "p": float(stats.norm.sf(z)), "records": per}


def compare_replicated(y: Mapping[str, np.ndarray], current: Mapping[str, np.ndarray],
                       candidate: Mapping[str, np.ndarray], noise: Mapping[str, ObservationError]) -> dict:
    """:func:`compare_cv` for replicated real-simulator runs on common realizations: ``current[j]`` and
    ``candidate[j]`` are ``(K, m)`` arrays, row ``k`` of both run on record ``j``'s realization ``k`` (its
    mesh), so the simulator's variability of the *difference* is measured, not assumed.

    Per record ``Delta_k = |y - a_k|^2 - |y - b_k|^2`` and ``delta = mean_k Delta_k`` (> 0: the candidate
    is better, on average over realizations). Two independent parts of its variance: the realizations',
    ``s^2 / K`` (``s^2`` the sample variance of ``Delta_k``: whatever the two models' mesh departures share
    cancels in it, whatever they do not is in it), and the instrument noise on ``y``, common to every
    ``k``, ``4 dbar' R dbar`` with ``dbar = mean_k (b_k - a_k)`` (exact: ``Delta`` is linear in the noise).
    Records are independent; ``z = delta / sd`` is referred to Student's t with Welch-Satterthwaite's
    degrees of freedom (the noise part known, each record's realization part on ``K - 1``)."""
    per, tot, v_mesh, v_noise, dof_den = {}, 0.0, 0.0, 0.0, 0.0
    for j in current:
        a, b = np.atleast_2d(np.asarray(current[j], float)), np.atleast_2d(np.asarray(candidate[j], float))
        if a.shape != b.shape or a.shape[0] < 2:
            raise ValueError(f"record {j}: replicated comparison needs two (K, m) arrays with K >= 2 on common "
                             f"realizations, got {a.shape} and {b.shape}")
        K = a.shape[0]
        yj = np.asarray(y[j], float)
        deltas = np.sum((yj - a) ** 2, axis=1) - np.sum((yj - b) ** 2, axis=1)
        dbar = np.mean(b - a, axis=0)
        vm = float(np.var(deltas, ddof=1)) / K
        vn = float(4.0 * dbar @ noise[j].dense() @ dbar)
        per[j] = {"delta": float(deltas.mean()), "sd": math.sqrt(vm + vn), "sd_realizations": math.sqrt(vm),
                  "sd_noise": math.sqrt(vn), "replicates": K, "delta_per_replicate": deltas.tolist()}
        tot += float(deltas.mean())
        v_mesh += vm
        v_noise += vn
        dof_den += vm ** 2 / (K - 1)
    var = v_mesh + v_noise
    sd = math.sqrt(var)
    dof = math.inf if dof_den == 0.0 else var ** 2 / dof_den
    z = tot / sd if sd > 0 else (math.inf if tot > 0 else -math.inf if tot < 0 else 0.0)
    p = float(stats.norm.sf(z) if math.isinf(dof) else stats.t.sf(z, dof))
    return {"delta": tot, "sd": sd, "sd_realizations": math.sqrt(v_mesh), "sd_noise": math.sqrt(v_noise),
            "dof": dof, "z": z, "p": p, "test": "paired replicates, Student t (Welch-Satterthwaite)", "records": per}


def holm(p_values: Sequence[float], alpha: float) -> tuple[list[bool], list[float]]:
    """Holm's step-down test of ``K`` one-sided hypotheses at family-wise level ``alpha``: per hypothesis,
    rejected or not and the level its p-value was held to (``alpha / (K - i)`` at step ``i`` from 0;
    ``alpha / K`` for the smallest p, Bonferroni's level)."""
    p = np.asarray(p_values, dtype=float)
    K = p.size
    order = np.argsort(p, kind="stable")
    rejected, levels = [False] * K, [alpha / K] * K
    still = True
    for i, k in enumerate(order):
        levels[k] = alpha / (K - i)
        still = still and bool(p[k] <= levels[k])
        rejected[k] = still
    return rejected, levels
