"""Figures of a calibration experiment (after the paper's Figs. 4-7), written as PNG.

* :func:`plot_parameters` -- ensemble-mean parameters per iteration with the members, the 5-95 %
  band and the truth (twin, Fig. 4) or the final value (measured, Fig. 6).
* :func:`plot_ensemble_curves` -- the ensemble's stress curves on the observation grid, one panel per
  iteration (columns) and record (rows), against the observations (Figs. 5 and 7).
* :func:`plot_forecast` -- observations with their +-2 sigma band, the prior ensemble mean and the
  forecast with the posterior-mean parameters, and the residuals, per record.
* :func:`plot_misfit` -- RMSE and chi^2 per observation of the ensemble mean per iteration.
* :func:`plot_sensitivity` -- correlation between each parameter and the stress at each time over the
  initial (LHS) ensemble, and the chi^2 map of the members in the parameter plane: where in the curve
  a parameter shows and whether two parameters trade off.

Axes show MPa and microseconds; files hold SI units. Matplotlib runs headless (Agg).
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from .observations import Observations  # noqa: E402

__all__ = ["plot_parameters", "plot_ensemble_curves", "plot_forecast", "plot_misfit", "plot_sensitivity",
           "UNITS"]

#: Display scale and label of each parameter (files stay SI).
UNITS = {"sigma_n": (1e-6, "MPa"), "sigma_t": (1e-6, "MPa"), "E_n": (1.0, "J/m$^2$"), "E_t": (1.0, "J/m$^2$"),
         "E": (1e-9, "GPa"), "nu": (1.0, "-"), "rho": (1.0, "kg/m$^3$"), "a": (1.0, "-"), "b": (1.0, "-"),
         "c": (1.0, "-")}
_ITER_COLORS = ["tab:blue", "tab:green", "goldenrod", "m", "tab:red", "tab:cyan", "tab:brown", "tab:olive"]


def _scale(p: str) -> tuple[float, str]:
    return UNITS.get(p.split(".")[-1], (1.0, ""))


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=120, metadata={"Software": None})
    plt.close(fig)
    tmp.replace(path)
    return path


def plot_parameters(path, params: Sequence[pd.DataFrame], alive: Sequence[np.ndarray], names: Sequence[str],
                    lower, upper, truth: Mapping[str, float] | None = None, title: str = "") -> Path:
    """Ensemble-mean parameter per iteration (blue), members (grey), 5-95 % band, truth (black) or the
    final mean (green dashed). ``params[k]`` is ``iter_<k>/params.csv``; ``alive[k]`` its mask."""
    n = len(names)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6), squeeze=False)
    its = np.arange(len(params))
    for j, p in enumerate(names):
        ax = axes[0, j]
        s, unit = _scale(p)
        means, q05, q95 = [], [], []
        for k, (df, a) in enumerate(zip(params, alive)):
            v = df[p].to_numpy(float) * s
            a = np.asarray(a, bool)
            ax.plot(np.full(v.size, k) + np.linspace(-0.12, 0.12, v.size), v, ".", color="0.65", ms=3,
                    zorder=1)
            if (~a).any():
                ax.plot(np.full((~a).sum(), k), v[~a], "x", color="tab:red", ms=5, zorder=2,
                        label="failed member" if k == 0 and j == 0 else None)
            means.append(v[a].mean())
            q05.append(np.quantile(v[a], 0.05))
            q95.append(np.quantile(v[a], 0.95))
        ax.fill_between(its, q05, q95, color="tab:blue", alpha=0.15, label="5-95 %")
        ax.plot(its, means, "o-", color="tab:blue", label="ensemble mean")
        if truth is not None and p in truth:
            ax.axhline(truth[p] * s, color="k", lw=1.5, label="reference (truth)")
        else:
            ax.axhline(means[-1], color="tab:green", ls="--", lw=1.2, label="final value")
        ax.set_ylim(lower[j] * s, upper[j] * s)
        ax.set_xticks(its)
        ax.set_xlabel("iteration")
        ax.set_ylabel(f"{p} [{unit}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_ensemble_curves(path, obs: Observations, responses: Sequence[np.ndarray], title: str = "",
                         truth_column: str | None = "truth_stress_Pa") -> Path:
    """Member curves on the grid per iteration (columns) and record (rows) against the observations."""
    recs = obs.records
    K = len(responses)
    fig, axes = plt.subplots(len(recs), K, figsize=(3.4 * K + 0.6, 2.9 * len(recs) + 0.5), squeeze=False,
                             sharex=True, sharey="row")
    for r, rec in enumerate(recs):
        sl = obs.record_slice(rec)
        t = obs.time[sl] * 1e6
        for k, Y in enumerate(responses):
            ax = axes[r, k]
            Yk = np.asarray(Y, float)[:, sl] * 1e-6
            for y in Yk:
                if np.all(np.isfinite(y)):
                    ax.plot(t, y, color=_ITER_COLORS[k % len(_ITER_COLORS)], lw=0.7, alpha=0.6)
            ax.plot(t, obs.values[sl] * 1e-6, "k-", lw=1.4, label="observations")
            if truth_column and truth_column in obs.frame:
                ax.plot(t, obs.frame[truth_column].to_numpy(float)[sl] * 1e-6, "w--", lw=0.8)
            ax.set_title(f"{rec}: " + ("initial ensemble" if k == 0 else f"iteration {k}"), fontsize=9)
            ax.grid(alpha=0.3)
            if r == len(recs) - 1:
                ax.set_xlabel("time [$\\mu$s]")
            if k == 0:
                ax.set_ylabel("stress [MPa]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_forecast(path, obs: Observations, prior_mean: np.ndarray, forecast: Mapping[str, pd.DataFrame | None],
                  title: str = "", posterior_mean: np.ndarray | None = None) -> Path:
    """Per record: observations with +-2 sigma, prior ensemble mean, posterior ensemble mean and the
    forecast run (posterior-mean parameters); residuals (forecast - observations) below."""
    from .observations import curve_on_grid

    recs = obs.records
    fig, axes = plt.subplots(2, len(recs), figsize=(5.2 * len(recs), 5.6), squeeze=False, sharex="col",
                             gridspec_kw={"height_ratios": [2.2, 1]})
    for r, rec in enumerate(recs):
        sl = obs.record_slice(rec)
        t = obs.time[sl] * 1e6
        y, s = obs.values[sl] * 1e-6, obs.sigma[sl] * 1e-6
        ax, axr = axes[0, r], axes[1, r]
        ax.fill_between(t, y - 2 * s, y + 2 * s, color="0.8", label="observations $\\pm 2\\sigma$")
        ax.plot(t, y, "k-", lw=1.3, label="observations")
        ax.plot(t, prior_mean[sl] * 1e-6, color="tab:blue", ls=":", label="prior ensemble mean")
        if posterior_mean is not None:
            ax.plot(t, posterior_mean[sl] * 1e-6, color="goldenrod", ls="--", label="posterior ensemble mean")
        fc = forecast.get(rec)
        if fc is not None and len(fc) > 1:
            yf = curve_on_grid(fc["time_s"].to_numpy(float), fc["stress_Pa"].to_numpy(float), obs.time[sl]) * 1e-6
            ax.plot(t, yf, color="tab:red", lw=1.3, label="forecast (posterior mean)")
            axr.plot(t, yf - y, color="tab:red", lw=1.0)
        axr.fill_between(t, -2 * s, 2 * s, color="0.8")
        axr.axhline(0.0, color="k", lw=0.8)
        axr.plot(t, prior_mean[sl] * 1e-6 - y, color="tab:blue", ls=":", lw=1.0)
        ax.set_title(rec, fontsize=10)
        ax.set_ylabel("stress [MPa]")
        axr.set_ylabel("residual [MPa]")
        axr.set_xlabel("time [$\\mu$s]")
        ax.grid(alpha=0.3)
        axr.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_misfit(path, misfit: Sequence[Mapping], per_record: Sequence[Mapping[str, Mapping]] | None = None,
                chi2_target: float | None = None, title: str = "", verdict: Mapping | None = None) -> Path:
    """RMSE [MPa] of the ensemble-mean response and chi^2 per observation of the members (the median
    member against R and, where a discrepancy was estimated, against R + D) per iteration; with a
    ``verdict`` (calibration.verdict), the best iteration ringed and the verdict and next step written under
    the panels."""
    its = [int(m["iteration"]) for m in misfit]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.5))
    a1.plot(its, [m["rmse_Pa"] * 1e-6 for m in misfit], "o-", color="k", label="all records")
    a2.semilogy(its, [m.get("median_chi2_per_obs", m["chi2_per_obs"]) for m in misfit], "o-", color="k",
                label="median member, against R")
    a2.semilogy(its, [m["chi2_per_obs"] for m in misfit], ":", color="0.5", label="ensemble-mean curve")
    if any(m.get("stop_chi2_per_obs") not in (None, m.get("median_chi2_per_obs")) for m in misfit):
        a2.semilogy(its, [m.get("stop_chi2_per_obs") for m in misfit], "s--", color="tab:blue",
                    label="median member, against R + discrepancy")
    if per_record and len(per_record[0]) > 1:
        for rec in per_record[0]:
            a1.plot(its, [pr[rec]["rmse_Pa"] * 1e-6 for pr in per_record], ".--", label=rec)
            a2.semilogy(its, [pr[rec]["chi2_per_obs"] for pr in per_record], ".--", label=rec)
    if chi2_target is not None:
        a2.axhline(chi2_target, color="tab:green", ls=":", label="stop target")
    for ax in (a1, a2):
        ax.set_xticks(its)
        ax.set_xlabel("iteration")
        ax.grid(alpha=0.3)
    a1.set_ylabel("RMSE of the ensemble mean [MPa]")
    a2.set_ylabel("$\\chi^2$ per observation")
    if verdict is not None:
        c = verdict["chi2_per_obs"]
        a2.semilogy([c["best_iteration"]], [c["best"]], "o", ms=12, mfc="none", color="tab:red",
                    label=f"best (iteration {c['best_iteration']})")
    a2.legend(fontsize=8)
    fig.suptitle(title)
    if verdict is not None:
        ratio = c.get("final_over_prior")
        head = f"verdict: {verdict['verdict']}" + (f" (chi^2 final / prior = {ratio:.3g})" if ratio is not None else "")
        body = textwrap.fill("next: " + verdict["next_step"], 130)
        fig.tight_layout(rect=(0, 0.14, 1, 1))
        fig.text(0.01, 0.01, head + "\n" + body, fontsize=7.5, va="bottom",
                 color="tab:red" if verdict["verdict"] != "ok" else "k")
    else:
        fig.tight_layout()
    return _save(fig, path)


def plot_sensitivity(path, obs: Observations, params: pd.DataFrame, responses: np.ndarray, names: Sequence[str],
                     chi2_members: np.ndarray | None = None, truth: Mapping[str, float] | None = None,
                     title: str = "") -> Path:
    """Left: correlation over the (LHS) ensemble between each parameter and the stress at each time,
    with the mean curve for orientation. Right: the members in the plane of the first two parameters,
    coloured by log10 chi^2 per observation (an elongated valley = the two trade off)."""
    Y = np.asarray(responses, float)
    ok = np.all(np.isfinite(Y), axis=1)
    P = params[list(names)].to_numpy(float)
    ncol = 2 if len(names) >= 2 and chi2_members is not None else 1
    fig, axes = plt.subplots(1, ncol, figsize=(6.0 * ncol, 4.0), squeeze=False)
    ax = axes[0, 0]
    t = np.arange(obs.m)
    xlabel = "observation index (records concatenated)" if len(obs.records) > 1 else "time [$\\mu$s]"
    if len(obs.records) == 1:
        t = obs.time * 1e6
    Yc = Y[ok] - Y[ok].mean(axis=0)
    for j, p in enumerate(names):
        pc = P[ok, j] - P[ok, j].mean()
        denom = np.sqrt(np.sum(pc ** 2) * np.sum(Yc ** 2, axis=0))
        corr = np.where(denom > 0, pc @ Yc / np.where(denom > 0, denom, 1.0), np.nan)
        ax.plot(t, corr, label=f"corr({p}, stress)")
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("correlation over the ensemble")
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(t, obs.values * 1e-6, color="0.6", lw=1.0, label="observations")
    ax2.set_ylabel("observed stress [MPa]", color="0.5")
    ax.legend(fontsize=8, loc="lower left")
    if ncol == 2:
        ax = axes[0, 1]
        (s0, u0), (s1, u1) = _scale(names[0]), _scale(names[1])
        c = np.log10(np.asarray(chi2_members, float)[ok])
        sc = ax.scatter(P[ok, 0] * s0, P[ok, 1] * s1, c=c, cmap="viridis_r", s=30)
        fig.colorbar(sc, ax=ax, label="log10 $\\chi^2$ per observation")
        if truth is not None and names[0] in truth and names[1] in truth:
            ax.plot(truth[names[0]] * s0, truth[names[1]] * s1, "r*", ms=14, label="truth")
            ax.legend(fontsize=8)
        ax.set_xlabel(f"{names[0]} [{u0}]")
        ax.set_ylabel(f"{names[1]} [{u1}]")
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_diagnosis_check(path, curves: Mapping[str, Mapping], errors: Mapping[str, Mapping],
                         added: Sequence[str], confirmation: str | None = None, bands: pd.DataFrame | None = None,
                         band_records: Mapping[str, Mapping] | None = None) -> Path:
    """The FDEM check of the frozen protocol's answer (:func:`calibration.closing.assemble`'s curves and
    errors): per record, the data and the real runs before (base model) and after (the confirmed model),
    every mesh realization of a replicated check drawn, with their RMSE; ``confirmation`` (the confirmation's
    text) as the figure's title. ``bands`` (check_band.csv) and ``band_records`` (check.json's
    ``predictive_band.records``): the shipped model's 90 % predictive band shaded, with its coverage."""
    return _save(check_figure(curves, errors, added, confirmation, bands, band_records), path)


