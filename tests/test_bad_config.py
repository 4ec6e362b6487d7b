"""Bad numbers in a config are refused before any job, as the Snakefile validates it (issue 56).

Each case starts from a shipped config (config/config.yaml, or it merged with another config/*.yaml),
changes one thing in a user's ``--configfile`` (mine.yaml), and checks that ``validate_config`` with
``sources=`` raises ConfigError naming the key path, the value, what was expected (range or type) and
the file that set it: NaN and infinities anywhere (a schema's ``minimum`` lets NaN through), values
outside the simulator's bounds (shpb.parameters.bounds), magnitudes no rock or test has (unit slips,
with the likely slip), and ensembles too small for emulated_esmda when members fail.
"""
from __future__ import annotations

import copy
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from snakemake.utils import update_config

from calibration.config_files import config_sources
from calibration.config_ranges import emulator_min_runs, survivors_needed
from calibration.workflow_io import ConfigError, validate_config

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"
SHIPPED = sorted(p.name for p in (REPO / "config").glob("*.yaml") if p.name not in ("config.yaml", "schema.yaml"))
NAN, INF = math.nan, math.inf

# (other shipped file or None, experiment (None: top level), change, key under the experiment,
#  value as shown, expected range or type as shown, likely slip or None)
CASES = [
    # NaN and infinities, anywhere
    (None, "twin_ref", {"fixed": {"sigma_n": NAN}}, "fixed.sigma_n", "nan", "expected a finite number", None),
    (None, "twin_ref", {"fixed": {"sigma_n": INF}}, "fixed.sigma_n", "inf", "expected a finite number", None),
    (None, "twin_ref", {"fixed": {"E_t": -INF}}, "fixed.E_t", "-inf", "expected a finite number", None),
    (None, "twin_ref", {"observations": {"noise": {"relative_sigma": NAN}}}, "observations.noise.relative_sigma",
     "nan", "expected a finite number", None),
    (None, "twin_ref", {"observations": {"dt": NAN}}, "observations.dt", "nan", "expected a finite number", None),
    (None, "twin_ref", {"simulation": {"t_end": NAN}}, "simulation.t_end", "nan", "expected a finite number", None),
    (None, "twin_ref", {"parameters": {"sigma_t": [NAN, 6e7]}}, "parameters.sigma_t", "item 0 is nan",
     "expected a finite number", None),
    (None, "twin_ref", {"observations": {"truth": {"E_t": INF}}}, "observations.truth.E_t", "inf",
     "expected a finite number", None),
    (None, "twin_ref", {"emulated": {"temper_base": NAN}}, "emulated.temper_base", "nan", "expected a finite number", None),
    (None, "twin_ref", {"stopping": {"chi2_target": INF}}, "stopping.chi2_target", "inf", "expected a finite number", None),
    (None, "twin_ref", {"inflation": NAN}, "inflation", "nan", "expected a finite number", None),
    (None, "marble_loop", {"esmda": {"alphas": [2.0, NAN]}}, "esmda.alphas", "item 1 is nan", "expected a finite number", None),
    (None, "marble_loop", {"observations": {"error": {"sigma_scale": NAN}}}, "observations.error.sigma_scale", "nan",
     "expected a finite number", None),
    (None, "marble_loop", {"diagnosis": {"alpha": NAN}}, "diagnosis.alpha", "nan", "expected a finite number", None),
    (None, "marble_loop", {"localization": {"E_t": [[0.0, NAN]]}}, "localization.E_t", "item 0: item 1 is nan",
     "expected a finite number", None),
    ("paper_twins.yaml", "twin_b", {"observations": {"truth": {"sigma_t": NAN}}}, "observations.truth.sigma_t", "nan",
     "expected a finite number", None),
    ("paper_twins.yaml", "twin_c", {"parameters": {"E_t": [200.0, INF]}}, "parameters.E_t", "item 1 is inf",
     "expected a finite number", None),
    ("validation_marble.yaml", "marble_unseen", {"fixed": {"rho": NAN}}, "fixed.rho", "nan", "expected a finite number", None),
    # the simulator's own bounds (shpb.parameters.bounds)
    (None, "twin_ref", {"fixed": {"sigma_n": -5.0e6}}, "fixed.sigma_n", "-5e+06", "expected > 0 and < inf", None),
    (None, "twin_ref", {"fixed": {"phi_deg": 95.0}}, "fixed.phi_deg", "95", "expected >= 0 and < 89", None),
    (None, "twin_ref", {"parameters": {"sigma_t": [-1.0e7, 6.0e7]}}, "parameters.sigma_t", "-1e+07",
     "expected > 0 and < inf", None),
    (None, "twin_ref", {"fixed": {"nu": 0.6}}, "fixed.nu", "0.6", "expected > -1 and < 0.5", None),
    (None, "twin_ref", {"fixed": {"damping.beta": 1.5}}, "fixed.damping.beta", "1.5", "expected >= 0 and < 1", None),
    (None, "twin_ref", {"fixed": {"penalty_factor": 2.0}}, "fixed.penalty_factor", "2", "expected > 3 and < inf", None),
    (None, "twin_ref", {"sensitivity": {"parameters": {"interface_friction.mu": [0.0, 6.0]}}},
     "sensitivity.parameters.interface_friction.mu", "6", "expected >= 0.0 and < 5.0", None),
    (None, "twin_ref", {"sensitivity": {"parameters": {"a": [-0.3, 0.9]}}}, "sensitivity.parameters.a", "-0.3",
     "expected > 0.0 and < inf", None),
    (None, "marble_loop", {"diagnosis": {"physical_upper": {"rate_strength.k": 3.0}}},
     "diagnosis.physical_upper.rate_strength.k", "3", "expected >= 0 and < 2", None),
    (None, "marble_loop", {"fixed": {"closure.range_m": -1.0e-4}}, "fixed.closure.range_m", "-0.0001",
     "expected >= 0 and < 0.002", None),
    (None, "marble_loop", {"fixed": {"face_gap.gap_m": 50.0}}, "fixed.face_gap.gap_m", "50",
     "expected >= 0 and < 0.002", "did you mean 50 um = 5e-05 m?"),
    ("diagnosis.yaml", "marble_loro", {"diagnosis": {"physical_upper": {"interface_friction.mu": 50.0}}},
     "diagnosis.physical_upper.interface_friction.mu", "50", "expected >= 0 and < 5", None),
    ("validation_marble.yaml", "marble_unseen", {"fixed": {"nu": -1.5}}, "fixed.nu", "-1.5", "expected > -1 and < 0.5", None),
    ("sensitivity.yaml", "disc_fast", {"sensitivity": {"parameters": {"mu_crack": [0.5, 7.0]}}},
     "sensitivity.parameters.mu_crack", "7", "expected >= 0.0 and < 5.0", None),
    # magnitudes no rock or test has: unit slips
    (None, "twin_ref", {"parameters": {"sigma_t": [20.0, 60.0]}}, "parameters.sigma_t", "20",
     "expected [100000, 1e+09] Pa", "did you mean 20 MPa = 2e+07 Pa?"),
    (None, "twin_ref", {"parameters": {"E_t": [0.2, 2.4]}}, "parameters.E_t", "0.2", "expected [1, 1e+06] J/m^2",
     "did you mean 0.2 kJ/m^2 = 200 J/m^2?"),
    (None, "twin_ref", {"observations": {"truth": {"sigma_n": 20.0}}}, "observations.truth.sigma_n", "20",
     "expected [100000, 1e+09] Pa", "did you mean 20 MPa = 2e+07 Pa?"),
    (None, "twin_ref", {"fixed": {"E": 35.0}}, "fixed.E", "35", "expected [1e+09, 2e+11] Pa", "did you mean 35 GPa = 3.5e+10 Pa?"),
    (None, "twin_ref", {"fixed": {"rho": 2.55}}, "fixed.rho", "2.55", "expected [1000, 5000] kg/m^3",
     "did you mean 2.55 g/cm^3 = 2550 kg/m^3?"),
    (None, "twin_ref", {"fixed": {"rho": 25500.0}}, "fixed.rho", "25500", "expected [1000, 5000] kg/m^3", None),
    (None, "twin_ref", {"fixed": {"E_n": 5.0e7}}, "fixed.E_n", "5e+07", "expected [1, 1e+06] J/m^2", None),
    (None, "twin_ref", {"observations": {"t_end": 160.0}}, "observations.t_end", "160", "expected [1e-06, 0.01] s",
     "did you mean 160 us = 0.00016 s?"),
    (None, "twin_ref", {"simulation": {"t_end": 160.0}}, "simulation.t_end", "160", "expected [1e-06, 0.01] s",
     "did you mean 160 us = 0.00016 s?"),
    (None, "twin_ref", {"observations": {"dt": 1.0}}, "observations.dt", "1", "expected [1e-09, 0.0001] s",
     "did you mean 1 us = 1e-06 s?"),
    (None, "twin_ref", {"simulation": {"sample_dt": 0.5}}, "simulation.sample_dt", "0.5", "expected [1e-09, 0.0001] s",
     "did you mean 0.5 us = 5e-07 s?"),
    (None, "twin_ref", {"observations": {"t_start": 20.0}}, "observations.t_start", "20", "expected [0, 0.01] s",
     "did you mean 20 us = 2e-05 s?"),
    (None, "twin_ref", {"observations": {"noise": {"relative_sigma": 2.0}}}, "observations.noise.relative_sigma", "2",
     "expected [1e-06, 0.5]", "did you mean 2 % = 0.02?"),
    (None, "twin_ref", {"observations": {"noise": {"relative_sigma": 1.0}}}, "observations.noise.relative_sigma", "1",
     "expected [1e-06, 0.5]", "did you mean 1 % = 0.01?"),
    (None, "twin_ref", {"observations": {"noise": {"sigma_Pa": 0.5}}}, "observations.noise.sigma_Pa", "0.5",
     "expected [1000, 1e+08] Pa", "did you mean 0.5 MPa = 500000 Pa?"),
    (None, "twin_ref", {"observations": {"noise": {"corr_time": 5.0}}}, "observations.noise.corr_time", "5",
     "expected [0, 0.01] s", "did you mean 5 us = 5e-06 s?"),
    (None, "marble_loop", {"localization": {"sigma_t": [[0.0, 100.0]]}}, "localization.sigma_t", "100",
     "expected [0, 0.01] s", "did you mean 100 us = 0.0001 s?"),
    (None, "marble_loop", {"parameters": {"E_t": [100.0, 5.0e7]}}, "parameters.E_t", "5e+07", "expected [1, 1e+06] J/m^2", None),
    (None, "marble_loop", {"observations": {"t_end": 0.36}}, "observations.t_end", "0.36", "expected [1e-06, 0.01] s",
     "did you mean 0.36 ms = 0.00036 s?"),
    (None, "marble_loop", {"observations": {"dt": 2.0}}, "observations.dt", "2", "expected [1e-09, 0.0001] s",
     "did you mean 2 us = 2e-06 s?"),
    (None, "marble_loop", {"fixed": {"sigma_n": 10.0}}, "fixed.sigma_n", "10", "expected [100000, 1e+09] Pa",
     "did you mean 10 MPa = 1e+07 Pa?"),
    ("diagnosis.yaml", "sandstone_loro", {"parameters": {"sigma_t": [4.0, 60.0]}}, "parameters.sigma_t", "4",
     "expected [100000, 1e+09] Pa", "did you mean 4 MPa = 4e+06 Pa?"),
    ("sensitivity.yaml", "disc_fast", {"sensitivity": {"parameters": {"E_n": [0.05, 0.2]}}}, "sensitivity.parameters.E_n",
     "0.05", "expected [1, 1e+06] J/m^2", "did you mean 0.05 kJ/m^2 = 50 J/m^2?"),
    ("own_data.yaml", "granite_own", {"fixed": {"E": 3.5e13}}, "fixed.E", "3.5e+13", "expected [1e+09, 2e+11] Pa", None),
    ("validation.yaml", "sandstone_unseen", {"observations": {"dt": -2.0e-6}}, "observations.dt", "-2e-06",
     "less than or equal to the minimum of 0", None),
    ("sensitivity.yaml", "disc_fast", {"observations": {"noise": {"relative_sigma": 0.0}}},
     "observations.noise.relative_sigma", "0", "less than or equal to the minimum of 0", None),
    (None, None, {"member_time_limit_s": {"paper": 10000000}}, "member_time_limit_s.paper", "1e+07",
     "expected [1, 604800] s", None),
    (None, None, {"member_time_limit_s": {"fast": 0.5}}, "member_time_limit_s.fast", "0.5", "is not of type 'integer'", None),
    # emulated_esmda's emulator needs n_params + 2 runs, also after the failures the policy tolerates
    (None, "twin_ref", {"ensemble_size": 3}, "ensemble_size", "3 members", "expected ensemble_size >= 7", None),
    (None, "twin_ref", {"ensemble_size": 4}, "ensemble_size", "4 members", "expected ensemble_size >= 7", None),
    (None, "twin_ref", {"ensemble_size": 6}, "ensemble_size", "6 members", "expected ensemble_size >= 7", None),
    (None, "twin_ref", {"ensemble_size": 25, "min_alive_fraction": 0.1}, "ensemble_size",
     "25 members with min_alive_fraction 0.1", "expected ensemble_size >= 31", None),
    ("own_data.yaml", "granite_own", {"ensemble_size": 5}, "ensemble_size", "5 members", "expected ensemble_size >= 7", None),
    ("paper_twins.yaml", "twin_b", {"ensemble_size": 2}, "ensemble_size", "2 is less than the minimum of 3",
     "minimum of 3", None),
]


