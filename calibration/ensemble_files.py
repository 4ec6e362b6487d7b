"""The ensemble's files: member folder names, a member's parameters, one member's status over its records,
and ``iter_<k>/responses.csv`` (every member's curve on the observation grid).

Units are SI everywhere (docs/workflow.md, "What goes where"). Nothing here imports Snakemake.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .contracts import atomic_write_csv, read_json

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

__all__ = ["member_ids", "member_params", "simulation_params", "combine_member_runs", "write_responses", "read_responses"]


def member_ids(n_members: int) -> list[str]:
    """Folder names of the members: ``000``, ``001``, ... (three digits, more if needed)."""
    width = max(3, len(str(n_members - 1)))
    return [f"{i:0{width}d}" for i in range(n_members)]


def _params_rows(params_csv: str | Path) -> list[dict]:
    """The rows of ``params.csv``: ``{"member": int, parameter: float}`` each. ``float()`` reads the written
    digits exactly (pandas' default parser may be one unit in the last place off)."""
    import csv

    with open(params_csv, newline="") as fh:
        return [{c: int(v) if c == "member" else float(v) for c, v in r.items()} for r in csv.DictReader(fh)]


def member_params(params_csv: str | Path, member: str | int, fixed: Mapping[str, float] | None = None) -> dict:
    """The simulator parameters of one member: its row of ``params.csv`` plus the fixed parameters."""
    rows = [r for r in _params_rows(params_csv) if r["member"] == int(member)]
    if len(rows) != 1:
        raise KeyError(f"{params_csv}: member {member} not found")
    values = {c: v for c, v in rows[0].items() if c != "member"}
    return {**(fixed or {}), **values}


def simulation_params(source: Mapping, fixed: Mapping[str, float], params_file: str | Path | None = None,
                      experiments: Mapping | None = None) -> dict:
    """The simulator parameters of one simulation job: the experiment's ``fixed`` parameters overlaid with
    those ``source`` names (the ``parameters`` param of the simulation rules, rules/simulate.smk):

    - ``{"values": {name: value}}``: given (the truth, a design point of the approximation error, a check run);
    - ``{"row": member, "held": {name: value}}``: the member's row of the CSV ``params_file``, ``held`` (optional)
      between the fixed parameters and the row (the sensitivity design's other parameters at their centres);
    - ``{"key": name}``: the mapping under ``name`` in the JSON ``params_file`` (forecast/params.json);
    - ``{"ensemble_mean": experiment}``: the mean of the ensemble in ``params_file`` in the unbounded space of
      the analysis (the replicates), the experiment's config looked up in ``experiments``.
    """
    if "values" in source:
        return {**fixed, **source["values"]}
    if "row" in source:
        return member_params(params_file, source["row"], {**fixed, **(source.get("held") or {})})
    if "key" in source:
        return {**fixed, **read_json(params_file)[source["key"]]}
    if "ensemble_mean" in source:
        return {**fixed, **_ensemble_mean(params_file, source["ensemble_mean"], experiments)}
    raise ValueError(f"simulation parameters: source {dict(source)!r} has none of the keys values, row, key, "
                     "ensemble_mean")


def _ensemble_mean(params_csv: str | Path, name: str, experiments: Mapping) -> dict:
    # numpy and the transform only, imported here: the experiment module (SciPy's statistics, pandas, the
    # process) cost each replicate job 2 s, and every other simulation job needs none of them
    import numpy as np

    from enkf.transforms import BoxTransform

    exp = experiments[name]
    # the columns the ensemble has are the calibrated parameters (``parameters: auto``, not a mapping: those
    # selected, drawn over the sensitivity stage's boxes)
    boxes = exp["parameters"] if isinstance(exp["parameters"], Mapping) else exp["sensitivity"]["parameters"]
    rows = _params_rows(params_csv)
    names = [c for c in rows[0] if c != "member"]
    unknown = [p for p in names if p not in boxes]
    if unknown:
        raise ValueError(f"{params_csv}: columns {unknown} are not parameters of experiments.{name}")
    P = np.array([[r[p] for p in names] for r in rows], float)
    transform = BoxTransform(np.array([boxes[p][0] for p in names], float),
                             np.array([boxes[p][1] for p in names], float), kind=exp.get("transform", "logit"))
    # the mean in the unbounded space of the analysis: for a box over orders of magnitude (E_t 100-50,000
    # J/m^2) the arithmetic mean of a prior Latin hypercube sits far from where the members are
    mean = transform.to_bounded(transform.to_unbounded(P).mean(axis=0)[None, :])[0]
    return dict(zip(names, map(float, mean)))


def combine_member_runs(runs: Mapping[str, Mapping]) -> dict:
    """One member's status over its records (``{record: run.json}``): ok only if every record is ok."""
    failed = {rec: r for rec, r in runs.items() if r.get("status") != "ok"}
    reason = "; ".join(f"{rec}: {r.get('reason') or 'failed'}" for rec, r in failed.items())
    wall = sum(float(r.get("wall_s") or 0.0) for r in runs.values())
    return {"status": "failed" if failed else "ok", "reason": reason, "wall_s": wall}


def write_responses(path: str | Path, members: Sequence[int], status: Sequence[Mapping], Y: np.ndarray) -> Path:
    """``iter_<k>/responses.csv``: one row per member, ``member, status, reason, wall_s`` and the curve
    on the observation grid as ``y_0 ... y_{m-1}`` (the order of ``obs.csv``; empty = missing)."""
    import numpy as np
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
