"""File contracts of the calibration workflow: config validation, atomic writes, member runs.

The Snakemake workflow (``Snakefile``, ``rules/*.smk``) names files and calls ``scripts/*.py``; the
scripts call this module, :mod:`calibration.observations`, :mod:`calibration.experiment` and :mod:`calibration.plots`.
Nothing here imports Snakemake.

* :func:`validate_config` checks the workflow config against ``config/schema.yaml`` (JSON Schema),
  fills in the schema's defaults and adds the checks a schema cannot express (prior box, truth inside
  the box, observation window inside the simulated window, records exist ...). Every problem is
  reported in one :class:`ConfigError` whose message names the key (``experiments.<name>.<key>``)
  and, given the merged files (:func:`calibration.config_files.config_sources`), the config file
  that set it.
* :func:`atomic_write_text`, :func:`atomic_write_json`, :func:`atomic_write_csv`: temporary file in the
  destination folder, then ``os.replace``, so that "the file exists" means "the file is complete"
  (Snakemake reuses existing outputs of later checkpoint iterations without checking them).
* :func:`run_member`: one ``python -m shpb simulate`` run of an ensemble member with the exit-code
  contract 0 = ok, 3 = numerical failure (``run.json`` says why), 2 = bad arguments; writes the member's
  ``curve.csv`` and ``run.json`` atomically whatever happened, except for a genuine crash before the
  last attempt, which raises so that Snakemake retries the job.

Units are SI everywhere (docs/workflow.md, "What goes where").
"""

from __future__ import annotations


import copy
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

# the base contracts, re-exported: the scripts and tests import them from here
from shpb.contract import CURVE_COLUMNS as _SIM_CURVE_COLUMNS, EXIT_BAD_INPUT, EXIT_NUMERICAL, EXIT_OK
from shpb.lab.sheet import is_sheet
from .contracts import (PARAM_NAMES, ConfigError, atomic_write_csv, atomic_write_json,  # noqa: F401
                        atomic_write_text, experiment_records, known_parameters, read_json, record_name)
from .config_files import coerce_numbers, config_sources, error_origin, load_config_file  # noqa: F401

__all__ = [
    "PARAM_NAMES", "CURVE_COLUMNS", "ConfigError", "SimulatorCrash", "load_yaml", "load_config_file",
    "config_sources", "validate_config",
    "apply_defaults", "atomic_write_text", "atomic_write_json", "atomic_write_csv", "read_json",
    "member_ids", "record_name", "experiment_records", "run_member", "simulator_command",
    "simulate_argv", "failed_curve_text", "member_params", "combine_member_runs", "write_responses",
    "read_responses", "known_parameters", "coerce_yaml_floats",
]

#: Columns of a simulated curve: the simulator's own definition (``python -m shpb simulate`` contract),
#: so that a failed member's header cannot drift from a successful member's.
CURVE_COLUMNS = tuple(_SIM_CURVE_COLUMNS)

#: Default simulator command: the package's command-line entry.
DEFAULT_SIMULATOR = "python -m shpb simulate"

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")


class SimulatorCrash(RuntimeError):
    """The simulator ended without the exit-code contract (crash, kill, missing outputs)."""


class SimulatorRejected(RuntimeError):
    """The simulator refused its arguments or could not find its input (exit code 2): a configuration
    error, not a property of the member's parameters. The job fails with the simulator's message and
    leaves no output, so a re-run after the fix runs it again."""


# --------------------------------------------------------------------------------------------------
# Atomic writes
# --------------------------------------------------------------------------------------------------
# --------------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------------
def load_yaml(path: str | Path) -> dict:
    import yaml

    with open(path) as fh:
        return yaml.safe_load(fh)


def _key(path: Sequence) -> str:
    return ".".join(str(p) for p in path) if path else "<top level>"


