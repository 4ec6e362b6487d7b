"""A batch of simulations in one process: the job of ``rule simulate`` (rules/simulate.smk).

:func:`run_batch` runs each simulation of the batch through :func:`calibration.runner.run_member`, so
every run keeps the member contract: its own ``curve.csv``, ``run.json``, ``simulate.log`` and
``manifest.json``, exit codes 0/2/3, the time limit, a failed run recorded with its reason. With the
shipped simulator each run is a forked child of this process, and this process loads the compiled
engine once before the first fork (:func:`shpb.simulate.warm_up`), so a child starts with the engine
in memory: what a run costs beyond its solver is the fork and its files, where a job per run paid
Snakemake's job start, an interpreter, the imports and the engine's load every time.

A run whose files are intact (their manifest checks out) and were made by the same request (the
run's settings with the simulator command, parameters, the record's content, mesh seed, run.json entries, and the
source of the shipped simulator's packages, ``fdem`` and ``shpb``: a SHA-256 kept in its
``manifest.json``, written only where the outcome was the simulator's own: a success or a numerical
failure) is not run again: the simulation is deterministic, so it would write the same files. A batch re-run because one of its
runs was altered (:func:`calibration.heal.heal_results`), or after a kill, re-simulates only what is
missing, altered or asked differently.

Failure stays per run. A numerical failure or a run past its time limit is a failed run (the analysis
drops it), the batch goes on. A crash (the simulator ended outside the contract) is retried: the other
runs finish, then the batch raises :class:`~calibration.runner.SimulatorCrash` while attempts remain,
Snakemake runs the job again (``retries``), and that attempt re-runs only what did not finish (the runs
that finished carry their request in their manifests, below); on the last attempt ``run_member`` records
the crash as a failed run.
Rejected arguments or a missing input (exit code 2) stop the batch at once: a configuration error.

Nothing here imports Snakemake.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from .contracts import atomic_write_json, read_json
from .ensemble_files import simulation_params
from .heal import MANIFEST, check_manifest
from .run_store import copy_made, remember
from .runner import SimulatorCrash, failure_card, run_member, simulator_command

__all__ = ["run_batch", "request_key"]

_CODE: list[str] = []


def _code_hash() -> str:
    """SHA-256 of the shipped simulator's source (every .py file of the fdem and shpb packages)."""
    if not _CODE:
        import fdem
        import shpb

        h = hashlib.sha256()
        for pkg in (fdem, shpb):
            root = Path(pkg.__file__).parent
            for path in sorted(root.rglob("*.py")):
                h.update(str(path.relative_to(root.parent)).encode() + b"\0" + path.read_bytes())
        _CODE.append(h.hexdigest())
    return _CODE[0]


def request_key(spec: Mapping, params: Mapping) -> str:
    """What makes a run's files: its settings (the simulator command among them), resolved parameters,
    the record's content (:func:`_record_digest`), mesh seed, snapshots and run.json entries, with the shipped simulator's source. A user's own
    simulator is taken as unchanged while its command is (Snakemake does not track it either)."""
    what = {"sim": spec["sim"], "params": {k: float(v) for k, v in params.items()},
            "record": _record_digest(spec.get("record_file")), "mesh_seed": spec.get("mesh_seed"),
            "snapshots": spec.get("snapshots"), "run": spec.get("run") or {},
            "outputs": sorted(spec["outputs"]), "code": _code_hash()}
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()


def _record_digest(record_file: str | None) -> str | None:
    """What a run reads of its record, by content: the reduced record's record.json and the incident wave
    beside it (rules/common.smk, record_input), so that one record reduced in two experiments' folders
    is one input. A path that is not a file stands for itself (the simulator will say it is missing)."""
    if not record_file or not Path(record_file).is_file():
        return record_file
    h = hashlib.sha256(Path(record_file).read_bytes())
    incident = Path(record_file).with_name("incident.csv")
    if incident.is_file():
        h.update(b"\0" + incident.read_bytes())
    return h.hexdigest()


def _made_by(folder: Path, key: str) -> bool:
    """The folder's files are intact and its manifest names the request ``key``."""
    manifest = folder / MANIFEST
    if not manifest.is_file() or check_manifest(manifest)[1] is not None:
        return False
    try:
        return json.loads(manifest.read_text()).get("request") == key
    except (OSError, ValueError, AttributeError):
        return False


def _folder(spec: Mapping) -> str:
    return str(Path(spec["outputs"]["curve"]).parent)


def _warm_engine(specs: Sequence[Mapping]) -> float | None:
    """Load the engine here once when the runs fork from this process (the shipped simulator)."""
    from .runner import _forkable

    if not any(_forkable(simulator_command(s["sim"]["command"])) for s in specs):
        return None
    from shpb.simulate import warm_up

    return warm_up()