def check_figure(curves, errors, added, confirmation=None, bands=None, band_records=None):
    """:func:`plot_diagnosis_check`'s figure."""
    # the legends go under the axes: inside, they hid the rise and the peak the check is about
    fig, axes = plt.subplots(1, len(curves), figsize=(4.2 * len(curves), 4.6), squeeze=False)
    after_label = "with " + ", ".join(added) if added else "after (nothing added)"
    shipped = "after" if added else "before"  # the model the check ships: its band is the one a lab reads
    for ax, (r, c) in zip(axes[0], curves.items()):
        if bands is not None and len(bands):
            b = bands[(bands["record"] == r) & (bands["model"] == shipped)]
            if len(b):
                cov = ((band_records or {}).get(r) or {}).get(shipped) or {}
                got = cov.get("predictive_coverage_90")
                ax.fill_between(b["time_s"] * 1e6, b["lower_Pa"] / 1e6, b["upper_Pa"] / 1e6, color="tab:green",
                                alpha=0.18, lw=0, label="90 % predictive band" + (f" (covers {got:.2f})"
                                                                                 if got is not None else ""))
        corrected = c.get("observed") is not None
        if corrected:
            ax.plot(c["time"] * 1e6, c["observed"] / 1e6, ".", ms=1.5, color="0.8", label="data as observed")
        ax.plot(c["time"] * 1e6, c["obs"] / 1e6, ".", ms=2, color="0.5",
                label="data less the coarse mesh's mean error" if corrected else "data")
        for which, name, color in (("before", "base model", "tab:blue"), ("after", after_label, "tab:orange")):
            if which == "after" and not added:
                continue  # the base model kept: its runs are already drawn
            if c[which] is not None:
                rmse = errors[r][which]["rmse"] / 1e6
                runs = np.atleast_2d(c[which])  # replicated runs: one line per mesh realization
                reps = f", {runs.shape[0]} meshes" if runs.shape[0] > 1 else ""
                for k, run in enumerate(runs):
                    ax.plot(c["time"] * 1e6, run / 1e6, color=color, lw=1.4 if runs.shape[0] == 1 else 0.9,
                            label=f"FDEM, {name} (RMSE {rmse:.1f} MPa{reps})" if k == 0 else None)
        ax.set_title(f"{r} ({c['data']})", fontsize=9)
        ax.set_xlabel("time [us]")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    axes[0][0].set_ylabel("stress [MPa]")
    if confirmation:
        fig.suptitle(textwrap.fill(confirmation, width=int(55 * len(curves))), fontsize=9)
    fig.tight_layout()
    return fig


