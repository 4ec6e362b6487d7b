"""The selection on real runs, round by round (issue 53, item 2: "local derivatives from real FDEM runs").

Why: the walk's proposals and their fitted points come from the anchored surrogate, which cannot follow the
strength an end friction or a rate law trades off with; on the development series the selection fitted on
real runs alone named the planted friction, seating and face gap and nothing on the null
(``studies/realrun_selection.py``, studies/README.md). This module is that selection as a state machine the
workflow can drive between jobs, as :mod:`calibration.refit` is: each round lists the FDEM runs it needs
(``rows``), and :func:`next_round` takes their curves and returns the next state. Nothing here runs a
simulation or reads a file; the state is a JSON-able dict. The workflow runs it where an experiment's
``diagnosis.realrun_selection`` asks (rules/diagnosis.smk), beside the confirmation walk: the report's
verdict stays the walk's.

The algorithm, on the calibration records only:

1. **Weights**: per time ``1 / (noise^2 + mesh scatter^2)``, the scatter the base model's runs at the start
   show over the first three check meshes (smoothed over :data:`SMOOTH` samples): the walk's form
   (:func:`enkf.diagnosis.walk_weights`), with the scatter measured on these runs, not the calibration's
   replicates.
2. **Fits**: the base model and each candidate (the base names plus the effect's parameters, a per-record
   effect one copy per record) fitted by Gauss-Newton steps whose Jacobian comes from real runs (finite
   differences averaged over :data:`FIT_MESHES` meshes), each move capped at half the parameter's box. A
   shared effect starts from a profile: ``profile`` interior grid values of its box, ``sigma_t`` and
   ``E_t`` fitted at each, the value whose fitted point leaves the least weighted error on real runs.
3. **Cross-validation points**: each calibration record predicted from the fit on the others (from the
   last linearisation; a per-record copy at the mean of the others' values), run on ``check_meshes``.
4. **Naming**: each candidate against the base by the walk's paired test on those runs
   (:func:`enkf.diagnosis.crossval.compare_replicated`, the curves weighted as in 1); named where
   ``p < level``, the largest ``z``; the named effect against each other passing candidate on the same
   runs, one group unless it beats it at ``level`` (:func:`grouped`).
5. **Intervals**: each fit's 90 % intervals from its last linearisation (:func:`fit_interval`), once its
   check runs are in: they carry the records' AR(1) noise and the mesh scatter as the check runs'
   covariance over time (:func:`mesh_term`), a realization moving a whole curve.
6. **Resolution** (``resolution``: a finer preset): the reported model's fit (the named one, or the base)
   run on ``meshes`` realizations at the finer preset and at the experiment's, and linearised again there;
   the records less the mean difference of the two are fitted by one Gauss-Newton step, the difference's
   own scatter added to the interval's error (:func:`resolution_corrected`). Why: the `fast` mesh fails
   differently from a finer one at the same parameters, and its fit carries that into the parameters (its
   `sigma_t` low by 2-11 % on four development series made at `standard`). Off by default: on those series
   it raised `sigma_t` but held the planted parameters less often than item 5's intervals alone
   (studies/README.md, realrun_resolution row).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from enkf.covariance import AR1Error
from enkf.diagnosis.crossval import RecordErrors, compare_replicated
from enkf.diagnosis.weights import Weighted
from shpb import effects as fx

__all__ = ["FIT_MESHES", "GN_STEPS", "LEVEL", "compare_tracks", "first_round", "fit_interval", "gn_solve", "grouped",
           "mesh_covariance", "mesh_term", "named", "names_of", "next_round", "paired_test", "resolution_corrected",
           "run_rounds", "smoothed_weights"]

FIT_MESHES = 2          # meshes a linearisation's runs are averaged over
WEIGHT_MESHES = 3       # the first check meshes, whose scatter sets the weights
GN_STEPS = 3
PROFILE_STEPS = 4       # Gauss-Newton steps of sigma_t and E_t at each profile grid value
LEVEL = 0.005
SMOOTH = 11
REL_STEP = {"sigma_t": 0.03, "E_t": 0.15}
EFFECT_STEP = 0.1       # of the effect parameter's box width
MAX_MOVE = 0.5          # of a parameter's box width per Gauss-Newton step
BASE = ("sigma_t", "E_t")


def names_of(effect: str | None, records: Sequence[str]) -> tuple[list[str], dict[str, list[str]]]:
    """``(shared names, {record: its own names})`` of the base model plus ``effect`` (None: the base)."""
    shared, own = list(BASE), {r: [] for r in records}
    if effect is not None:
        e = fx.get_effect(effect)
        for p in e.params:
            name = f"{e.name}.{p.name}"
            if e.scope == "shared":
                shared.append(name)
            else:
                for r in records:
                    own[r].append(f"{name}@{r}")
    return shared, own


def _sim_params(theta: Mapping, record: str, shared, own) -> dict:
    p = {n: float(theta[n]) for n in shared}
    p.update({n.split("@")[0]: float(theta[n]) for n in own[record]})
    return p


def _bounds(box: Mapping, name: str) -> tuple[float, float]:
    return tuple(box[name.split("@")[0]])


def _step(box, name, theta) -> float:
    if name in REL_STEP:
        return REL_STEP[name] * theta[name]
    lo, hi = _bounds(box, name)
    return EFFECT_STEP * (hi - lo)


def _smoothed_var(runs) -> np.ndarray:
    """The runs' sample variance per time (rows: meshes), smoothed over SMOOTH samples."""
    return np.convolve(np.var(np.asarray(runs), axis=0, ddof=1), np.ones(SMOOTH) / SMOOTH, mode="same")


