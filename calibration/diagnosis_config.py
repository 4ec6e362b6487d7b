"""An experiment's ``diagnosis`` block read without the inference: whether the experiment runs the
diagnosis (:func:`diagnosis_settings`), the effects it offers (:func:`candidate_effects`) and its
leave-one-record-out folds (:func:`loro_folds`) and a record's position in its series
(:func:`series_position`).

The ``Snakefile`` and ``rules/*.smk`` call these while Snakemake parses the workflow, before any job
runs, so this module imports no NumPy-heavy inference: :mod:`calibration.closing` and
:mod:`calibration.experiment`, which re-export the three, import :mod:`enkf` and SciPy's stats, about
1.5 s of every dry run's start (issue 54; tests/test_dry_run_imports.py).
"""
from __future__ import annotations

from collections.abc import Mapping

from shpb import effects as fx

from .contracts import experiment_records, record_name

__all__ = ["FOLD_SEPARATOR", "SELECTION_MODELS", "candidate_effects", "design_mesh_point", "design_size", "diagnosis_settings", "loro_folds",
           "selection_model", "series_position"]

#: What the selection re-calibrates on (``diagnosis.selection_model``): ``anchored``, one-at-a-time real
#: FDEM runs from the posterior mean (:func:`calibration.diagnose.anchored_design`); ``emulator``, an RBF
#: emulator of a space-filling design (:func:`calibration.diagnose.design_points`).
SELECTION_MODELS = ("anchored", "emulator")

#: Between an experiment's name and a held-out record's in a leave-one-record-out fold's name.
FOLD_SEPARATOR = "__"


def diagnosis_settings(exp: Mapping | None) -> Mapping | None:
    """The experiment's ``diagnosis`` block if it runs the diagnosis (a measured experiment with the
    block enabled), else None; its ``seed`` is the experiment's where the block gives none."""
    d = (exp or {}).get("diagnosis")
    if not (d and d.get("enabled", True) and (exp or {}).get("kind") == "measured"):
        return None
    return d if d.get("seed") is not None else {**d, "seed": int(exp["seed"])}


def candidate_effects(diagnosis: Mapping) -> list[str]:
    """The effects the loop may add: the whole catalogue, less ``exclude`` (``candidates`` narrows it
    further where given)."""
    names = list(diagnosis.get("candidates") or [e.name for e in fx.effects()])
    return [n for n in names if n not in set(diagnosis.get("exclude") or [])]


def selection_model(diagnosis: Mapping) -> str:
    """The ``diagnosis`` block's ``selection_model`` (default ``anchored``, the schema's), checked."""
    model = diagnosis.get("selection_model", SELECTION_MODELS[0])
    if model not in SELECTION_MODELS:
        raise ValueError(f"diagnosis.selection_model must be one of {SELECTION_MODELS}, got {model!r}")
    return model


def design_mesh_point(exp: Mapping, point) -> int:
    """The design point whose mesh realization a design run takes: its own in a space-filling design; the
    anchor's (point 0) for every run of an anchored one, so that a record's runs differ by their
    parameters only (:func:`calibration.diagnose.anchored_design`)."""
    return 0 if selection_model(diagnosis_settings(exp)) == "anchored" else int(point)


def design_size(exp: Mapping) -> int:
    """The number of runs per record of a diagnosed experiment's design (the Snakefile's design points):
    ``design_points`` for the emulator; for the anchored model the anchor, two runs per estimated
    parameter and ``sweep_points`` per physical candidate's parameter, again per name in ``interactions``
    (:func:`calibration.diagnose.anchored_design`)."""
    d = diagnosis_settings(exp)
    if selection_model(d) == "emulator":
        return int(d["design_points"])
    base = exp.get("parameters")
    if not isinstance(base, Mapping):
        raise ValueError(f"diagnosis.selection_model: anchored needs the estimated parameters listed, got "
                         f"parameters: {base!r} (set diagnosis.selection_model: emulator, or list them)")
    physical = [p for c in candidate_effects(d) for p in fx.get_effect(c).params
                if fx.get_effect(c).kind == "physical"]
    unknown = [n for n in d.get("interactions") or [] if n not in base]
    if unknown:
        raise ValueError(f"diagnosis.interactions names {unknown}, which are not estimated parameters "
                         f"(parameters: {list(base)})")
    sweeps = 1 + len(d.get("interactions") or [])  # the physical sweeps, once plus once per interaction
    return 1 + 2 * len(base) + sweeps * int(d.get("sweep_points", 3)) * len(physical)


def loro_folds(name: str, exp: Mapping) -> dict[str, dict]:
    """``{<name>__<record>: experiment}``: one experiment per record of ``exp``'s ``observations.records``,
    that record held out and the others calibrated, everything else as ``exp`` (its seed included, so
    the folds differ only in their split)."""
    records = list(exp["observations"]["records"])
    folds = {}
    for path in records:
        rec = record_name(path)
        fold = {**exp, "observations": {**exp["observations"], "records": [p for p in records if p != path]},
                "diagnosis": {**exp["diagnosis"], "validation": "holdout", "heldout_records": [path]},
                "description": f"leave-one-record-out fold of {name}: {rec} held out", "loro_of": name}
        folds[f"{name}{FOLD_SEPARATOR}{rec}"] = fold
    return folds


def series_position(experiments: Mapping, name: str, record: str) -> int:
    """The position of ``record`` (a record name) among the records of experiment ``name``'s series:
    for a leave-one-record-out fold the series' own list (``loro_of``), so that a record's runs (their
    mesh realizations) do not depend on which other record the fold holds out and the runs that no
    held-out record enters (the prior ensemble and its replicates) are the same requests in every fold,
    made once (:mod:`calibration.run_store`); otherwise the experiment's list. 0 for a record not in it
    (a twin's synthetic record)."""
    exp = experiments[name]
    names = list(experiment_records(experiments.get(exp.get("loro_of"), exp)))
    return names.index(record) if record in names else 0