def run_batch(specs: Sequence[Mapping], *, batch_path: str | Path, attempt: int = 1, max_attempts: int = 1,
              params_file: str | None = None, experiments: Mapping | None = None, label: str = "",
              log_path: str | Path | None = None, store: str | Path | None = None) -> dict:
    """Run the simulations ``specs``, then write ``batch_path``: the runs' folders, statuses and reasons.
    Each spec (rules/inputs.smk, batch_runs) holds ``sim`` (the experiment's simulation settings),
    ``parameters``, ``record_file``, ``mesh_seed``, ``snapshots``, ``run`` (entries added to run.json),
    ``must_succeed``, ``outputs`` (curve, run and any snapshot pictures), ``log`` and ``time_limit_s``. Returns that dict. ``params_file`` is the stage's parameter file
    (the batch's ``params`` input), ``experiments`` the config's, for ``parameters`` that name them.
    ``store``: the index of runs made by other experiments' batches (:mod:`calibration.run_store`; None:
    every run is made here)."""
    params = [simulation_params(s["parameters"], s["sim"]["fixed"], params_file, experiments) for s in specs]
    keys = [request_key(s, p) for s, p in zip(specs, params)]
    kept = {_folder(s) for s, k in zip(specs, keys) if _made_by(Path(_folder(s)), k)}
    copied = _copy_shared(specs, keys, kept, store)
    kept |= set(copied)
    todo = [s for s in specs if _folder(s) not in kept]
    log = _Log(log_path, f"batch of {len(specs)} simulations, attempt {attempt} of {max_attempts}; "
                         f"{len(kept)} made before by the same request"
                         + (f" ({len(copied)} of them copied from other experiments' runs)" if copied else ""))
    for folder, source in copied.items():
        log.line(f"{folder}: copied from {source}")
    if todo:
        warm = _warm_engine(todo)
        if warm is not None:
            log.line(f"engine loaded in {warm:.2f} s")
    runs, crashed = [], []
    for spec, values, key in zip(specs, params, keys):
        folder = _folder(spec)
        if folder in kept:
            run = read_json(spec["outputs"]["run"])
            runs.append({"folder": folder, "status": run.get("status"), "reason": run.get("reason", "")})
            continue
        try:
            run = _run_one(spec, values, key, attempt, max_attempts)
        except SimulatorCrash as exc:
            crashed.append(f"{folder}: {exc}")
            log.line(f"{folder}: crashed: {exc}")
            continue
        log.line(f"{folder}: {run.get('status')} {run.get('reason', '')} ({float(run.get('wall_s') or 'nan'):.1f} s)")
        if store is not None and _made_by(Path(folder), key):
            remember(store, key, folder)
        if spec.get("must_succeed") and run["status"] != "ok":
            raise RuntimeError(f"the {label or 'batch'} simulation {folder} failed: {run.get('reason')}")
        runs.append({"folder": folder, "status": run.get("status"), "reason": run.get("reason", "")})
    if crashed:
        raise SimulatorCrash(f"{len(crashed)} of {len(specs)} simulations of the batch crashed "
                             f"(attempt {attempt} of {max_attempts}; the others are kept for the next): "
                             + "; ".join(crashed))
    # no wall times: a re-run writes the same file
    report = {"runs": runs}
    atomic_write_json(batch_path, report)
    return report


def _copy_shared(specs: Sequence[Mapping], keys: Sequence[str], kept: set, store) -> dict[str, str]:
    """``{folder: source}`` of the runs copied from the store (runs with snapshots are always made)."""
    if store is None:
        return {}
    copied = {}
    for spec, key in zip(specs, keys):
        folder = _folder(spec)
        if folder not in kept and not spec.get("snapshots"):
            source = copy_made(store, key, folder, _made_by)
            if source is not None:
                copied[folder] = source
    return copied


class _Log:
    """The batch's log: one line per run, written as it goes (a killed batch keeps its lines)."""

    def __init__(self, path, first: str):
        self.path = None if path is None else Path(path)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(first + "\n")

    def line(self, text: str) -> None:
        if self.path is not None:
            with self.path.open("a") as fh:
                fh.write(text + "\n")


def _run_one(spec: Mapping, params: Mapping, key: str, attempt: int, max_attempts: int) -> dict:
    sim, out = spec["sim"], spec["outputs"]
    run = run_member(command=simulator_command(sim["command"]), geometry=sim["geometry"], preset=sim["preset"],
                     params=params,
                     record=spec.get("record_file") or None, t_end=sim["t_end"], sample_dt=sim["sample_dt"],
                     curve_path=out["curve"], run_path=out["run"], log_path=spec["log"], attempt=attempt,
                     time_limit_s=spec["time_limit_s"], max_attempts=max_attempts,
                     mesh_seed=spec.get("mesh_seed"), extra_run=spec.get("run") or None,
                     snapshots=spec.get("snapshots"), request=key)
    # the outputs besides the curve and run.json are the snapshots' pictures: a failed run, or a
    # simulator that writes none, gets a picture saying so
    for name, png in out.items():
        if name not in ("curve", "run") and not Path(png).is_file():
            why = (f"the run failed: {run.get('reason', '')}" if run.get("status") != "ok"
                   else f"the simulator ({sim['command']}) wrote no fracture snapshots")
            failure_card(png, f"No fracture snapshot: {why}")
    return run
