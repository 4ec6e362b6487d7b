"""The approximation error of a coarse model against a finer one (enkf.approximation) and its use on
observations (calibration.observations.with_approximation_error)."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from calibration.observations import Observations, with_approximation_error
from enkf import AR1Error, DiagonalError
from enkf.approximation import approximation_error

T = np.arange(120) * 1e-6


@pytest.mark.parametrize("coarse_variability, sd", [
    ("counted", np.hypot(1.5e6, 0.5e6 / np.sqrt(2))),       # the fine scatter and the two-run coarse mean's
    ("subtracted", np.sqrt(1.5e6 ** 2 - 0.5e6 ** 2)),       # ... less (1 + 1/2) times a coarse run's variance
])
def test_paired_runs_recover_a_planted_offset_scatter_and_correlation_time(coarse_variability, sd):
    """A fine model = coarse + a fixed 2 MPa bump + AR(1) scatter (1.5 MPa, 6 us), the coarse runs with
    their own 0.5 MPa white mesh noise averaged over two realizations: from 400 pairs the offset within
    five standard errors everywhere, the scatter's rms within 10 % of its planted value and the
    correlation time of the pairs' differences within 10 %. Counted, the rms is that of the differences;
    subtracted, what the data need beyond the 0.5 MPa the error model already gives them as ``S``:
    sqrt(1.5^2 - 0.5^2) MPa, so that ``S + M`` is the fine scatter's 1.5 MPa."""
    rng = np.random.default_rng(3)
    n = 400
    base = 30e6 * np.sin(np.pi * T / T[-1])[None, :] * rng.uniform(0.5, 1.5, (n, 1))
    bump = 2e6 * np.exp(-((T - 60e-6) / 15e-6) ** 2)
    scatter = AR1Error(np.full(T.size, 1.5e6), T, 6e-6).sample(rng, n)
    fine = base + bump + scatter
    coarse = base[:, None, :] + 0.5e6 * rng.standard_normal((n, 2, T.size))
    offset, M, info = approximation_error(fine, coarse, T, coarse_variability=coarse_variability)
    diff_sd = np.hypot(1.5e6, 0.5e6 / np.sqrt(2))
    assert np.max(np.abs(offset - bump)) < 5 * diff_sd / np.sqrt(n)
    assert info["rms_Pa"] == pytest.approx(sd, rel=0.10)
    if coarse_variability == "subtracted":
        assert info["coarse_variability_rms_Pa"] == pytest.approx(0.5e6, rel=0.10)
        assert info["scatter_rms_Pa"] == pytest.approx(diff_sd, rel=0.10)
    # the lag-1 correlation of the differences: the AR(1) part's exp(-1 us / 6 us), weighted by its share
    rho = np.exp(-1.0 / 6.0) * 1.5e6 ** 2 / diff_sd ** 2
    assert info["corr_time_s"] == pytest.approx(-1e-6 / np.log(rho), rel=0.10)
    assert info["n_pairs_used"] == n and info["offset_rms_Pa"] == pytest.approx(np.sqrt(np.mean(bump ** 2)), rel=0.05)


def test_failed_pairs_are_left_out_and_too_few_pairs_are_refused():
    rng = np.random.default_rng(4)
    fine = rng.standard_normal((5, T.size))
    coarse = rng.standard_normal((5, T.size))
    fine[1, 7] = np.nan
    _, _, info = approximation_error(fine, coarse, T, coarse_variability="counted")
    assert info["n_pairs"] == 5 and info["n_pairs_used"] == 4
    fine[2:4, 0] = np.nan
    with pytest.raises(ValueError, match="at least 3 usable pairs"):
        approximation_error(fine, coarse, T, coarse_variability="counted")
    with pytest.raises(ValueError, match="must match"):
        approximation_error(fine[:, :-1], coarse, T, coarse_variability="counted")
    with pytest.raises(ValueError, match="needs at least 2 coarse realizations per design point"):
        approximation_error(fine, coarse, T)