def apply_defaults(instance, schema: Mapping):
    """Fill in the ``default`` of every schema property missing from ``instance`` (recursively, also
    through ``additionalProperties`` and array ``items``). Returns a new object."""
    if isinstance(instance, dict) and schema.get("type") in ("object", None):
        out = dict(instance)
        props = schema.get("properties", {})
        for key, sub in props.items():
            if key not in out and "default" in sub:
                out[key] = copy.deepcopy(sub["default"])
            if key in out:
                out[key] = apply_defaults(out[key], sub)
        extra = schema.get("additionalProperties")
        if isinstance(extra, dict):
            for key in out:
                if key not in props:
                    out[key] = apply_defaults(out[key], extra)
        return out
    if isinstance(instance, list) and isinstance(schema.get("items"), dict):
        return [apply_defaults(v, schema["items"]) for v in instance]
    return instance


def _schema_errors(config, schema) -> list[str]:
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema)
    messages = []
    for err in sorted(validator.iter_errors(config), key=lambda e: [str(p) for p in e.absolute_path]):
        where = _key(list(err.absolute_path))
        if err.validator == "additionalProperties":
            allowed = sorted(err.schema.get("properties", {}))
            extra = sorted(set(err.instance) - set(allowed)) if isinstance(err.instance, dict) else []
            messages.append(f"{where}: unknown key(s) {extra}; allowed keys: {allowed}")
        else:
            messages.append(f"{where}: {err.message}")
    return messages


