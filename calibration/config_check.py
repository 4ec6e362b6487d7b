"""Config validation of the calibration workflow: the schema and the checks a schema cannot express.

* :func:`validate_config` checks the workflow config against ``config/schema.yaml`` (JSON Schema),
  fills in the schema's defaults and adds the checks a schema cannot express (prior box, truth inside
  the box, observation window inside the simulated window, records exist and their test sheets are
  valid, the diagnosis block, the sensitivity blocks ...) and the numbers' checks of
  :mod:`calibration.config_ranges` (finite, the simulator's bounds, plausible magnitudes, each method's
  smallest ensemble). Every problem is reported in one
  :class:`ConfigError` whose message names the key (``experiments.<name>.<key>``) and, given the
  merged files (:func:`calibration.config_files.config_sources`), the config file that set it.
* :func:`coerce_yaml_floats`: YAML 1.1's ``4.0e6`` (a string) read as a number.

Nothing here imports Snakemake (the ``Snakefile`` calls :func:`validate_config` before any job runs).
"""

from __future__ import annotations

import copy
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

from shpb.lab.sheet import is_sheet
from .contracts import ConfigError, known_parameters, record_name
from .config_files import coerce_numbers, config_sources, error_origin, load_config_file, safe_load  # noqa: F401
from .config_ranges import nonfinite_errors, range_errors

__all__ = ["ConfigError", "load_yaml", "load_config_file", "config_sources", "validate_config", "apply_defaults",
           "coerce_yaml_floats"]

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")


def load_yaml(path: str | Path) -> dict:
    with open(path) as fh:
        return safe_load(fh.read())


def _key(path: Sequence) -> str:
    return ".".join(str(p) for p in path) if path else "<top level>"


def apply_defaults(instance, schema: Mapping):
    """Fill in the ``default`` of every schema property missing from ``instance`` (recursively, also
    through ``additionalProperties`` and array ``items``). Returns a new object."""
    kind = schema.get("type")
    # an object that may also be null (``type: [object, "null"]``) gets its defaults where it is given
    if isinstance(instance, dict) and (kind in ("object", None) or (isinstance(kind, list) and "object" in kind)):
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


#: settings that only the reported emulator posterior reads (posterior: emulator_mcmc)
_EMULATOR_POSTERIOR_ONLY = ("self_calibrate", "emulator_error", "tempering", "recalibrate", "refine_runs",
                            "refine_temper")


def _posterior_option_errors(config: Mapping, schema: Mapping) -> list[str]:
    """Settings of the emulator posterior written beside ``posterior: ensemble`` would silently do nothing.
    Checked on the config as written, before the schema's defaults (which set them for every experiment);
    an experiment without ``posterior`` gets the schema's default."""
    default = schema["properties"]["experiments"]["additionalProperties"]["properties"]["posterior"]["default"]
    errors = []
    for name, exp in (config.get("experiments") or {}).items():
        em = exp.get("emulated") or {}
        if exp.get("posterior", default) != "ensemble":
            if em.get("recalibrate", "none") != "none" and (em.get("self_calibrate") is False
                                                             or em.get("tempering", "power") != "power"):
                errors.append(f"experiments.{name}.emulated.recalibrate: {em['recalibrate']!r} reads the "
                              "self-calibration's pseudo-runs under the power tempering; it needs self_calibrate: "
                              "true and tempering: power")
            continue
        for key in _EMULATOR_POSTERIOR_ONLY:
            if key in (exp.get("emulated") or {}):
                errors.append(f"experiments.{name}.emulated.{key}: {exp['emulated'][key]!r} is a setting of the "
                              f"reported emulator posterior, which posterior: ensemble does not use; drop it or use "
                              f"posterior: emulator_mcmc")
    return errors


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
        emulated = exp.get("emulated") or {}
        if 0 < emulated.get("refine_runs", 0) < len(params) + 2 and not auto:
            errors.append(f"{where}.emulated.refine_runs: {emulated['refine_runs']} runs cannot measure the "
                          f"emulator's error over {len(params)} parameters; use 0 (none) or at least {len(params) + 2}")
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
        errors += _approximation_errors(where, exp)
        method = exp.get("method")
        if method == "esmda" and exp.get("esmda", {}).get("alphas") is not None:
            total = math.fsum(1.0 / float(a) for a in exp["esmda"]["alphas"])  # the schema has alphas > 0
            if abs(total - 1.0) > 1e-6:
                errors.append(f"{where}.esmda.alphas: sum of 1/alpha must be 1 (got {total:.6g})")
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
    from .diagnosis_config import candidate_effects

    offered = candidate_effects(diag)
    for key in diag.get("physical_upper") or {}:
        if key.split(".")[0] not in offered:
            errors.append(f"{where}.diagnosis.physical_upper.{key}: not a parameter of an offered candidate")
    for key in diag.get("scopes") or {}:
        if key not in offered:
            errors.append(f"{where}.diagnosis.scopes.{key}: not an offered candidate")
    if diag.get("realrun_selection") is not None:
        # each calibration record is predicted from the others, on several mesh realizations
        n = len(obs.get("records") or []) - (1 if diag.get("validation") == "loro" else 0)
        if n < 2:
            errors.append(f"{where}.diagnosis.realrun_selection: needs at least 2 calibration records (each is "
                          f"predicted from the fit on the others), got {n}")
        if (exp.get("simulation") or {}).get("mesh_realizations") == "shared":
            errors.append(f"{where}.diagnosis.realrun_selection: compares runs over mesh realizations, but "
                          f"simulation.mesh_realizations is 'shared' (one mesh); set it to 'per_run'")
        res = diag["realrun_selection"].get("resolution")
        own = exp.get("preset")
        if res and own in PRESET_ORDER and PRESET_ORDER.index(res["preset"]) <= PRESET_ORDER.index(own):
            errors.append(f"{where}.diagnosis.realrun_selection.resolution.preset: {res['preset']!r} is not finer "
                          f"than the experiment's preset {own!r} (presets from coarse to fine: {list(PRESET_ORDER)}); "
                          f"set a finer one or resolution: null")
    if diag.get("validation") == "loro":
        if held:
            errors.append(f"{where}.diagnosis.heldout_records: with validation loro every record of "
                          f"observations.records is held out once; list no others")
        if len(obs.get("records") or []) < 3:
            errors.append(f"{where}.diagnosis.validation: loro needs at least 3 records (each fold calibrates "
                          f"on the others), got {len(obs.get('records') or [])}")
    return errors


