"""Where a strength-confounded effect is fitted when its design spans the strength: the sweep of each such
candidate made at a third strength, the design box's lower bound (issue 53, item 2; after
``insample_interactions.py``).

``insample_interactions.py`` gave the anchored surrogate the ``sigma_t`` x effect term from one sweep at
the design's lower ``sigma_t`` step, a term linear in ``sigma_t``. On the development friction series the
base sat at 39-54 MPa for a planted 25, and the in-sample fit then either kept the friction near its null
(mu 0.03; the walk's weights) or reached the box's lower bound by extrapolating that term (mu 0.21 at
``sigma_t`` 16.8 MPa; the noise's weights), whose real runs were worse on two of three records.

Here, per calibration record on its design mesh, the candidate's sweep (and the candidate at its null) is
run again at the design box's lower ``sigma_t``, so the term is measured at three strengths (the anchor,
where it is zero by construction, the lower step and the box's bound) and interpolated piecewise-linearly
between them. For each candidate named, the base and base + candidate are fitted in sample on all
calibration records, with the walk's weights and with the noise's, run on each record's check meshes and
compared in pairs (the walk's weights, and the plain squared error).

Development data only. Run after ``insample_interactions.py`` on the same series (its lower-step sweeps
are read from its run folder)::

    python studies/tensor_points.py --series <clone>/results/planted_interface_friction_5391 \\
        --effects interface_friction rate_strength --out studies/results/tensor_points_interface_friction_5391.json
"""
from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

from enkf.emulator import AnchoredEmulator, _chords  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402
from studies.insample_interactions import compare, sweeps_at  # noqa: E402
from studies.insample_ranking import fits, load, real_curves  # noqa: E402


class LevelledPairs(AnchoredEmulator):
    """The anchored emulator whose ``(sigma_t, effect)`` terms are measured at several strengths and
    interpolated piecewise-linearly in ``sigma_t`` between them (zero at the anchor; the end segments
    extended linearly), instead of one level scaled linearly."""

    levels: dict = {}

    def __call__(self, P) -> np.ndarray:
        P = np.array(P, dtype=float, ndmin=2)
        Y = super().__call__(P)  # built without one-level pairs (levelled): the axes' first-order sum
        for (i, j), lv in self.levels.items():
            us = np.array([self.anchor[i]] + [u for u, _, _ in lv])
            terms = np.stack([np.zeros((P.shape[0], self.m))] + [_chords(v, G, P[:, j]) for _, v, G in lv])
            order = np.argsort(us)
            us, terms = us[order], terms[order]
            k = np.clip(np.searchsorted(us, P[:, i]), 1, us.size - 1)
            w = ((P[:, i] - us[k - 1]) / (us[k] - us[k - 1]))[:, None]
            rows = np.arange(P.shape[0])
            Y += terms[k - 1, rows] + w * (terms[k, rows] - terms[k - 1, rows])
        return Y


def levelled(em: AnchoredEmulator, sigma_run: tuple, sweeps: dict) -> LevelledPairs:
    """``em`` with a ``sigma_t`` axis run ``(u, curve)`` added and, per effect index, the pair terms of
    ``sweeps[j] = [(u, values, curves), ...]`` at each strength."""
    i = em.names.index("sigma_t")
    axes = {j: (v[v != em.anchor[j]], (D + em.f0)[v != em.anchor[j]]) for j, (v, D) in em._axes.items()}
    u0, y0 = sigma_run
    axes[i] = (np.append(axes[i][0], u0), np.vstack([axes[i][1], y0]))
    out = LevelledPairs(em.anchor, em.f0, axes, em.lower, em.upper, names=em.names)
    out.levels = {(i, j): [out._pair_term(i, j, u, v, Y) for u, v, Y in lv] for j, lv in sweeps.items()}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", required=True)
    ap.add_argument("--effects", nargs="+", required=True)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    series = Path(a.series)
    work = series / "study_tensor_points"
    state = load(series)
    with ThreadPoolExecutor(2) as pool:
        _, mid = sweeps_at(series, state, series / "study_insample_interactions" / "cross", pool)
        low, sweeps = sweeps_at(series, state, work / "lower", pool, at="bound", effects=a.effects, with_null=True)
    for rec in state["calib"]:
        em = state["model"].emulators[rec]
        per = {j: [mid[rec][j], sweeps[rec][j]] for j in sweeps[rec]}
        state["model"].emulators[rec] = levelled(em, low[rec], per)
    obs = pd.read_csv(series / "observations" / "obs.csv")
    sig_noise = np.concatenate([obs[obs.record == j].sigma_Pa.to_numpy() for j in state["calib"]])
    yy = np.concatenate([state["y"][j] for j in state["calib"]])
    out = {"series": series.name, "effects": a.effects, "fits": {}}
    with ThreadPoolExecutor(2) as pool:
        for wname, sig in (("walk_weights", state["sig"]), ("noise", sig_noise)):
            at = fits(dict(state, sig=sig), a.effects, yy, starts=12, seed=a.seed)
            pts = {c: dict(zip(at[c]["names"], map(float, at[c]["x"]))) for c in [None, *a.effects]}
            real = {c: real_curves(state, series, pts[c], work / "points", pool) for c in [None, *a.effects]}
            out["fits"][wname] = {"base_point": pts[None], "candidates": {
                c: {"point": pts[c], **compare(state, state["y"], real[None], real[c])} for c in a.effects}}
    out["what"] = __doc__.split("\n")[0]
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