def test_a_biased_coarse_model_covers_its_truths_only_with_the_approximation_error():
    """Gauss-linear stand-in: the fine model is the coarse one (y = G theta) plus a bias that grows with
    theta_1 and a scatter of its own; data from the fine model, 1 % noise. Over 300 truths from the
    prior, the exact posterior of the coarse model with the noise alone puts the truth inside its 90 %
    interval of theta_1 in under half of them; with the approximation error of 40 prior pairs, in
    0.80-0.98 (the 90 % intervals' binomial band for 300 truths is 0.86-0.93; the bias's dependence
    on theta, which a prior-averaged correction leaves in the scatter, and 40 pairs' estimate of it
    make it approximate, not exact)."""
    rng = np.random.default_rng(5)
    m = T.size
    G = np.stack([np.sin(np.pi * T / T[-1]), (T / T[-1]) ** 2], axis=1) * 10e6  # (m, 2)
    mu0, sd0 = np.array([1.0, 1.0]), np.array([0.3, 0.3])
    shape = np.exp(-((T - 80e-6) / 20e-6) ** 2) * 1e6
    scatter = AR1Error(np.full(m, 0.4e6), T, 5e-6)

    def fine(theta, n=1):
        return theta @ G.T + (1.5 + theta[:, :1]) * shape + scatter.sample(rng, n)

    design = mu0 + sd0 * rng.standard_normal((40, 2))
    offset, M, _ = approximation_error(fine(design, 40), design @ G.T, T, coarse_variability="counted")
    noise = DiagonalError(np.full(m, 0.1e6))
    truths = mu0 + sd0 * rng.standard_normal((300, 2))
    data = fine(truths, 300) + noise.sample(rng, 300)
    z = stats.norm.ppf(0.95)
    inside = {}
    for name, C, shift in (("noise", noise.dense(), 0.0), ("approx", noise.dense() + M.dense(), offset)):
        Ci = np.linalg.inv(C)
        P = np.linalg.inv(G.T @ Ci @ G + np.diag(1 / sd0 ** 2))
        mean = (P @ (G.T @ Ci @ (data - shift).T + (mu0 / sd0 ** 2)[:, None])).T
        inside[name] = np.mean(np.abs(mean[:, 0] - truths[:, 0]) <= z * np.sqrt(P[0, 0]))
    assert inside["noise"] < 0.5
    assert 0.80 <= inside["approx"] <= 0.98


def test_subtracting_the_coarse_variability_calibrates_what_counting_it_widens():
    """Gauss-linear stand-in whose coarse runs scatter by a mesh variability of their own (AR(1),
    0.6 MPa) and whose fine runs by theirs (0.8 MPa) about a bias that grows with theta_1; the error
    model gives the data the coarse ``S`` (as the workflow's likelihood ``R + S + D`` does) plus ``M``
    from 400 pairs with two coarse realizations each. Over 400 truths from the prior, the exact posterior
    with ``M`` subtracted holds the truth in its 50 % and 90 % intervals at their levels (binomial
    sd 0.025 and 0.015: bands of about 2.8 sd); counted, the coarse variability enters 1.5 times too
    often and the 50 % intervals hold more than 0.56 (0.6-0.66 expected)."""
    rng = np.random.default_rng(11)
    m = T.size
    G = np.stack([np.sin(np.pi * T / T[-1]), (T / T[-1]) ** 2], axis=1) * 10e6
    mu0, sd0 = np.array([1.0, 1.0]), np.array([0.3, 0.3])
    shape = np.exp(-((T - 80e-6) / 20e-6) ** 2) * 1e6
    S_fine, S_coarse = AR1Error(np.full(m, 0.8e6), T, 5e-6), AR1Error(np.full(m, 0.6e6), T, 5e-6)

    def fine(theta):
        return theta @ G.T + (1.5 + 0.3 * theta[:, :1]) * shape + S_fine.sample(rng, theta.shape[0])

    design = mu0 + sd0 * rng.standard_normal((400, 2))
    coarse = (design @ G.T)[:, None, :] + S_coarse.sample(rng, 800).reshape(400, 2, m)
    F = fine(design)
    noise = DiagonalError(np.full(m, 0.1e6))
    truths = mu0 + sd0 * rng.standard_normal((400, 2))
    data = fine(truths) + noise.sample(rng, 400)
    inside = {}
    for mode in ("subtracted", "counted"):
        offset, M, _ = approximation_error(F, coarse, T, coarse_variability=mode)
        Ci = np.linalg.inv(noise.dense() + S_coarse.dense() + M.dense())
        P = np.linalg.inv(G.T @ Ci @ G + np.diag(1 / sd0 ** 2))
        mean = (P @ (G.T @ Ci @ (data - offset).T + (mu0 / sd0 ** 2)[:, None])).T
        err = np.abs(mean - truths) / np.sqrt(np.diag(P))
        inside[mode] = {level: np.mean(err <= stats.norm.ppf(0.5 + level / 2), axis=0) for level in (0.5, 0.9)}
    assert np.all((inside["subtracted"][0.5] >= 0.43) & (inside["subtracted"][0.5] <= 0.57))
    assert np.all((inside["subtracted"][0.9] >= 0.86) & (inside["subtracted"][0.9] <= 0.94))
    assert np.all(inside["counted"][0.5] > 0.56)
    # the two forms must differ where it matters: counting the coarse mesh twice widens every interval
    assert np.all(inside["subtracted"][0.5] < inside["counted"][0.5])


