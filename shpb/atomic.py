"""Atomic file writes: a temporary file in the same folder, flushed and fsynced, then os.replace.

A file that exists is therefore complete: a killed job never leaves half a file behind (Snakemake
re-uses existing outputs of later iterations without checking them).

The temporary file is created like any new file, with mode 0666 filtered by the process umask (0644
under umask 022; ``tempfile.mkstemp`` would give 0600), so the renamed file has the permissions a
plain ``open(path, "w")`` would give it.
"""
from __future__ import annotations

import os
import secrets
from pathlib import Path


def create_temp(directory: str | Path, prefix: str = "", suffix: str = "") -> tuple[int, str]:
    """A new, empty file in ``directory``: ``(fd open for writing, path)``, mode 0666 & ~umask.

    Like ``tempfile.mkstemp`` (exclusive creation under a random name), but the mode is that of a
    normally created file, so it can be renamed onto its final name as it is."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        path = os.path.join(directory, f"{prefix}{secrets.token_hex(6)}{suffix}")
        try:
            return os.open(path, flags, 0o666), path
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name {prefix}*{suffix} in {directory}")


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write text (UTF-8, newlines as given) to path atomically; creates the parent folder."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write bytes to path atomically; creates the parent folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = create_temp(path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def emit_json(obj, path: str | Path | None = None):
    """A benchmark's ending: ``obj`` printed as indented JSON (NumPy scalars as Python numbers) and, with
    ``path``, written there atomically; returns ``obj``."""
    import json

    text = json.dumps(obj, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    if path:
        atomic_write_text(path, text)
    print(text)
    return obj
