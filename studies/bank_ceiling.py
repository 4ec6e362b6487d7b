"""How much a `fast` disc curve can tell about `sigma_t` and `E_t`, measured without the workflow's
posterior (issue 52's information bars: WIS over the prior's <= 0.25 for `sigma_t`, <= 0.55 for `E_t`).

A bank of twins is drawn exactly as the coverage harness draws its twins (``benchmarks/bench_coverage.py``:
the truth uniform over the default twin's box, its own `fast` mesh realization, 1 % white noise of its own
peak on the 0-160 us grid), each with a seed of its own (``BANK_SEED * 1000 + i``, no benchmark's twin).
A bank sampled from the joint law of parameters and data gives a posterior that needs no likelihood:
approximate Bayesian computation with the semi-automatic summaries of Fearnhead & Prangle (2012; the
regression of the parameters on the curve, fitted on a pilot part of the bank) and the local-linear
regression adjustment of Beaumont et al. (2002), in the box's logit space. Its calibration is checked on the
bank itself (each member of the reference part held out in turn as a pseudo-twin) and on the development
twins of seeds 70 and 72 (their data from ``bench_coverage.py --keep-runs``); its weighted interval score
over the prior's is what a calibrated posterior reaches from the same data with this many runs: an
achievable score, not the best possible one.

    python studies/bank_ceiling.py simulate --bank /work/scratch/bank --n 4000
    python studies/bank_ceiling.py score --bank /work/scratch/bank --kept 70=/work/scratch/keep70 \
        --kept 72=/work/dev72/keep --out studies/results/bank_ceiling.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import _simulate, truths, twin_experiment, twin_task  # noqa: E402
from calibration.experiment import ExperimentSpec, mesh_seed, rng_for  # noqa: E402
from calibration.observations import observation_grid, twin_observations  # noqa: E402
from studies.pit_recalibration import LOW_SIGMA_T  # noqa: E402  (where the shipped median sits high)

#: the bank's design seed; member i is twin seed ``BANK_SEED * 1000 + i`` (benchmark twins use seeds < 100)
BANK_SEED = 990
CHUNK = 200


def bank_design(n: int) -> tuple[ExperimentSpec, dict, np.ndarray]:
    exp = twin_experiment()
    spec = ExperimentSpec.from_config("twin_ref", exp)
    return spec, exp, truths(n, spec.lower, spec.upper, BANK_SEED)


def _noisy(exp: dict, curve: np.ndarray, seed: int) -> np.ndarray:
    """The twin's data from its reference curve, as ``bench_coverage.simulate_twin`` makes them."""
    o = exp["observations"]
    grid = observation_grid(o["t_start"], o["t_end"], o["dt"])
    obs = twin_observations(pd.DataFrame({"time_s": grid, "stress_Pa": curve}), grid, rng=rng_for(seed, "noise"),
                            relative_sigma=o["noise"]["relative_sigma"])
    return obs.frame["stress_Pa"].to_numpy(float)