@pytest.fixture(autouse=True, scope="module")
def _imports_loaded():
    """The validation's lazy imports (the sensitivity checks load pandas, SciPy and enkf), loaded before
    the timings as the Snakefile has them loaded (calibration.observations) when it validates."""
    import calibration.closing  # noqa: F401
    import calibration.sensitivity  # noqa: F401


def _merged(sources) -> dict:
    """The config as Snakemake hands it to the Snakefile: the files deep-merged in order."""
    merged: dict = {}
    for _, data in sources:
        update_config(merged, copy.deepcopy(data))
    return merged


def _sources(extra: str | None, change: dict | None = None, tmp_path: Path | None = None):
    paths = [REPO / "config" / "config.yaml"] + ([REPO / "config" / extra] if extra else [])
    if change is not None:
        (tmp_path / "mine.yaml").write_text(yaml.safe_dump(change))
        paths.append(tmp_path / "mine.yaml")
    return config_sources(paths)


@pytest.mark.parametrize("extra, exp, change, key, value, expected, slip", CASES,
                         ids=[f"{c[1]}.{c[3]}={c[4]}" for c in CASES])
def test_a_bad_number_is_refused_naming_key_value_range_and_file(tmp_path, monkeypatch, extra, exp, change, key,
                                                                 value, expected, slip):
    monkeypatch.chdir(tmp_path)  # mine.yaml is named relative to the working folder
    change = change if exp is None else {"experiments": {exp: change}}
    sources = _sources(extra, change, tmp_path)
    start = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        validate_config(_merged(sources), SCHEMA, base_dir=REPO, sources=sources)
    elapsed = time.perf_counter() - start
    full = key if exp is None else f"experiments.{exp}.{key}"
    lines = [ln for ln in str(err.value).splitlines() if ln.startswith(f"  - {full}: ")]
    assert lines, str(err.value)
    line = next((ln for ln in lines if value in ln and expected in ln), None)
    assert line is not None, str(err.value)
    assert line.endswith("(set in mine.yaml)"), line
    if slip:
        assert slip in line, line
    assert elapsed < 3.0