def smoothed_weights(runs: np.ndarray, noise_sd: float) -> np.ndarray:
    """``1 / (noise^2 + var)`` per time, ``var`` the runs' sample variance (rows: meshes) smoothed over SMOOTH."""
    return 1.0 / (noise_sd ** 2 + _smoothed_var(runs))


def gn_solve(theta: Mapping, base: Mapping, jac: Mapping, allnames: Sequence[str], w: Mapping, y: Mapping,
             records: Sequence[str], box: Mapping) -> dict:
    """One Gauss-Newton update of ``theta`` from ``records``' data, weighted by ``w``, on the columns some
    record's Jacobian moves; each move capped at MAX_MOVE of the box and clipped to it."""
    cols = sorted({allnames.index(n) for r in records for n in allnames
                   if np.any(jac[r][:, allnames.index(n)] != 0)})
    A = np.vstack([np.sqrt(w[r])[:, None] * jac[r][:, cols] for r in records])
    b = np.concatenate([np.sqrt(w[r]) * (y[r] - base[r]) for r in records])
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    d, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    d = d / scale
    new = dict(theta)
    for j, c in enumerate(cols):
        n = allnames[c]
        lo, hi = _bounds(box, n)
        move = float(np.clip(d[j], -MAX_MOVE * (hi - lo), MAX_MOVE * (hi - lo)))
        new[n] = float(np.clip(theta[n] + move, lo, hi))
    return new


def named(z_p: Mapping[str, tuple[float, float]], level: float = LEVEL) -> str:
    """Among the candidates whose ``(z, p)`` against the base has ``p < level``, the largest ``z``; else
    ``"base_kept"``."""
    passing = {e: z for e, (z, p) in z_p.items() if p < level}
    return max(passing, key=passing.get) if passing else "base_kept"


def grouped(name: str, z_p: Mapping[str, tuple[float, float]], level: float = LEVEL) -> list[str]:
    """The named effect's group: itself and every other passing candidate it does not beat at ``level``
    (``z_p``: the named one against each, ``z > 0`` where the named one predicts better)."""
    return [name] + sorted(e for e, (z, p) in z_p.items() if not p < level)


# --- the rounds ---------------------------------------------------------------------------------------
#
# A track is one model being fitted (the base, or the base plus one candidate). Its stage says what its
# next runs are: "profile" (a shared effect's grid values, sigma_t and E_t fitted at each), "profile_real"
# (each grid value's fitted point run as it is), "gn" (a full linearisation), "check" (the
# cross-validation points on the check meshes), "done". Every run a round asks for is a row:
# {"track", "part", "record", "simulator", "kind": "fit" | "check", "mesh": k, "name", "h"}; the workflow
# maps (kind, k) to a mesh realization (the fit meshes, the check's own realizations).


