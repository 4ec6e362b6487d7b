"""The selection on real runs (:mod:`calibration.realrun`) as the workflow reads and writes it: what its
rounds read of an experiment's calibration records, a run's curve on a record's grid, realrun.json, and
the held-out records' predictions from the fits it reports (rules/diagnosis.smk). The held-out records
are run only here, after the last round, at fits made without them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from shpb import effects as fx

from .realrun import BASE

__all__ = ["heldout_errors", "heldout_rows", "on_grid", "series_of", "summary_of"]

def series_of(obs, exp: Mapping) -> dict:
    """What the rounds read of an experiment's calibration records (``obs``:
    :class:`calibration.observations.Observations`, ``exp``: its config block): ``y``, ``times`` and the
    AR(1) ``noise`` per record, as the workflow estimated it from each record's pre-trigger, and the ``box``
    of the base parameters (the prior's) and of every physical effect
    (:func:`calibration.diagnose.physical_design_ranges`)."""
    from .diagnose import physical_design_ranges

    info = obs.meta["record_info"]
    box = {n: [float(v[0]), float(v[1])] for n, v in exp["parameters"].items() if n in BASE}
    # the physical effects' boxes as the walk's design takes them: null to the catalogue's bound or physical_upper
    names, lo, hi = physical_design_ranges([e.name for e in fx.effects()],
                                           (exp.get("diagnosis") or {}).get("physical_upper"))
    box.update({n: [float(a), float(b)] for n, a, b in zip(names, lo, hi)})
    return {"y": {r: obs.values[obs.record_slice(r)] for r in obs.records},
            "times": {r: obs.time[obs.record_slice(r)] for r in obs.records},
            "noise": {r: (float(info[r]["noise_estimate"]["sigma"]), float(info[r]["noise_estimate"]["corr_time"]))
                      for r in obs.records},
            "box": box}


def on_grid(frame, times: np.ndarray) -> np.ndarray | None:
    """A run's curve (``time_s``, ``stress_Pa``) on a record's grid; None for a failed run or one that does
    not cover the grid."""
    from .observations import curve_on_grid

    if len(frame) < 2:
        return None
    v = curve_on_grid(frame["time_s"].to_numpy(float), frame["stress_Pa"].to_numpy(float), times)
    return v if np.all(np.isfinite(v)) else None


def _reported_fit(summary: Mapping, track: str) -> dict:
    """A track's fit as realrun.json reports it: the resolution round's where it corrected that track."""
    res = summary.get("resolution") or {}
    if res.get("track") == track:
        return res["fit"]
    return summary["base"]["fit"] if track == "base" else summary["candidates"][track]["fit"]


def heldout_rows(summary: Mapping, heldout: Sequence[str], check_meshes: int) -> list[dict]:
    """The held-out records' predictions from realrun.json (``summary``): each held-out record run at the
    base's fit (``model`` "before") and, where an effect is named, at its fit ("after"), on every check
    mesh; a per-record parameter at the mean of the calibration records' copies, the population's value
    (as a cross-validation point takes it). Nothing of a held-out record enters its own prediction."""
    models = {"before": "base"}
    if summary["named"] != "base_kept":
        models["after"] = summary["named"]
    rows = []
    for model, track in models.items():
        fit = _reported_fit(summary, track)
        point = {n: float(v) for n, v in fit.items() if "@" not in n}
        for stem in sorted({n.split("@")[0] for n in fit if "@" in n}):
            point[stem] = float(np.mean([v for n, v in fit.items() if n.split("@")[0] == stem]))
        rows += [{"model": model, "track": track, "record": h, "simulator": point, "mesh": m}
                 for h in heldout for m in range(int(check_meshes))]
    return rows


def heldout_errors(rows: Sequence[Mapping], curves: Sequence, y: Mapping, times: Mapping) -> dict:
    """Per held-out record, the errors of each model's runs (:func:`heldout_rows`; None: a failed run,
    left out) against the record (:func:`enkf.diagnosis.acceptance.replicate_curve_errors`: the RMSE of one
    run on a random mesh, the peak and time-to-peak errors their means)."""
    from enkf.diagnosis.acceptance import replicate_curve_errors

    out = {}
    for h in y:
        out[h] = {}
        for model in ("before", "after"):
            runs = [c for row, c in zip(rows, curves) if row["record"] == h and row["model"] == model and c is not None]
            if runs:
                out[h][model] = replicate_curve_errors(times[h], np.array(runs), y[h])
    return out


def summary_of(state: Mapping) -> dict:
    """realrun.json: the last round's result with the selection's settings and its cost in runs."""
    return {"named": state["result"]["named"], "group": state["result"]["group"], "level": state["result"]["level"],
            "candidates": state["result"]["candidates"], "versus": state["result"]["versus"],
            "base": state["result"]["base"], "resolution": state["result"].get("resolution"),
            "records": state["records"], "start": state["start"],
            "profile": state["profile"], "check_meshes": state["check_meshes"], "rounds": state["round"],
            "runs": state.get("runs_so_far", 0),
            "note": ("beside the confirmation walk: the report's verdict is the walk's; an effect is named where "
                     "its real runs predict the calibration records better than the base's at p < level, the "
                     "largest z; the group holds the passing candidates the named one does not beat")}
