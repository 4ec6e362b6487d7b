"""Runs that heal after a kill or a corrupted file.

* :func:`die_with_parent` / :func:`child_dies_with_parent`: Linux's parent-death signal
  (``prctl(PR_SET_PDEATHSIG, SIGKILL)``), so that a job script dies with the Snakemake process that
  started it (``import calibration`` arms it in every Snakemake script job) and a simulator with its
  job script (:func:`calibration.runner.run_member`). Without it a SIGKILLed Snakemake left its running
  jobs alive, and they moved their outputs into place after the run had died, where the next run took
  them as finished.
* :func:`write_manifest`: ``manifest.json`` beside a member's files, the sha256 and size of each, written
  atomically after them (:func:`calibration.runner.run_member`).
* :func:`heal_results`: at the start of a run (the Snakefile, main process) removes the stale temporaries
  under ``results/`` (``.sim-*`` folders, ``.*.tmp`` files) and every member whose files no longer match
  their manifest (truncated, altered), printing one line each, so that Snakemake simulates it again.

Nothing here imports Snakemake.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import re
import shutil
import signal
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

from shpb.atomic import atomic_write_text

__all__ = ["MANIFEST", "PARENT_ENV", "mark_job_parent", "die_with_parent", "child_dies_with_parent", "file_sha256", "write_manifest",
           "check_manifest", "is_dry_invocation", "heal_results"]

#: The checksum file of a member folder.
MANIFEST = "manifest.json"
#: Siblings removed with a manifest that cannot be read (the files run_member writes).
MEMBER_FILES = ("curve.csv", "run.json")
#: The environment variable holding the pid of the Snakemake process that starts this process's jobs.
PARENT_ENV = "CALIBRATION_SNAKEMAKE_PID"
_PR_SET_PDEATHSIG = 1
_TEMP_FILE = re.compile(r"^\..+\.tmp$")
_TEMP_DIR_PREFIX = ".sim-"
_LIBC = None


def _prctl():
    """libc's prctl, loaded once in the parent (a forked child should not load libraries)."""
    global _LIBC
    if _LIBC is None and sys.platform.startswith("linux"):
        try:
            _LIBC = ctypes.CDLL(None, use_errno=True)
        except OSError:  # pragma: no cover (a Linux without a loadable libc)
            _LIBC = False
    return getattr(_LIBC, "prctl", None) if _LIBC else None


def _set_death_signal(sig: int) -> bool:
    prctl = _prctl()
    return bool(prctl) and prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0


def mark_job_parent() -> None:
    """Tell the jobs this process starts its pid (:data:`PARENT_ENV`): called by every Snakemake process
    reading the Snakefile (the main one, a cluster job step's), so that a job can tell that its Snakemake
    died before the job asked to die with it."""
    os.environ[PARENT_ENV] = str(os.getpid())


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        return False


def die_with_parent() -> bool:
    """SIGKILL this process when its parent dies (Linux; elsewhere a no-op returning False).

    Called on ``import calibration`` in a Snakemake script job (every ``scripts/*.py``): its parent is
    the Snakemake process (on a cluster, the job step's Snakemake), which starts each local job's Python
    directly. A parent that died before the request cannot signal any more (a job still importing when
    its Snakemake was killed): the process then exits at once, told by :data:`PARENT_ENV`
    (:func:`mark_job_parent`) or by a parent that changed during the call."""
    parent = os.getppid()
    if not _set_death_signal(signal.SIGKILL):
        return False
    watched = os.environ.get(PARENT_ENV, "")
    if (parent != 1 and os.getppid() != parent) or (watched.isdigit() and not _running(int(watched))):
        os._exit(128 + signal.SIGKILL)
    return True


