"""Does the reported posterior's ``sigma_t`` shift come from where its likelihood is centred? Two more
families of forms on an exact grid (issue 52).

Looking at development twins' curves (data, the emulator at the truth and +-10 % of ``sigma_t``, the runs
nearest the truth) shows the information on ``sigma_t`` sits in the level of the first kink (about
100-120 us) and that the runs scatter after it far more one way than the other: most realizations hold
the plateau, a few fail early and drag the realizations' mean (what the emulator fits) below a typical
realization (what one twin's data are). Two explanations of the median sitting above the truth follow,
each with a form that would remove it:

* ``median_center``: the likelihood centred on a typical realization instead of the mean: the emulator
  moved by the pointwise median of its own leave-one-out residuals at the latest runs (no truth read),
  its AR(1) error fitted to those residuals minus that median. Power-tempered with the shipped ``lambda``
  (``median_center``) and untempered (``median_center_untempered``).
* ``stretch_*``: the width from ``lambda`` but the location from the untempered likelihood: the
  likelihood stretched by ``sqrt(lambda)`` about a centre, ``L(c + (theta - c) / sqrt(lambda))``, with
  ``c`` the untempered posterior's mean (``stretch_mean``), its marginal medians (``stretch_median``) or
  the likelihood's maximum on the grid (``stretch_mode``, the shipped ``tempering: curvature`` form but
  with the power form's ``lambda``, not one calibrated for it).

* ``registered`` (``--registered``): the emulator's error where the scatter is, for each candidate: its
  per-time sd measured on the latest runs' residuals aligned on each run's own kink and placed at the
  candidate curve's kink (:class:`RegisteredDeviance`, log-determinant included), untempered and
  power-tempered by its own ``lambda`` (the median rule on its own pseudo-runs). A fixed per-time sd
  makes a candidate whose kink comes late cheap (its misfit falls where the latest runs scatter) and
  one whose kink comes early dear: an asymmetric likelihood, which the power form turns into a long
  upper tail.

``power`` (shipped) and ``untempered`` (``lambda`` = 1) are the references. Per form: ``sigma_t``'s and
``E_t``'s weighted interval score over the prior's, 90 % and 50 % coverage, the KS p-value of the truths'
PITs and, below 40 MPa, the median's ratio to the truth and the share above it. Everything as
``studies/pit_recalibration.py`` reads it (the kept runs and refinement batch of ``bench_coverage.py
--keep-runs``; the emulator, its AR(1) error and ``lambda`` as :mod:`enkf.ces` builds them).

Run: ``python studies/center_forms.py --kept KEEP --seed S --registered --out
studies/results/center_forms_devS.json`` (about 5 min for 16 twins on one core).

What it found on development seeds 70 and 72 (16 well-specified twins each, 11 below 40 MPa; no benchmark
twin read): neither family beats the shipped form. Centring on the median realization leaves the power
form's shift where it was (below 40 MPa, median over truth 1.027 -> 1.041 and 1.037 -> 1.035; ``sigma_t``
WIS over the prior's 0.249 -> 0.252, 0.234 -> 0.242); untempered it does centre the median (0.999 and
1.005; 5 and 6 of 11 above the truth) but covers 0.69 at 90 %. The stretched forms take the untempered
location (1.004-1.028) but score no better (``stretch_median`` 0.286 / 0.240, ``stretch_mode`` 0.494 /
0.230: on seed 70 the box-top twins' spurious low mode again). The registered error profile is
far worse: its own ``lambda`` is 10-122 (the fixed profile's 3-18), the candidate's kink jumps between
samples and the log-determinant with it, and the median sits 1.39 and 1.30 times the truth below 40 MPa
(WIS 0.626 / 0.588). So the shift is the power form's flattening of an asymmetric likelihood, and the
forms that keep the location lose more in width or coverage than the shift costs. Nothing adopted; no
benchmark planned for these forms.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
from scipy import linalg, stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import truths, twin_experiment  # noqa: E402
from calibration.experiment import ExperimentSpec  # noqa: E402
from enkf.emulator import CurveEmulator  # noqa: E402
from enkf.scores import QUANTILES, prior_expected_wis, weighted_interval_score  # noqa: E402
from enkf.variability import lag1_correlation  # noqa: E402
from studies.pit_recalibration import (GRID, LOW_SIGMA_T, cdf_at, cdfs_of, grid_of, grid_weights,  # noqa: E402
                                       quantile_at)
from studies.sigma_t_bias import write  # noqa: E402
from studies.tempering_forms import deviance, kept_posterior  # noqa: E402

FORMS = ("power", "untempered", "median_center", "median_center_untempered", "stretch_mean", "stretch_median",
         "stretch_mode")
REGISTERED = ("registered", "registered_untempered")
NAMES = ("sigma_t", "E_t")
# a curve's kink: the first sample after its steepest rise where the slope is below this fraction of it
KINK_SLOPE = 0.5
# an aligned lag's variance needs this many residuals; fewer: the nearest lag that has them
MIN_ALIGNED = 3
# the registered form's pseudo-runs' noise draws: a stream of this study's own
PSEUDO_STREAM = 53


def chi2_of(em, C, d):
    """``P -> chi2`` of the emulated likelihood with covariance ``C`` at data ``d``."""
    chi2 = deviance(em, C)
    return lambda P: chi2(P, d)


def form_cdfs(k, P, edges) -> dict:
    """``{form: (cdf_sigma_t, cdf_E_t)}`` of one kept twin ``k`` (:func:`kept_posterior`)."""
    r = k.em.loo_residuals()[k.latest]
    B = k.terms.emulated().dense()
    chi2 = chi2_of(k.em, B + k.error_model(r).dense(), k.d)
    c0 = chi2(P).reshape(GRID, GRID)
    # the typical realization: the emulator moved by its residuals' pointwise median (the data moved back)
    delta = np.median(r, axis=0)
    c_med = chi2_of(k.em, B + k.error_model(r - delta).dense(), k.d - delta)(P).reshape(GRID, GRID)
    w_u = grid_weights(c0, 1.0)
    cdf_u = cdfs_of(w_u)
    out = {"power": cdfs_of(grid_weights(c0, k.lam)), "untempered": cdf_u,
           "median_center": cdfs_of(grid_weights(c_med, k.lam)),
           "median_center_untempered": cdfs_of(grid_weights(c_med, 1.0))}
    centres = {"stretch_mean": (w_u.reshape(-1)[:, None] * P).sum(axis=0),
               "stretch_median": np.array([quantile_at(cdf_u[a], edges[a], 0.5) for a in (0, 1)]),
               "stretch_mode": P[int(np.argmin(c0.reshape(-1)))]}
    for form, c in centres.items():
        # points between the centre and a box cell: inside the box, where the emulator is defined
        out[form] = cdfs_of(grid_weights(chi2(c + (P - c) / math.sqrt(k.lam)).reshape(GRID, GRID), 1.0))
    return out


def kinks(curves: np.ndarray) -> np.ndarray:
    """Each curve's kink index (:data:`KINK_SLOPE`; the window's last sample where the slope never falls)."""
    s = np.gradient(np.atleast_2d(curves), axis=1)
    i_s = np.argmax(s, axis=1)
    below = (s < KINK_SLOPE * s[np.arange(len(s)), i_s][:, None]) & (np.arange(s.shape[1])[None, :] > i_s[:, None])
    return np.where(below.any(axis=1), np.argmax(below, axis=1), s.shape[1] - 1)


def aligned_sd(r: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The residuals' rms ``(2m - 1,)`` at each lag from their own curve's kink (index ``lag + m - 1``)."""
    m = r.shape[1]
    s2, n = np.zeros(2 * m - 1), np.zeros(2 * m - 1)
    for ri, ki in zip(r, k):
        lags = np.arange(m) - ki + m - 1
        s2[lags] += ri ** 2
        n[lags] += 1
    ok = np.flatnonzero(n >= MIN_ALIGNED)
    near = ok[np.clip(np.searchsorted(ok, np.arange(2 * m - 1)), 0, ok.size - 1)]
    s2 = np.where(n >= MIN_ALIGNED, s2 / np.maximum(n, 1), s2[near] / n[near])
    return np.sqrt(np.maximum(s2, 1e-18 * s2.max()))


class RegisteredDeviance:
    """``-2 log N(y; em(theta), B + D A D)``, log-determinant included, with ``D`` the emulator's error sd
    measured on residuals aligned on their own curve's kink and placed at the candidate curve's kink:
    the scatter after the first damage moves with ``theta`` instead of staying where the latest runs
    put it. ``A``: the residuals' AR(1) correlation."""

    def __init__(self, em, r: np.ndarray, curves: np.ndarray, B: np.ndarray, times: np.ndarray):
        _, tau = lag1_correlation(r, times, np.zeros(times.size, int))
        self.em, self.B, self.m = em, B, times.size
        self.A = np.exp(-np.abs(times[:, None] - times[None, :]) / tau) if tau > 0 else np.eye(self.m)
        self.sd = aligned_sd(r, kinks(curves))
        self._chol = {}

    def _factor(self, k: int):
        if k not in self._chol:
            sd = self.sd[np.arange(self.m) - k + self.m - 1]
            L = linalg.cholesky(self.B + sd[:, None] * self.A * sd[None, :], lower=True)
            self._chol[k] = (L, 2.0 * float(np.sum(np.log(np.diag(L)))))
        return self._chol[k]

    def __call__(self, P, y) -> np.ndarray:
        F = self.em(np.atleast_2d(P))
        ks, out = kinks(F), np.empty(len(F))
        for k in np.unique(ks):
            sel = ks == k
            L, logdet = self._factor(int(k))
            w = linalg.solve_triangular(L, (F[sel] - y).T, lower=True)
            out[sel] = np.sum(w * w, axis=0) + logdet
        return out