def _lin_rows(track: str, part, theta, shared, own, records, box, vary=None) -> list[dict]:
    rows = []
    for r in records:
        for name in [None] + [n for n in shared + own[r] if vary is None or n in vary]:
            th, h = dict(theta), 0.0
            if name is not None:
                lo, hi = _bounds(box, name)
                step = _step(box, name, theta)
                th[name] = theta[name] + step if theta[name] + step <= hi else theta[name] - step
                h = th[name] - theta[name]
            for m in range(FIT_MESHES):
                rows.append({"track": track, "part": part, "record": r, "simulator": _sim_params(th, r, shared, own),
                             "kind": "fit", "mesh": m, "name": name, "h": h})
    return rows


def _linearised(rows: Sequence[dict], curves: Sequence, shared, own, records):
    """``(base, jac, allnames)`` of one linearisation's rows and curves (a failed run, None, is left out of
    its mean; a name all of whose runs failed keeps a zero column: not moved this step)."""
    allnames = shared + [n for r in records for n in own[r]]
    base, jac = {}, {}
    for r in records:
        mine = [(row, c) for row, c in zip(rows, curves) if row["record"] == r]
        at_runs = [c for row, c in mine if row["name"] is None and c is not None]
        if not at_runs:
            raise RuntimeError(f"record {r}: every run at the fitted point failed; the real-run fit cannot go on")
        at = np.mean(at_runs, axis=0)
        J = np.zeros((at.size, len(allnames)))
        for name in shared + own[r]:
            runs = [(row, c) for row, c in mine if row["name"] == name and c is not None]
            if runs:
                J[:, allnames.index(name)] = (np.mean([c for _, c in runs], axis=0) - at) / runs[0][0]["h"]
        base[r], jac[r] = at, J
    return base, jac, allnames


def _sse(w, y, at, records) -> float:
    return float(sum(np.sum(w[r] * (y[r] - at[r]) ** 2) for r in records))


def _cv_points(last, base, jac, allnames, w, y, records, shared, own, box) -> dict:
    cv = {}
    for r in records:
        others = [o for o in records if o != r]
        fit = gn_solve(last, base, jac, allnames, w, y, others, box)
        point = {n: fit[n] for n in shared}
        for n in own[r]:
            stem = n.split("@")[0]
            point[n] = float(np.mean([fit[f"{stem}@{o}"] for o in others]))
        cv[r] = point
    return cv


Z90 = 1.6448536269514722     # the standard normal's 95 % point: a central 90 % interval


def mesh_covariance(runs) -> np.ndarray:
    """The sample covariance over time of runs on different mesh realizations (rows). Why full: a
    realization moves a whole curve (its onset, its peak), so its departures are correlated over the record;
    taken as independent per sample, a few MPa of scatter average away over hundreds of samples and the
    intervals come out several times too narrow (about ten times for a development series' friction)."""
    X = np.asarray(runs, float)
    d = X - X.mean(axis=0)
    return d.T @ d / (len(X) - 1)