def test_observations_carry_the_offset_and_the_added_covariance_record_by_record():
    t = np.arange(5) * 1e-6
    frame = pd.DataFrame({"record": ["a"] * 5 + ["b"] * 5, "time_s": np.r_[t, t],
                          "stress_Pa": np.arange(10.0) * 1e6, "sigma_Pa": np.full(10, 1e5)})
    obs = Observations(frame)
    M = AR1Error(np.full(10, 2e5), np.r_[t, t], 2e-6, groups=np.r_[np.zeros(5), np.ones(5)])
    offset = np.full(10, 0.5e6)
    out = with_approximation_error(obs, offset, M, {"n_pairs": 3, "sd_Pa": [0.0]})
    assert np.allclose(out.values, obs.values - 0.5e6)
    assert np.allclose(out.frame["stress_uncorrected_Pa"], obs.values)
    assert np.allclose(out.error_model().dense(), obs.error_model().dense() + M.dense())
    assert np.allclose(out.of_record("b").error_model().dense(), 1e10 * np.eye(5) + M.dense()[5:, 5:])
    assert out.meta["approximation_error"] == {"n_pairs": 3, "sd_Pa": [0.0]}
    with pytest.raises(ValueError, match="approximation error on 9 times"):
        with_approximation_error(obs, offset[:9], M, {})