def child_dies_with_parent(parent_pid: int):
    """A ``preexec_fn`` for ``subprocess.Popen``: the child is SIGKILLed when ``parent_pid`` (the process
    starting it) dies, and exits at once if that happened before the request took effect. The death
    signal survives ``exec`` and is tied to the thread that forks: call Popen from a thread that outlives
    the child (a job script's main thread). None (no ``preexec_fn``) where Linux's prctl is missing."""
    if _prctl() is None:
        return None

    def preexec():
        _set_death_signal(signal.SIGKILL)
        if os.getppid() != parent_pid:
            os._exit(128 + signal.SIGKILL)
    return preexec


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_manifest(folder: str | Path, files: Iterable[str | Path], request: str | None = None) -> Path:
    """``folder/manifest.json``: ``{"files": {name: {"sha256", "bytes"}}}`` of ``files`` (paths as opened;
    names relative to the folder), with ``request`` (what made the files, calibration.batch.request_key)
    when given, written atomically. Written last, so a manifest vouches for files already in place."""
    folder = Path(folder)
    entries = {}
    for path in map(Path, files):
        entries[os.path.relpath(path, folder)] = {"sha256": file_sha256(path), "bytes": path.stat().st_size}
    data = {"files": entries, **({"request": request} if request is not None else {})}
    return atomic_write_text(folder / MANIFEST, json.dumps(data, indent=1))


def check_manifest(manifest: str | Path) -> tuple[list[Path], str | None]:
    """``(the member's files, why they are bad)`` for one manifest; ``why`` None: every listed file that
    exists matches (a missing one: :func:`heal_results` re-queues its batch). A size is compared before hashing."""
    manifest = Path(manifest)
    folder = manifest.parent
    try:
        entries = json.loads(manifest.read_text())["files"]
        listed = [(folder / name, e["sha256"], int(e["bytes"])) for name, e in entries.items()]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        return [folder / n for n in MEMBER_FILES], f"{manifest.name} is unreadable ({type(exc).__name__})"
    files = [p for p, _, _ in listed]
    for path, sha, size in listed:
        if not path.is_file():
            continue
        actual = path.stat().st_size
        if actual != size:
            return files, f"{path.name} has {actual} bytes, its manifest says {size} (truncated or altered)"
        if file_sha256(path) != sha:
            return files, f"the sha256 of {path.name} does not match its manifest (altered)"
    return files, None


#: Invocations that run no job (a dry run, --unlock, a listing, a report): heal_results removes nothing.
_NO_RUN_FLAGS = ("--dry-run", "--dryrun", "--unlock", "--touch", "--list", "--lint", "--summary",
                 "--detailed-summary", "--dag", "--rulegraph", "--filegraph", "--d3dag", "--report",
                 "--cleanup-metadata", "--cm", "--delete-all-output", "--delete-temp-output", "--containerize",
                 "--archive", "--generate-unit-tests", "--export-cwl", "--print-compilation", "--version")


def is_dry_invocation(argv: Sequence[str]) -> bool:
    """Whether Snakemake's command line runs no job (Snakemake tells a Snakefile nothing of a dry run
    while it is parsed): ``-n``/``--dry-run`` (also in a cluster like ``-np``), ``-t``, ``--unlock``,
    the listings and reports."""
    for arg in argv[1:]:
        if arg.startswith("--"):
            if arg.split("=")[0].startswith(_NO_RUN_FLAGS):
                return True
        elif re.fullmatch(r"-[A-Za-z]+", arg) and ("n" in arg or "t" in arg):
            return True
    return False


def _locked(workdir: Path) -> bool:
    locks = workdir / ".snakemake" / "locks"
    return locks.is_dir() and any(locks.iterdir())


