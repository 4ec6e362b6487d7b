"""Misfit and spread diagnostics: values against hand computations, JSON and DataFrame outputs."""

import json

import numpy as np
import pandas as pd
import pytest

from enkf import (AR1Error, DiagonalError, chi2_per_obs, enkf_update, jsonable, member_table, misfit_table,
                  nrmse, parameter_summary, posterior_dict, rmse)

OBS = np.array([0.0, 10.0, 20.0, 10.0, 0.0])


def test_rmse_nrmse_and_chi2_per_obs_values():
    sim = OBS + np.array([1.0, -1.0, 2.0, 0.0, -2.0])
    assert rmse(sim, OBS) == pytest.approx(np.sqrt(10.0 / 5.0))
    assert nrmse(sim, OBS) == pytest.approx(np.sqrt(2.0) / 20.0)
    assert chi2_per_obs(sim, OBS, DiagonalError(2.0, m=5)) == pytest.approx(10.0 / 4.0 / 5.0)
    rows = np.vstack([sim, OBS])
    assert np.allclose(rmse(rows, OBS), [np.sqrt(2.0), 0.0])
    e = AR1Error(2.0, np.arange(5.0), 1.5)
    r = sim - OBS
    assert chi2_per_obs(sim, OBS, e) == pytest.approx(r @ np.linalg.solve(e.dense(), r) / 5.0, rel=1e-12)


def test_tables_and_posterior_dict_are_ready_for_csv_and_json():
    P = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0], [4.0, 40.0]])
    Y = np.vstack([OBS + k for k in range(4)])
    Y[2] = np.nan
    err = DiagonalError(1.0, m=5)
    mis = misfit_table(Y, OBS, err)
    assert mis["alive"].tolist() == [True, True, False, True]
    assert mis.loc[3, "rmse"] == pytest.approx(3.0)
    assert np.isnan(mis.loc[2, "chi2_per_obs"])
    table = member_table(P, ["sigma_t", "E_t"], Y, OBS, err)
    assert list(table.columns[:3]) == ["member", "sigma_t", "E_t"]
    assert table.loc[1, "chi2_per_obs"] == pytest.approx(1.0)
    summary = parameter_summary(P, ["sigma_t", "E_t"], alive=mis["alive"].to_numpy())
    assert isinstance(summary, pd.DataFrame)
    assert summary.loc["E_t", "mean"] == pytest.approx((10 + 20 + 40) / 3)
    post = posterior_dict(P, ["sigma_t", "E_t"])
    assert post["sigma_t"]["mean"] == pytest.approx(2.5)
    assert post["sigma_t"]["std"] == pytest.approx(np.std([1, 2, 3, 4], ddof=1))
    assert post["sigma_t"]["q05"] == pytest.approx(np.quantile([1, 2, 3, 4], 0.05))
    json.dumps(post, allow_nan=False)


def test_analysis_diagnostics_serialise_to_strict_json():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(10, 2))
    Y = P @ rng.normal(size=(2, 5))
    Y[4] = np.nan
    res = enkf_update(P, Y, OBS, DiagonalError(1.0, m=5), rng=1, inflation=None, names=["a", "b"])
    blob = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert blob["n_alive"] == 9 and blob["dead_members"] == [4]
    assert set(blob["params"]) == {"a", "b"}
    assert blob["misfit_members"]["rmse"][4] is None
    alive = np.arange(10) != 4
    assert blob["misfit_mean"]["rmse"] == pytest.approx(rmse(Y[alive].mean(axis=0), OBS), rel=1e-12)
    assert blob["misfit_members"]["chi2_per_obs"][0] == pytest.approx(np.sum((Y[0] - OBS) ** 2) / 5, rel=1e-10)
    assert jsonable({"x": np.float32(np.inf), "y": np.arange(2)}) == {"x": None, "y": [0, 1]}