#: The presets from coarse to fine (shpb.presets).
PRESET_ORDER = ("fast", "standard", "paper")


def _approximation_errors(where: str, exp: Mapping) -> list[str]:
    block = ((exp.get("observations") or {}).get("model_error") or {}).get("approximation_error") or {}
    pairs = block.get("pairs") or 0
    key = f"{where}.observations.model_error.approximation_error"
    if not pairs:
        return []
    if pairs < 3:
        return [f"{key}.pairs: {pairs} pairs cannot give a mean and a scatter; use at least 3 (or 0 for off)"]
    fine, own = block.get("preset"), exp.get("preset")
    if fine is None:
        return [f"{key}.preset: pairs > 0 needs the finer preset to compare with ({list(PRESET_ORDER[1:])})"]
    if exp.get("parameters") == "auto":
        return [f"{key}: the pairs' design spans the prior box, which parameters: auto leaves to the sensitivity "
                f"stage; name the parameters and their boxes"]
    subtracted = block.get("coarse_variability", "subtracted") == "subtracted"
    if subtracted and block.get("coarse_realizations", 2) < 2:
        return [f"{key}.coarse_realizations: coarse_variability: subtracted measures the coarse model's own "
                f"variability from its realizations at each design point; use at least 2 (or coarse_variability: counted)"]
    if subtracted and exp["observations"]["model_error"].get("simulator_replicates") == 0:
        # subtracted leaves the data's own mesh variability to S; with S not measured nothing would count it
        return [f"{key}.coarse_variability: subtracted takes the coarse mesh's variability off the pairs because "
                f"S carries it, but {where}.observations.model_error.simulator_replicates is 0 (S not measured); "
                f"measure S (simulator_replicates >= 2) or use coarse_variability: counted"]
    if own in PRESET_ORDER and PRESET_ORDER.index(fine) <= PRESET_ORDER.index(own):
        return [f"{key}.preset: {fine!r} is not finer than the experiment's preset {own!r} "
                f"(presets from coarse to fine: {list(PRESET_ORDER)})"]
    return []


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
    # NaN passes a schema's minimum (every comparison with it is false): refused first, anywhere
    errors = nonfinite_errors(cfg) + _schema_errors(cfg, schema)
    if not errors:
        errors = _posterior_option_errors(cfg, schema)
    if not errors:
        cfg = apply_defaults(cfg, schema)
        errors = _semantic_errors(cfg, Path(base_dir)) + range_errors(cfg)
        if not errors:
            from .sensitivity import config_errors as sensitivity_errors  # on call: it loads pandas
            errors = sensitivity_errors(cfg)
    if errors:
        if sources:
            errors = [e + error_origin(e, sources) for e in errors]
        raise ConfigError(f"invalid workflow config ({source}):\n  - " + "\n  - ".join(errors))
    return cfg