def fit_interval(theta, last, base, jac, allnames, w, y, records, box, noise, times, mesh=None, extra=None) -> dict:
    """The Gauss-Newton fit's 90 % intervals from its last linearisation: the weighted least squares
    estimator's sandwich covariance ``H^-1 (sum A' W C W A) H^-1`` (``H = sum A' W A``), with ``C`` each
    record's error as the fit sees it: its AR(1) instrument noise, plus ``mesh[r]`` (a full covariance over
    time: the records' own realization and the fit's runs'; None: the scatter the weights hold, per time),
    plus ``extra[r]`` (a full covariance: an estimated correction's own scatter); scaled up where the
    model misses the records by more than ``C`` allows (the weighted squared residual over its expectation).
    Returns ``{"q05", "q95", "sd", "misfit_scale"}``, the parameters the data move (a column no record's
    Jacobian moves has none); the interval is clipped to the box."""
    cols = [c for c in range(len(allnames)) if any(np.any(jac[r][:, c] != 0) for r in records)]
    names = [allnames[c] for c in cols]
    d = np.array([theta[n] - last[n] for n in names])
    # columns scaled to unit weighted norm, as in gn_solve: sigma_t [Pa] and a friction coefficient differ
    # by seven orders of magnitude, past what a pseudo-inverse's cut-off keeps apart
    u = np.linalg.norm(np.vstack([np.sqrt(w[r])[:, None] * jac[r][:, cols] for r in records]), axis=0)
    u[u == 0] = 1.0
    H, M, sse, expected = 0.0, 0.0, 0.0, 0.0
    for r in records:
        A = jac[r][:, cols] / u
        sd, corr_time = noise[r]
        scatter = np.diag(np.maximum(1.0 / w[r] - sd ** 2, 0.0))     # what the weights hold beyond the noise
        C = (AR1Error(np.full(y[r].size, sd), times[r], corr_time).dense() + (scatter if mesh is None else mesh[r])
             + (0.0 if extra is None else extra[r]))
        WA = w[r][:, None] * A
        H = H + A.T @ WA
        M = M + WA.T @ C @ WA
        res = y[r] - base[r] - A @ (d * u)
        sse += float(np.sum(w[r] * res ** 2))
        expected += float(np.sum(w[r] * np.diag(C)))
    Hi = np.linalg.pinv(H)
    # the weighted squared residual against its expectation under C, tr(WC) - tr(H^-1 M) (the fit's own
    # share taken out): a covariance from a few meshes has too low a rank to whiten a residual with
    scale = max(1.0, sse / max(expected - float(np.trace(Hi @ M)), 1e-300))
    sds = np.sqrt(np.maximum(np.diag(Hi @ M @ Hi), 0.0) * scale) / u
    out = {"q05": {}, "q95": {}, "sd": {}, "misfit_scale": scale}
    for n, sdv in zip(names, sds):
        lo, hi = _bounds(box, n)
        out["q05"][n] = float(max(lo, theta[n] - Z90 * sdv))
        out["q95"][n] = float(min(hi, theta[n] + Z90 * sdv))
        out["sd"][n] = float(sdv)
    return out


def mesh_term(check_runs: Mapping, records) -> dict:
    """``fit_interval``'s ``mesh``: per record the covariance of a track's check runs (its cross-validation
    point on every check mesh, near its fit), once for the records' own realization and once over the
    FIT_MESHES the fit's curves average."""
    out = {}
    for r in records:
        runs = [c for c in check_runs[r] if c is not None]
        if len(runs) < 2:
            raise RuntimeError(f"record {r}: fewer than two check runs succeeded; no mesh covariance for the intervals")
        out[r] = (1.0 + 1.0 / FIT_MESHES) * mesh_covariance(runs)
    return out


def resolution_corrected(theta, rows, curves, shared, own, w, y, records, box, noise, times, mesh=None) -> dict:
    """``theta`` corrected for the experiment's mesh resolution (module docstring, item 6). ``rows``: the
    resolution round's, a linearisation at ``theta`` (kind ``fit``) and runs at ``theta`` at the
    experiment's preset (``coarse``) and at the finer one (``fine``); ``curves`` their runs (None: failed).
    The records less ``b = mean(fine) - mean(coarse)`` fitted by one Gauss-Newton step from ``theta`` (its
    curve: every coarse run there averaged); the interval (``mesh``: :func:`fit_interval`'s) gains ``b``'s
    own sampling covariance. Returns ``{"fit", "interval_90", "bias_rms"}`` (``bias_rms`` per record, the
    records' units)."""
    lin = [(row, c) for row, c in zip(rows, curves) if row["kind"] == "fit"]
    _, jac, alln = _linearised([row for row, _ in lin], [c for _, c in lin], shared, own, records)
    at, y_c, extra, rms = {}, {}, {}, {}
    for r in records:
        runs = {k: [c for row, c in zip(rows, curves) if row["record"] == r and row["kind"] == k and c is not None]
                for k in ("coarse", "fine")}
        if min(len(v) for v in runs.values()) < 2:
            raise RuntimeError(f"record {r}: fewer than two runs at a preset succeeded in the resolution round")
        b = np.mean(runs["fine"], axis=0) - np.mean(runs["coarse"], axis=0)
        extra[r] = sum(mesh_covariance(v) / len(v) for v in runs.values())
        at[r] = np.mean(runs["coarse"] + [c for row, c in lin if row["record"] == r and row["name"] is None
                                          and c is not None], axis=0)
        y_c[r], rms[r] = y[r] - b, float(np.sqrt(np.mean(b ** 2)))
    fit = gn_solve(theta, at, jac, alln, w, y_c, records, box)
    return {"fit": fit, "interval_90": fit_interval(fit, theta, at, jac, alln, w, y_c, records, box, noise, times,
                                                    mesh=mesh, extra=extra), "bias_rms": rms}