def test_the_cases_are_distinct_and_at_least_fifty():
    keys = {(c[0], c[1], yaml.safe_dump(c[2])) for c in CASES}
    assert len(keys) == len(CASES) >= 50


@pytest.mark.parametrize("extra", [None] + SHIPPED)
def test_every_shipped_config_still_validates_quickly(extra, monkeypatch):
    monkeypatch.chdir(REPO)
    sources = _sources(extra)
    start = time.perf_counter()
    cfg = validate_config(_merged(sources), SCHEMA, base_dir=REPO, sources=sources)
    assert time.perf_counter() - start < 3.0
    assert cfg["experiments"]


def test_nan_given_on_the_command_line_is_refused_naming_config():
    from snakemake.cli import parse_config  # what `snakemake --config` does with its arguments

    overrides = parse_config(['experiments={"twin_ref": {"fixed": {"sigma_n": "nan"}}}'])
    sources = config_sources([REPO / "config" / "config.yaml"], overrides=overrides)
    with pytest.raises(ConfigError) as err:
        validate_config(_merged(sources), SCHEMA, base_dir=REPO, sources=sources)
    assert ("experiments.twin_ref.fixed.sigma_n: nan is not a finite number (expected a finite number) "
            "(set in --config)") in str(err.value)


# --------------------------------------------------------------------------------------------------
# the failed-member path at the smallest ensemble validation accepts for emulated_esmda
# --------------------------------------------------------------------------------------------------
def test_the_smallest_accepted_emulated_ensemble_goes_on_past_failures_or_stops_saying_why():
    """Two parameters: the emulator needs 4 runs; with min_alive_fraction 0.5 the analysis goes on with
    ceil(N / 2) survivors, so 7 members is the smallest ensemble validation accepts (6 would go on with 3
    runs and stop at the emulator with a bare error). At 7, one and three failed members leave enough
    runs and the analysis draws a full next ensemble; four stop it with EnsembleFailure naming them."""
    from enkf import EnsembleFailure
    from calibration.experiment import ExperimentSpec, analysis_step, initial_ensemble, rng_for
    from calibration.observations import observation_grid, twin_observations
    from test_workflow import twin_config

    assert emulator_min_runs(2) == 4 and survivors_needed(7, 0.5) == 4 and survivors_needed(6, 0.5) == 3
    with pytest.raises(ConfigError, match="ensemble_size: 6 members with min_alive_fraction 0.5"):
        validate_config(twin_config(ensemble_size=6, method="emulated_esmda", max_iterations=2), SCHEMA)
    cfg = validate_config(twin_config(ensemble_size=7, method="emulated_esmda", max_iterations=2,
                                      emulated={"inner_members": 40, "inner_steps": 2}), SCHEMA)
    spec = ExperimentSpec.from_config("twin", cfg["experiments"]["twin"])
    t = observation_grid(0.0, 1e-4, 2e-6)

    def model(P):
        P = np.atleast_2d(P)
        return P[:, :1] * np.sin(np.pi * t / 1e-4) + 1e4 * P[:, 1:2] * (t / 1e-4)

    obs = twin_observations(pd.DataFrame({"time_s": t, "stress_Pa": model(np.array([45e6, 500.0]))[0]}), t,
                            rng=rng_for(spec.seed, "noise"), relative_sigma=0.01)
    params = initial_ensemble(spec)
    Y0 = model(params[list(spec.names)].to_numpy())
    for n_failed in (1, 3, 4):
        Y = Y0.copy()
        Y[:n_failed] = np.nan
        status = pd.DataFrame({"member": params["member"], "status": "ok", "reason": ""})
        status.loc[:n_failed - 1, ["status", "reason"]] = ["failed", "numerical failure: energy balance diverged"]
        if n_failed == 4:
            with pytest.raises(EnsembleFailure, match=r"only 3 of 7 members succeeded \(need 4"):
                analysis_step(spec, 0, params, Y, status, obs, params)
            continue
        a = analysis_step(spec, 0, params, Y, status, obs, params)
        assert a["n_alive"] == 7 - n_failed and a["update"]["design_points"] == 7 - n_failed
        assert np.array(a["next_params"]["values"]).shape == (7, 2)
        assert np.all(np.isfinite(a["next_params"]["values"]))