def _semantic_errors(config: Mapping, base: Path) -> list[str]:
    errors: list[str] = []
    exps = config.get("experiments", {})
    for name, exp in exps.items():
        where = f"experiments.{name}"
        if not _NAME_RE.match(name):
            errors.append(f"{where}: experiment names must match {_NAME_RE.pattern} (they become folder names)")
        params = exp.get("parameters", {})
        known = known_parameters(exp.get("geometry", ""))
        # calibration.sensitivity.AUTO: the candidates are the sensitivity boxes (checked with that block)
        auto = params == "auto"
        if auto:
            params = (exp.get("sensitivity") or {}).get("parameters") or {}
            if not params:
                errors.append(f"{where}.parameters: auto calibrates what the sensitivity stage recommends; "
                              f"the experiment needs a sensitivity block with its candidate parameters and boxes")
        for p, box in ({} if auto else params).items():
            if p not in known:
                errors.append(f"{where}.parameters.{p}: unknown parameter; the simulator knows {list(known)}")
            lo, hi = box
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                errors.append(f"{where}.parameters.{p}: prior box [{lo}, {hi}] must have lower < upper")
        for p in exp.get("fixed", {}):
            if p not in known:
                errors.append(f"{where}.fixed.{p}: unknown parameter; the simulator knows {list(known)}")
            if p in params:
                errors.append(f"{where}.fixed.{p}: also listed under parameters (estimated); choose one")
        n_members = exp.get("ensemble_size", 0)
        if params and n_members <= len(params) and not auto:
            errors.append(f"{where}.ensemble_size: {n_members} members cannot span {len(params)} parameters; "
                          f"use more than {len(params)}")
        obs = exp.get("observations", {})
        sim = exp.get("simulation", {})
        t0, t1 = obs.get("t_start", 0.0), obs.get("t_end")
        if t1 is not None and t1 <= t0:
            errors.append(f"{where}.observations: t_end ({t1}) must exceed t_start ({t0})")
        if t1 is not None and sim.get("t_end") is not None and sim["t_end"] < t1:
            errors.append(f"{where}.simulation.t_end ({sim['t_end']}) must cover the observation window "
                          f"(observations.t_end = {t1})")
        if t1 is not None and obs.get("dt") is not None and (t1 - t0) / obs["dt"] < 5:
            errors.append(f"{where}.observations.dt ({obs['dt']}) gives fewer than 5 observations in the window")
        if exp.get("kind") == "twin":
            truth = obs.get("truth")
            if truth is None:
                errors.append(f"{where}.observations.truth: a twin experiment needs the reference parameters")
            else:
                missing = sorted(set(params) - set(truth))
                if missing:
                    errors.append(f"{where}.observations.truth: no reference value for {missing}")
                for p, v in truth.items():
                    if p not in known:
                        errors.append(f"{where}.observations.truth.{p}: unknown parameter")
                    elif p in params and not params[p][0] < v < params[p][1]:
                        errors.append(f"{where}.observations.truth.{p}: {v} lies outside the prior box {params[p]}")
            if obs.get("records"):
                errors.append(f"{where}.observations.records: a twin experiment takes no measured records "
                              f"(a cylinder twin takes its incident wave from observations.incident_record)")
            inc = obs.get("incident_record")
            if exp.get("geometry") == "cylinder" and not inc:
                errors.append(f"{where}.observations.incident_record: a cylinder twin needs a raw record "
                              f"for its incident wave")
            if exp.get("geometry") == "brazilian_disc" and inc:
                errors.append(f"{where}.observations.incident_record: only the cylinder takes a measured "
                              f"incident wave; the Brazilian disc is loaded by the simulator's pulse")
            if inc:
                p = Path(inc) if Path(inc).is_absolute() else base / inc
                if not p.is_file():
                    errors.append(f"{where}.observations.incident_record: file not found: {inc} (looked at {p})")
        elif exp.get("kind") == "measured":
            recs = obs.get("records") or []
            if exp.get("geometry") != "cylinder" and not (recs and all(is_sheet(r) for r in recs)):
                errors.append(f"{where}.geometry: measured records of a Brazilian disc must be test sheets "
                              f"whose specimen.geometry is brazilian_disc (a Freiburg raw file is a cylinder); "
                              f"use 'cylinder' or name the records' sheets")
            errors += _record_errors(where, exp, obs.get("records") or [], base)
            for key in ("truth", "incident_record"):
                if obs.get(key) is not None:
                    errors.append(f"{where}.observations.{key}: only twin experiments take it")
        errors += _diagnosis_errors(where, exp, obs, base)
        method = exp.get("method")
        if method == "esmda" and exp.get("esmda", {}).get("alphas") is not None:
            alphas = np.asarray(exp["esmda"]["alphas"], float)
            if abs(np.sum(1.0 / alphas) - 1.0) > 1e-6:
                errors.append(f"{where}.esmda.alphas: sum of 1/alpha must be 1 (got {np.sum(1.0 / alphas):.6g})")
        if method == "emulated_esmda":
            inner = exp["emulated"]["inner_members"]  # the schema's default is filled in before these checks
            if inner < exp.get("ensemble_size", 0):
                errors.append(f"{where}.emulated.inner_members: {inner} is smaller than ensemble_size "
                              f"{exp['ensemble_size']} (the next ensemble is drawn from the inner ES-MDA's members)")
            if exp.get("localization"):
                errors.append(f"{where}.localization: emulated_esmda has no localization (the emulator "
                              f"models the whole curve); remove it or use method esmda/enkf")
        loc = exp.get("localization") or {}
        for p in loc:
            if p not in params:
                errors.append(f"{where}.localization.{p}: not an estimated parameter ({sorted(params)})")
    for name in config.get("run", []) or []:
        if name not in exps:
            errors.append(f"run: experiment {name!r} is not defined under experiments ({sorted(exps)})")
    return errors


def _record_errors(where: str, exp: Mapping, records: Sequence, base: Path) -> list[str]:
    """A measured experiment's records: listed, once each, found, named safely for a Snakemake wildcard
    (the name is a folder of every member), and a test sheet valid with its signals readable and its
    specimen the experiment's geometry (shpb.lab.sheet: each problem names the sheet, field, expectation)."""
    from shpb.lab.sheet import WILDCARD_SAFE, SheetError, is_sheet
    from shpb.lab.sheet_readers import check_sheet

    errors = []
    if not records:
        errors.append(f"{where}.observations.records: list at least one raw record file or test sheet")
    names = [record_name(r) for r in records]
    for dup in sorted({n for n in names if names.count(n) > 1}):
        errors.append(f"{where}.observations.records: record {dup!r} listed twice")
    for r in records:
        p = Path(r) if Path(r).is_absolute() else base / r
        if not WILDCARD_SAFE.match(record_name(r)):
            errors.append(f"{where}.observations.records: the record name {record_name(r)!r} (from {r}) is not safe "
                          f"as a Snakemake wildcard and folder name; expected letters, digits, '_', '.', '-' "
                          f"and no spaces: rename the file")
        if not p.is_file():
            errors.append(f"{where}.observations.records: file not found: {r} (looked at {p})")
        elif is_sheet(p):
            try:
                sheet, _ = check_sheet(p)
            except SheetError as exc:
                errors += [f"{where}.observations.records: {line}" for line in exc.problems]
                continue
            if sheet.geometry != exp.get("geometry"):
                errors.append(f"{where}.observations.records: {p}: specimen.geometry is {sheet.geometry!r} but "
                              f"the experiment's geometry is {exp.get('geometry')!r}")
    return errors