def _new_track(effect, start, records, box, profile) -> dict:
    shared, own = names_of(effect, records)
    theta = {n: float(start[n]) for n in BASE}
    for n in shared[2:] + [n for r in records for n in own[r]]:
        theta[n] = float(fx.null_values([n.split("@")[0]])[n.split("@")[0]])
    t = {"effect": effect, "shared": shared, "own": own, "theta": theta, "path": [dict(theta)], "step": 0,
         "stage": "gn"}
    if profile and effect is not None and fx.get_effect(effect).scope == "shared":
        lo, hi = _bounds(box, shared[2])
        t["grid"] = [{"theta": {**theta, shared[2]: float(v)}, "sse": None}
                     for v in np.linspace(lo, hi, profile + 2)[1:-1]]
        t["stage"] = "profile"
    return t


def _track_rows(key: str, t: dict, records, box, check_meshes: int, resolution=None) -> list[dict]:
    sh, own = t["shared"], t["own"]
    if t["stage"] == "resolution":
        at = [{"track": key, "part": 0, "record": r, "simulator": _sim_params(t["theta"], r, sh, own), "kind": kind,
               "mesh": m, "name": None, "h": 0.0, "preset": resolution["preset"] if kind == "fine" else None}
              for r in records for kind in ("coarse", "fine") for m in range(int(resolution["meshes"]))]
        return _lin_rows(key, 0, t["theta"], sh, own, records, box) + at
    if t["stage"] == "profile":
        return [row for i, g in enumerate(t["grid"])
                for row in _lin_rows(key, i, g["theta"], sh, own, records, box, vary=BASE)]
    if t["stage"] == "profile_real":
        return [row for i, g in enumerate(t["grid"]) for row in _lin_rows(key, i, g["theta"], sh, own, records, box, vary=())]
    if t["stage"] == "gn":
        return _lin_rows(key, 0, t["theta"], sh, own, records, box)
    if t["stage"] == "check":
        return [{"track": key, "part": 0, "record": r, "simulator": _sim_params(t["cv_points"][r], r, sh, own),
                 "kind": "check", "mesh": m, "name": None, "h": 0.0} for r in records for m in range(check_meshes)]
    return []


def first_round(start: Mapping[str, float], candidates: Sequence[str], records: Sequence[str],
                box: Mapping[str, Sequence[float]], *, profile: int = 5, check_meshes: int = 8,
                resolution: Mapping | None = None) -> dict:
    """Round 0: the weights' runs (the base at ``start`` on the first check meshes) and every track's first
    linearisation. ``box``: ``{name: (lower, upper)}`` for ``sigma_t``, ``E_t`` and every candidate's
    parameters (a per-record parameter by its plain name); ``resolution``: ``{"preset", "meshes"}``, the
    finer preset and the run count of the last round (module docstring, item 6), None: no such round."""
    if check_meshes < WEIGHT_MESHES:
        raise ValueError(f"check_meshes must be at least {WEIGHT_MESHES} (the weights' meshes), got {check_meshes}")
    records = list(records)
    tracks = {"base": _new_track(None, start, records, box, 0)}
    tracks.update({e: _new_track(e, start, records, box, profile) for e in candidates})
    shared, own = names_of(None, records)
    rows = [{"track": "weights", "part": 0, "record": r, "simulator": _sim_params(start, r, shared, own),
             "kind": "check", "mesh": m, "name": None, "h": 0.0} for r in records for m in range(WEIGHT_MESHES)]
    state = {"phase": "running", "round": 0, "records": records, "box": {k: list(v) for k, v in box.items()},
             "start": dict(start), "profile": profile, "check_meshes": check_meshes, "weights": None,
             "resolution": None if resolution is None else dict(resolution), "tracks": tracks, "rows": rows}
    state["rows"] += [row for k, t in tracks.items() for row in _track_rows(k, t, records, box, check_meshes)]
    return state


