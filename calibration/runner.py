"""The member runner: one ``python -m shpb simulate`` run of an ensemble member, its files written atomically.

:func:`run_member` runs the simulator with the exit-code contract of :mod:`shpb.contract` (0 = ok,
3 = numerical failure, ``run.json`` says why, 2 = bad arguments or a missing input) and leaves the
member's ``curve.csv`` and ``run.json`` behind whatever happened, except for a configuration error
(exit code 2: :class:`SimulatorRejected`) and a genuine crash before the last attempt
(:class:`SimulatorCrash`), which raise so that Snakemake fails or retries the job. A simulation
running past ``time_limit_s`` is stopped and recorded as a failed member.

The shipped simulator (:data:`DEFAULT_SIMULATOR`) runs in a forked child of the calling process rather
than in a second interpreter: its imports (NumPy, Numba, the engine) are done once here and inherited,
which saves the interpreter's start and the re-import of what the job already holds; the child runs the
same command-line entry with the same arguments, so exit codes, files and log are those of the
subprocess. A user's own simulator command runs as a subprocess.

The curve columns and exit codes are the simulator's own definitions (:mod:`shpb.contract`), so that a
failed member's header cannot drift from a successful member's. Nothing here imports Snakemake.
"""

from __future__ import annotations

import gc
import locale
import math
import numbers
import os
import select
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path

from shpb.contract import CURVE_COLUMNS as _SIM_CURVE_COLUMNS, EXIT_BAD_INPUT, EXIT_NUMERICAL, EXIT_OK
from .contracts import atomic_write_json, atomic_write_text, read_json
from .heal import child_dies_with_parent, write_manifest

__all__ = ["CURVE_COLUMNS", "DEFAULT_SIMULATOR", "SimulatorCrash", "SimulatorRejected", "run_member",
           "simulator_command", "simulate_argv", "failed_curve_text", "failure_card"]

#: Columns of a simulated curve: the simulator's own definition (``python -m shpb simulate`` contract),
#: so that a failed member's header cannot drift from a successful member's.
CURVE_COLUMNS = tuple(_SIM_CURVE_COLUMNS)

#: Default simulator command: the package's command-line entry.
DEFAULT_SIMULATOR = "python -m shpb simulate"


class SimulatorCrash(RuntimeError):
    """The simulator ended without the exit-code contract (crash, kill, missing outputs)."""


class SimulatorRejected(RuntimeError):
    """The simulator refused its arguments or could not find its input (exit code 2): a configuration
    error, not a property of the member's parameters. The job fails with the simulator's message and
    leaves no output, so a re-run after the fix runs it again."""


def simulator_command(spec: str | Sequence[str] | None = None) -> list[str]:
    """The simulator command as an argv prefix (default ``python -m shpb simulate`` with this Python)."""
    if spec is None or spec == DEFAULT_SIMULATOR:
        return [sys.executable, "-m", "shpb", "simulate"]
    return shlex.split(spec) if isinstance(spec, str) else [str(s) for s in spec]


def simulate_argv(command: Sequence[str], *, geometry: str, preset: str, params: Mapping[str, float],
                  out_dir: str | Path, record: str | None = None, t_end: float | None = None,
                  sample_dt: float | None = None, snapshots: int | None = None,
                  mesh_seed: int | None = None) -> list[str]:
    """The argv of one simulation (the ``python -m shpb simulate`` contract); ``mesh_seed`` None keeps
    the unperturbed specimen mesh, an integer is one realization of it (``--mesh-seed``)."""
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
    if mesh_seed is not None:
        argv += ["--mesh-seed", str(int(mesh_seed))]
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
               time_limit_s: float | None = None, snapshots: int | None = None,
               mesh_seed: int | None = None, request: str | None = None) -> dict:
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

    The simulator dies with the process calling this (:func:`calibration.heal.child_dies_with_parent`),
    and nothing is moved into place once that process has lost its parent (a killed Snakemake), so a
    killed run leaves no file written after the kill. ``manifest.json`` (the sha256 of ``curve.csv``
    and ``run.json``, :func:`calibration.heal.write_manifest`) is written last, whatever the outcome;
    ``request`` (what made the files, :func:`calibration.batch.request_key`) goes into it where the
    outcome is the simulator's own (exit 0 or 3), not after a crash or the time limit, which a new
    attempt may not repeat.

    Returns the ``run.json`` dict written.
    """
    curve_path, run_path = Path(curve_path), Path(run_path)
    out = curve_path.parent
    parent = os.getppid()
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".sim-", dir=out))
    argv = simulate_argv(command, geometry=geometry, preset=preset, params=params, out_dir=tmp, record=record,
                         t_end=t_end, sample_dt=sample_dt, snapshots=snapshots, mesh_seed=mesh_seed)
    t0 = time.perf_counter()
    try:
        try:
            proc = (_fork_with_limit if _forkable(command) else _run_with_limit)(argv, time_limit_s)
        except subprocess.TimeoutExpired as exc:
            _still_wanted(parent)
            return _timed_out(exc, argv=argv, wall=time.perf_counter() - t0, geometry=geometry, preset=preset,
                              params=params, curve_path=curve_path, run_path=run_path, log_path=log_path,
                              extra=dict(extra_run or {}, attempt=attempt, exit_code=None))
        wall = time.perf_counter() - t0
        _still_wanted(parent)
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
            _write_run(run_path, run, curve_path, request)
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
            _write_run(run_path, run, curve_path, request)
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
        _write_run(run_path, run, curve_path)  # no request: a crash need not recur
        return run
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _run_with_limit(argv, time_limit_s):
    """subprocess.run(argv, capture_output=True, text=True) that kills the simulator at the time limit
    and does not then wait for processes it may have started that still hold its pipes."""
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          preexec_fn=child_dies_with_parent(os.getpid())) as proc:
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


def _forkable(command: Sequence[str]) -> bool:
    """Run in a forked child: the command is the shipped simulator with this Python, on Linux (elsewhere
    system libraries may not survive a fork without exec, and the child could not die with the job),
    and this process holds a single thread once the simulator is imported (a fork copies only the
    calling thread, so a lock held by another one would stay locked in the child; the member jobs pin
    OpenBLAS and Numba to one thread, rules/common.smk). Otherwise the subprocess, as for any command."""
    if list(command) != simulator_command() or not sys.platform.startswith("linux"):
        return False
    try:  # the entry, imported here so that the thread count below sees NumPy's BLAS threads and the
        import shpb.__main__  # noqa: F401  child inherits these modules
        import shpb.simulate  # noqa: F401
    except Exception:  # a broken install: the subprocess path reports it as the simulator's crash
        return False
    try:
        threads = len(os.listdir("/proc/self/task"))
    except OSError:  # no /proc: not knowing, keep the subprocess
        return False
    return threads == 1 and threading.active_count() == 1


def _fork_with_limit(argv, time_limit_s):
    """:func:`_run_with_limit` for the shipped simulator: ``shpb.__main__.main(argv[3:])`` in a forked
    child (dying with this process, stdout and stderr to unnamed files), killed at the time limit
    (:class:`subprocess.TimeoutExpired`), its exit status mapped as a subprocess's (``-N``: signal N)."""
    from shpb import __main__ as entry

    parent = os.getpid()
    arm = child_dies_with_parent(parent)  # loads libc here: the child should not load libraries
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        for stream in (sys.stdout, sys.stderr):  # else the child would write this process's buffered text
            if stream is not None:
                stream.flush()
        # the inherited objects out of the child's garbage collections: their traversal would write to
        # every page the child shares with this process, copying each (bench_member_overhead.py)
        gc.freeze()
        try:
            pid = os.fork()
        finally:
            if os.getpid() == parent:
                gc.unfreeze()
        if pid == 0:
            _child(entry, argv, out.fileno(), err.fileno(), arm)
        try:
            status = _wait(pid, time_limit_s)
        except BaseException:
            _kill(pid)
            raise
        if status is None:
            _kill(pid)
            raise subprocess.TimeoutExpired(argv, time_limit_s, output=_text(out), stderr=_text(err))
        return subprocess.CompletedProcess(argv, os.waitstatus_to_exitcode(status), _text(out), _text(err))