def simulate(bank: Path, n: int, cores: int) -> None:
    spec, exp, theta = bank_design(n)
    bank.mkdir(parents=True, exist_ok=True)
    names = list(spec.names)
    with get_context("spawn").Pool(cores) as pool:
        for c0 in range(0, n, CHUNK):
            path = bank / f"chunk_{c0:05d}.npz"
            if path.is_file():
                continue
            idx = range(c0, min(n, c0 + CHUNK))
            seeds = [BANK_SEED * 1000 + i for i in idx]
            t0 = time.time()
            curves = np.array(pool.map(_simulate, [twin_task(exp, names, theta[i], "fast", mesh_seed(s, "truth"))
                                                   for i, s in zip(idx, seeds)], chunksize=4))
            data = np.array([_noisy(exp, y, s) if np.all(np.isfinite(y)) else np.full(y.size, np.nan)
                             for y, s in zip(curves, seeds)])
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, theta=theta[list(idx)], curve=curves, data=data, seed=np.array(seeds))
            tmp.rename(path)
            print(f"bank {idx[-1] + 1}/{n} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)


def load_bank(bank: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(theta, data, seed)`` of every finished chunk, the runs that failed left out."""
    parts = [np.load(p) for p in sorted(bank.glob("chunk_*.npz")) if ".tmp" not in p.name]
    theta, data, seed = (np.concatenate([z[k] for z in parts]) for k in ("theta", "data", "seed"))
    ok = np.all(np.isfinite(data), axis=1)
    return theta[ok], data[ok], seed[ok]


def to_u(theta: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    x = np.clip((theta - lo) / (hi - lo), 1e-9, 1 - 1e-9)
    return np.log(x) - np.log1p(-x)


def to_theta(u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return lo + (hi - lo) / (1.0 + np.exp(-u))


#: samples after the observed maximum at which the curve's fall is read (the grid's 1 us step)
AFTER_PEAK = (5, 10, 20, 40)


def shape_features(data: np.ndarray) -> np.ndarray:
    """What the disc's curve says most plainly: its log peak, the time of the peak (samples), and the
    stress at a few delays after it over the peak (the last sample's where the window ends first)."""
    n = data.shape[1]
    i = np.argmax(data, axis=1)
    peak = data[np.arange(len(data)), i]
    after = [data[np.arange(len(data)), np.minimum(i + d, n - 1)] / peak for d in AFTER_PEAK]
    return np.column_stack([np.log(np.maximum(peak, 1.0)), i / n, *after])


class Summaries:
    """Fearnhead & Prangle's semi-automatic summaries: the parameters' regression on the curve (each as its
    fraction of the box: on the pilot, R^2 0.92 / 0.58 against 0.86 / 0.55 for their logits), a ridge fit
    on the curve's leading principal components, its shape features and their products."""

    def __init__(self, data: np.ndarray, target: np.ndarray, components: int, ridge: float):
        self.scale = float(np.std(data))
        z = data / self.scale
        self.mean = z.mean(axis=0)
        _, _, vt = np.linalg.svd(z - self.mean, full_matrices=False)
        self.basis = vt[:components]
        X = self._features(data)
        self.x_mean, self.x_sd = X.mean(axis=0), X.std(axis=0) + 1e-12
        Xs = (X - self.x_mean) / self.x_sd
        A = Xs.T @ Xs + ridge * len(Xs) * np.eye(Xs.shape[1])
        self.t_mean = target.mean(axis=0)
        self.coef = np.linalg.solve(A, Xs.T @ (target - self.t_mean))
        # each summary's residual sd on the pilot: the distance weighs them by how well they predict
        self.sd = np.std(target - self(data), axis=0)

    def _features(self, data: np.ndarray) -> np.ndarray:
        pc = np.hstack([(data / self.scale - self.mean) @ self.basis.T, shape_features(data)])
        i, j = np.triu_indices(pc.shape[1])
        return np.hstack([pc, pc[:, i] * pc[:, j]])

    def __call__(self, data: np.ndarray) -> np.ndarray:
        return self.t_mean + ((self._features(data) - self.x_mean) / self.x_sd) @ self.coef


def abc_posterior(s_ref: np.ndarray, u_ref: np.ndarray, s_obs: np.ndarray, k: int, sd: np.ndarray,
                  adjust: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(u, w)``: the k nearest reference runs' parameters (logit), regression-adjusted to ``s_obs``
    (Beaumont et al. 2002), with Epanechnikov weights."""
    d = np.sqrt((((s_ref - s_obs) / sd) ** 2).sum(axis=1))
    near = np.argpartition(d, k)[:k + 1]
    near = near[np.argsort(d[near])]
    h = d[near[-1]]
    near = near[:k]
    w = 1.0 - (d[near] / h) ** 2
    u = u_ref[near]
    if adjust:
        X = np.hstack([np.ones((k, 1)), s_ref[near] - s_obs])
        sw = np.sqrt(w)[:, None]
        beta = np.linalg.lstsq(X * sw, u * sw, rcond=None)[0]
        u = u - (s_ref[near] - s_obs) @ beta[1:]
    return u, w / w.sum()


def weighted_quantiles(x: np.ndarray, w: np.ndarray, q) -> np.ndarray:
    o = np.argsort(x)
    c = np.cumsum(w[o]) - 0.5 * w[o]
    return np.interp(q, c, x[o])


QS = (0.05, 0.25, 0.5, 0.75, 0.95)


def posterior_row(u: np.ndarray, w: np.ndarray, j: int, lo: float, hi: float, truth_u: float) -> dict:
    q = to_theta(weighted_quantiles(u[:, j], w, QS), lo, hi)
    return {**{f"q{int(100 * a):02d}": float(v) for a, v in zip(QS, q)},
            "pit": float(np.sum(w[u[:, j] < truth_u]) + 0.5 * np.sum(w[u[:, j] == truth_u]))}


def score_rows(rows: list, t: np.ndarray, lo: float, hi: float) -> dict:
    from scipy import stats

    from benchmarks.scores import proper_scores

    q = {k: np.array([r[k] for r in rows]) for k in ("q05", "q25", "q75", "q95")}
    pit = np.array([r["pit"] for r in rows if "pit" in r])
    ps = proper_scores(rows, t, lo, hi)
    return {"n": len(rows), "coverage_90": float(np.mean((q["q05"] <= t) & (t <= q["q95"]))),
            "coverage_50": float(np.mean((q["q25"] <= t) & (t <= q["q75"]))),
            "width_90_over_box": float(np.mean((q["q95"] - q["q05"]) / (hi - lo))),
            "pit_ks_p": float(stats.kstest(pit, "uniform").pvalue) if pit.size else None,
            "wis_over_prior": ps["wis_over_prior"],
            # the product's flag (estimated from the five quantiles, as the harness does for its records) and
            # the twins it would call learned
            "uninformative_share": ps["product_flag"]["uninformative_share"],
            "called_learned": ps["product_flag"]["informative"]}


PILOT = 1000
KS = (50, 100, 200, 400)
COMPONENTS = (4, 8, 12)
RIDGES = (1e-5, 1e-4, 1e-3)


def fit_summaries(data: np.ndarray, x: np.ndarray) -> tuple[Summaries, dict]:
    """The summaries' setting with the least held-out squared error on the pilot's last fifth (``x``: the
    parameters as fractions of the box)."""
    cut = int(0.8 * len(data))
    err = {(c, r): float(np.mean(((Summaries(data[:cut], x[:cut], c, r)(data[cut:]) - x[cut:])
                                  / x.std(axis=0)) ** 2)) for c in COMPONENTS for r in RIDGES}
    c, r = min(err, key=err.get)
    e = Summaries(data[:cut], x[:cut], c, r)(data[cut:]) - x[cut:]
    r2 = 1.0 - e.var(axis=0) / x[cut:].var(axis=0)
    return Summaries(data, x, c, r), {"components": c, "ridge": r, "validation_r2": r2.tolist(),
                                      "validation_rmse_over_box": np.sqrt((e**2).mean(axis=0)).tolist(),
                                      "validation_mse": {f"{a}_{b}": v for (a, b), v in err.items()}}


def bank_loo(s_ref, u_ref, theta_ref, sd, k: int, lo, hi, names, adjust=True, parts=None) -> dict:
    """Each reference run held out in turn and scored; ``parts``: ``{label: mask}``, the same scored apart
    on each part of the runs (under ``"parts"``)."""
    rows = {p: [] for p in names}
    idx = np.arange(len(s_ref))
    for j in idx:
        keep = idx != j
        u, w = abc_posterior(s_ref[keep], u_ref[keep], s_ref[j], k, sd, adjust)
        for a, p in enumerate(names):
            rows[p].append(posterior_row(u, w, a, lo[a], hi[a], u_ref[j, a]))
    out = {p: score_rows(rows[p], theta_ref[:, a], lo[a], hi[a]) for a, p in enumerate(names)}
    if parts:
        out["sigma_t_low"] = low_strength_shift(rows[names[0]], theta_ref[:, 0])
        out["parts"] = {label: {p: score_rows([r for r, m in zip(rows[p], mask) if m], theta_ref[mask, a],
                                              lo[a], hi[a]) for a, p in enumerate(names)}
                        for label, mask in parts.items()}
    return out


def low_strength_shift(rows: list, t: np.ndarray) -> dict:
    """Of the runs whose ``sigma_t`` lies below :data:`LOW_SIGMA_T`: how many have their median above the
    truth, and the median of median over truth (what the README counts for the shipped form)."""
    low = t < LOW_SIGMA_T
    med = np.array([r["q50"] for r in rows])
    return {"below_Pa": LOW_SIGMA_T, "runs": int(low.sum()), "median_above_truth": int(np.sum(med[low] > t[low])),
            "median_over_truth_median": float(np.median(med[low] / t[low]))}


#: a run's window holds no post-peak when its data's maximum lies this close to the window's end (the
#: harness's threshold, tools/coverage_table.py CENSOR_S; samples every 1 us)
CENSOR_SAMPLES = 2


def window_parts(data: np.ndarray) -> dict:
    """``{label: mask}``: the runs whose observed maximum lies in the window's last 2 us, and the others."""
    late = np.argmax(data, axis=1) >= data.shape[1] - 1 - CENSOR_SAMPLES
    return {"no_post_peak": late, "post_peak": ~late}


def choose_k(loo: dict, names) -> int:
    """The rule fixed before any development twin was scored: the least summed WIS over the prior's among
    the k whose pseudo-twins' 90 % coverage lies within 0.02 of 0.90 for every parameter."""
    ok = [k for k in KS if all(abs(loo[k][p]["coverage_90"] - 0.9) <= 0.02 for p in names)]
    pool = ok or list(KS)
    return min(pool, key=lambda k: sum(loo[k][p]["wis_over_prior"] for p in names))


#: (pilot, reference) runs of the smaller banks, each scored on the same last 1000 runs of the bank
SIZES = ((250, 250), (500, 500), (500, 1000), (1000, 1000), (1000, 2000))
TARGETS = 1000
SIZE_KS = (25, 50, 100, 200)


def bank_sizes(theta, data, u, lo, hi, names) -> list:
    """How the score falls with the bank's size: smaller banks (their first runs) scored on the bank's last
    :data:`TARGETS` runs, which none of them holds."""
    x = (theta - lo) / (hi - lo)
    tgt = slice(len(theta) - TARGETS, None)
    out = []
    for npil, nref in SIZES:
        summ, _ = fit_summaries(data[:npil], x[:npil])
        s_ref, u_ref, s_t = summ(data[npil:npil + nref]), u[npil:npil + nref], summ(data[tgt])
        for k in (k for k in SIZE_KS if k < nref // 2):
            rows = {p: [] for p in names}
            for i in range(len(s_t)):
                uu, w = abc_posterior(s_ref, u_ref, s_t[i], k, summ.sd)
                for a, p in enumerate(names):
                    rows[p].append(posterior_row(uu, w, a, lo[a], hi[a], u[tgt][i, a]))
            out.append({"runs": npil + nref, "pilot": npil, "reference": nref, "k": k,
                        **{p: score_rows(rows[p], theta[tgt][:, a], lo[a], hi[a]) for a, p in enumerate(names)}})
    return out


def kept_twins(folder: Path, seed: int, lo, hi, n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    import pickle

    t = truths(n, lo, hi, seed)
    data = np.array([pickle.loads((folder / f"well_specified_{seed}_{i:03d}.pkl").read_bytes())[4]
                     .frame["stress_Pa"].to_numpy(float) for i in range(n)])
    return t, data


def shipped_rows(seed: int) -> list | None:
    """The shipped (power) posterior's rows on the same development twins (studies/center_forms.py)."""
    path = ROOT / "studies" / "results" / f"center_forms_dev{seed}.json"
    if not path.is_file():
        return None
    return [r["forms"]["power"] for r in json.loads(path.read_text())["rows"]]


def paired(rows: dict, shipped: list, t: np.ndarray, names) -> dict:
    """Twin by twin on the same development twins: where the bank's WIS is the lower, and the ratio of the
    two mean WIS (bank over shipped)."""
    from benchmarks.scores import weighted_interval_score

    out = {}
    for a, p in enumerate(names):
        wb = np.array([weighted_interval_score(r, y) for r, y in zip(rows[p], t[:, a])])
        ws = np.array([weighted_interval_score(r[p], y) for r, y in zip(shipped, t[:, a])])
        out[p] = {"bank_lower": int(np.sum(wb < ws)), "n": len(wb), "mean_wis_bank_over_shipped":
                  float(wb.mean() / ws.mean())}
    return out


def score(bank: Path, kept: dict[int, Path], out: Path | None) -> dict:
    spec, exp, _ = bank_design(1)
    names, lo, hi = list(spec.names), np.asarray(spec.lower, float), np.asarray(spec.upper, float)
    theta, data, seed = load_bank(bank)
    order = np.argsort(seed)
    theta, data, seed = theta[order], data[order], seed[order]
    pilot = seed < BANK_SEED * 1000 + PILOT
    u = to_u(theta, lo, hi)
    summ, setting = fit_summaries(data[pilot], (theta[pilot] - lo) / (hi - lo))
    ref = ~pilot
    s_ref, u_ref, theta_ref = summ(data[ref]), u[ref], theta[ref]
    t0 = time.time()
    loo = {k: bank_loo(s_ref, u_ref, theta_ref, summ.sd, k, lo, hi, names) for k in KS}
    k = choose_k(loo, names)
    loo_plain = bank_loo(s_ref, u_ref, theta_ref, summ.sd, k, lo, hi, names, adjust=False)
    loo[k] = bank_loo(s_ref, u_ref, theta_ref, summ.sd, k, lo, hi, names, parts=window_parts(data[ref]))
    dev = {}
    for sd_seed, folder in kept.items():
        t, y = kept_twins(folder, sd_seed, lo, hi)
        s_obs = summ(y)
        rows = {p: [] for p in names}
        for i in range(len(t)):
            uu, w = abc_posterior(s_ref, u_ref, s_obs[i], k, summ.sd)
            tu = to_u(t[i][None, :], lo, hi)[0]
            for a, p in enumerate(names):
                rows[p].append(posterior_row(uu, w, a, lo[a], hi[a], tu[a]))
        shipped = shipped_rows(sd_seed)
        dev[str(sd_seed)] = {"paired": None if shipped is None else paired(rows, shipped, t, names),
            "bank": {p: score_rows(rows[p], t[:, a], lo[a], hi[a]) for a, p in enumerate(names)},
            "shipped_power": None if shipped is None else
            {p: score_rows([r[p] for r in shipped], t[:, a], lo[a], hi[a]) for a, p in enumerate(names)},
            "rows": [{p: rows[p][i] for p in names} | {"truth": dict(zip(names, map(float, t[i])))}
                     for i in range(len(t))]}
    sizes = bank_sizes(theta, data, u, lo, hi, names)
    result = {"study": "bank_ceiling", "what": __doc__.split("\n\n")[0].replace("\n", " "), "bank_seed": BANK_SEED, "bank_runs": int(len(seed)),
              "pilot_runs": int(pilot.sum()), "reference_runs": int(ref.sum()),
              "summaries": setting, "k_rule": choose_k.__doc__.strip(), "k": k,
              "bank_leave_one_out": {str(kk): v for kk, v in loo.items()},
              "bank_leave_one_out_unadjusted": loo_plain, "bank_sizes": sizes, "development_twins": dev,
              "score_s": round(time.time() - t0, 1)}
    if out is not None:
        out.write_text(json.dumps(result, indent=1) + "\n")
    return result


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("simulate")
    s.add_argument("--bank", required=True)
    s.add_argument("--n", type=int, default=4000)
    s.add_argument("--cores", type=int, default=2)
    c = sub.add_parser("score")
    c.add_argument("--bank", required=True)
    c.add_argument("--kept", action="append", default=[], help="SEED=FOLDER of bench_coverage.py --keep-runs")
    c.add_argument("--out")
    args = ap.parse_args(argv)
    if args.cmd == "simulate":
        simulate(Path(args.bank), args.n, args.cores)
    else:
        kept = {int(a.split("=", 1)[0]): Path(a.split("=", 1)[1]) for a in args.kept}
        res = score(Path(args.bank), kept, Path(args.out) if args.out else None)
        print(json.dumps({k: v for k, v in res.items() if k != "development_twins"}, indent=1))
        for sd_seed, d in res["development_twins"].items():
            print(sd_seed, json.dumps({k: v for k, v in d.items() if k != "rows"}, indent=1))


if __name__ == "__main__":
    main()