def _weights(rows, curves, records, noise) -> dict:
    w = {}
    for r in records:
        Y = [c for row, c in zip(rows, curves) if row["record"] == r and c is not None]
        if len(Y) < 2:
            raise RuntimeError(f"record {r}: fewer than two of the weights' runs succeeded; no mesh scatter to weigh by")
        w[r] = smoothed_weights(np.array(Y), noise[r][0])
    return w


def _advance(t: dict, rows, curves, y, w, records, box, noise, times) -> None:
    """One track's state after its round's runs (module comment above)."""
    sh, own = t["shared"], t["own"]
    part = lambda i: ([row for row in rows if row["part"] == i], [c for row, c in zip(rows, curves) if row["part"] == i])
    if t["stage"] == "profile":
        for i, g in enumerate(t["grid"]):
            base, jac, alln = _linearised(*part(i), sh, own, records)
            g["theta"] = gn_solve(g["theta"], base, jac, alln, w, y, records, box)
        t["step"] += 1
        if t["step"] == PROFILE_STEPS:
            t["stage"] = "profile_real"
    elif t["stage"] == "profile_real":
        for i, g in enumerate(t["grid"]):
            g["sse"] = _sse(w, y, _linearised(*part(i), sh, own, records)[0], records)
            t["path"].append({**g["theta"], "profile_sse": g["sse"]})
        best = min(range(len(t["grid"])), key=lambda i: t["grid"][i]["sse"])
        t["theta"], t["stage"], t["step"] = dict(t["grid"][best]["theta"]), "gn", 0
    elif t["stage"] == "gn":
        base, jac, alln = _linearised(rows, curves, sh, own, records)
        last, t["theta"] = t["theta"], gn_solve(t["theta"], base, jac, alln, w, y, records, box)
        t["path"].append(dict(t["theta"]))
        t["step"] += 1
        if t["step"] == GN_STEPS:
            t["cv_points"] = _cv_points(last, base, jac, alln, w, y, records, sh, own, box)
            # the last linearisation, for the interval once the check runs give the mesh covariance
            t["lin"] = {"last": last, "allnames": alln, "base": {r: base[r].tolist() for r in records},
                        "jac": {r: jac[r].tolist() for r in records}}
            t["stage"] = "check"
    elif t["stage"] == "resolution":
        t["resolution"] = resolution_corrected(t["theta"], rows, curves, sh, own, w, y, records, box, noise, times,
                                               mesh=mesh_term(t["check_runs"], records))
        t["stage"] = "done"
    elif t["stage"] == "check":
        t["check_runs"] = {r: [None if c is None else np.asarray(c, float).tolist()
                               for row, c in zip(rows, curves) if row["record"] == r] for r in records}
        lin = t["lin"]
        t["interval"] = fit_interval(t["theta"], lin["last"], {r: np.asarray(v) for r, v in lin["base"].items()},
                                     {r: np.asarray(v) for r, v in lin["jac"].items()}, lin["allnames"], w, y,
                                     records, box, noise, times, mesh=mesh_term(t["check_runs"], records))
        t["stage"] = "done"


def paired_test(y, w, noise, times, ref: Mapping, other: Mapping, records) -> dict:
    """The walk's weighted paired test (:class:`enkf.diagnosis.weights.Weighted`,
    :func:`enkf.diagnosis.crossval.compare_replicated`) of ``other``'s runs against ``ref``'s, ``{record: (K, m)}``
    on common meshes (z > 0: ``other`` predicts the records better); ``noise`` each record's AR(1) ``(sd,
    corr_time)``."""
    errors = RecordErrors({r: AR1Error(noise[r][0], times[r], noise[r][1]) for r in records})
    wt = Weighted(errors, list(records), w)
    c = compare_replicated(wt.scale(y), wt.scale(ref), wt.scale(other), wt.errors.noise)
    return {"z": c["z"], "p": c["p"], "dof": c["dof"],
            "per_record_z": {r: v["delta"] / v["sd"] if v["sd"] > 0 else 0.0 for r, v in c["records"].items()}}


