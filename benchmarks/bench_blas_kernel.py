"""How far the last bits of the linear algebra move an answer: one experiment run twice on the same machine,
once with the BLAS kernel OpenBLAS picks for this CPU and once with another (``OPENBLAS_CORETYPE``), the
two compared iteration by iteration and in their reported posteriors.

Results are bit-identical on one machine whatever the thread count (``bench_threads.py``). Another CPU
can make OpenBLAS pick another kernel, whose products and factorizations differ in the last bits; the
loop's FDEM runs are chaotic after the peak and carry such a difference into the next ensembles. This
measures how much of the reported posterior that moves: the difference of the posterior means in units
of the posterior's sd. The coverage harness's twins each run once, so their coverage already includes
this run-to-run variability; a single run's interval does not show it.

    python benchmarks/bench_blas_kernel.py [--experiment twin_ref] [--other-kernel Haswell] [--out ...]
    python benchmarks/bench_blas_kernel.py --runs DIR_A DIR_B --kernels SkylakeX Haswell  # assemble two
                                                                                             # finished runs

Two fresh clones of the committed HEAD, each ``snakemake --cores 2 results/<experiment>/summary.json``
(the default twin: about 5 min each on 2 cores).
"""
from __future__ import annotations

import argparse
import ctypes
import glob
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
PARAMS = ("sigma_t", "E_t")


def blas_kernel(env: dict | None = None) -> str:
    """The kernel OpenBLAS picks in a fresh process with ``env`` (numpy's bundled scipy-openblas)."""
    code = ("import ctypes, glob, os, numpy as np\n"
            "lib = ctypes.CDLL(glob.glob(os.path.join(os.path.dirname(np.__file__), '..', 'numpy.libs', "
            "'*openblas*'))[0])\n"
            "f = lib.scipy_openblas_get_corename64_\nf.restype = ctypes.c_char_p\nprint(f().decode())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    return out.stdout.strip() or f"unknown ({out.stderr.strip()[-200:]})"


def run_clone(where: Path, experiment: str, env: dict) -> float:
    subprocess.run(["git", "clone", "--quiet", str(REPO), str(where)], check=True)
    t0 = time.perf_counter()
    subprocess.run(["snakemake", "--cores", "2", f"results/{experiment}/summary.json"], cwd=where, check=True,
                   env={**env, "PYTHONPATH": str(where)}, capture_output=True)
    return time.perf_counter() - t0


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.abs(a - b) / np.maximum(np.abs(a), np.abs(b))
    return float(np.nanmax(np.where(np.isfinite(r), r, 0.0))) if r.size else 0.0


def iterations(a: Path, b: Path) -> list[dict]:
    """Per iteration: the largest relative difference of the members' parameters and of their responses."""
    out = []
    for k in range(100):
        pa, pb = a / f"iter_{k}" / "params.csv", b / f"iter_{k}" / "params.csv"
        if not (pa.exists() and pb.exists()):
            break
        row = {"iteration": k, "params_max_rel_diff": _rel(*(pd.read_csv(p)[list(PARAMS)].to_numpy(float)
                                                              for p in (pa, pb)))}
        ra, rb = a / f"iter_{k}" / "responses.csv", b / f"iter_{k}" / "responses.csv"
        if ra.exists() and rb.exists():
            row["responses_max_rel_diff"] = _rel(*(pd.read_csv(r).filter(like="y_").to_numpy(float)
                                                   for r in (ra, rb)))
        out.append(row)
    return out


def posteriors(a: dict, b: dict) -> dict:
    """Each parameter's reported posterior in both runs and the means' difference in posterior sd."""
    out = {}
    for p in PARAMS:
        qa, qb = a["posterior"][p], b["posterior"][p]
        sd = 0.5 * (qa["std"] + qb["std"])
        out[p] = {"a": {k: qa[k] for k in ("mean", "std", "q05", "q95")},
                  "b": {k: qb[k] for k in ("mean", "std", "q05", "q95")},
                  "mean_difference_over_sd": (qb["mean"] - qa["mean"]) / sd,
                  "truth": (a.get("truth") or {}).get(p)}
    return out


def assemble(dir_a: Path, dir_b: Path, experiment: str, kernels: tuple, walls=(None, None)) -> dict:
    a, b = dir_a / "results" / experiment, dir_b / "results" / experiment
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    return {"benchmark": "bench_blas_kernel", "experiment": experiment, "cores": 2, "cpu_count": os.cpu_count(),
            "cpu": next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                         if ln.startswith("model name")), "unknown"),
            "kernels": {"a": kernels[0], "b": kernels[1]}, "wall_s": {"a": walls[0], "b": walls[1]},
            "iterations": iterations(a, b), "posterior": posteriors(sa, sb),
            "stop": {"a": [sa["iterations"], sa["stop_reason"]], "b": [sb["iterations"], sb["stop_reason"]]},
            "flags": {"a": sa["verdict"]["flags"], "b": sb["verdict"]["flags"]}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--experiment", default="twin_ref")
    ap.add_argument("--other-kernel", default="Haswell", help="OPENBLAS_CORETYPE of the second run")
    ap.add_argument("--runs", nargs=2, type=Path, metavar=("DIR_A", "DIR_B"),
                    help="assemble two finished runs (their clones) instead of running")
    ap.add_argument("--kernels", nargs=2, help="with --runs: the kernel each ran with")
    ap.add_argument("--note", default="")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "bench_blas_kernel.json")
    args = ap.parse_args(argv)
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    if args.runs:
        res = assemble(*args.runs, args.experiment, tuple(args.kernels or ("?", "?")))
    else:
        other = {**env, "OPENBLAS_CORETYPE": args.other_kernel}
        with tempfile.TemporaryDirectory() as tmp:
            walls = (run_clone(Path(tmp) / "a", args.experiment, env), run_clone(Path(tmp) / "b", args.experiment, other))
            res = assemble(Path(tmp) / "a", Path(tmp) / "b", args.experiment, (blas_kernel(env), blas_kernel(other)),
                           walls)
    res["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                                   text=True).stdout.strip()
    res["note"] = args.note
    args.out.write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res["posterior"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