def test_obs_files_carry_the_approximation_error_and_a_bad_one_is_named(tmp_path):
    """obs.csv holds the corrected stress beside the observed one; obs.json the term, from which
    read_observations rebuilds the same error model."""
    import json

    from calibration.observations import read_observations

    t = np.arange(8) * 1e-6
    frame = pd.DataFrame({"record": ["a"] * 8, "time_s": t, "stress_Pa": np.linspace(0, 7e6, 8),
                          "sigma_Pa": np.full(8, 1e5)})
    rng = np.random.default_rng(9)
    fine, coarse = rng.normal(1e6, 3e5, (6, 8)), rng.normal(0.0, 1e5, (6, 2, 8))
    obs = with_approximation_error(Observations(frame), *approximation_error(fine, coarse, t))
    obs.write(tmp_path / "obs.csv", tmp_path / "obs.json")
    back = read_observations(tmp_path / "obs.csv", tmp_path / "obs.json")
    assert np.allclose(back.values, obs.values) and np.allclose(back.frame["stress_uncorrected_Pa"], frame["stress_Pa"])
    assert np.allclose(back.error_model().dense(), obs.error_model().dense(), rtol=1e-12)
    meta = json.loads((tmp_path / "obs.json").read_text())
    meta["approximation_error"]["sd_Pa"] = meta["approximation_error"]["sd_Pa"][:5]
    (tmp_path / "obs.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="obs.json: approximation_error.sd_Pa has 5 values for 8 observations"):
        read_observations(tmp_path / "obs.csv", tmp_path / "obs.json")


def test_the_workflow_runs_the_pairs_and_calibrates_on_corrected_observations(tmp_path):
    """A twin made at ``standard`` and calibrated at ``fast`` with 5 pairs, on the stand-in simulator
    whose finer presets peak 7 % lower: the pairs run at their presets on mesh realizations of their
    own, obs.csv holds the data less the pairs' mean difference (before the wave's peak, where the
    stand-in has no mesh ripple, exactly -7 % of the design's mean rise), obs.json the scatter that
    read_observations adds to the error model, and summary.json reports the term."""
    from calibration.approximation import approximation_design, approximation_mesh_seed, approximation_run_ids
    from calibration.observations import read_observations
    from calibration.workflow_io import validate_config
    from test_workflow import SCHEMA, snakemake, twin_config, write_config, write_stand_in

    cfg = twin_config(esmda={"steps": 1})
    exp = cfg["experiments"]["twin"]
    exp["observations"]["preset"] = "standard"
    exp["observations"]["model_error"]["approximation_error"] = {"preset": "standard", "pairs": 5}
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    run = snakemake(tmp_path, "--cores", "2")
    assert run.returncode == 0, run.stderr[-4000:]
    res = tmp_path / "results" / "twin"
    full = validate_config(cfg, SCHEMA, base_dir=tmp_path)["experiments"]["twin"]
    ids = approximation_run_ids(full)
    assert len(ids) == 15
    runs = {r: json.loads((res / "approximation" / r / "synthetic" / "run.json").read_text()) for r in ids}
    assert {runs[r]["preset"] for r in ids if r.startswith("fine")} == {"standard"}
    assert {runs[r]["preset"] for r in ids if r.startswith("coarse")} == {"fast"}
    assert [runs[r]["design_point"] for r in ids[:3]] == [0, 0, 0] and runs[ids[1]]["approximation"] == "coarse"
    assert runs["coarse_004_1"]["params"]["sigma_t"] == approximation_design("twin", full)[4, 0]
    assert len({approximation_mesh_seed(full, r) for r in ids}) == 15  # the stand-in does not echo its seed
    design = approximation_design("twin", full)
    obs = read_observations(res / "observations" / "obs.csv", res / "observations" / "obs.json")
    offset = obs.values - obs.frame["stress_uncorrected_Pa"].to_numpy()
    t = obs.time
    rise = 0.8 * np.sin(0.5 * np.pi * t / 20e-6) ** 2 * design[:, 0].mean()
    before = t < 19.5e-6
    assert np.allclose(-offset[before], -0.07 * rise[before], rtol=1e-9, atol=1e-3)
    after = t > 25e-6
    assert np.all(obs.error_model().std[after] > obs.sigma[after])
    summary = json.loads((res / "summary.json").read_text())
    assert summary["approximation_error"]["n_pairs_used"] == 5
    assert summary["approximation_error"]["fine_preset"] == "standard"


@pytest.mark.parametrize("block, message", [
    ({"preset": "standard", "pairs": 2}, "approximation_error.pairs: 2 pairs cannot give a mean and a scatter"),
    ({"preset": "standard", "pairs": 10, "coarse_realizations": 1},
     "approximation_error.coarse_realizations: coarse_variability: subtracted measures"),
    ({"preset": "standard", "pairs": 10, "replicates": 0},
     "approximation_error.coarse_variability: subtracted takes the coarse mesh's variability off"),
    ({"pairs": 10}, "approximation_error.preset: pairs > 0 needs the finer preset"),
    ({"preset": "standard", "pairs": 10}, "'standard' is not finer than the experiment's preset 'standard'"),
    ({"preset": "fast", "pairs": 10}, "approximation_error.preset: 'fast' is not one of"),
    ({"preset": "paper", "pairs": 10}, "approximation_error: the pairs' design spans the prior box, which parameters: auto"),
])
def test_a_bad_approximation_error_block_is_named_before_any_job_runs(block, message):
    from calibration.workflow_io import ConfigError, validate_config
    from test_workflow import SCHEMA, twin_config

    cfg = twin_config(preset="standard" if "finer than the experiment" in message else "fast")
    block = dict(block)
    if "replicates" in block:
        cfg["experiments"]["twin"]["observations"]["model_error"]["simulator_replicates"] = block.pop("replicates")
    cfg["experiments"]["twin"]["observations"]["model_error"]["approximation_error"] = block
    if "auto" in message:
        cfg["experiments"]["twin"]["parameters"] = "auto"
        cfg["experiments"]["twin"]["sensitivity"] = {"parameters": {"sigma_t": [4.0e6, 60.0e6], "E_t": [200.0, 2400.0]}}
    with pytest.raises(ConfigError) as err:
        validate_config(cfg, SCHEMA)
    assert "experiments.twin.observations.model_error.approximation_error" in str(err.value)
    assert message in str(err.value)


def test_a_held_out_record_is_corrected_by_pairs_run_on_its_own_incident_wave(tmp_path):
    """The default run's marble series with 3 pairs, on the stand-in simulator (finer presets peak 7 %
    lower): the pairs run on the held-out record's incident wave too, so its obs.csv is corrected by the
    same -7 % of the design's mean rise before the peak and carries the pairs' scatter in its error model,
    as the calibration records' obs.csv is (their pairs on the mesh realizations they had before)."""
    import yaml

    from calibration.approximation import approximation_design, approximation_run_ids
    from calibration.observations import read_observations
    from calibration.workflow_io import validate_config
    from test_workflow import REPO, SCHEMA, snakemake, write_stand_in

    base = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    exp = base["experiments"]["marble_loop"]
    exp["observations"]["records"] = [str(REPO / p) for p in exp["observations"]["records"]]
    exp["diagnosis"]["heldout_records"] = [str(REPO / p) for p in exp["diagnosis"]["heldout_records"]]
    exp["observations"]["model_error"]["approximation_error"] = {"preset": "standard", "pairs": 3}
    cfg = {"run": ["marble_loop"], "experiments": {"marble_loop": exp}, "simulator": write_stand_in(tmp_path)}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    res = tmp_path / "results" / "marble_loop"
    run = snakemake(tmp_path, "--cores", "2", "results/marble_loop/diagnosis/heldout/obs.csv",
                    "results/marble_loop/observations/obs.csv")
    assert run.returncode == 0, run.stderr[-4000:]
    full = validate_config(cfg, SCHEMA, base_dir=tmp_path)["experiments"]["marble_loop"]
    ids = approximation_run_ids(full)
    presets = {r: json.loads((res / "approximation" / r / "CaMa_SHPB_006" / "run.json").read_text())["preset"]
               for r in ids}
    assert len(ids) == 9 and {presets[r] for r in ids if r.startswith("fine")} == {"standard"}
    assert {presets[r] for r in ids if r.startswith("coarse")} == {"fast"}
    logs = {rec: (res / "approximation/fine_000" / rec / "simulate.log").read_text().split("\n")[0]
            for rec in ("CaMa_SHPB_004", "CaMa_SHPB_014", "CaMa_SHPB_006")}
    assert "--record results/marble_loop/observations/CaMa_SHPB_006/record.json" in logs["CaMa_SHPB_006"]
    assert len({line.split("--mesh-seed ")[1].split()[0] for line in logs.values()}) == 3
    rise_scale = approximation_design("marble_loop", full)[:, 0].mean()
    held = read_observations(res / "diagnosis/heldout/obs.csv", res / "diagnosis/heldout/obs.json")
    calib = read_observations(res / "observations/obs.csv", res / "observations/obs.json")
    assert held.records == ["CaMa_SHPB_006"] and calib.records == ["CaMa_SHPB_004", "CaMa_SHPB_014"]
    for obs in (held, calib):
        t = obs.time
        offset = obs.values - obs.frame["stress_uncorrected_Pa"].to_numpy()
        before = t < 19.5e-6
        rise = 0.8 * np.sin(0.5 * np.pi * t[before] / 20e-6) ** 2 * rise_scale
        assert before.sum() == 10 * len(obs.records) and np.allclose(offset[before], 0.07 * rise, rtol=1e-9, atol=1e-3)
        assert np.all(obs.error_model().std[t > 25e-6] > obs.sigma[t > 25e-6])
    assert held.meta["approximation_error"]["n_pairs_used"] == 3


def test_a_series_runs_each_record_s_pairs_once_and_every_fold_reads_them(tmp_path):
    """config/diagnosis.yaml's leave-one-record-out marble series with 3 pairs, on the stand-in: the pairs
    run once per record under the series (not per fold), and a record's correction is the same whether
    its fold calibrates on it or holds it out."""
    import yaml

    from calibration.observations import read_observations
    from test_workflow import REPO, snakemake, write_stand_in

    exp = yaml.safe_load((REPO / "config" / "diagnosis.yaml").read_text())["experiments"]["marble_loro"]
    exp["observations"]["records"] = [str(REPO / p) for p in exp["observations"]["records"]]
    exp["observations"].setdefault("model_error", {})["approximation_error"] = {"preset": "standard", "pairs": 3}
    cfg = {"run": ["marble_loro"], "experiments": {"marble_loro": exp}, "simulator": write_stand_in(tmp_path)}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    folds = ("marble_loro__CaMa_SHPB_006", "marble_loro__CaMa_SHPB_016")
    targets = [f"results/{f}/{part}/obs.csv" for f in folds for part in ("observations", "diagnosis/heldout")]
    run = snakemake(tmp_path, "--cores", "2", *targets)
    assert run.returncode == 0, run.stderr[-4000:]
    res = tmp_path / "results"
    made = sorted(p.parent.relative_to(res).parts[0] for p in res.glob("*/approximation/*/*/run.json"))
    assert set(made) == {"marble_loro"} and len(made) == 4 * 9  # four records, 3 pairs x (1 fine + 2 coarse)

    def offsets(fold, part):
        obs = read_observations(res / fold / part / "obs.csv", res / fold / part / "obs.json")
        d = obs.values - obs.frame["stress_uncorrected_Pa"].to_numpy()
        return {r: d[obs.record_slice(r)] for r in obs.records}

    held_006, calib_016 = offsets(folds[0], "diagnosis/heldout"), offsets(folds[1], "observations")
    assert list(held_006) == ["CaMa_SHPB_006"] and "CaMa_SHPB_006" in calib_016
    np.testing.assert_array_equal(held_006["CaMa_SHPB_006"], calib_016["CaMa_SHPB_006"])
    assert np.max(np.abs(held_006["CaMa_SHPB_006"])) > 1e5  # the stand-in's finer mesh: a real offset