def compare_tracks(ref: dict, other: dict, y, w, noise, times, records) -> dict:
    """:func:`paired_test` of two tracks' check runs; a mesh where either run failed is left out."""
    a, b = {}, {}
    for r in records:
        pairs = [(x, z) for x, z in zip(ref["check_runs"][r], other["check_runs"][r]) if x is not None and z is not None]
        a[r], b[r] = np.array([x for x, _ in pairs]), np.array([z for _, z in pairs])
    return paired_test(y, w, noise, times, a, b, records)


def _result(state, y, w, noise, times) -> dict:
    T, recs = state["tracks"], state["records"]
    fits = {k: {"fit": t["theta"], "interval_90": t["interval"], "path": t["path"], "cv_points": t["cv_points"]}
            for k, t in T.items()}
    cands = {e: {**fits[e], **compare_tracks(T["base"], T[e], y, w, noise, times, recs)} for e in T if e != "base"}
    name = named({e: (c["z"], c["p"]) for e, c in cands.items()})
    versus = {}
    if name != "base_kept":
        versus = {e: compare_tracks(T[e], T[name], y, w, noise, times, recs)
                  for e, c in cands.items() if e != name and c["p"] < LEVEL}
    group = grouped(name, {e: (v["z"], v["p"]) for e, v in versus.items()}) if name != "base_kept" else []
    return {"level": LEVEL, "base": fits["base"], "candidates": cands, "named": name, "versus": versus,
            "group": group}


def next_round(state: Mapping, curves: Sequence, y: Mapping[str, np.ndarray],
               noise: Mapping[str, tuple[float, float]], times: Mapping[str, np.ndarray]) -> dict:
    """The state after ``state``'s round: ``curves`` are its rows' runs in order (an array on the records'
    grid, or None for a failed run); ``y`` the calibration records' values, ``noise`` their AR(1) noise
    ``(sd, corr_time)``, ``times`` their grids. The last round's state has ``phase`` "done", no rows and
    the ``result``."""
    if len(curves) != len(state["rows"]):
        raise ValueError(f"round {state['round']}: {len(state['rows'])} runs asked for, {len(curves)} curves given")
    new = {**state, "tracks": copy.deepcopy(state["tracks"]), "round": state["round"] + 1,
           "runs_so_far": state.get("runs_so_far", 0) + len(curves)}
    recs, box = new["records"], new["box"]
    rows = new["rows"]
    if new["weights"] is None:
        picked = [(row, c) for row, c in zip(rows, curves) if row["track"] == "weights"]
        new["weights"] = {r: v.tolist() for r, v in _weights([p[0] for p in picked], [p[1] for p in picked], recs,
                                                             noise).items()}
    w = {r: np.asarray(v) for r, v in new["weights"].items()}
    for key, t in new["tracks"].items():
        mine = [(row, c) for row, c in zip(rows, curves) if row["track"] == key]
        if mine:
            _advance(t, [m[0] for m in mine], [m[1] for m in mine], y, w, recs, box, noise, times)
    new["rows"] = [row for k, t in new["tracks"].items()
                   for row in _track_rows(k, t, recs, box, new["check_meshes"])]
    if new["rows"]:
        return new
    res = new.get("resolution")
    if "result" not in new:
        new["result"] = _result(new, y, w, noise, times)
        if res:   # the reported model's fit at the finer preset: one more round
            key = _reported(new["result"])
            new["tracks"][key]["stage"] = "resolution"
            new["rows"] = _track_rows(key, new["tracks"][key], recs, box, new["check_meshes"], res)
            return new
    else:
        key = _reported(new["result"])
        new["result"] = {**new["result"], "resolution": {"track": key, **res, **new["tracks"][key]["resolution"]}}
    new["phase"] = "done"
    return new


def _reported(result: Mapping) -> str:
    """The track whose fit the result reports: the named effect's, or the base's."""
    return "base" if result["named"] == "base_kept" else result["named"]


def run_rounds(state: dict, simulate: Callable[[Sequence[dict]], Sequence], y, noise, times) -> dict:
    """Every round in this process: ``simulate(rows)`` gives each row's curve (or None). What a study or a
    test drives; the workflow runs each round's rows as jobs between its checkpoints."""
    while state["phase"] != "done":
        state = next_round(state, simulate(state["rows"]), y, noise, times)
    return state
