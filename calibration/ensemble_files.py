"""The ensemble's files: member folder names, a member's parameters, one member's status over its records,
and ``iter_<k>/responses.csv`` (every member's curve on the observation grid).

Units are SI everywhere (docs/workflow.md, "What goes where"). Nothing here imports Snakemake.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .contracts import atomic_write_csv

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

__all__ = ["member_ids", "member_params", "combine_member_runs", "write_responses", "read_responses"]


def member_ids(n_members: int) -> list[str]:
    """Folder names of the members: ``000``, ``001``, ... (three digits, more if needed)."""
    width = max(3, len(str(n_members - 1)))
    return [f"{i:0{width}d}" for i in range(n_members)]


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
