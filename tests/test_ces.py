"""Calibrate-emulate-sample (enkf.ces): the MCMC posterior on the emulator against exact posteriors.

A linear model ``f(theta) = A theta + b`` with Gaussian noise and a box prior far wider than the
likelihood has the Gaussian posterior ``N(mu, S)``, ``S = (A^T R^-1 A)^-1``, ``mu = S A^T R^-1 (d - b)``
(the box truncation is below 1e-30 there). The thin-plate emulator with its linear polynomial
reproduces a linear model exactly, so the sample must reproduce ``mu`` and ``S``. Tolerances: the
Monte Carlo error of a mean over ``n_eff`` effective samples is ``sd / sqrt(n_eff)``; with n_eff >= 1,000
(asserted) that is <= 0.032 sd, so 0.1 sd is three such errors; the sd's relative error is
~ 1 / sqrt(2 n_eff) <= 0.022, so 7 % is three.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from enkf import DiagonalError, latin_hypercube
from enkf.ces import emulator_posterior


def _linear_problem(seed=0, m=30):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, m)
    A = np.column_stack([np.sin(3 * t) + 0.2, t ** 2 - 0.3 * t])
    b = 0.5 * np.cos(2 * t)
    truth = np.array([1.0, 2.0])
    sigma = np.full(m, 0.05)
    d = A @ truth + b + sigma * rng.standard_normal(m)
    R = DiagonalError(sigma)
    Ri = np.diag(1.0 / sigma ** 2)
    S = np.linalg.inv(A.T @ Ri @ A)
    mu = S @ A.T @ Ri @ (d - b)
    return t, A, b, d, R, mu, S, rng


def test_the_sample_of_a_linear_gaussian_problem_has_the_exact_posterior_mean_covariance_and_quantiles():
    t, A, b, d, R, mu, S, rng = _linear_problem()
    lo, hi = np.array([-3.0, -3.0]), np.array([5.0, 8.0])
    X = latin_hypercube(lo, hi, 30, rng)
    Y = X @ A.T + b
    latest = np.zeros(30, bool)
    latest[-10:] = True
    post = emulator_posterior(X, Y, latest, d, R, lower=lo, upper=hi, times=t, rng=1, names=["p", "q"])
    diag = post.diagnostics
    assert diag["converged_chain"] and diag["effective_samples"] >= 1000
    assert 0.2 < diag["acceptance_fraction"] < 0.9  # the stretch move's healthy range
    # the exact emulator's leave-one-out error is round-off: it must not widen the posterior
    assert diag["emulator_error"]["max"] < 1e-6 * R.std.min()
    sd = np.sqrt(np.diag(S))
    mean, cov = post.samples.mean(axis=0), np.cov(post.samples.T)
    assert np.all(np.abs(mean - mu) < 0.1 * sd)
    assert np.sqrt(np.diag(cov)) == pytest.approx(sd, rel=0.07)
    corr = S[0, 1] / (sd[0] * sd[1])
    assert cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]) == pytest.approx(corr, abs=0.05)
    for j, name in enumerate(["p", "q"]):
        s = post.summary[name]
        for key, q in (("q05", 0.05), ("q25", 0.25), ("q75", 0.75), ("q95", 0.95)):
            assert s[key] == pytest.approx(mu[j] + stats.norm.ppf(q) * sd[j], abs=0.12 * sd[j])


def test_a_posterior_against_a_bound_is_truncated_by_the_box_prior():
    """The same problem with the box's upper end at the posterior mean of p: the marginal of p is
    the Gaussian's lower half (its mean is mu - sd sqrt(2/pi) for an independent parameter, here the
    conditional structure shifts it; checked: every sample is inside and the median is below the end)."""
    t, A, b, d, R, mu, S, rng = _linear_problem(seed=2)
    lo, hi = np.array([-3.0, -3.0]), np.array([mu[0], 8.0])
    X = latin_hypercube(lo, hi, 40, rng)
    post = emulator_posterior(X, X @ A.T + b, np.ones(40, bool), d, R, lower=lo, upper=hi, times=t, rng=3)
    p = post.samples[:, 0]
    assert p.max() <= hi[0] and p.min() >= lo[0]
    sd = np.sqrt(S[0, 0])
    assert hi[0] - 1.0 * sd < np.median(p) < hi[0] - 0.2 * sd


def test_the_same_rng_gives_the_same_sample_and_bad_input_is_named():
    t, A, b, d, R, mu, S, rng = _linear_problem(seed=4)
    lo, hi = np.array([-3.0, -3.0]), np.array([5.0, 8.0])
    X = latin_hypercube(lo, hi, 20, rng)
    kw = dict(lower=lo, upper=hi, times=t, min_steps=500)
    a = emulator_posterior(X, X @ A.T + b, np.ones(20, bool), d, R, rng=7, **kw)
    c = emulator_posterior(X, X @ A.T + b, np.ones(20, bool), d, R, rng=7, **kw)
    assert np.array_equal(a.samples, c.samples)
    with pytest.raises(ValueError, match="walkers must be even and at least 2 n = 4"):
        emulator_posterior(X, X @ A.T + b, np.ones(20, bool), d, R, rng=7, walkers=3, **kw)
    with pytest.raises(ValueError, match="curves have 30 values, the observations 29"):
        emulator_posterior(X, X @ A.T + b, np.ones(20, bool), d[:-1], R, rng=7, **kw)


def test_the_workflow_reports_the_emulator_posterior_with_posterior_emulator_mcmc(tmp_path):
    """End to end with the stand-in simulator of tests/test_workflow.py (peak 0.8 sigma_t, decay set by
    E_t): posterior.csv is the MCMC sample, summary.json's posterior its summary, the forecast runs at
    its mean, and the last ensemble is kept as posterior_ensemble. With ``emulated.refine_runs`` the
    refinement batch is simulated after the loop (one job per run, on its own mesh), is the posterior's
    latest runs and is counted with the simulations."""
    import json

    import pandas as pd

    from test_workflow import snakemake, twin_config, write_config, write_stand_in

    # min_alive_fraction 0.6: 6 members go on with 4 survivors, the emulator's 4 runs (calibration.config_ranges)
    cfg = twin_config(method="emulated_esmda", posterior="emulator_mcmc", ensemble_size=6, max_iterations=2,
                      min_alive_fraction=0.6, emulated={"refine_runs": 5, "self_calibrate": False})
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    out = snakemake(tmp_path, "--cores", "2")
    assert out.returncode == 0, out.stderr[-4000:]
    res = tmp_path / "results/twin"
    samples = pd.read_csv(res / "posterior.csv")
    assert list(samples.columns) == ["sample", "sigma_t", "E_t"] and len(samples) >= 1000
    assert samples.equals(pd.read_csv(res / "posterior/samples.csv"))
    summary = json.loads((res / "summary.json").read_text())
    assert summary["posterior_method"] == "emulator_mcmc" and summary["posterior_sampler"]["converged_chain"]
    # a stand-in's loop of 6 members is no loop the coverage harness scored: its summary says so
    assert summary["posterior_form"] == {"posterior": "emulator_mcmc", "self_calibrate": False,
                                         "emulator_error": "ar1", "refine_runs": 5, "scored_by": None,
                                         "form_scored_on": None}
    assert summary["posterior"]["sigma_t"]["mean"] == pytest.approx(samples["sigma_t"].mean(), rel=1e-12)
    assert set(summary["posterior_ensemble"]) == {"sigma_t", "E_t"}
    fc = json.loads((res / "forecast/params.json").read_text())
    assert fc["posterior"] == "emulator_mcmc" and fc["params"]["E_t"] == pytest.approx(samples["E_t"].mean())
    # the stand-in's curve is linear in sigma_t: its posterior is near Gaussian, and a mean more than
    # 3 sd from the truth would happen by chance in 0.3 % of noise draws (this draw: 1.7 sd)
    post, truth = summary["posterior"]["sigma_t"], summary["truth"]["sigma_t"]
    assert abs(post["mean"] - truth) < 3 * post["std"] and abs(summary["accuracy"]["sigma_t"]["rel_error"]) < 0.02
    assert set(summary["accuracy"]["E_t"]) == {"rel_error", "in_90_interval", "in_50_interval"}
    design = pd.read_csv(res / "refine/params.csv")
    assert list(design.columns) == ["member", "sigma_t", "E_t"] and len(design) == 5
    runs = [json.loads((res / f"refine/members/{m:03d}/synthetic/run.json").read_text()) for m in range(5)]
    assert [r["iteration"] for r in runs] == ["refine"] * 5 and all(r["status"] == "ok" for r in runs)
    sampler = summary["posterior_sampler"]
    assert sampler["refine"]["runs"] == 5 and sampler["refine"]["failed"] == 0 and sampler["refine"]["temper"] == 4.0
    assert sampler["latest_points"] == 5 and sampler["design_points"] == 3 * 6 + 5
    # 6 members and 3 replicates in each of 3 iterations, the truth, the forecast and the batch
    assert summary["n_simulations"] == 3 * (6 + 3) + 1 + 1 + 5


def test_a_tempered_posterior_of_a_linear_gaussian_problem_is_sqrt_temper_times_wider():
    """``temper`` divides the log-likelihood: the Gaussian posterior's covariance is ``temper S`` around
    the same ``mu`` (the refinement batch's design posterior, enkf.refine). Tolerances as above."""
    t, A, b, d, R, mu, S, rng = _linear_problem(seed=2)
    lo, hi = np.array([-6.0, -6.0]), np.array([8.0, 10.0])
    X = latin_hypercube(lo, hi, 30, rng)
    post = emulator_posterior(X, X @ A.T + b, np.ones(30, bool), d, R, lower=lo, upper=hi, times=t, rng=4,
                              temper=4.0)
    assert post.diagnostics["temper"] == 4.0 and post.diagnostics["effective_samples"] >= 1000
    sd = 2.0 * np.sqrt(np.diag(S))
    assert np.all(np.abs(post.samples.mean(axis=0) - mu) < 0.1 * sd)
    assert post.samples.std(axis=0, ddof=1) == pytest.approx(sd, rel=0.07)
    with pytest.raises(ValueError, match="temper must be at least 1, got 0.5"):
        emulator_posterior(X, X @ A.T + b, np.ones(30, bool), d, R, lower=lo, upper=hi, times=t, rng=4, temper=0.5)


def test_the_curvature_tempering_of_a_linear_gaussian_problem_is_the_power_tempering():
    """A quadratic log-likelihood stretched by ``sqrt(temper)`` about its maximum is the same Gaussian as
    the log-likelihood divided by ``temper``: covariance ``temper S`` around ``mu``, and the maximum found
    is ``mu``. Tolerances as above."""
    t, A, b, d, R, mu, S, rng = _linear_problem(seed=2)
    lo, hi = np.array([-6.0, -6.0]), np.array([8.0, 10.0])
    X = latin_hypercube(lo, hi, 30, rng)
    post = emulator_posterior(X, X @ A.T + b, np.ones(30, bool), d, R, lower=lo, upper=hi, times=t, rng=4,
                              temper=4.0, tempering="curvature", names=["p", "q"])
    sd = 2.0 * np.sqrt(np.diag(S))
    assert post.diagnostics["tempering"] == "curvature" and post.diagnostics["effective_samples"] >= 1000
    assert np.abs(np.array(list(post.diagnostics["likelihood_maximum"].values())) - mu) == pytest.approx(0, abs=1e-3 * sd.min())
    assert np.all(np.abs(post.samples.mean(axis=0) - mu) < 0.1 * sd)
    assert post.samples.std(axis=0, ddof=1) == pytest.approx(sd, rel=0.07)
    with pytest.raises(ValueError, match="tempering must be one of"):
        emulator_posterior(X, X @ A.T + b, np.ones(30, bool), d, R, lower=lo, upper=hi, times=t, rng=4,
                           tempering="sqrt")


def test_the_curvature_tempering_keeps_a_skewed_likelihoods_shape_where_the_power_form_does_not():
    """``f(theta) = a exp(theta)``: the likelihood is Gaussian in ``exp(theta)``, skewed in ``theta``. The
    exact tempered posteriors on a fine grid: ``L(theta)^(1/4)`` (power) and ``L(theta_hat + (theta -
    theta_hat)/2)`` (curvature). The sample's quantiles must be the curvature form's within 0.12 sd (three
    Monte Carlo errors at n_eff >= 1000, as above), and the power form's 5 % quantile lies 0.29 sd away from
    it, so the check tells the forms apart. The emulator interpolates 121 runs of a smooth curve in 1D:
    its error (below 1e-4 of the noise) is left out."""
    m = 20
    t = np.linspace(0.0, 1.0, m)
    a, sigma = 1.0 + t, np.full(m, 0.8)
    d = a * np.exp(0.5) + sigma * np.random.default_rng(0).standard_normal(m)
    lo, hi = np.array([-3.0]), np.array([3.0])
    g = np.linspace(lo[0], hi[0], 200001)

    def loglik(th):
        return -0.5 * np.sum((d[None, :] - np.outer(np.exp(th), a)) ** 2 / sigma ** 2, axis=1)

    def quantiles(logp, qs):
        c = np.cumsum(np.exp(logp - logp.max()))
        return np.interp(qs, c / c[-1], g)

    qs = np.array([0.05, 0.25, 0.5, 0.75, 0.95])
    theta_hat = g[np.argmax(loglik(g))]
    curvature = quantiles(loglik(theta_hat + (g - theta_hat) / 2.0), qs)
    power = quantiles(loglik(g) / 4.0, qs)
    sd = (curvature[-1] - curvature[0]) / (2 * 1.645)
    assert abs(power[0] - curvature[0]) > 0.25 * sd
    X = np.linspace(lo[0], hi[0], 121)[:, None]
    post = emulator_posterior(X, np.exp(X) * a[None, :], np.ones(121, bool), d, DiagonalError(sigma), lower=lo,
                              upper=hi, times=t, rng=1, emulator_error=False, temper=4.0, tempering="curvature",
                              walkers=16)
    assert post.diagnostics["effective_samples"] >= 1000
    assert post.diagnostics["likelihood_maximum"]["p0"] == pytest.approx(theta_hat, abs=1e-3)
    assert np.quantile(post.samples[:, 0], qs) == pytest.approx(curvature, abs=0.12 * sd)
