"""Global sensitivity analysis of the simulated stress curve (issue 19), on SALib.

Which parameters does the curve carry information on, and where in time? An experiment's optional
``sensitivity:`` block (config/schema.yaml) names a box per parameter; :func:`design` draws SALib's
design (eFAST, Saltelli/Sobol' or Morris), the workflow runs one FDEM simulation per row
(rules/sensitivity.smk), and :func:`analyze` turns the curves on the observation grid into indices per
time point and per scalar feature of the curve (:func:`features`). :func:`recommend` lists the
parameters worth calibrating; :func:`report` and :func:`tables` are the files; no Snakemake here.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .contracts import ConfigError, experiment_records, known_parameters

__all__ = ["METHODS", "FEATURES", "AUTO", "SensitivitySpec", "config_errors", "design", "features",
           "analyze", "recommend", "report", "tables", "plot_sensitivity_indices", "report_path",
           "selected_parameters"]

#: ``experiments.<name>.parameters: auto``: calibrate what the experiment's sensitivity stage recommends.
AUTO = "auto"

METHODS = ("efast", "sobol", "morris")
# Defaults of `samples` (SALib's N): eFAST's smallest valid N (N > 4 M^2), a power of two for the
# Sobol' sequence, and Morris' usual 10 trajectories.
DEFAULT_SAMPLES = {"efast": 65, "sobol": 64, "morris": 10}
EFAST_M = 4
MORRIS_LEVELS = 4
CONF_LEVEL = 0.95
FEATURES = ("peak_stress_Pa", "time_to_peak_s", "post_peak_slope_Pa_per_s", "residual_stress_Pa")
POST_PEAK_WINDOW_S = 20e-6
RESIDUAL_FRACTION = 0.1
# A time point whose spread across the design is below this fraction of the largest spread over time
# (e.g. before the wave reaches the specimen) has no variance to share out: its indices would be ratios
# of round-off, so it is reported as NaN.
NO_SPREAD_REL = 1e-6
# spawn_key purposes, disjoint from calibration.experiment.PURPOSES (1-3), so the design is not correlated
# with the experiment's LHS or noise streams drawn from the same seed.
_SEED_PURPOSE = {"design": 19, "bootstrap": 20}
_MEASURES = {"efast": ("S1", "S1_conf", "ST", "ST_conf"), "sobol": ("S1", "S1_conf", "ST", "ST_conf"),
             "morris": ("mu", "mu_star", "mu_star_conf", "sigma", "mu_star_rel", "mu_star_rel_conf")}
_TOTAL = {"efast": "ST", "sobol": "ST", "morris": "mu_star_rel"}
_FIRST = {"efast": "S1", "sobol": "S1", "morris": None}
_NOTES = {"efast": "eFAST (Saltelli et al. 1999): S1 and ST are shares of the output variance. The confidence "
                   "intervals are SALib's bootstrap over half-windows of the search curve, which SALib flags as "
                   "unreliable (SALib issue 649; zero width for some parameters): indicative only.",
          "sobol": "Saltelli/Sobol' (Jansen estimators, no second order): S1 and ST are shares of the output "
                   "variance, with bootstrap confidence intervals over the N base rows.",
          "morris": "Morris elementary effects give a screening measure, not variance shares: mu_star is the mean "
                    "absolute effect of moving a parameter across its box (output units), sigma its spread "
                    "(nonlinearity, interactions); the recommendation uses mu_star_rel = mu_star / the largest "
                    "mu_star on the same output."}


def _seed(seed: int, purpose: str) -> int:
    # SALib's analyze functions ignore a seed of 0 (`if seed:`), so the derived seed is never 0.
    s = np.random.SeedSequence(int(seed), spawn_key=(_SEED_PURPOSE[purpose],)).generate_state(1)[0]
    return int(s) or 1


@dataclass(frozen=True)
class SensitivitySpec:
    """The validated ``experiments.<name>.sensitivity`` block of one experiment."""

    experiment: str
    method: str
    samples: int
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    threshold: float = 0.05
    bootstrap: int = 200
    seed: int = 0
    record: str = "synthetic"
    # Estimated parameters of the experiment not varied here: held at the centre of their prior box.
    held: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def from_config(cls, name: str, exp: Mapping) -> "SensitivitySpec":
        errors = _experiment_errors(name, exp)
        if errors:
            raise ConfigError("invalid sensitivity config:\n  - " + "\n  - ".join(errors))
        s = exp["sensitivity"]
        method, box, seed = s.get("method") or "efast", s.get("parameters") or exp["parameters"], s.get("seed")
        names = tuple(box)
        estimated = {} if exp["parameters"] == AUTO else exp["parameters"]
        held = {p: 0.5 * (lo + hi) for p, (lo, hi) in estimated.items() if p not in box}
        return cls(experiment=name, method=method, samples=int(s.get("samples") or DEFAULT_SAMPLES[method]),
                   names=names, lower=np.array([box[p][0] for p in names], float),
                   upper=np.array([box[p][1] for p in names], float), threshold=float(s.get("threshold", 0.05)),
                   bootstrap=int(s.get("bootstrap", 200)), seed=int(exp["seed"] if seed is None else seed),
                   record=s.get("record") or next(iter(experiment_records(exp))), held=held)

    @property
    def problem(self) -> dict:
        return {"num_vars": len(self.names), "names": list(self.names),
                "bounds": [[float(lo), float(hi)] for lo, hi in zip(self.lower, self.upper)]}

    @property
    def n_simulations(self) -> int:
        """Rows of SALib's design; known from the config alone, so the workflow's DAG needs no checkpoint."""
        D = len(self.names)
        return self.samples * {"efast": D, "sobol": D + 2, "morris": D + 1}[self.method]

    def settings(self) -> dict:
        """Everything the design depends on (Snakemake's params: a change re-draws it)."""
        from enkf import jsonable  # on call: the workflow's parse reads this module (SciPy under enkf)

        return jsonable({"method": self.method, "samples": self.samples, "names": list(self.names),
                         "lower": self.lower, "upper": self.upper, "seed": self.seed, "held": dict(self.held)})


def _experiment_errors(name: str, exp: Mapping) -> list[str]:
    """What a JSON schema cannot check in a sensitivity block: names, boxes, N per method, record."""
    from shpb.parameters import resolve

    s, where, errors = exp.get("sensitivity"), f"experiments.{name}.sensitivity", []
    if s is None:
        return [f"{where}: the experiment has no sensitivity block"]
    method = s.get("method") or "efast"
    if exp.get("parameters") == AUTO and not s.get("parameters"):
        return [f"{where}.parameters: `parameters: auto` calibrates a subset of these boxes; list the candidates"]
    if method not in METHODS:
        return [f"{where}.method: {method!r} is not one of {list(METHODS)}"]
    known = known_parameters(exp.get("geometry", ""))
    for p, box in (s.get("parameters") or exp.get("parameters")).items():
        if p not in known:
            errors.append(f"{where}.parameters.{p}: unknown parameter; the simulator knows {list(known)}")
            continue
        lo, hi = (float(v) for v in box)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            errors.append(f"{where}.parameters.{p}: box [{lo}, {hi}] must have lower < upper")
            continue
        for v in (lo, hi):
            try:
                resolve(exp.get("geometry", ""), {p: v})
            except ValueError as exc:
                errors.append(f"{where}.parameters.{p}: the simulator rejects the box end: {exc}")
    n = s.get("samples")
    if n is not None:
        if method == "efast" and n <= 4 * EFAST_M ** 2:
            errors.append(f"{where}.samples: eFAST needs N > 4 M^2 = {4 * EFAST_M ** 2} (M = {EFAST_M}), got {n}")
        if method == "sobol" and (n < 2 or n & (n - 1)):
            errors.append(f"{where}.samples: Sobol' needs a power of two (the sequence's balance), got {n}")
        if method == "morris" and n < 2:
            errors.append(f"{where}.samples: Morris needs at least 2 trajectories, got {n}")
    recs = list(experiment_records(exp)) if exp.get("kind") in ("twin", "measured") else []
    if s.get("record") and s["record"] not in recs:
        errors.append(f"{where}.record: {s['record']!r} is not a record of the experiment ({recs})")
    return errors


def config_errors(config: Mapping) -> list[str]:
    """Problems of every experiment's sensitivity block (after config/schema.yaml has passed)."""
    return [e for name, exp in config.get("experiments", {}).items() if exp.get("sensitivity") is not None
            for e in _experiment_errors(name, exp)]


def report_path(name: str) -> str:
    """Where the workflow writes an experiment's sensitivity report (relative to the working directory)."""
    return f"results/{name}/sensitivity/report.json"


def selected_parameters(name: str, exp: Mapping, report: Mapping | str | None = None) -> dict[str, list[float]]:
    """The estimated parameters of an experiment configured with ``parameters: auto``: those its
    sensitivity report recommends, each with its box from ``sensitivity.parameters``; the others keep
    the simulator's defaults (or ``fixed``). ``report``: the report's content or path (default
    :func:`report_path`). A report drawn over other boxes than the config's (a stale report), an empty
    recommendation or one the ensemble cannot span is a :class:`ConfigError` naming what to change."""
    import json
    from pathlib import Path

    if isinstance(report, Mapping):
        rep, path = report, f"the sensitivity report of {name}"
    else:
        path = report or report_path(name)
        if not Path(path).is_file():
            raise ConfigError(f"experiments.{name}.parameters: auto needs the sensitivity report {path}; "
                              f"run `snakemake results/{name}/sensitivity/report.json` first (the workflow does)")
        rep = json.loads(Path(path).read_text())
    boxes = {p: [float(lo), float(hi)] for p, (lo, hi) in exp["sensitivity"]["parameters"].items()}
    drawn = {p: [float(lo), float(hi)] for p, (lo, hi) in rep.get("parameters", {}).items()}
    if drawn != boxes:
        raise ConfigError(f"{path}: the report was drawn over {drawn}, but experiments.{name}.sensitivity.parameters "
                          f"is now {boxes}; re-run the sensitivity stage")
    chosen = [r["parameter"] for r in rep.get("recommended", [])]
    if not chosen:
        raise ConfigError(f"{path}: no parameter has a total index above the threshold ({rep.get('threshold')}), "
                          f"so `experiments.{name}.parameters: auto` has nothing to calibrate; lower "
                          f"sensitivity.threshold or list the parameters by hand")
    n = int(exp["ensemble_size"])
    if n <= len(chosen):
        raise ConfigError(f"experiments.{name}.ensemble_size: {n} members cannot span the {len(chosen)} parameters "
                          f"the sensitivity report selects ({chosen}); use more than {len(chosen)}")
    return {p: boxes[p] for p in boxes if p in chosen}


def design(spec: SensitivitySpec) -> pd.DataFrame:
    """SALib's design for ``spec.method``: one row per simulation, columns ``spec.names`` (SI units)."""
    from SALib.sample import fast_sampler, morris, sobol

    p, n, seed = spec.problem, spec.samples, _seed(spec.seed, "design")
    X = (fast_sampler.sample(p, n, M=EFAST_M, seed=seed) if spec.method == "efast" else
         sobol.sample(p, n, calc_second_order=False, seed=seed) if spec.method == "sobol" else
         morris.sample(p, n, num_levels=MORRIS_LEVELS, seed=seed))
    return pd.DataFrame(np.asarray(X, float), columns=list(spec.names))


def features(t: np.ndarray, Y: np.ndarray) -> pd.DataFrame:
    """Scalar features of each curve (row of ``Y`` on the times ``t`` [s]), one row per curve.

    peak (first maximum), its time, the mean slope over the 20 us after it (= the stress change over
    those 20 us / 20 us, Pa/s; NaN if the window ends sooner, since a shorter span measures something
    else) and the mean stress over the last 10 % of the window (what the broken specimen still carries).
    """
    t = np.asarray(t, float)
    Y = np.atleast_2d(np.asarray(Y, float))
    out = np.full((Y.shape[0], len(FEATURES)), np.nan)
    tail = t >= t[-1] - RESIDUAL_FRACTION * (t[-1] - t[0]) - 1e-9 * (t[-1] - t[0])  # slack: grid round-off
    for i, y in enumerate(Y):
        if not np.all(np.isfinite(y)):
            continue
        k = int(np.argmax(y))
        t_after = t[k] + POST_PEAK_WINDOW_S
        slope = ((np.interp(t_after, t, y) - y[k]) / POST_PEAK_WINDOW_S
                 if t_after <= t[-1] + 1e-9 * POST_PEAK_WINDOW_S else np.nan)
        out[i] = (y[k], t[k], slope, y[tail].mean())
    return pd.DataFrame(out, columns=list(FEATURES))


def _indices(spec: SensitivitySpec, X: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
    from SALib.analyze import fast, morris, sobol

    seed = _seed(spec.seed, "bootstrap")
    if spec.method == "efast":
        # SALib's eFAST seeds NumPy's global generator and warns about its own bootstrap at every call;
        # restore the global state and keep the caveat once, in the report's method note.
        state = np.random.get_state()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                S = fast.analyze(spec.problem, y, M=EFAST_M, num_resamples=spec.bootstrap, conf_level=CONF_LEVEL,
                                 seed=seed)
        finally:
            np.random.set_state(state)
    elif spec.method == "sobol":
        S = sobol.analyze(spec.problem, y, calc_second_order=False, num_resamples=spec.bootstrap,
                          conf_level=CONF_LEVEL, seed=seed)
    else:
        S = morris.analyze(spec.problem, X, y, num_resamples=spec.bootstrap, conf_level=CONF_LEVEL,
                           num_levels=MORRIS_LEVELS, seed=seed)
        top = float(np.max(S["mu_star"])) or np.nan  # nothing moves the output: no relative measure
        S = {k: np.asarray(S[k], float) for k in ("mu", "mu_star", "mu_star_conf", "sigma")}
        S["mu_star_rel"], S["mu_star_rel_conf"] = S["mu_star"] / top, S["mu_star_conf"] / top
    return {k: np.asarray(S[k], float) for k in _MEASURES[spec.method]}


def analyze(spec: SensitivitySpec, X, Y, t=None, failed_reasons: Mapping[int, str] | None = None) -> dict:
    """Indices of every parameter per time point (columns of ``Y``, shape (n_simulations, n_time)) and,
    with the times ``t`` [s], per feature of the curve (:func:`features`).

    Raises ValueError naming the experiment and the rows if any simulation failed (a NaN in its row):
    eFAST and Sobol' estimate from the complete, structured design; a row cannot be dropped or filled
    without biasing every index, so the stage refuses rather than report wrong shares.
    """
    X, Y = np.asarray(X, float), np.asarray(Y, float).reshape(len(Y), -1)
    if X.shape != (spec.n_simulations, len(spec.names)) or Y.shape[0] != spec.n_simulations:
        raise ValueError(f"experiment {spec.experiment!r}: the {spec.method} design has {spec.n_simulations} rows "
                         f"of {len(spec.names)} parameters; got X {X.shape} and Y {Y.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(Y), axis=1))
    if bad.size:
        why = "".join(f"\n  row {i}: {(failed_reasons or {}).get(int(i), 'no curve on the whole grid')}"
                      for i in bad[:20])
        raise ValueError(f"experiment {spec.experiment!r}: {bad.size} of {len(Y)} sensitivity simulations failed "
                         f"(rows {bad.tolist()}); {spec.method} needs every row of its design, so no indices are "
                         f"computed. Fix the cause or shrink the box away from it and re-run.{why}")
    F = features(t, Y) if t is not None else pd.DataFrame()
    t = np.arange(Y.shape[1], dtype=float) if t is None else np.asarray(t, float)
    std = Y.std(axis=0)
    analysed = std > NO_SPREAD_REL * float(std.max())  # all False when nothing varies
    per_time = {k: np.full((Y.shape[1], len(spec.names)), np.nan) for k in _MEASURES[spec.method]}
    for j in np.flatnonzero(analysed):
        for k, v in _indices(spec, X, Y[:, j]).items():
            per_time[k][j] = v
    out = {"method": spec.method, "names": list(spec.names), "total": _TOTAL[spec.method],
           "first": _FIRST[spec.method], "measures": list(_MEASURES[spec.method]),
           "time": {"t": t, "mean": Y.mean(axis=0), "std": std, "analysed": analysed, "indices": per_time},
           "features": {}}
    nan = {k: np.full(len(spec.names), np.nan) for k in _MEASURES[spec.method]}
    for name in F.columns:
        f = F[name].to_numpy()
        undefined = np.flatnonzero(~np.isfinite(f))
        entry = {"mean": np.nanmean(f) if undefined.size < f.size else np.nan,
                 "std": np.nanstd(f) if undefined.size < f.size else np.nan, "note": None, "indices": nan}
        if undefined.size:
            entry["note"] = f"undefined for rows {undefined.tolist()[:20]} (e.g. the peak within 20 us of the end)"
        elif np.ptp(f) <= 1e-12 * max(float(np.max(np.abs(f))), 1e-300):
            entry["note"] = "the same for every simulation of the design: no variance to attribute"
        else:
            entry["indices"] = _indices(spec, X, f)
        out["features"][name] = entry
    return out


def _max_over_time(indices: dict, key: str) -> tuple[np.ndarray, np.ndarray, list]:
    """Per parameter: the largest index over the analysed times, its time and its row (None if none)."""
    v, t = indices["time"]["indices"][key], indices["time"]["t"]
    rows = [int(np.nanargmax(v[:, i])) if np.any(np.isfinite(v[:, i])) else None for i in range(v.shape[1])]
    return (np.array([np.nan if j is None else v[j, i] for i, j in enumerate(rows)]),
            np.array([np.nan if j is None else t[j] for j in rows]), rows)


def recommend(indices: dict, threshold: float) -> list[dict]:
    """Parameters whose total index (ST; Morris: mu_star_rel) exceeds ``threshold`` as the
    variance-weighted index of the whole curve (:func:`_aggregated`, the estimate), or on a scalar
    feature with the lower end of its confidence interval, each with the reasons.

    A feature is one number per run, so its index at N = 65 is noisy: on the disc the time to peak
    (bimodal: the split or a later plateau) gave `a`, `b` and `c` total indices of 0.21-0.25 with
    half-widths 0.41-0.54 and first-order indices of 0.01-0.03; the whole curve (160 times) gives them
    0.03-0.04.

    Not the largest index over time: where the curve hardly varies (the elastic rise, before any
    joint breaks) the variance is shared among parameters by estimator noise (measured on the marble
    cylinder at N = 65: every parameter reached ST > 0.97 at some time, with CI half-widths up to 0.7),
    and a share of almost no variance says nothing about what the curve constrains."""
    key = indices["total"]
    agg = _aggregated(indices, key)
    out = []
    for i, p in enumerate(indices["names"]):
        reasons = []
        for fname, entry in indices["features"].items():
            v, ci = entry["indices"][key][i], entry["indices"][f"{key}_conf"][i]
            if np.isfinite(v) and v - (ci if np.isfinite(ci) else 0.0) > threshold:
                reasons.append(f"{key} = {v:.3f} +- {ci:.3f} on {fname}")
        if np.isfinite(agg[i]) and agg[i] > threshold:
            reasons.append(f"{key} of the whole curve (variance-weighted over time) = {agg[i]:.3f}")
        if reasons:
            out.append({"parameter": p, "reasons": reasons})
    return out


def _aggregated(indices: dict, key: str) -> np.ndarray:
    # Variance-weighted mean over time (Gamboa et al. 2014's aggregated index of a vector output):
    # the share of the curve's total variance, so time points with little spread count little.
    v, var = indices["time"]["indices"][key], indices["time"]["std"] ** 2
    ok = indices["time"]["analysed"]
    return (var[ok] @ v[ok]) / var[ok].sum() if ok.any() else np.full(v.shape[1], np.nan)


def report(spec: SensitivitySpec, indices: dict, **extra) -> dict:
    """report.json: settings, per-feature indices with CIs, the time-resolved summary, recommendation."""
    from enkf import jsonable  # on call: the workflow's parse reads this module (SciPy under enkf)

    names, key, first = indices["names"], indices["total"], indices["first"]
    per_param = {p: {} for p in names}
    for m in [key] + ([first] if first else []):
        vmax, tmax, _ = _max_over_time(indices, m)
        agg = _aggregated(indices, m)
        for i, p in enumerate(names):
            per_param[p].update({f"max_{m}": vmax[i], f"t_max_{m}_s": tmax[i], f"aggregated_{m}": agg[i]})
    feats = {f: {"mean": e["mean"], "std": e["std"], "note": e["note"],
                 "indices": {p: {m: e["indices"][m][i] for m in indices["measures"]} for i, p in enumerate(names)}}
             for f, e in indices["features"].items()}
    rec = recommend(indices, spec.threshold)
    tt = indices["time"]
    return jsonable({
        "experiment": spec.experiment, "method": spec.method, "method_note": _NOTES[spec.method],
        "N": spec.samples, "n_simulations": spec.n_simulations, "record": spec.record, "seed": spec.seed,
        "bootstrap": spec.bootstrap, "conf_level": CONF_LEVEL,
        "parameters": {p: [lo, hi] for p, lo, hi in zip(names, spec.lower, spec.upper)}, "held": dict(spec.held),
        "features": feats,
        "time_resolved": {"n_times": len(tt["t"]), "n_analysed": int(np.sum(tt["analysed"])),
                          "t_start_s": tt["t"][0], "t_end_s": tt["t"][-1], "skipped": "time points without spread "
                          f"(std <= {NO_SPREAD_REL:g} x the largest std over time): indices NaN",
                          "per_parameter": per_param},
        "threshold": spec.threshold, "criterion": f"{key} above the threshold for the whole curve (variance-weighted over time), or on a feature "
                     "by the lower end of its confidence interval",
        "recommended": rec, "not_recommended": [p for p in names if p not in {r["parameter"] for r in rec}],
        **extra})


def tables(indices: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """indices_time.csv (time_s, parameter, measures, response mean/std) and indices_features.csv."""
    tt, names, measures = indices["time"], indices["names"], indices["measures"]
    rows = {"time_s": np.repeat(tt["t"], len(names)), "parameter": np.tile(names, len(tt["t"])),
            **{m: tt["indices"][m].ravel() for m in measures}, "response_mean_Pa": np.repeat(tt["mean"], len(names)),
            "response_std_Pa": np.repeat(tt["std"], len(names))}
    feat = [{"feature": f, "parameter": p, **{m: e["indices"][m][i] for m in measures}, "feature_mean": e["mean"],
             "feature_std": e["std"]} for f, e in indices["features"].items() for i, p in enumerate(names)]
    return pd.DataFrame(rows), pd.DataFrame(feat)


def plot_sensitivity_indices(path, t: np.ndarray, indices: dict, title: str = "") -> None:
    """One panel per parameter: the first-order (dashed) and total (solid) index over time with their
    CI bands and the mean curve (grey, right axis) for orientation; below, the feature indices as bars
    with CI error bars. Saved atomically (temporary name, then rename)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names, key, first = indices["names"], indices["total"], indices["first"]
    tt, us = indices["time"], np.asarray(t, float) * 1e6
    ncol = min(3, len(names))
    nrow = -(-len(names) // ncol)  # ceil
    fig = plt.figure(figsize=(4.4 * ncol, 2.8 * nrow + 3.4))
    gs = fig.add_gridspec(nrow + 1, ncol, height_ratios=[1.0] * nrow + [1.2])
    for i, p in enumerate(names):
        ax = fig.add_subplot(gs[i // ncol, i % ncol])
        ax2 = ax.twinx()
        ax2.plot(us, tt["mean"] * 1e-6, color="0.7", lw=1.0)
        ax2.set_ylabel("mean stress [MPa]", color="0.5", fontsize=8)
        ax.set_zorder(ax2.get_zorder() + 1)
        ax.patch.set_visible(False)
        for m, style in [(key, "-")] + ([(first, "--")] if first else []):
            v, c = tt["indices"][m][:, i], tt["indices"][f"{m}_conf"][:, i]
            line, = ax.plot(us, v, style, lw=1.4, label=m)
            ax.fill_between(us, v - c, v + c, color=line.get_color(), alpha=0.15, lw=0)
        ax.set(ylim=(-0.05, 1.05), title=p)
        ax.set_xlabel("time [$\\mu$s]", fontsize=8)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8, loc="upper left")
    ax = fig.add_subplot(gs[nrow, :])
    feats = list(indices["features"])
    width = 0.8 / len(names)
    for i, p in enumerate(names):
        x = np.arange(len(feats)) + (i - (len(names) - 1) / 2) * width
        v = np.array([indices["features"][f]["indices"][key][i] for f in feats])
        c = np.array([indices["features"][f]["indices"][f"{key}_conf"][i] for f in feats])
        ax.bar(x, np.nan_to_num(v), width, yerr=np.nan_to_num(c), capsize=2, label=p)
    ax.set_xticks(np.arange(len(feats)))
    ax.set_xticklabels([f + ("\n(no spread / undefined)" if indices["features"][f]["note"] else "") for f in feats],
                       fontsize=8)
    ax.set_ylabel(f"{key} per feature")
    ax.legend(fontsize=8, ncol=min(len(names), 7))
    ax.grid(alpha=0.3, axis="y")
    fig.suptitle(title)
    fig.tight_layout()
    from .plots import _save  # the workflow's atomic PNG writer

    _save(fig, path)
