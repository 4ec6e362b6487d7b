"""The self-calibration's pseudo-runs read per parameter: does one factor widen each axis as it needs?

The reported posterior divides the emulated log-likelihood by one factor ``lambda`` (``enkf.selfcal``): the
median over the last runs, each taken as data of known parameters, of the profile likelihood ratio at
those parameters (two degrees of freedom), over chi-square's median. The same pseudo-runs give one ratio
per parameter, the profile over the other parameter at the run's own value of this one (one degree of
freedom): its median over chi-square(1)'s median is the factor that axis alone asks for, and the share of
ratios divided by the joint ``lambda`` below chi-square(1)'s 90 % point is how often that axis' 90 %
interval would hold the run's own value with the joint factor.

Reads a finished run's folder (its iterations, refinement batch, observations and last analysis) and
rebuilds the reported posterior's pseudo-runs exactly as ``calibration.posterior.sample_posterior`` does
(the same random stream: ``lambda_joint`` equals the run's own ``self_calibration`` factor, checked). Each
profile is a grid of 801 points over the other parameter's box. Two-parameter experiments only.

    python studies/selfcal_axes.py RUN_FOLDER EXPERIMENT [EXPERIMENT ...] [--out studies/results/selfcal_axes.json]

RUN_FOLDER is a clone in which ``snakemake --cores 2`` has run (its ``config/config.yaml`` and ``results/``).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calibration.experiment import ExperimentSpec, all_runs, rng_for  # noqa: E402
from calibration.model_error import stored_error  # noqa: E402
from calibration.observations import read_observations  # noqa: E402
from calibration.posterior import refine_batch  # noqa: E402
from calibration.workflow_io import read_responses  # noqa: E402
from enkf.emulated import emulator_error_model  # noqa: E402
from enkf.emulator import design_arrays, smoothed_emulator  # noqa: E402
from enkf.sampling import latin_hypercube  # noqa: E402
from enkf.selfcal import _deviance, box_minimum, pseudo_runs  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402

GRID = 801


def _inputs(root: Path, exp: str):
    """The reported posterior's design, error model and spec, as calibration.posterior.sample_posterior
    builds them from the run's files."""
    cfg = yaml.safe_load((root / "config" / "config.yaml").read_text())
    spec = ExperimentSpec.from_config(exp, cfg["experiments"][exp])
    res = root / "results" / exp
    K = max(int(p.name.split("_")[1]) for p in res.glob("iter_*") if (p / "analysis.json").exists())
    params = [pd.read_csv(res / f"iter_{k}" / "params.csv") for k in range(K + 1)]
    responses = [read_responses(res / f"iter_{k}" / "responses.csv")[1] for k in range(K + 1)]
    last = json.loads((res / f"iter_{K}" / "analysis.json").read_text())
    obs = read_observations(res / "observations" / "obs.csv", res / "observations" / "obs.json")
    (P_ref, Y_ref), _ = refine_batch(spec, pd.read_csv(res / "refine" / "params.csv"),
                                     *read_responses(res / "refine" / "responses.csv"))
    P_ref = pd.DataFrame(P_ref[list(spec.names)].to_numpy(float) if isinstance(P_ref, pd.DataFrame)
                         else np.asarray(P_ref, float), columns=list(spec.names))
    Y_ref = np.asarray(Y_ref, float)
    X, Y, latest = all_runs(spec, [*params, P_ref], [*responses, Y_ref], np.all(np.isfinite(Y_ref), axis=1))
    X, Y, latest, _ = design_arrays(X, Y, latest, obs.values)
    sampler = json.loads((res / "posterior" / "sampler.json").read_text())
    return spec, obs, stored_error(obs, last), X, Y, latest, sampler


def axes(root: Path, exp: str) -> dict:
    spec, obs, terms, X, Y, latest, sampler = _inputs(root, exp)
    lo, hi, names = np.asarray(spec.lower, float), np.asarray(spec.upper, float), list(spec.names)
    if lo.size != 2:
        raise SystemExit(f"{exp}: {lo.size} parameters; the study reads two-parameter experiments")
    error = terms.emulated()
    _, info = smoothed_emulator(X, Y, lo, hi, names, latest, spec.smoothing, terms.likelihood().std)
    times, groups = obs.time, obs.frame["record"].to_numpy(str)
    rng = rng_for(spec.seed, "posterior")
    starts = np.vstack([latin_hypercube(lo, hi, 1000, rng), X[latest]])  # enkf.selfcal's order of draws
    R = error.dense()
    joint, per_axis = [], [[], []]
    for i, em, C, y in pseudo_runs(X, Y, latest, error, lower=lo, upper=hi, smoothing=info["smoothing"],
                                   error_model=lambda r: emulator_error_model(r, times, groups)[0], rng=rng):
        keep = np.arange(X.shape[0]) != i
        dev = _deviance(em, C, R, None, X[keep], lo, hi, False)

        def chi2(P, dev=dev, y=y):
            return dev(P, y)
        least, _ = box_minimum(chi2, lo, hi, starts)
        joint.append(max(0.0, float(chi2(X[i])[0]) - least))
        for j in range(2):
            P = np.empty((GRID, 2))
            P[:, j] = X[i, j]
            P[:, 1 - j] = np.linspace(lo[1 - j], hi[1 - j], GRID)
            per_axis[j].append(max(0.0, float(chi2(P).min()) - least))
    joint = np.array(joint)
    lam = max(1.0, float(np.median(joint) / stats.chi2.median(2)))
    product = _product_lambda(sampler)
    out = {"experiment": exp, "pseudo_runs": int(joint.size), "lambda_joint": lam, "lambda_of_the_run": product,
           "joint_inside_90_at_lambda": float(np.mean(joint / lam <= stats.chi2.ppf(0.9, 2))), "axes": {}}
    for j, p in enumerate(names):
        d = np.array(per_axis[j])
        out["axes"][p] = {"lambda_alone": float(np.median(d) / stats.chi2.median(1)),
                          "inside_90_at_joint_lambda": float(np.mean(d / lam <= stats.chi2.ppf(0.9, 1)))}
    return out


def _product_lambda(sampler: dict):
    def find(o):
        if isinstance(o, dict):
            if isinstance(o.get("self_calibration"), dict):
                return o["self_calibration"].get("lambda")
            return next((v for v in map(find, o.values()) if v is not None), None)
        return None
    return find(sampler)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("root", type=Path)
    ap.add_argument("experiments", nargs="+")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    doc = {"study": "selfcal_axes", "run_folder_commit": _commit(a.root),
           "experiments": [axes(a.root, e) for e in a.experiments]}
    return emit_json(doc, a.out)


def _commit(root: Path) -> str | None:
    out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=False)
    return out.stdout.strip() or None


if __name__ == "__main__":
    main()