_YAML11_FLOAT = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)[eE][+-]?\d+$")


def _diagnosis_errors(where: str, exp: Mapping, obs: Mapping, base: Path) -> list[str]:
    """The semantic checks of an experiment's ``diagnosis`` block."""
    diag = exp.get("diagnosis")
    errors: list[str] = []
    if diag is None:
        return errors
    if exp.get("kind") != "measured":
        errors.append(f"{where}.diagnosis: the discrepancy loop runs on measured experiments (a twin "
                      f"knows its model; the planted-effect tests cover twins)")
    held = diag.get("heldout_records") or []
    calib = {record_name(r) for r in obs.get("records") or []}
    for r in held:
        p = Path(r) if Path(r).is_absolute() else base / r
        if not p.is_file():
            errors.append(f"{where}.diagnosis.heldout_records: file not found: {r} (looked at {p})")
        if record_name(r) in calib:
            errors.append(f"{where}.diagnosis.heldout_records: {record_name(r)} is also a calibration "
                          f"record; held-out data must not be used to calibrate")
    for key in diag.get("physical_upper") or {}:
        if key.split(".")[0] not in (diag.get("candidates") or []):
            errors.append(f"{where}.diagnosis.physical_upper.{key}: not a parameter of a listed candidate")
    for key in diag.get("scopes") or {}:
        if key not in (diag.get("candidates") or []):
            errors.append(f"{where}.diagnosis.scopes.{key}: not a listed candidate")
    return errors


