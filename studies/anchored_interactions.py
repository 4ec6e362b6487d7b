"""Why the anchored selection fitted a planted end friction at the wrong point, and whether an
interaction term fixes it (issue 53, item 2: the selection's power).

The anchored emulator (:class:`enkf.emulator.AnchoredEmulator`) is first order (cut-HDMR): each
parameter's effect is measured by moving it alone from the base posterior's mean and the effects are
added. On the retired series ``interface_friction_5302`` (planted ``interface_friction.mu`` 0.3 at
``sigma_t`` 25 MPa) the base calibration absorbed the friction into ``sigma_t`` (44 MPa), so the
friction's runs were made at 44 MPa, where a friction of 0.3 raises the peak by far more than at 25 MPa
(the confinement scales with the strength). Added to a ``sigma_t`` lowered to 25 MPa that increment
overshoots the peaks, and the emulated fit settled at mu 0.04 with ``sigma_t`` 37 MPa: a wrong point,
refuted on real runs.

This study measures it on a kept series folder (a retired seed: development data) with a few new FDEM
runs on each record's design mesh:

* the cross points ``(sigma_t`` at its lower axis run, the effect at each of its axis runs``)``, from
  which the second-order term ``f(a+ds+dm) - f(a+ds) - f(a+dm) + f(a)`` of the pair is read;
* two check points at the planted base (``sigma_t`` of the plan's truth, ``E_t`` at the anchor), with
  the effect off and at its planted value: the emulators' error there against the real runs;
* the fit of ``(sigma_t, E_t, effect)`` to the calibration records (noise-weighted least squares on
  each emulator, several starts) and real runs at each emulator's fit, predicted and held out.

Run (cwd: the clone whose ``results/`` holds the series; about 30 runs of 5-7 s on one core)::

    python studies/anchored_interactions.py --series results/planted_interface_friction_5302 \
        --effect interface_friction.mu --truth-sigma-t 25e6 --truth-effect 0.3 \
        --out studies/results/anchored_interactions_interface_friction_5302.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.diagnose import interpolation_matrix  # noqa: E402
from calibration.runner import simulate_argv, simulator_command  # noqa: E402
from enkf.emulator import AnchoredEmulator  # noqa: E402
from shpb.atomic import emit_json  # noqa: E402


def load(series: Path):
    dz = series / "diagnosis"
    meta = json.loads((dz / "design" / "design.json").read_text())
    P = pd.read_csv(dz / "design" / "params.csv")
    obs = pd.concat([pd.read_csv(series / "observations" / "obs.csv"),
                     pd.read_csv(dz / "heldout" / "obs.csv")], ignore_index=True)
    report = json.loads((dz / "report.json").read_text())
    return meta, P, obs, report


def curve(path: Path) -> pd.DataFrame:
    return pd.read_csv(path)


def run_point(series: Path, record: str, params: dict, run0: dict, out: Path, sample_dt: float) -> pd.DataFrame:
    """One FDEM run of ``record`` on its design mesh (run0: the anchor's run.json) with ``params``
    changed; kept under ``out`` (re-used when there)."""
    wanted = {**run0["params"], **params}
    if (out / "run.json").exists() and json.loads((out / "run.json").read_text())["params"] != wanted:
        raise RuntimeError(f"{out} holds a run of other parameters; remove it to run this point")
    if not (out / "curve.csv").exists():
        argv = simulate_argv(simulator_command(), geometry=run0["geometry"], preset=run0["preset"],
                             params=wanted, out_dir=out,
                             record=str(series / "observations" / record / "record.json"), t_end=run0["t_end_s"],
                             sample_dt=sample_dt, mesh_seed=run0["mesh_seed"])
        env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
        r = subprocess.run(argv, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{record} {params}: exit {r.returncode}: {r.stderr[-800:]}")
    return curve(out / "curve.csv")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--series", required=True)
    ap.add_argument("--effect", required=True)
    ap.add_argument("--truth-sigma-t", type=float, required=True)
    ap.add_argument("--truth-effect", type=float, required=True)
    ap.add_argument("--runs", default=None, help="folder for the new runs (default: <series>/study_interactions)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    series = Path(a.series)
    runs_dir = Path(a.runs) if a.runs else series / "study_interactions"
    meta, P, obs, report = load(series)
    names = meta["names"]
    js, je, jm = names.index("sigma_t"), names.index("E_t"), names.index(a.effect)
    axis = np.array([-1] + list(meta["axis"])) if len(meta["axis"]) == len(P) - 1 else np.array(meta["axis"])
    calib, held = report["calib_records"], report["heldout_records"]
    records = calib + held
    anchor = P.iloc[0][names].to_numpy(float)
    pts = {j: [i for i in range(len(P)) if axis[i] == j] for j in (js, je, jm)}
    s_low = min(P.iloc[i]["sigma_t"] for i in pts[js])
    m_vals = sorted(P.iloc[i][a.effect] for i in pts[jm])
    out = {"series": series.name, "effect": a.effect, "anchor": dict(zip(names, anchor.tolist())),
           "sigma_t_low": s_low, "effect_axis": m_vals, "records": {}}
    emus, f0s, Ws, ys, sig = {}, {}, {}, {}, {}
    for rec in records:
        d0 = series / "diagnosis" / "design" / "000" / rec
        run0 = json.loads((d0 / "run.json").read_text())
        c0 = curve(d0 / "curve.csv")
        t = c0.time_s.to_numpy()
        dt = float(np.median(np.diff(t)))
        o = obs[obs.record == rec]
        W = interpolation_matrix(t, o.time_s.to_numpy())
        Ws[rec], ys[rec], sig[rec] = W, o.stress_Pa.to_numpy(), o.sigma_Pa.to_numpy()
        f0 = W @ c0.stress_Pa.to_numpy()
        f0s[rec] = f0

        def on_obs(i):
            return W @ curve(series / "diagnosis" / "design" / f"{i:03d}" / rec / "curve.csv").stress_Pa.to_numpy()

        # the first-order model from the design's axis runs, the second-order one with the cross runs
        axes = {k: ([P.iloc[i][names[j]] for i in pts[j]], [on_obs(i) for i in pts[j]])
                for k, j in enumerate((js, je, jm))}
        cross = [W @ run_point(series, rec, {"sigma_t": s_low, a.effect: mv}, run0, runs_dir / rec / f"cross_{mv:g}",
                               dt).stress_Pa.to_numpy() for mv in m_vals]
        box = ([meta["lower"][j] for j in (js, je, jm)], [meta["upper"][j] for j in (js, je, jm)])
        first = AnchoredEmulator(anchor[[js, je, jm]], f0, axes, *box)
        second = AnchoredEmulator(anchor[[js, je, jm]], f0, axes, *box, pairs={(0, 2): (s_low, m_vals, cross)})
        emus[rec] = {"first": first, "second": second}
        G = second._pairs[(0, 2)][2]
        # the emulators' error at the planted base, effect off and on, against real runs on the same mesh
        rows = {}
        for label, mv in (("effect_off", 0.0), ("effect_planted", a.truth_effect)):
            x = np.array([a.truth_sigma_t, anchor[je], mv])
            real = W @ run_point(series, rec, {"sigma_t": x[0], a.effect: mv}, run0,
                                 runs_dir / rec / f"truthlike_{mv:g}", dt).stress_Pa.to_numpy()
            rows[label] = {"real_peak_Pa": float(real.max()),
                           **{form: {"rmse_Pa": float(np.sqrt(np.mean((emus[rec][form](x[None])[0] - real) ** 2))),
                                     "peak_Pa": float(emus[rec][form](x[None])[0].max())}
                              for form in ("first", "second")}}
        out["records"][rec] = {"data": "held out" if rec in held else "calibration", "at_planted_base": rows,
                               "second_order_term_rms_Pa": float(np.sqrt(np.mean(np.vstack(G) ** 2)))}
    # the fit of (sigma_t, E_t, effect) to the calibration records on each emulator
    lo = np.array([meta["lower"][js], meta["lower"][je], meta["lower"][jm]])
    hi = np.array([meta["upper"][js], meta["upper"][je], meta["upper"][jm]])
    fits = {}
    for form in ("first", "second"):
        def loss(u):
            x = lo + u * (hi - lo)
            return sum(float(np.sum(((emus[r][form](x[None])[0] - ys[r]) / sig[r]) ** 2)) for r in calib)

        best = None
        for u0 in np.random.default_rng(0).uniform(0.05, 0.95, (24, 3)):
            res = optimize.minimize(loss, u0, method="L-BFGS-B", bounds=[(0, 1)] * 3)
            if best is None or res.fun < best.fun:
                best = res
        x = lo + best.x * (hi - lo)
        fit = {"sigma_t": float(x[0]), "E_t": float(x[1]), a.effect: float(x[2]), "loss": float(best.fun)}
        # real runs at the fit: the calibration records' and the held-out one's error
        err = {}
        for rec in records:
            d0 = series / "diagnosis" / "design" / "000" / rec
            run0 = json.loads((d0 / "run.json").read_text())
            dt = float(np.median(np.diff(curve(d0 / "curve.csv").time_s.to_numpy())))
            real = Ws[rec] @ run_point(series, rec, {"sigma_t": x[0], "E_t": x[1], a.effect: x[2]}, run0,
                                       runs_dir / rec / f"fit_{form}", dt).stress_Pa.to_numpy()
            err[rec] = {"real_rmse_Pa": float(np.sqrt(np.mean((real - ys[rec]) ** 2))),
                        "emulated_rmse_Pa": float(np.sqrt(np.mean((emus[rec][form](x[None])[0] - ys[rec]) ** 2))),
                        "real_peak_rel_error": float((real.max() - ys[rec].max()) / ys[rec].max())}
        fits[form] = {"point": fit, "errors": err}
    out["fits"] = fits
    out["note"] = ("development data (a retired seed); the fit is an in-sample least-squares on the calibration "
                   "records, not the selection's cross-validated ES-MDA: it shows where each emulator puts the "
                   "optimum, the real runs say whether that point is right")
    emit_json(out, a.out)
    return out


if __name__ == "__main__":
    main()