def heal_results(root: str | Path = "results", argv: Sequence[str] | None = None, out=None) -> list[str]:
    """At the start of a run: remove the stale temporaries under ``root`` and put every member whose
    files no longer match their manifest, or that a batch file lists and whose files are gone, out of
    date; returns (and prints to ``out``, default stderr) one
    line each.

    A bad member's files are dated back to the epoch, with the batch file of the job that wrote them
    (rule simulate; the member's own rule runs no job), older than any input of that job: Snakemake's
    default rerun trigger (``mtime``) then runs the batch again, which re-simulates what is altered
    (calibration.batch keeps its runs made by the same request), and reruns what depends on it.
    Deleting them here would not do: Snakemake does not rebuild a missing file whose consumers are up to
    date. Until a run asks for the member, the files stay bad and each start says so again.

    Nothing is changed in an invocation that runs no job (:func:`is_dry_invocation`; the lines then say
    what a run would do), nor while ``.snakemake/locks`` holds a lock: another run may be live in this
    folder and own the temporaries (after a hard kill, ``snakemake --unlock`` first)."""
    root = Path(root)
    out = sys.stderr if out is None else out
    if not root.is_dir():
        return []
    if _locked(Path(".")):
        lines = [f"{root}: not checked for stale temporaries and altered member files: .snakemake/locks holds "
                 f"a lock (another run may be live here; after a hard kill run `snakemake --unlock` first)"]
    else:
        lines = _heal(root, dry=is_dry_invocation(sys.argv if argv is None else argv))
    for line in lines:
        print(line, file=out, flush=True)
    return lines


def _batch_files(root: Path) -> dict[str, Path]:
    """{a run's folder: the batch file of the job that wrote it} (rule simulate's outputs under
    ``<root>/<experiment>/simulate/``; calibration.batch.run_batch lists each run's folder)."""
    out = {}
    for path in root.glob("*/simulate/*/*/batch_*.json"):
        try:
            folders = [r["folder"] for r in json.loads(path.read_text())["runs"]]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # unreadable: Snakemake's to notice (an incomplete job's output)
        out.update({str(Path(f)): path for f in folders})
    return out


def _heal(root: Path, dry: bool) -> list[str]:
    lines, stale, bad = [], [], []
    batches = _batch_files(root) if root.is_dir() else {}
    for folder, dirs, files in os.walk(root):
        here = Path(folder)
        for d in [d for d in dirs if d.startswith(_TEMP_DIR_PREFIX)]:
            dirs.remove(d)  # a temporary's inside is never looked at
            stale.append(here / d)
        stale += [here / f for f in files if _TEMP_FILE.match(f)]
        if MANIFEST in files:
            member_files, why = check_manifest(here / MANIFEST)
            if why:
                bad.append((here, [p for p in member_files if p.is_file()], why))
    # a run removed with its manifest: no rule asks for its files (the stages' collecting rules take the
    # batch files, rules/inputs.smk stage_batch_files), so its batch is what must run again
    listed = {str(f) for f, _, _ in bad}
    for folder in sorted(set(batches) - listed):
        missing = [name for name in MEMBER_FILES if not (Path(folder) / name).is_file()]
        if missing:
            bad.append((Path(folder), [], f"{', '.join(missing)} missing"))
    if stale:
        if not dry:
            for path in stale:
                shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)
        lines.append(f"{root}: {'would remove' if dry else 'removed'} {len(stale)} stale "
                     f"temporar{'y' if len(stale) == 1 else 'ies'} of killed jobs (.sim-* folders, .*.tmp files)"
                     + (" (dry run)" if dry else ""))
    for folder, member_files, why in bad:
        # the job that wrote the files is its batch's (rule simulate): dated back with them, it is out of
        # date against its inputs and runs again; the files' own rule runs no job
        batch = batches.get(str(folder))
        member_files = member_files + ([batch] if batch is not None and batch.is_file() else [])
        if not dry:
            for path in member_files:
                os.utime(path, (0, 0))
        names = ", ".join(p.name for p in member_files)
        lines.append(f"{folder}: {why}; " + ("a run would re-simulate it (dry run)" if dry else
                     f"re-queued: {names} dated back to 1970, out of date, so a run that needs them "
                     f"simulates the member again"))
    return lines
