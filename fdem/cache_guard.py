"""Keeps Numba's on-disk cache of the engine from outliving the source it was compiled from.

Numba checks a cached function against its *own* file's time stamp only. ``run_loop`` (integrator.py)
inlines the kernels of kernels.py and contact.py, so after an edit to a kernel alone (a ``git pull``,
an editable install) the cache would keep running the old kernel, silently. On import, the package's
sources are hashed; when the hash differs from the one stamped beside the cache, the package's cache
files are removed and Numba recompiles once.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

STAMP = "numba_sources.sha256"


def sources_hash(pkg_dir: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(pkg_dir.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def cache_dirs(pkg_dir: Path) -> list[Path]:
    """Where Numba keeps this package's cache: ``__pycache__`` beside the sources and, when
    NUMBA_CACHE_DIR is set, the folder Numba names after the package's path below it
    (``<folder name>_<sha1 of its absolute path>``, numba.core.caching.UserProvidedCacheLocator)."""
    dirs = [pkg_dir / "__pycache__"]
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        folder = os.path.abspath(pkg_dir)
        dirs.append(Path(env) / f"{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}")
    return dirs


def clear_if_stale(pkg_dir: Path) -> bool:
    """Remove the package's Numba cache files when its sources changed since they were stamped.
    Returns True when files were removed. Never raises for a read-only install (nothing to guard:
    Numba cannot write a cache there either)."""
    digest = sources_hash(pkg_dir)
    cleared = False
    for d in cache_dirs(pkg_dir):
        stamp = d / STAMP
        try:
            if stamp.read_text().strip() == digest:
                continue
        except OSError:
            pass
        try:
            for f in list(d.glob("*.nbi")) + list(d.glob("*.nbc")):
                f.unlink(missing_ok=True)
                cleared = True
            d.mkdir(parents=True, exist_ok=True)
            tmp = d / f".{STAMP}.{os.getpid()}.tmp"
            tmp.write_text(digest + "\n")
            os.replace(tmp, stamp)
        except OSError:
            continue
    return cleared