def coerce_yaml_floats(obj):
    """Turn strings such as ``"4.0e6"`` or ``"1e-6"`` into floats, recursively.

    PyYAML (YAML 1.1, what Snakemake reads configs with) takes ``4.0e6`` as a *string*: its float
    pattern wants a dot and a signed exponent (``4.0e+6``). Only strings that are exactly a number in
    scientific notation are converted, so paths and names are left alone.
    """
    if isinstance(obj, dict):
        return {k: coerce_yaml_floats(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [coerce_yaml_floats(v) for v in obj]
    if isinstance(obj, str) and _YAML11_FLOAT.match(obj.strip()):
        return float(obj)
    return obj


def validate_config(config: Mapping, schema: Mapping | str | Path, *, base_dir: str | Path = ".",
                    source: str = "config", sources: Sequence[tuple[str, Mapping]] | None = None) -> dict:
    """Validate the workflow config and return a copy with the schema's defaults filled in.

    ``sources``: the config files merged into ``config`` (:func:`config_sources`); the message then
    names them instead of ``source``, and after each problem the file that sets that key.

    Raises
    ------
    ConfigError
        Listing every schema violation and semantic problem, each prefixed with its key path
        (e.g. ``experiments.twin_ref.method: 'esmd' is not one of ['esmda', 'enkf']``).
    """
    if sources:
        source = " + ".join(name for name, _ in sources)
    if not isinstance(schema, Mapping):
        schema = load_yaml(schema)
    if not isinstance(config, Mapping):
        raise ConfigError(f"{source}: the config must be a mapping, got {type(config).__name__}")
    try:
        cfg = coerce_yaml_floats(json.loads(json.dumps(config)))  # plain dicts and lists
        cfg = coerce_numbers(cfg, schema)
    except TypeError as exc:
        raise ConfigError(f"{source}: a value is not plain YAML data (numbers, strings, lists, maps): {exc}") from exc
    errors = _schema_errors(cfg, schema)
    if not errors:
        cfg = apply_defaults(cfg, schema)
        errors = _semantic_errors(cfg, Path(base_dir))
        if not errors:
            from .sensitivity import config_errors as sensitivity_errors  # it imports this module
            errors = sensitivity_errors(cfg)
    if errors:
        if sources:
            errors = [e + error_origin(e, sources) for e in errors]
        raise ConfigError(f"invalid workflow config ({source}):\n  - " + "\n  - ".join(errors))
    return cfg


# --------------------------------------------------------------------------------------------------
# Members
# --------------------------------------------------------------------------------------------------
def member_ids(n_members: int) -> list[str]:
    """Folder names of the members: ``000``, ``001``, ... (three digits, more if needed)."""
    width = max(3, len(str(n_members - 1)))
    return [f"{i:0{width}d}" for i in range(n_members)]


def simulator_command(spec: str | Sequence[str] | None = None) -> list[str]:
    """The simulator command as an argv prefix (default ``python -m shpb simulate`` with this Python)."""
    if spec is None or spec == DEFAULT_SIMULATOR:
        return [sys.executable, "-m", "shpb", "simulate"]
    return shlex.split(spec) if isinstance(spec, str) else [str(s) for s in spec]


def simulate_argv(command: Sequence[str], *, geometry: str, preset: str, params: Mapping[str, float],
                  out_dir: str | Path, record: str | None = None, t_end: float | None = None,
                  sample_dt: float | None = None, snapshots: int | None = None) -> list[str]:
    """The argv of one simulation (the ``python -m shpb simulate`` contract)."""
    argv = list(command) + ["--geometry", geometry, "--preset", preset]
    if record:
        argv += ["--record", str(record)]
    for name, value in params.items():
        argv += ["--param", f"{name}={float(value)!r}"]
    if t_end is not None:
        argv += ["--t-end", repr(float(t_end))]
    if sample_dt is not None:
        argv += ["--sample-dt", repr(float(sample_dt))]
    if snapshots is not None:
        argv += ["--snapshots", str(int(snapshots))]
    return argv + ["--out", str(out_dir)]


def failure_card(path, text: str):
    """A picture saying why a run has no fracture snapshots (:func:`shpb.snapshots.failure_card`; imported
    here on call, so that member jobs do not load matplotlib)."""
    from shpb.snapshots import failure_card as card

    return card(path, text)


def failed_curve_text() -> str:
    """The curve file of a failed member: the contract's header and no rows (all values missing)."""
    return ",".join(CURVE_COLUMNS) + "\n"


def _tail(text: str, n: int = 1500) -> str:
    text = (text or "").strip()
    return text if len(text) <= n else "..." + text[-n:]


def run_member(*, command: Sequence[str], geometry: str, preset: str, params: Mapping[str, float],
               curve_path: str | Path, run_path: str | Path, record: str | None = None,
               t_end: float | None = None, sample_dt: float | None = None, attempt: int = 1,
               max_attempts: int = 1, log_path: str | Path | None = None, extra_run: Mapping | None = None,
               time_limit_s: float | None = None, snapshots: int | None = None) -> dict:
    """Run one simulation and leave ``curve_path`` and ``run_path`` behind, atomically.

    Exit code 0: the simulator's ``curve.csv``/``run.json`` are moved into place. Exit code 3 (numerical
    failure, e.g. an unstable run): the member is failed -- the simulation is deterministic, so running
    it again cannot help -- and a ``run.json`` with ``status: "failed"`` and the reason plus an empty
    curve are written; the analysis drops it. Exit code 2 (arguments rejected, an input file missing):
    a configuration error, raised as :class:`SimulatorRejected` with the simulator's message and no
    output written, so the Snakemake job fails and a re-run after the fix runs the member again (a
    stored failed member would make the analysis refuse on every re-run). Any other outcome (crash,
    signal, missing outputs) is a :class:`SimulatorCrash`: raised while ``attempt < max_attempts`` so
    that Snakemake's ``retries`` re-run the job, recorded as a failed member on the last attempt.

    ``time_limit_s``: the simulator is killed after this wall time and the member is failed at once
    (``reason`` starts with ``time limit``). The limit sits below the job's scheduler wall time, so a
    member that runs too long is dropped under the failed-member policy instead of being killed by
    Slurm on every attempt, which would stop the whole run.

    ``snapshots``: a count of fracture snapshots (``--snapshots``); their folder is moved next to the
    curve, replacing an older one, before the curve and run.json.

    Returns the ``run.json`` dict written.
    """
    curve_path, run_path = Path(curve_path), Path(run_path)
    out = curve_path.parent
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".sim-", dir=out))
    argv = simulate_argv(command, geometry=geometry, preset=preset, params=params, out_dir=tmp, record=record,
                         t_end=t_end, sample_dt=sample_dt, snapshots=snapshots)
    t0 = time.perf_counter()
    try:
        try:
            proc = _run_with_limit(argv, time_limit_s)
        except subprocess.TimeoutExpired as exc:
            return _timed_out(exc, argv=argv, wall=time.perf_counter() - t0, geometry=geometry, preset=preset,
                              params=params, curve_path=curve_path, run_path=run_path, log_path=log_path,
                              extra=dict(extra_run or {}, attempt=attempt, exit_code=None))
        wall = time.perf_counter() - t0
        if log_path is not None:
            atomic_write_text(log_path, f"$ {shlex.join(argv)}\n# exit code {proc.returncode}, "
                                        f"attempt {attempt}/{max_attempts}, {wall:.1f} s\n"
                                        f"--- stdout\n{proc.stdout}\n--- stderr\n{proc.stderr}\n")
        run_json, curve_csv = tmp / "run.json", tmp / "curve.csv"
        extra = dict(extra_run or {}, attempt=attempt, exit_code=proc.returncode)
        if proc.returncode == EXIT_OK and run_json.is_file() and curve_csv.is_file():
            run = read_json(run_json)
            run.update(extra)
            if (tmp / "snapshots").is_dir():
                shutil.rmtree(out / "snapshots", ignore_errors=True)
                os.replace(tmp / "snapshots", out / "snapshots")
            os.replace(curve_csv, curve_path)
            atomic_write_json(run_path, _jsonable(run))
            return run
        if proc.returncode == EXIT_BAD_INPUT:
            raise SimulatorRejected(f"the simulator rejected its arguments or input (exit code 2): "
                                    f"{_tail(proc.stderr, 600) or 'no message'}\n  command: {shlex.join(argv)}")
        if proc.returncode == EXIT_NUMERICAL:
            run = read_json(run_json) if run_json.is_file() else {}
            reason = run.get("reason") or _tail(proc.stderr) or f"exit code {proc.returncode}"
            run.update({"status": "failed", "reason": f"numerical failure: {reason}", "geometry": geometry,
                        "preset": preset, "params": dict(params)}, **extra)
            run.setdefault("wall_s", wall)
            atomic_write_text(curve_path, failed_curve_text())
            atomic_write_json(run_path, _jsonable(run))
            return run
        what = (f"simulator exited with code {proc.returncode}" if proc.returncode >= 0
                else f"simulator killed by signal {-proc.returncode}")
        if proc.returncode == 0:
            what = "simulator exited 0 but did not write curve.csv and run.json"
        message = f"{what} (attempt {attempt} of {max_attempts}): {_tail(proc.stderr, 600)}"
        if attempt < max_attempts:
            raise SimulatorCrash(message)
        run = {"status": "failed", "reason": f"crashed on every attempt: {message}", "geometry": geometry,
               "preset": preset, "params": dict(params), "wall_s": wall, **extra}
        atomic_write_text(curve_path, failed_curve_text())
        atomic_write_json(run_path, _jsonable(run))
        return run
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _run_with_limit(argv, time_limit_s):
    """subprocess.run(argv, capture_output=True, text=True) that kills the simulator at the time limit
    and does not then wait for processes it may have started that still hold its pipes."""
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        try:
            out, err = proc.communicate(timeout=time_limit_s)
        except subprocess.TimeoutExpired as exc:
            proc.kill()
            try:
                exc.stdout, exc.stderr = proc.communicate(timeout=10.0)
            except subprocess.TimeoutExpired:
                pass
            raise
        except BaseException:
            proc.kill()
            raise
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def _timed_out(exc: subprocess.TimeoutExpired, *, argv, wall, geometry, preset, params, curve_path, run_path,
               log_path, extra) -> dict:
    """The failed member of a simulation stopped by ``time_limit_s`` (subprocess.run killed it)."""
    def text(b):
        return b.decode(errors="replace") if isinstance(b, bytes) else (b or "")
    if log_path is not None:
        atomic_write_text(log_path, f"$ {shlex.join(argv)}\n# killed after the time limit of {exc.timeout:g} s\n"
                                    f"--- stdout\n{text(exc.stdout)}\n--- stderr\n{text(exc.stderr)}\n")
    run = {"status": "failed", "geometry": geometry, "preset": preset, "params": dict(params), "wall_s": wall,
           "reason": f"time limit: the simulation ran longer than {exc.timeout:g} s (member_time_limit_s) "
                     f"and was stopped", **extra}
    atomic_write_text(curve_path, failed_curve_text())
    atomic_write_json(run_path, _jsonable(run))
    return run


