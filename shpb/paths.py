"""Where the shared (not version-controlled) data live.

The measured SHPB records are kept outside the repository, in ``../shared`` beside the checkout
(``<repo>/../shared/data/measured/...``). Set the environment variable ``FDEM_SHARED_DIR`` to point
somewhere else. Every function here raises :class:`FileNotFoundError` with a message that names the
path it looked at and how to fix it; nothing returns a silent ``None``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = [
    "ENV_SHARED_DIR",
    "repository_root",
    "shared_data_dir",
    "measured_data_dir",
    "freiburg_data_dir",
    "freiburg_raw_files",
    "FREIBURG_LITHOLOGIES",
]

#: Environment variable that overrides the location of the shared directory.
ENV_SHARED_DIR = "FDEM_SHARED_DIR"

#: Lithology codes of the Freiburg (Rae et al. 2021) raw records held in the shared data.
FREIBURG_LITHOLOGIES = ("CaMa", "SaLi", "SeeSst")


def repository_root() -> Path:
    """The repository checkout that holds this package (``<repo>/shpb/paths.py`` -> ``<repo>``)."""
    return Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    """The shared directory: ``$FDEM_SHARED_DIR`` if set, else ``<repo>/../shared``.

    Raises
    ------
    FileNotFoundError
        If the directory does not exist, with the path tried and how to set it.
    """
    env = os.environ.get(ENV_SHARED_DIR)
    if env:
        path = Path(env).expanduser().resolve()
        origin = f"environment variable {ENV_SHARED_DIR}={env!r}"
    else:
        path = repository_root().parent / "shared"
        origin = f"default location beside the checkout (set {ENV_SHARED_DIR} to override)"
    if not path.is_dir():
        raise FileNotFoundError(
            f"shared data directory not found: {path} ({origin}). The measured SHPB records "
            f"are expected under <shared>/data/measured/; put the shared folder there or point "
            f"{ENV_SHARED_DIR} at it."
        )
    return path


def measured_data_dir() -> Path:
    """``<shared>/data/measured``: one folder per lab, each with a PROVENANCE.md."""
    path = shared_data_dir() / "data" / "measured"
    if not path.is_dir():
        raise FileNotFoundError(f"measured-data directory not found: {path}")
    return path


def freiburg_data_dir() -> Path:
    """``<shared>/data/measured/freiburg-rae-rock-shpb`` (Rae et al., Freiburg rock SHPB)."""
    path = measured_data_dir() / "freiburg-rae-rock-shpb"
    if not path.is_dir():
        raise FileNotFoundError(f"Freiburg SHPB data directory not found: {path}")
    return path


def freiburg_raw_files(lithologies: tuple[str, ...] | list[str] = FREIBURG_LITHOLOGIES) -> list[Path]:
    """Sorted raw DAQ files ``Rae2021/SHPBdata/<lith>/*.txt`` for the given lithology codes.

    Raises
    ------
    FileNotFoundError
        If a lithology folder is missing or holds no ``.txt`` record.
    """
    root = freiburg_data_dir() / "Rae2021" / "SHPBdata"
    files: list[Path] = []
    for lith in lithologies:
        folder = root / lith
        found = sorted(folder.glob("*.txt"))
        if not found:
            raise FileNotFoundError(f"no Freiburg raw records (*.txt) for lithology {lith!r} in {folder}")
        files.extend(found)
    return files