def plot_loro(path, table: Mapping) -> Path:
    """Leave one record out (:func:`calibration.closing.loro_table`): per fold, the held-out record's real
    FDEM RMSE with the base model and with the model the fold kept, the effects named under each pair."""
    rows = list(table["rows"])
    fig, ax = plt.subplots(figsize=(max(4.0, 1.6 * len(rows) + 1.5), 3.8))
    x = np.arange(len(rows))
    before = [r["rmse_before"] / 1e6 for r in rows]
    after = [r["rmse_after"] / 1e6 for r in rows]
    ax.bar(x - 0.18, before, 0.36, label="base model", color="0.6")
    ax.bar(x + 0.18, after, 0.36, label="model kept by the fold", color="tab:blue")
    labels = []
    for r in rows:
        rate = r.get("strain_rate_per_s")
        head = r["heldout"] + (f"\n{rate:.0f} 1/s" if rate else "")
        labels.append(head + "\n" + (", ".join(r["effects"]) or "base kept"))
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("held-out RMSE, real FDEM [MPa]")
    t = table["totals"]
    if t.get("mean_rmse_change") is not None:
        sd = t.get("sd_rmse_change")
        ax.set_title(f"leave one record out: mean change {t['mean_rmse_change'] / 1e6:+.2f} MPa"
                     + (f" (sd {sd / 1e6:.2f})" if sd is not None else "") + f" over {t['folds']} folds", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)
