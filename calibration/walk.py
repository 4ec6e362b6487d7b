"""The confirmation walk on the check's real FDEM runs (docs/closing-the-loop.md, step 5), and the
identification gate the refit applies to what it confirmed (step 6).

Why a gate after the walk: the walk confirms whatever lowers the real cross-validated error of the
calibration records, and after a first effect a second one with a small value can still do so without
being what the data lack. On the default run's planted series (a face gap planted) the walk confirmed
the gap and then a rate law nobody planted, at p 0.0070 against its level 0.0071; re-fitted on real runs
its `k` was 0.045 [0, 0.084], its interval holding the law's null. With the approximation error the same
series added a trigger shift whose re-fitted per-record shifts (0.85 and 0.87 us) held zero
(studies/planted_gap_approximation.py). An effect is kept only if real runs place at least one of its
parameters away from its null value: improvement and identification.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from enkf.covariance import DenseError
from enkf.diagnosis import replicated, walk_weights
from shpb import effects as fx

from .observations import Observations, read_curve
from .protocol import confirm

__all__ = ["chain_of", "check_runs_of", "gated", "identified", "walk"]


def check_runs_of(diagnosis: str | Path) -> tuple[list[dict], list]:
    """``(rows, runs)`` of an experiment's check (``diagnosis``: its ``results/<exp>/diagnosis`` folder):
    the rows of ``check_runs.json`` and each row's FDEM curve (``check/<i>/curve.csv``; an empty frame for a
    failed run, :func:`calibration.observations.read_curve`)."""
    d = Path(diagnosis)
    rows = json.loads((d / "check_runs.json").read_text())["rows"]
    return rows, [read_curve(d / "check" / str(i) / "curve.csv") for i in range(len(rows))]


def walk(selection, real: Mapping, obs: Observations, noise: Mapping, simulator: Mapping) -> dict:
    """The confirmation walk on ``real`` (:func:`calibration.protocol.real_curves` of the check):
    ``{"conf", "noise", "simulator", "weights"}``, the walk's result and the error terms it used."""
    y = {r: obs.values[obs.record_slice(r)] for r in obs.records}
    # each time weighted by the inverse of its noise and mesh-scatter variance (walk_weights: why)
    weights = walk_weights(noise, simulator, list(obs.records))
    # the walk's own rule (enkf.diagnosis.replicated), so the error terms given and the test it picks agree
    if replicated(real["cv"].get(0, {}), list(obs.records)):
        # replicated runs on common meshes: the walk measures the variability of the difference of two
        # steps (enkf.diagnosis.compare_replicated); the data carry only their instrument noise
        walk_noise, walk_sim = {r: noise[r] for r in obs.records}, {}
        conf = confirm(selection, real["cv"], y, walk_noise, weights=weights)
    else:
        # one run per point: the data carry their own realization (S on the data, common to every step)
        # and each run its own; the runs of two steps share a mesh, but their departures are taken as
        # independent (nothing measures their correlation): cautious, a real gain can be refuted
        walk_noise = {r: DenseError(noise[r].dense() + (simulator[r].dense() if r in simulator else 0.0),
                                    _symmetric=True) for r in obs.records}
        walk_sim = {r: simulator[r] for r in obs.records if r in simulator}
        conf = confirm(selection, real["cv"], y, walk_noise, simulator=walk_sim, weights=weights)
    return {"conf": conf, "noise": walk_noise, "simulator": walk_sim, "weights": weights}


def identified(names: Sequence[str], draws, effect: str, level: float) -> dict:
    """Whether real runs place ``effect``'s parameters away from their nulls: ``draws`` (rows over
    ``names``) is the refit's posterior of the model that added ``effect`` last. The effect is identified
    when at least one of its parameters (every per-record copy) has a central interval that excludes its
    null value; with m such parameters each interval is at ``1 - (1 - level) / m`` (Bonferroni), so that,
    where the refit's intervals hold their truths at their level, a null effect is kept with probability at
    most ``1 - level`` however many records it has a copy for.
    An interval whose end lies on the null (a draw clipped to the box's edge, where most nulls sit) holds
    it. Returns ``{"effect", "identified", "level", "parameters": [{name, null, lower, upper, excludes}]}``."""
    draws = np.asarray(draws, float)
    own = [i for i, n in enumerate(names) if getattr(fx.effect_of(n), "name", None) == effect]
    if not own:
        raise ValueError(f"no parameter of {effect!r} among {list(names)}")
    tail = (1.0 - float(level)) / (2.0 * len(own))
    nulls = fx.null_values([names[i] for i in own])
    params = []
    for i in own:
        lo, hi = (float(v) for v in np.quantile(draws[:, i], [tail, 1.0 - tail]))
        null = float(nulls[names[i]])
        params.append({"name": names[i], "null": null, "lower": lo, "upper": hi,
                       "excludes": bool(lo > null or hi < null)})
    return {"effect": effect, "identified": any(p["excludes"] for p in params), "level": float(level),
            "parameters": params}


def chain_of(conf: Mapping) -> list[int]:
    """The steps the walk confirmed one after another, the base (0) first: what the gate can fall back on."""
    return [0] + [int(e["step"]) for e in conf["steps"] if e.get("confirmed")]


def gated(conf: Mapping, selection, refit: Mapping | None) -> dict:
    """The walk's result ``conf`` with the identification gate's outcome (``refit``: diagnosis/refit.json,
    None without a refit): the shipped step is the refit's, each dropped model's reason in the text."""
    if refit is None or not refit.get("gated"):
        return {**conf, "identification_gate": _gate_entry(refit)}
    k = int(refit["step"])
    if k not in chain_of(conf):
        raise ValueError(f"the refit's step {k} is not on the walk's chain {chain_of(conf)}")
    spec = selection.step(k).spec
    rmse, loss = conf["real_cv_rmse"], conf["real_cv_loss"]
    dropped = "; ".join(_dropped_text(g) for g in refit["gated"])
    text = (f"shipped: {spec.label()} (real cross-validated RMSE {rmse[0]:.4g} -> {rmse[k]:.4g}"
            + (f"; weighted error per observation {loss[0]:.4g} -> {loss[k]:.4g}" if conf.get("weighted") else "")
            + f"); {dropped}")
    return {**conf, "confirmed": k, "model": spec.label(), "effects": list(spec.effect_names), "text": text,
            "identification_gate": _gate_entry(refit)}


def _gate_entry(refit: Mapping | None) -> dict | None:
    if refit is None:
        return None
    return {"level": refit.get("gate_level"), "kept": refit.get("identification"),
            "dropped": [{k: g[k] for k in ("step", "model", "identification")} for g in refit.get("gated") or []],
            "earlier": refit.get("earlier_identification")}


def _dropped_text(g: Mapping) -> str:
    ident = g["identification"]
    held = ", ".join(f"{p['name']} [{p['lower']:.3g}, {p['upper']:.3g}] holds {p['null']:g}"
                     for p in ident["parameters"])
    return (f"{ident['effect']} was confirmed by the walk but not identified on real runs ({held}, at "
            f"{ident['level']:.0%} over its parameters): dropped")