# --------------------------------------------------------------------------------------------------
# Ensemble files
# --------------------------------------------------------------------------------------------------
def member_params(params_csv: str | Path, member: str | int, fixed: Mapping[str, float] | None = None) -> dict:
    """The simulator parameters of one member: its row of ``params.csv`` plus the fixed parameters."""
    import csv

    with open(params_csv, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if int(r["member"]) == int(member)]
    if len(rows) != 1:
        raise KeyError(f"{params_csv}: member {member} not found")
    values = {c: float(v) for c, v in rows[0].items() if c != "member"}
    return {**(fixed or {}), **values}


def combine_member_runs(runs: Mapping[str, Mapping]) -> dict:
    """One member's status over its records (``{record: run.json}``): ok only if every record is ok."""
    failed = {rec: r for rec, r in runs.items() if r.get("status") != "ok"}
    reason = "; ".join(f"{rec}: {r.get('reason') or 'failed'}" for rec, r in failed.items())
    wall = sum(float(r.get("wall_s") or 0.0) for r in runs.values())
    return {"status": "failed" if failed else "ok", "reason": reason, "wall_s": wall}


def write_responses(path: str | Path, members: Sequence[int], status: Sequence[Mapping], Y: np.ndarray) -> Path:
    """``iter_<k>/responses.csv``: one row per member, ``member, status, reason, wall_s`` and the curve
    on the observation grid as ``y_0 ... y_{m-1}`` (the order of ``obs.csv``; empty = missing)."""
    import pandas as pd

    Y = np.asarray(Y, float)
    head = pd.DataFrame({"member": [int(m) for m in members], "status": [s["status"] for s in status],
                         "reason": [s.get("reason", "") for s in status],
                         "wall_s": [float(s.get("wall_s") or 0.0) for s in status]})
    body = pd.DataFrame(Y, columns=[f"y_{j}" for j in range(Y.shape[1])])
    return atomic_write_csv(pd.concat([head, body], axis=1), path)


def read_responses(path: str | Path):
    """``(status frame [member, status, reason, wall_s], Y (N, m))`` from :func:`write_responses`."""
    import pandas as pd

    df = pd.read_csv(path, keep_default_na=True)
    ycols = [c for c in df.columns if c.startswith("y_")]
    status = df[["member", "status", "reason", "wall_s"]].copy()
    status["reason"] = status["reason"].fillna("").astype(str)
    return status, df[ycols].to_numpy(float)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj
