"""Why the twins' reported posterior returns the prior box on measured records (issue 52, item 1).

The twins report ``posterior: emulator_mcmc`` with the self-calibration, the heteroscedastic emulator
error and a refinement batch; run on the default run's measured marble it gave the prior box (CHANGELOG,
a self-calibration factor of 97). This study re-samples the reported posterior of a finished default run's
experiments (``results/<exp>`` of ``snakemake --cores 2``: every run of its loop, the refinement batch
where it has one, the last analysis' error terms) with each form below, and for the heteroscedastic form
splits each self-calibration pseudo-run's ``delta chi^2`` into its quadratic part and its
log-determinant part:

* ``forms``: per experiment and form, the self-calibration factor ``lambda`` and the 5/50/95 % quantiles
  of the reported posterior, their 90 % width over the box's (a twin's truth beside them);
* ``heteroscedastic_split``: per pseudo-run of the measured experiment, the local scale
  ``a(theta)`` at its own parameters and at the deviance's minimum over the box, the quadratic forms
  there, the log-determinant difference and ``delta``, and the AR(1) form's ``delta`` on the same
  pseudo-data.

Nothing here reads a held-out record: the measured experiment's posterior is of its calibration records.

    snakemake --cores 2                       # a default run (about 7 min on 2 cores)
    python studies/posterior_forms_measured.py --results results --out studies/results/posterior_forms_measured.json
"""

from __future__ import annotations

import argparse
import copy
import os
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import pandas as pd
import yaml
from scipy import linalg

from calibration.experiment import ExperimentSpec, all_runs
from calibration.model_error import stored_error
from calibration.observations import read_observations
from calibration.posterior import refine_batch, sample_posterior
from calibration.workflow_io import read_json, read_responses
from enkf.emulated import emulator_error_model
from enkf.emulator import smoothed_emulator
from enkf.hetero import HeteroscedasticError
from enkf.sampling import latin_hypercube
from enkf.selfcal import pseudo_runs
from shpb.atomic import emit_json

ROOT = Path(__file__).resolve().parents[1]
#: (emulator error, with the refinement batch); the refinement batch only where the run made one
FORMS = (("heteroscedastic", True), ("ar1", True), ("heteroscedastic", False), ("ar1", False))
SEARCH_POINTS = 2000


def _loop(folder: Path, name: str, exp: dict):
    its = sorted(int(p.name.split("_")[-1]) for p in folder.glob("iter_*"))
    params = [pd.read_csv(folder / f"iter_{k}" / "params.csv") for k in its]
    responses = [read_responses(folder / f"iter_{k}" / "responses.csv")[1] for k in its]
    obs = read_observations(folder / "observations" / "obs.csv", folder / "observations" / "obs.json")
    return params, responses, obs, read_json(folder / f"iter_{its[-1]}" / "analysis.json")


def _spec(name: str, exp: dict, emulator_error: str) -> ExperimentSpec:
    exp = copy.deepcopy(exp)
    exp["posterior"] = "emulator_mcmc"
    exp.setdefault("emulated", {}).update({"self_calibrate": True, "emulator_error": emulator_error})
    return ExperimentSpec.from_config(name, exp)


def forms(folder: Path, name: str, exp: dict) -> list[dict]:
    params, responses, obs, last = _loop(folder, name, exp)
    truth = (exp.get("observations") or {}).get("truth")
    rows = []
    for err, with_refine in FORMS:
        if with_refine and not (folder / "refine" / "params.csv").is_file():
            continue
        spec = _spec(name, exp, err)
        refine = None
        if with_refine:
            refine, _ = refine_batch(spec, pd.read_csv(folder / "refine" / "params.csv"),
                                     *read_responses(folder / "refine" / "responses.csv"))
        post = sample_posterior(spec, params, responses, last, obs, refine).to_dict()
        box = dict(zip(spec.names, np.asarray(spec.upper) - np.asarray(spec.lower)))
        rows.append({"emulator_error": err, "refinement_batch": with_refine,
                     "lambda": post["emulator_error"]["self_calibration"]["lambda"],
                     "posterior": {p: {"q05": s["q05"], "q50": s["q50"], "q95": s["q95"],
                                       "width_90_over_box": (s["q95"] - s["q05"]) / box[p],
                                       **({"truth": truth[p]} if truth else {})}
                                   for p, s in post["posterior"].items()}})
    return rows


def heteroscedastic_split(folder: Path, name: str, exp: dict, seed: int = 1) -> list[dict]:
    """Each pseudo-run's delta under the heteroscedastic deviance, split (module docstring)."""
    params, responses, obs, last = _loop(folder, name, exp)
    spec = _spec(name, exp, "heteroscedastic")
    terms = stored_error(obs, last)
    B = terms.emulated()
    X, Y, latest = all_runs(spec, params, responses, np.asarray(last["alive"], bool))
    lo, hi = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
    groups = obs.frame["record"].to_numpy(str)
    _, info = smoothed_emulator(X, Y, lo, hi, list(spec.names), latest, spec.smoothing, terms.likelihood().std)
    rng = np.random.default_rng(seed)
    starts = latin_hypercube(lo, hi, SEARCH_POINTS, rng)
    Bd = B.dense()
    out = []
    for i, em, _, y in pseudo_runs(X, Y, latest, B, lower=lo, upper=hi, smoothing=info["smoothing"],
                                   error_model=lambda r: emulator_error_model(r, obs.time, groups)[0], rng=rng):
        keep = np.arange(X.shape[0]) != i
        C_em = emulator_error_model(em.loo_residuals()[latest[keep]], obs.time, groups)[0].dense()
        het = HeteroscedasticError(Bd, C_em, (X[keep] - lo) / (hi - lo), em.loo_residuals())
        P = np.vstack([starts, X[i]])
        U = (P - lo) / (hi - lo)
        quad, logdet = het.parts(em(P) - y, U)
        j = int(np.argmin(quad + logdet))
        a = het.scale(U)
        L = linalg.cholesky(Bd + C_em, lower=True)
        w = linalg.solve_triangular(L, (em(P) - y).T, lower=True)
        chi2 = np.sum(w * w, axis=0)
        out.append({"run": int(i), "bandwidth": het.bandwidth, "a_own": float(a[-1]), "a_at_minimum": float(a[j]),
                    "quadratic_own": float(quad[-1]), "quadratic_at_minimum": float(quad[j]),
                    "logdet_own_minus_minimum": float(logdet[-1] - logdet[j]),
                    "delta": float(quad[-1] + logdet[-1] - quad[j] - logdet[j]),
                    "delta_ar1": float(chi2[-1] - chi2.min()),
                    "whitened_eigenvalues": {"median": float(np.median(het.g)), "max": float(het.g.max())}})
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", default="results", help="a default run's results folder")
    ap.add_argument("--config", default=str(ROOT / "config" / "config.yaml"))
    ap.add_argument("--measured", default="marble_loop")
    ap.add_argument("--twin", default="twin_ref")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    cfg = yaml.safe_load(Path(a.config).read_text())["experiments"]
    res = Path(a.results)
    result = {"study": "posterior_forms_measured", "cores": os.cpu_count(),
              "forms": {name: forms(res / name, name, cfg[name]) for name in (a.measured, a.twin)},
              "heteroscedastic_split": {a.measured: heteroscedastic_split(res / a.measured, a.measured,
                                                                           cfg[a.measured])}}
    return emit_json(result, a.out)


if __name__ == "__main__":
    main()
