"""The Snakemake calibration workflow: config validation, observations, the analysis step, member
failures, and end-to-end runs of `snakemake --cores 2`.

* Unit tests of the workflow modules (``calibration.workflow_io``, ``calibration.observations``)
  against exact expectations (the reduced record, the seed); the analysis step is in
  test_workflow_analysis.py.
* ``test_workflow_runs_end_to_end_and_a_second_run_has_nothing_to_do``: the real simulator
  (``python -m shpb simulate``, fast preset), a twin experiment with N = 8 and two ES-MDA analyses;
  checks the files of docs/workflow.md ("What goes where"), ``summary.json``, the misfit falling, and that a second
  invocation has nothing to do.
* Robustness tests (failed members, kill and resume, malformed observations) drive the workflow
  with a *stand-in* simulator written by this file into the test's folder (an analytic pulse through
  the same command-line contract, through the config's ``simulator`` command), because they test the
  workflow's handling of failures and interruptions, not the physics: failures are injected on
  purpose and the members must be fast enough to kill a run between two of them.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from calibration.experiment import ExperimentSpec, initial_ensemble, rng_for
from calibration.observations import (ObservationFileError, check_record, curve_on_grid,
                               measured_observations, observation_grid, read_observations, twin_observations)
from calibration.workflow_io import (ConfigError, SimulatorRejected, load_yaml, member_ids, run_member,
                              validate_config)

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"
CAMA005 = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_005_Ti25_60b_Al12b_0_001.txt"


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------
def twin_config(**overrides) -> dict:
    exp = {
        "kind": "twin", "geometry": "brazilian_disc", "preset": "fast", "seed": 3, "ensemble_size": 8,
        "method": "esmda", "esmda": {"steps": 2},
        # the workflow's mechanics, on the cheaper reported posterior (the shipped form: test_one_posterior.py)
        "posterior": "ensemble",
        "parameters": {"sigma_t": [4.0e6, 60.0e6], "E_t": [200.0, 2400.0]},
        "simulation": {"t_end": 1.2e-4, "sample_dt": 1.0e-6},
        "observations": {"t_end": 1.0e-4, "dt": 1.0e-6, "truth": {"sigma_t": 45.0e6, "E_t": 500.0},
                         "noise": {"relative_sigma": 0.01}, "model_error": {"simulator_replicates": 3}},
    }
    for key, value in overrides.items():
        exp[key] = value
    return {"experiments": {"twin": exp}}


STAND_IN = textwrap.dedent('''
    """Stand-in for `python -m shpb simulate` in workflow robustness tests (an analytic pulse, not FDEM).

    Peak 0.8 sigma_t at 20 us, exponential decay with tau = 5 us + 30 us E_t / 2400 J/m^2. A mesh
    realization (--mesh-seed) adds a ripple after the peak, 0.5 % of it at 10 us period with a phase
    drawn from the seed: the stand-in's own "simulator variability". The finer presets (standard, paper)
    peak 7 % lower: a planted resolution error (test_approximation_error.py).
    Injected failures (environment): STAND_IN_FAIL_BELOW: sigma_t below it -> exit 3 with a failed
    run.json; STAND_IN_CRASH_ONCE_BELOW: sigma_t below it -> crash (exit 1) on the first call only
    (a marker file per parameter set); STAND_IN_SLEEP: seconds per run; STAND_IN_HANG_RANGE "lo,hi":
    sigma_t inside it -> hang (sleep 10 min) on every call; STAND_IN_REJECT: exit 2 with a message, as the
    real simulator does when it cannot find an input file.
    """
    import argparse, hashlib, json, os, sys, time
    import numpy as np
    ap = argparse.ArgumentParser()
    for a in ("--geometry", "--preset", "--record", "--out", "--snapshots"):
        ap.add_argument(a)
    ap.add_argument("--param", action="append", default=[])
    ap.add_argument("--t-end", type=float, default=1.0e-4)
    ap.add_argument("--sample-dt", type=float, default=1.0e-6)
    ap.add_argument("--mesh-seed", type=int, default=None)
    a = ap.parse_args()
    p = {k: float(v) for k, v in (s.split("=") for s in a.param)}
    if os.environ.get("STAND_IN_REJECT"):
        print("python -m shpb simulate: error: " + os.environ["STAND_IN_REJECT"], file=sys.stderr)
        sys.exit(2)
    time.sleep(float(os.environ.get("STAND_IN_SLEEP", "0")))
    st, et = p["sigma_t"], p["E_t"]
    hang = [float(v) for v in os.environ.get("STAND_IN_HANG_RANGE", "1,-1").split(",")]
    if hang[0] < st < hang[1]:
        time.sleep(600.0)
    key = hashlib.md5(repr(sorted(p.items())).encode()).hexdigest()
    crash_below = float(os.environ.get("STAND_IN_CRASH_ONCE_BELOW", "-1"))
    marker = os.path.join(os.environ.get("STAND_IN_MARKERS", "."), key)
    if st < crash_below and not os.path.exists(marker):
        open(marker, "w").close()
        sys.exit("stand-in: simulated crash")
    t = np.arange(0.0, a.t_end + 1e-12, a.sample_dt)
    tau = 5e-6 + 30e-6 * et / 2400.0
    y = np.where(t < 20e-6, 0.8 * st * np.sin(0.5 * np.pi * t / 20e-6) ** 2, 0.8 * st * np.exp(-(t - 20e-6) / tau))
    if a.preset in ("standard", "paper"):
        y = 0.93 * y
    if a.mesh_seed is not None:
        phase = 2.0 * np.pi * np.random.default_rng(a.mesh_seed).random()
        y = y + np.where(t < 20e-6, 0.0, 0.004 * st * np.sin(2.0 * np.pi * (t - 20e-6) / 10e-6 + phase))
    fail = st < float(os.environ.get("STAND_IN_FAIL_BELOW", "-1"))
    os.makedirs(a.out, exist_ok=True)
    cols = ["time_s", "stress_Pa", "stress_front_Pa", "stress_back_Pa", "force_balance", "centre_sxx_Pa",
            "eps_incident_gauge", "eps_transmitted_gauge"]
    with open(os.path.join(a.out, "curve.csv"), "w") as fh:
        fh.write(",".join(cols) + "\\n")
        for ti, yi in zip(t, y):
            fh.write(",".join(repr(float(v)) for v in (ti, yi, yi, yi, 0.0, yi, 0.0, 0.0)) + "\\n")
    run = {"status": "failed" if fail else "ok", "reason": "energy balance diverged (stand-in)" if fail else "",
           "geometry": a.geometry, "preset": a.preset, "params": p, "wall_s": 0.01, "t_end_s": a.t_end}
    with open(os.path.join(a.out, "run.json"), "w") as fh:
        json.dump(run, fh)
    sys.exit(3 if fail else 0)
''')


def write_stand_in(folder: Path) -> str:
    path = folder / "stand_in_simulator.py"
    path.write_text(STAND_IN)
    return f"{sys.executable} {path}"


def snakemake(workdir: Path, *args: str, env: dict | None = None, timeout: float = 600.0):
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(workdir),
           "--configfile", str(workdir / "config.yaml"), "--workflow-profile", "none", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env={**os.environ, **(env or {})})


def write_config(workdir: Path, cfg: dict) -> None:
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))


# --------------------------------------------------------------------------------------------------
# config
# --------------------------------------------------------------------------------------------------
def test_shipped_configs_are_valid():
    from calibration.closing import candidate_effects

    base = load_yaml(REPO / "config" / "config.yaml")
    cfg = validate_config(base, SCHEMA, base_dir=REPO)
    assert set(cfg["run"]) <= set(cfg["experiments"])
    assert cfg["experiments"]["twin_ref"]["observations"]["truth"] == {"sigma_t": 45.0e6, "E_t": 500.0}
    assert cfg["experiments"]["twin_ref"]["ensemble_size"] == 25
    # the reported posterior the coverage benchmark measures (benchmarks/bench_coverage.py)
    assert cfg["experiments"]["twin_ref"]["emulated"]["refine_runs"] == 25
    # the default run closes the loop on measured data: a calibration on two records, one held out, the
    # catalogue's measurement and physical candidates (issue 17)
    # (the whole catalogue less what the config excludes, issue 32)
    loops = [cfg["experiments"][e] for e in cfg["run"] if cfg["experiments"][e].get("diagnosis")]
    assert loops and all(len(x["observations"]["records"]) == 2 and len(x["diagnosis"]["heldout_records"]) == 1
                         and {"face_gap", "closure", "rate_strength", "gauge_gain"}
                         <= set(candidate_effects(x["diagnosis"])) for x in loops)
    twins = load_yaml(REPO / "config" / "paper_twins.yaml")
    merged = {**base, **twins, "experiments": {**base["experiments"], **twins["experiments"]}}
    cfg = validate_config(merged, SCHEMA, base_dir=REPO)
    truths = [cfg["experiments"][e]["observations"].get("truth") for e in cfg["run"]]
    assert len({(t["sigma_t"], t["E_t"]) for t in truths}) == 3  # the paper's three reference points
    diag = load_yaml(REPO / "config" / "diagnosis.yaml")
    merged = {**base, **diag, "experiments": {**base["experiments"], **diag["experiments"]}}
    cfg = validate_config(merged, SCHEMA, base_dir=REPO)
    for e in cfg["run"]:
        d = cfg["experiments"][e]["diagnosis"]
        # every record held out once (validation: loro), the catalogue's candidates incl. end friction
        assert d["validation"] == "loro" and len(cfg["experiments"][e]["observations"]["records"]) >= 4
        assert {"closure", "rate_strength", "gauge_gain", "interface_friction"} <= set(candidate_effects(d))
    # the validation series: records no other shipped config (nor the sandstone box's check) has used
    seen = {Path(r).name for c in (base, diag) for x in c["experiments"].values()
            for r in list(x.get("observations", {}).get("records", [])) + list((x.get("diagnosis") or {}).get("heldout_records", []))}
    series = {}
    for name in ("validation.yaml", "validation_marble.yaml"):
        val = load_yaml(REPO / "config" / name)
        merged = {**base, **val, "experiments": {**base["experiments"], **val["experiments"]}}
        cfg = validate_config(merged, SCHEMA, base_dir=REPO)
        series[name] = {Path(r).name for e in cfg["run"] for r in cfg["experiments"][e]["observations"]["records"]}
        unseen = series[name]
        assert len(unseen) >= 4 and not unseen & seen and not any("SeeSst_SHPB_024" in r for r in unseen)
    assert not series["validation.yaml"] & series["validation_marble.yaml"]
    sens = load_yaml(REPO / "config" / "sensitivity.yaml")
    merged = {**base, **sens, "experiments": {**base["experiments"], **sens["experiments"]}}
    cfg = validate_config(merged, SCHEMA, base_dir=REPO)
    fast = cfg["experiments"]["disc_fast"]
    assert fast["preset"] == "fast" and fast["sensitivity"]["parameters"] == \
        cfg["experiments"]["twin_ref"]["sensitivity"]["parameters"]  # the same boxes as the standard run


@pytest.mark.parametrize("mutate, expected", [
    (lambda c: c["experiments"]["twin"].update(ensemble_sise=8), "experiments.twin: unknown key(s) ['ensemble_sise']"),
    (lambda c: c["experiments"]["twin"].update(method="esmd"), "experiments.twin.method: 'esmd' is not one of"),
    (lambda c: c["experiments"]["twin"]["parameters"].update(E_t=[2400.0, 200.0]), "experiments.twin.parameters.E_t"),
    (lambda c: c["experiments"]["twin"]["parameters"].update(sigma_tt=[1.0, 2.0]), "experiments.twin.parameters.sigma_tt: unknown parameter"),
    (lambda c: c["experiments"]["twin"]["observations"]["truth"].update(E_t=5000.0), "truth.E_t: 5000.0 lies outside the prior box"),
    (lambda c: c["experiments"]["twin"]["observations"].update(t_end=5.0e-4), "experiments.twin.simulation.t_end"),
    (lambda c: c["experiments"]["twin"].update(kind="measured"), "experiments.twin.geometry: measured records"),
    (lambda c: c.update(run=["nope"]), "run: experiment 'nope' is not defined"),
    (lambda c: c["experiments"]["twin"].update(diagnosis={}), "experiments.twin.diagnosis: the discrepancy loop runs on measured"),
    (lambda c: c["experiments"]["twin"].update(diagnosis={"candidates": ["seeting"]}), "experiments.twin.diagnosis.candidates"),
    (lambda c: c.update(member_time_limit_s={"fast": 0}), "member_time_limit_s.fast"),
    (lambda c: c["experiments"]["twin"].update(method="emulated_esmda", ensemble_size=20, emulated={"inner_members": 12}),
     "experiments.twin.emulated.inner_members: 12 is smaller than ensemble_size 20"),
    (lambda c: c["experiments"]["twin"].update(method="emulated_esmda", localization={"E_t": [[0.0, 1.0e-5]]}),
     "experiments.twin.localization: emulated_esmda has no localization"),
    (lambda c: c["experiments"]["twin"].update(emulated={"temper_base": 0.5}), "experiments.twin.emulated.temper_base"),
    (lambda c: c["experiments"]["twin"].update(emulated={"refine_runs": 25}),
     "experiments.twin.emulated.refine_runs: 25 is a setting of the reported emulator posterior, which posterior: ensemble does not use"),
    (lambda c: c["experiments"]["twin"].update(posterior="emulator_mcmc", emulated={"refine_runs": 3}),
     "experiments.twin.emulated.refine_runs: 3 runs cannot measure the emulator's error over 2 parameters; use 0 (none) or at least 4"),
    (lambda c: c["experiments"]["twin"].update(emulated={"refine_temper": 0.5}), "experiments.twin.emulated.refine_temper"),
    (lambda c: c["experiments"]["twin"].update(posterior="emulator_mcmc", emulated={"recalibrate": "location",
                                                                                    "self_calibrate": False}),
     "experiments.twin.emulated.recalibrate: 'location' reads the self-calibration's pseudo-runs under the power "
     "tempering; it needs self_calibrate: true and tempering: power"),
    (lambda c: c["experiments"]["twin"].update(posterior="emulator_mcmc", emulated={"recalibrate": "scale"}),
     "experiments.twin.emulated.recalibrate: 'scale' is not one of"),
    (lambda c: c["experiments"]["twin"].update(method="esmda", esmda={"alphas": [2.0, 3.0]}),
     "experiments.twin.esmda.alphas: sum of 1/alpha must be 1 (got 0.833333)"),
])
def test_a_bad_config_key_or_value_fails_with_a_message_naming_it(mutate, expected):
    cfg = twin_config()
    mutate(cfg)
    with pytest.raises(ConfigError) as err:
        validate_config(cfg, SCHEMA)
    assert expected in str(err.value), str(err.value)


def test_a_nested_number_given_on_the_command_line_is_read_as_a_number():
    from snakemake.cli import parse_config  # what `snakemake --config` does with its arguments
    cfg = twin_config()
    cfg.update(parse_config(['member_time_limit_s={"paper": 14400}']))
    assert cfg["member_time_limit_s"] == {"paper": "14400"}  # Snakemake hands it over as a string
    assert validate_config(cfg, SCHEMA)["member_time_limit_s"]["paper"] == 14400
    cfg.update(parse_config(['member_time_limit_s={"paper": "lots"}']))
    with pytest.raises(ConfigError, match="member_time_limit_s.paper: 'lots' is not of type 'integer'"):
        validate_config(cfg, SCHEMA)


def test_yaml_scientific_notation_strings_are_read_as_numbers_and_defaults_are_filled():
    cfg = twin_config()
    cfg["experiments"]["twin"]["parameters"]["sigma_t"] = ["4.0e6", "60e6"]  # what PyYAML returns for 4.0e6
    out = validate_config(cfg, SCHEMA)
    exp = out["experiments"]["twin"]
    assert exp["parameters"]["sigma_t"] == [4.0e6, 60.0e6]
    assert exp["stopping"]["collapse_fraction"] == 1e-3 and exp["observations"]["noise"]["corr_time"] == 0.0
    assert out["simulator"] == "python -m shpb simulate" and out["member_retries"] == 1


# --------------------------------------------------------------------------------------------------
# observations
# --------------------------------------------------------------------------------------------------
def test_measured_observations_are_the_reduced_stress_with_the_records_noise_level():
    from calibration.observations import reduce_measured_record

    red, _, noise = reduce_measured_record(CAMA005)
    obs, reduced = measured_observations({"CaMa_SHPB_005": CAMA005}, t_start=0.0, t_end=3.2e-4, dt=None)
    n = int(round(3.2e-4 / red.dt)) + 1
    assert obs.m == n and np.allclose(obs.time, red.time[:n], rtol=0, atol=1e-12)
    np.testing.assert_allclose(obs.values, red.stress[:n], rtol=1e-12)
    assert np.all(obs.sigma == red.noise_std_Pa["stress"])
    assert 0.3e6 < red.noise_std_Pa["stress"] < 2e6  # about 0.6 MPa on a 195 MPa peak
    # the AR(1) estimate sees the same pre-trigger samples: same sigma within the ddof difference
    assert noise.sigma == pytest.approx(red.noise_std_Pa["stress"], rel=0.01)
    assert obs.error_model().kind in ("ar1", "diagonal")


def test_a_malformed_observation_file_is_reported_with_its_name_and_problem(tmp_path):
    bad = tmp_path / "CaMa_SHPB_005_truncated.txt"
    lines = CAMA005.read_text(encoding="latin-1").splitlines()
    bad.write_text("\n".join(lines[:200]) + "\n", encoding="latin-1")
    with pytest.raises(ObservationFileError) as err:
        check_record(bad)
    assert str(bad) in str(err.value) and "Blocklength" in str(err.value)
    missing = tmp_path / "nope.txt"
    with pytest.raises(ObservationFileError, match="nope.txt"):
        check_record(missing)


def test_twin_noise_is_fixed_by_the_seed_and_has_the_declared_level():
    t = observation_grid(0.0, 2.0e-4, 1.0e-6)
    truth = pd.DataFrame({"time_s": t, "stress_Pa": 30e6 * np.sin(np.pi * t / 2e-4)})
    a = twin_observations(truth, t, rng=rng_for(1, "noise"), relative_sigma=0.02)
    b = twin_observations(truth, t, rng=rng_for(1, "noise"), relative_sigma=0.02)
    c = twin_observations(truth, t, rng=rng_for(2, "noise"), relative_sigma=0.02)
    assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)
    resid = a.values - truth["stress_Pa"].to_numpy()
    assert a.sigma[0] == pytest.approx(0.02 * 30e6)
    assert np.std(resid) == pytest.approx(0.6e6, rel=0.15)


def test_a_curve_that_does_not_cover_the_grid_is_missing_there():
    t = np.arange(0.0, 50e-6, 1e-6)
    grid = observation_grid(0.0, 80e-6, 2e-6)
    y = curve_on_grid(t, 2.0 * t, grid)
    assert np.allclose(y[grid <= 49e-6], 2.0 * grid[grid <= 49e-6])
    assert np.all(np.isnan(y[grid > 50e-6]))
    assert np.all(np.isnan(curve_on_grid([], [], grid)))


def test_observation_files_round_trip_and_bad_ones_are_named(tmp_path):
    t = observation_grid(0.0, 1e-4, 1e-6)
    truth = pd.DataFrame({"time_s": t, "stress_Pa": 1e6 * t / 1e-4})
    obs = twin_observations(truth, t, rng=rng_for(0, "noise"), relative_sigma=0.01)
    obs.write(tmp_path / "obs.csv", tmp_path / "obs.json")
    back = read_observations(tmp_path / "obs.csv", tmp_path / "obs.json")
    assert np.array_equal(back.values, obs.values) and back.records == ["synthetic"]
    lines = (tmp_path / "obs.csv").read_text().splitlines()
    cells = lines[4].split(",")
    cells[2] = "oops"  # stress_Pa of data row 4
    lines[4] = ",".join(cells)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ObservationFileError, match=r"bad.csv: column 'stress_Pa' is not a finite number"):
        read_observations(tmp_path / "bad.csv", tmp_path / "obs.json")


# --------------------------------------------------------------------------------------------------
# one member run and its exit codes
# --------------------------------------------------------------------------------------------------
def test_member_exit_codes_numerical_failure_is_recorded_and_a_crash_is_retried_then_recorded(tmp_path):
    cmd = write_stand_in(tmp_path).split()
    common = dict(command=cmd, geometry="brazilian_disc", preset="fast", t_end=5e-5, sample_dt=1e-6)
    ok = run_member(params={"sigma_t": 30e6, "E_t": 500.0}, curve_path=tmp_path / "ok/curve.csv",
                    run_path=tmp_path / "ok/run.json", **common)
    assert ok["status"] == "ok" and len(pd.read_csv(tmp_path / "ok/curve.csv")) == 51
    os.environ["STAND_IN_FAIL_BELOW"] = "1e7"
    try:
        bad = run_member(params={"sigma_t": 5e6, "E_t": 500.0}, curve_path=tmp_path / "bad/curve.csv",
                         run_path=tmp_path / "bad/run.json", log_path=tmp_path / "bad/log", **common)
    finally:
        del os.environ["STAND_IN_FAIL_BELOW"]
    assert bad["status"] == "failed" and bad["reason"].startswith("numerical failure: energy balance diverged")
    assert json.loads((tmp_path / "bad/run.json").read_text())["exit_code"] == 3
    assert pd.read_csv(tmp_path / "bad/curve.csv").empty
    crash = [sys.executable, "-c", "import sys; sys.exit('boom')"]
    with pytest.raises(Exception, match="exited with code 1"):
        run_member(command=crash, geometry="brazilian_disc", preset="fast", params={"sigma_t": 1.0},
                   curve_path=tmp_path / "c/curve.csv", run_path=tmp_path / "c/run.json", attempt=1, max_attempts=2)
    assert not (tmp_path / "c/run.json").exists()
    last = run_member(command=crash, geometry="brazilian_disc", preset="fast", params={"sigma_t": 1.0},
                      curve_path=tmp_path / "c/curve.csv", run_path=tmp_path / "c/run.json", attempt=2,
                      max_attempts=2)
    assert last["status"] == "failed" and "crashed on every attempt" in last["reason"] and "boom" in last["reason"]
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["curve.csv", "manifest.json", "run.json"]  # no temp
    # exit 2 (arguments rejected, an input missing) is a configuration error: the job fails with the
    # simulator's message and nothing is left behind, so that a re-run after the fix runs the member
    os.environ["STAND_IN_REJECT"] = "rock properties file data/x.xlsx not found"
    try:
        with pytest.raises(SimulatorRejected, match="exit code 2.*rock properties file data/x.xlsx not found"):
            run_member(params={"sigma_t": 30e6, "E_t": 500.0}, curve_path=tmp_path / "rej/curve.csv",
                       run_path=tmp_path / "rej/run.json", **common)
    finally:
        del os.environ["STAND_IN_REJECT"]
    assert not (tmp_path / "rej").exists() or list((tmp_path / "rej").iterdir()) == []


# --------------------------------------------------------------------------------------------------
# the workflow (snakemake --cores 2)
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", [{"method": "esmda", "esmda": {"steps": 1}, "ensemble_size": 6},
                                    {"method": "emulated_esmda", "max_iterations": 2, "emulated": {"inner_members": 100}}],
                         ids=["esmda", "emulated_esmda"])
def test_workflow_runs_end_to_end_and_a_second_run_has_nothing_to_do(tmp_path, method):
    """ES-MDA runs the real simulator at the fast preset, N = 6 and one analysis (two ensembles); the
    emulated variant runs the analytic stand-in, N = 8 and two analyses (three ensembles; the same jobs,
    files and checks; the emulator's own accuracy is tested in test_enkf_emulated.py). Sized so that
    the suite stays inside its 15 minutes: the loop's length is the emulated variant's to test."""
    cfg = twin_config(**method)
    n, analyses = cfg["experiments"]["twin"]["ensemble_size"], 1 if method["method"] == "esmda" else 2
    if method["method"] == "emulated_esmda":
        cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    t0 = time.time()
    first = snakemake(tmp_path, "--cores", "2")
    assert first.returncode == 0, first.stderr[-4000:]
    wall = time.time() - t0
    res = tmp_path / "results" / "twin"
    for k in range(analyses + 1):
        assert (res / f"iter_{k}" / "params.csv").is_file()
        assert (res / f"iter_{k}" / "analysis.json").is_file()
        for m in member_ids(n):
            assert (res / f"iter_{k}" / "members" / m / "synthetic" / "curve.csv").is_file()
            run = json.loads((res / f"iter_{k}" / "members" / m / "synthetic" / "run.json").read_text())
            assert run["preset"] == "fast" and "status" in run
    assert not (res / f"iter_{analyses + 1}").exists()
    for name in ("posterior.csv", "forecast/synthetic/curve.csv", "forecast/synthetic/run.json", "summary.json",
                 "observations/obs.csv", *(f"plots/{p}.png" for p in ("parameters", "ensemble_curves", "forecast",
                                                                       "misfit", "sensitivity"))):
        assert (res / name).is_file(), name
    summary = json.loads((res / "summary.json").read_text())
    for key in ("experiment", "iterations", "converged", "stop_reason", "n_simulations", "posterior", "truth",
                "misfit", "wall_s"):
        assert key in summary, key
    import numpy
    import scipy
    # the libraries that made the posterior: another version may move it
    assert summary["environment"]["numpy"] == numpy.__version__ and summary["environment"]["scipy"] == scipy.__version__
    assert summary["iterations"] == analyses and summary["stop_reason"] == "max_iterations" or summary["converged"]
    # n members and 3 replicates per ensemble, the truth and the forecast
    assert summary["n_simulations"] == (analyses + 1) * (n + 3) + 1 + 1
    for k in range(analyses + 1):
        for r in member_ids(3):
            run = json.loads((res / f"iter_{k}" / "replicates" / r / "synthetic" / "run.json").read_text())
            assert run.get("mesh_seed") is not None or method["method"] == "emulated_esmda"  # the stand-in writes none
    assert summary["simulator_variability"]["n_replicates"] == 3
    assert summary["simulator_variability"]["rms_Pa"] > 0.0
    assert summary["misfit"][-1]["rmse_Pa"] < summary["misfit"][0]["rmse_Pa"]
    assert summary["misfit"][-1]["chi2_per_obs"] < summary["misfit"][0]["chi2_per_obs"]
    assert set(summary["posterior"]) == {"sigma_t", "E_t"}
    v = summary["verdict"]
    assert "worse_than_prior" not in v["flags"] and v["next_step"]
    assert v["chi2_per_obs"]["final"] == summary["misfit"][-1]["median_chi2_per_obs"]
    assert ("not_converged" in v["flags"]) == (not summary["converged"])
    assert v["verdict"] != "ok" or summary["converged"]
    assert set(summary["predictive_coverage_90"]) == {"synthetic"}
    assert 0.0 <= summary["predictive_coverage_90"]["synthetic"] <= 1.0
    assert summary["posterior_ensemble_info"]["iteration"] == summary["posterior_iteration"]
    print(f"\nend-to-end fast workflow: {wall:.0f} s; misfit per iteration "
          f"{[round(m['rmse_Pa'] / 1e6, 2) for m in summary['misfit']]} MPa; posterior "
          f"{ {p: round(v['mean'], 1) for p, v in summary['posterior'].items()} }")
    second = snakemake(tmp_path, "--cores", "2")
    assert second.returncode == 0, second.stderr[-4000:]
    assert "Nothing to be done" in second.stdout + second.stderr


def test_a_failed_member_is_retried_then_dropped_with_its_reason_in_analysis_json(tmp_path):
    cfg = twin_config(ensemble_size=10, esmda={"steps": 1})
    cfg["simulator"] = write_stand_in(tmp_path)
    cfg["member_time_limit_s"] = {"fast": 5}
    write_config(tmp_path, cfg)
    lhs = validate_config(cfg, SCHEMA)
    p0 = initial_ensemble(ExperimentSpec.from_config("twin", lhs["experiments"]["twin"]))
    sig = np.sort(p0["sigma_t"].to_numpy())
    fail_below = 0.5 * (sig[0] + sig[1])  # exactly one member fails numerically
    crash_below = 0.5 * (sig[1] + sig[2])  # and the two lowest crash once (retried, then fine for one)
    hang = (0.5 * (sig[2] + sig[3]), 0.5 * (sig[3] + sig[4]))  # one member hangs on every attempt
    (tmp_path / "markers").mkdir()
    env = {"STAND_IN_FAIL_BELOW": repr(float(fail_below)), "STAND_IN_CRASH_ONCE_BELOW": repr(float(crash_below)),
           "STAND_IN_MARKERS": str(tmp_path / "markers"), "STAND_IN_HANG_RANGE": f"{float(hang[0])!r},{float(hang[1])!r}"}
    t0 = time.time()
    out = snakemake(tmp_path, "--cores", "2", env=env)
    assert out.returncode == 0, out.stderr[-4000:]
    assert time.time() - t0 < 300  # the hanging member was stopped at its 5 s limit, not after 10 min
    a0 = json.loads((tmp_path / "results/twin/iter_0/analysis.json").read_text())
    failed_member = int(p0["member"][p0["sigma_t"] < fail_below].iloc[0])
    crashed_once = int(p0["member"][(p0["sigma_t"] > fail_below) & (p0["sigma_t"] < crash_below)].iloc[0])
    hung = int(p0["member"][(p0["sigma_t"] > hang[0]) & (p0["sigma_t"] < hang[1])].iloc[0])
    assert a0["n_alive"] == 8 and a0["alive"][failed_member] is False and a0["alive"][hung] is False
    reasons = {f["member"]: f["reason"] for f in a0["failed_members"]}
    assert sorted(reasons) == sorted([failed_member, hung])
    assert "energy balance diverged (stand-in)" in reasons[failed_member]
    assert "time limit: the simulation ran longer than 5 s" in reasons[hung]
    assert sorted(a0["update"]["replaced_members"]) == sorted([failed_member, hung])
    run = json.loads((tmp_path / f"results/twin/iter_0/members/{crashed_once:03d}/synthetic/run.json").read_text())
    assert run["status"] == "ok" and run["attempt"] == 2  # crashed on attempt 1, Snakemake retried it
    summary = json.loads((tmp_path / "results/twin/summary.json").read_text())
    assert sorted(f["member"] for f in summary["failed_members"]["0"]) == sorted([failed_member, hung])


def test_a_rejected_argument_fails_the_run_and_a_rerun_after_the_fix_runs_those_members(tmp_path):
    """Exit code 2 of the simulator (a missing input, a rejected argument) is not a failed member: the
    run stops with the simulator's message and stores nothing for those members, so the re-run after
    the cause is fixed simulates them and finishes (a stored failed member would refuse again)."""
    cfg = twin_config(ensemble_size=4, esmda={"steps": 1})
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    first = snakemake(tmp_path, "--cores", "2", env={"STAND_IN_REJECT": "measured record data/missing.txt not found"})
    assert first.returncode != 0
    assert "exit code 2" in first.stderr and "measured record data/missing.txt not found" in first.stderr
    members = tmp_path / "results/twin/iter_0/members"
    assert not list(members.glob("*/synthetic/run.json")) if members.exists() else True
    # the re-run up to the first analysis: what is under test ends there (the rest of the loop is
    # test_workflow_runs_end_to_end's)
    fixed = snakemake(tmp_path, "--cores", "2", "results/twin/iter_0/analysis.json")
    assert fixed.returncode == 0, fixed.stderr[-4000:]
    runs = [json.loads(p.read_text()) for p in members.glob("*/synthetic/run.json")]
    assert len(runs) == 4 and all(r["status"] == "ok" for r in runs)
    a0 = json.loads((tmp_path / "results/twin/iter_0/analysis.json").read_text())
    assert a0["n_alive"] == 4 and a0["failed_members"] == []


def test_a_killed_run_resumes_without_redoing_finished_members(tmp_path):
    cfg = twin_config(ensemble_size=12, esmda={"steps": 1})
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--directory", str(tmp_path),
           "--configfile", str(tmp_path / "config.yaml"), "--workflow-profile", "none", "--cores", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "STAND_IN_SLEEP": "1.5"}, start_new_session=True)
    members = tmp_path / "results/twin/iter_0/members"
    deadline = time.time() + 240
    while time.time() < deadline and len(list(members.glob("*/synthetic/run.json"))) < 4:
        time.sleep(0.2)
    # members finished (and registered by Snakemake) well before the kill; the jobs still running then
    # (at most 2) are redone, as they must be. Identity by inode: every write is a new file renamed into
    # place, while Snakemake touches (re-dates) a job's outputs when it registers the job as finished.
    done = {p: p.stat().st_ino for p in members.glob("*/synthetic/run.json")}
    time.sleep(2.0)
    os.killpg(proc.pid, signal.SIGKILL)  # the whole process group, as a hard kill of the terminal would
    proc.wait()
    assert 4 <= len(done) < 12, len(done)
    assert len(list(members.glob("*/synthetic/run.json"))) < 12, "the run finished before it was killed"
    unlock = snakemake(tmp_path, "--unlock")
    assert unlock.returncode == 0, unlock.stderr[-2000:]
    # resumed up to the analysis of the interrupted ensemble: the rest of the loop is not under test here
    again = snakemake(tmp_path, "--cores", "2", "--rerun-incomplete", "results/twin/iter_0/analysis.json")
    assert again.returncode == 0, again.stderr[-4000:]
    for p, inode in done.items():
        assert p.stat().st_ino == inode, f"{p} was simulated again"
    assert len(list(members.glob("*/synthetic/run.json"))) == 12
    assert json.loads((tmp_path / "results/twin/iter_0/analysis.json").read_text())["n_alive"] == 12


def test_a_malformed_observation_file_fails_before_the_first_simulation(tmp_path):
    bad = tmp_path / "CaMa_SHPB_099_bad.txt"
    bad.write_text("\n".join(CAMA005.read_text(encoding="latin-1").splitlines()[:300]) + "\n", encoding="latin-1")
    cfg = {"experiments": {"marble": {
        "kind": "measured", "geometry": "cylinder", "preset": "fast", "seed": 1, "ensemble_size": 4,
        "parameters": {"sigma_t": [1.0e7, 1.2e8], "E_t": [100.0, 5000.0]},
        "simulation": {"t_end": 3.4e-4}, "observations": {"t_end": 3.2e-4, "records": [str(bad)]}}}}
    write_config(tmp_path, cfg)
    out = snakemake(tmp_path, "--cores", "2")
    assert out.returncode != 0
    assert str(bad) in out.stderr and "Blocklength" in out.stderr
    assert not (tmp_path / "results").exists()


def test_every_shipped_config_dry_runs_from_a_fresh_clone_with_nothing_beside_it(tmp_path):
    """A clone of the committed repository in an empty folder (nothing beside it, no FDEM_DATA_DIR), its own
    code first on the path: every shipped config passes its dry run there, and a dry run reads and reduces
    every record of every experiment the config defines (the Snakefile's check before any job) and
    resolves every job's input. A data file the product needs but did not commit fails here, before CI's
    own fresh clone runs the workflow and this suite (.ci/run). (Uncommitted changes are not in the clone:
    commit before relying on it.)"""
    if not (REPO / ".git").exists():
        pytest.fail(f"{REPO} is not a git checkout: this test clones it to prove a fresh clone runs")
    clone = tmp_path / "empty" / "fdem-enkf-shpb"
    subprocess.run(["git", "clone", "--quiet", str(REPO), str(clone)], check=True, timeout=120)
    assert sorted(p.name for p in clone.parent.iterdir()) == ["fdem-enkf-shpb"]
    env = {k: v for k, v in os.environ.items() if k != "FDEM_DATA_DIR"}
    env["PYTHONPATH"] = str(clone)
    configs = sorted(p.name for p in (clone / "config").glob("*.yaml") if p.name != "schema.yaml")
    assert {"config.yaml", "diagnosis.yaml", "own_data.yaml", "validation.yaml"} <= set(configs)
    for name in configs:
        out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "2", "--configfile",
                              f"config/{name}"], cwd=clone, capture_output=True, text=True, timeout=300, env=env)
        assert out.returncode == 0, (name, (out.stdout + out.stderr)[-3000:])
        assert "member" in out.stdout, name
    assert not (clone / "results").exists() and not (clone.parent / "shared").exists()