def registered_cdfs(k, P, seed: int) -> tuple[dict, float]:
    """``({form: cdfs}, lambda)``: the registered likelihood untempered and power-tempered by its own
    ``lambda``, the median rule of :mod:`enkf.selfcal` on its pseudo-runs (each latest run plus a noise
    draw, on the emulator of the other runs, the log-determinant in the deviance as the heteroscedastic
    form has it)."""
    B = k.terms.emulated().dense()
    times = np.asarray(k.times, float)
    L_R = linalg.cholesky(B, lower=True)
    rng = np.random.default_rng([seed, PSEUDO_STREAM])
    deltas = []
    for j in np.flatnonzero(k.latest):
        keep = np.arange(k.X.shape[0]) != j
        em = CurveEmulator(k.X[keep], k.Y[keep], k.lo, k.hi, smoothing=k.smoothing)
        dev = RegisteredDeviance(em, em.loo_residuals()[k.latest[keep]], k.Y[keep][k.latest[keep]], B, times)
        y = k.Y[j] + L_R @ rng.standard_normal(k.Y.shape[1])
        own = float(dev(k.X[j], y)[0])
        deltas.append(own - min(own, float(dev(P, y).min())))
    lam = max(1.0, float(np.median(deltas)) / stats.chi2.median(k.X.shape[1]))
    dev = RegisteredDeviance(k.em, k.em.loo_residuals()[k.latest], k.Y[k.latest], B, times)
    c = dev(P, k.d).reshape(GRID, GRID)
    return {"registered": cdfs_of(grid_weights(c, lam)), "registered_untempered": cdfs_of(grid_weights(c, 1.0))}, lam


def study_twin(keep: Path, i: int, seed: int, truth: np.ndarray, registered: bool = False) -> dict:
    k = kept_posterior(keep, i, seed)
    edges, P = grid_of(k.lo, k.hi)
    row = {"seed": 1000 * seed + i, "truth": dict(zip(NAMES, map(float, truth))), "lambda": k.lam, "forms": {}}
    forms = form_cdfs(k, P, edges)
    if registered:
        extra, row["lambda_registered"] = registered_cdfs(k, P, 1000 * seed + i)
        forms.update(extra)
    for form, cdfs in forms.items():
        row["forms"][form] = {}
        for a, name in enumerate(NAMES):
            q = {key: quantile_at(cdfs[a], edges[a], level) for key, level in QUANTILES.items()}
            row["forms"][form][name] = {
                **q, "pit": cdf_at(cdfs[a], edges[a], truth[a]),
                "wis_over_width": float(weighted_interval_score(q, truth[a])) / float(k.hi[a] - k.lo[a]),
                "median_over_truth": q["q50"] / float(truth[a])}
    return row


def summarise(rows: list[dict]) -> dict:
    prior = prior_expected_wis(0.0, 1.0)
    out = {}
    for form in [f for f in FORMS + REGISTERED if f in rows[0]["forms"]]:
        out[form] = {}
        for name in NAMES:
            r = [row["forms"][form][name] for row in rows]
            t = np.array([row["truth"][name] for row in rows])
            low = [x["median_over_truth"] for x, row in zip(r, rows) if row["truth"]["sigma_t"] < LOW_SIGMA_T]
            out[form][name] = {
                "wis_over_prior": float(np.mean([x["wis_over_width"] for x in r]) / prior),
                "coverage_90": float(np.mean([x["q05"] <= y <= x["q95"] for x, y in zip(r, t)])),
                "coverage_50": float(np.mean([x["q25"] <= y <= x["q75"] for x, y in zip(r, t)])),
                "pit_ks_p": float(stats.kstest([x["pit"] for x in r], "uniform").pvalue),
                "below_40MPa_median_over_truth": float(np.median(low)) if low else None,
                "below_40MPa_above_truth": f"{sum(v > 1.0 for v in low)} of {len(low)}"}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kept", required=True, help="bench_coverage.py --keep-runs folder of the seed's twins")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--twins", type=int, default=16)
    ap.add_argument("--registered", action="store_true",
                    help="add the registered error profile's forms (its own lambda: about 1 min a twin)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    spec = ExperimentSpec.from_config("twin_ref", twin_experiment())
    rows = []
    for i, truth in enumerate(truths(args.twins, spec.lower, spec.upper, args.seed)):
        rows.append(study_twin(Path(args.kept), i, args.seed, np.asarray(truth, float), args.registered))
        print(f"{i + 1}/{args.twins}: " + ", ".join(f"{f} {v['sigma_t']['median_over_truth']:.3f}"
                                                    for f, v in rows[-1]["forms"].items()), file=sys.stderr, flush=True)
    out = {"study": "center_forms", "what": __doc__.split("\n\n")[0].replace("\n", " "), "seed": args.seed,
           "grid": GRID, "twins": len(rows), "summary": summarise(rows), "rows": rows}
    return write(out, args.out)


if __name__ == "__main__":
    main()