def _child(entry, argv, out_fd: int, err_fd: int, arm) -> None:
    """The forked child: the command-line entry as ``python -m shpb`` would run it; never returns.
    Python's own exit rules: ``SystemExit``'s code, an uncaught exception's traceback and exit code 1."""
    code = 1
    try:
        if arm is not None:
            arm()
        for sig in signal.valid_signals():  # as after exec: the caller's Python handlers do not apply
            handler = signal.getsignal(sig)
            if callable(handler) and handler is not signal.default_int_handler:
                signal.signal(sig, signal.SIG_DFL)
        os.dup2(out_fd, 1)
        os.dup2(err_fd, 2)
        # fresh streams on the descriptors: the caller's may write elsewhere (a test's capture)
        encoding = locale.getpreferredencoding(False)
        sys.stdout = open(1, "w", encoding=encoding, closefd=False)
        sys.stderr = open(2, "w", encoding=encoding, errors="backslashreplace", closefd=False, buffering=1)
        sys.argv = [entry.__file__, *argv[3:]]
        code = entry.main(argv[3:])
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(int(code or 0) & 0xFF)


def _wait(pid: int, timeout: float | None):
    """The child's wait status, or None once ``timeout`` seconds passed without it ending."""
    if timeout is None:
        return os.waitpid(pid, 0)[1]
    deadline = time.monotonic() + timeout
    try:
        fd = os.pidfd_open(pid)  # readable once the child ends (Linux >= 5.3)
    except (AttributeError, OSError):
        fd = None
    try:
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            left = deadline - time.monotonic()
            if done:
                return status
            if left <= 0:
                return None
            if fd is None:
                time.sleep(min(left, 0.02))
            else:
                select.select([fd], [], [], left)
    finally:
        if fd is not None:
            os.close(fd)


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):  # already ended and reaped
        pass


def _text(fh) -> str:
    """A child's output as ``subprocess.run(..., text=True)`` decodes it (locale encoding, universal
    newlines); an undecodable byte is replaced instead of failing the job."""
    fh.seek(0)
    data = fh.read().decode(locale.getpreferredencoding(False), errors="replace")
    return data.replace("\r\n", "\n").replace("\r", "\n")


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
    _write_run(run_path, run, curve_path)  # no request: the time a run takes depends on the machine
    return run


def _still_wanted(parent: int) -> None:
    """Raise instead of writing outputs once the caller's parent has died (the job is an orphan of a
    killed Snakemake: its outputs would appear finished to the next run without Snakemake's record)."""
    if os.getppid() != parent:
        raise SimulatorCrash(f"the job's parent process {parent} died (a killed run): no output written")


def _write_run(run_path: Path, run: dict, curve_path: Path, request: str | None = None) -> None:
    """run.json, then the member folder's manifest.json of both files (written last)."""
    atomic_write_json(run_path, _jsonable(run))
    write_manifest(run_path.parent, [curve_path, run_path], request)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    # numbers' abstract types hold numpy's scalars too, without importing numpy into every member job
    if isinstance(obj, bool):
        return obj
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj
