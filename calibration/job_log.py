"""A workflow job's own log file (the `log:` of every rule in rules/*.smk).

`log_to(path)` sends everything the job prints -- Python's and C's output, warnings, subprocesses -- to
the job's log, so that the output of jobs running side by side (or on cluster nodes) is not interleaved
on the terminal. Two things still reach the terminal: a job's traceback (it is written to the log and to
the run's stderr, so a failing job says why where the user looks first) and what the job writes to the
stream `log_to` returns (the one line per analysis the run prints, scripts/analysis.py). The log's
first line is the job's thread settings; `library_versions` gives the numerical libraries' versions, which
summary.json records (the two things beside the code a re-run's numbers depend on).
"""
from __future__ import annotations

import os
import sys
import traceback
from typing import TextIO

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def log_to(path: str | os.PathLike) -> TextIO:
    """Redirect this process's stdout and stderr (file descriptors 1 and 2) to `path` (truncated).

    Returns a line-buffered stream on the run's original stdout."""
    sys.stdout.flush()
    sys.stderr.flush()
    console = os.fdopen(os.dup(1), "w", buffering=1)
    console_err = os.dup(2)
    fd = os.open(os.fspath(path), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    previous = sys.excepthook

    def _to_log_and_terminal(kind, value, tb):
        text = "".join(traceback.format_exception(kind, value, tb))
        os.write(console_err, f"(job log: {os.fspath(path)})\n{text}".encode())
        previous(kind, value, tb)

    sys.excepthook = _to_log_and_terminal
    # the thread settings the job runs with (rules/common.smk pins them: a BLAS's summation order
    # depends on its thread count)
    print("threads:", *(f"{v}={os.environ.get(v)}" for v in THREAD_VARIABLES), flush=True)
    return console


#: The libraries whose arithmetic a posterior depends on: a re-run on other versions may move it (the
#: loop, the emulator's smoothing choice and the MCMC amplify a last-digit change), so summary.json says
#: which ones made it.
LIBRARIES = ("numpy", "scipy", "numba", "iterative_ensemble_smoother", "emcee")


def library_versions() -> dict:
    """``{"python": ..., library: version}`` of this process (None for one not installed)."""
    import platform
    from importlib import metadata

    def version(name):
        try:
            return metadata.version(name.replace("_", "-"))
        except metadata.PackageNotFoundError:
            return None
    return {"python": platform.python_version(), **{n: version(n) for n in LIBRARIES}}
