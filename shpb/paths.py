"""Where the measured data live: ``<repo>/data`` (shipped with the repository), or a folder of the user's.

``data/`` holds one folder per source (``freiburg-rae-rock-shpb``, ``lanl-hoppybar-examples``,
``yao-shpb-shtb-metals-epoxy``), each with its ``PROVENANCE.md``. Set the environment variable
``FDEM_DATA_DIR`` to a folder laid out the same way to use your own data instead (e.g. the full
Freiburg set with more lithologies). Records named in a config are paths of their own and do not go
through here. Every function raises :class:`FileNotFoundError` naming the path it looked at and the
variable that sets it; nothing returns a silent ``None``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = [
    "ENV_DATA_DIR",
    "repository_root",
    "data_dir",
    "freiburg_data_dir",
    "freiburg_raw_files",
    "lanl_data_dir",
    "yao_data_dir",
    "data_file",
    "FREIBURG_LITHOLOGIES",
]

#: Environment variable that replaces ``<repo>/data`` as the measured-data folder.
ENV_DATA_DIR = "FDEM_DATA_DIR"

#: Lithology codes of the Freiburg (Rae et al. 2021) raw records shipped in data/.
FREIBURG_LITHOLOGIES = ("CaMa", "SaLi", "SeeSst")


def repository_root() -> Path:
    """The repository checkout that holds this package (``<repo>/shpb/paths.py`` -> ``<repo>``)."""
    return Path(__file__).resolve().parents[1]


def _origin() -> tuple[Path, str]:
    env = os.environ.get(ENV_DATA_DIR)
    if env:
        return Path(env).expanduser().resolve(), f"set by the environment variable {ENV_DATA_DIR}={env!r}"
    return repository_root() / "data", f"the repository's data folder (set {ENV_DATA_DIR} to use another)"


def data_dir() -> Path:
    """The measured-data folder: ``$FDEM_DATA_DIR`` if set, else ``<repo>/data``."""
    path, origin = _origin()
    if not path.is_dir():
        raise FileNotFoundError(f"measured-data folder not found: {path} ({origin})")
    return path


def _source_dir(name: str) -> Path:
    path = data_dir() / name
    if not path.is_dir():
        raise FileNotFoundError(f"data folder {name!r} not found: {path} ({_origin()[1]})")
    return path


def freiburg_data_dir() -> Path:
    """``<data>/freiburg-rae-rock-shpb`` (Rae et al., Freiburg rock SHPB)."""
    return _source_dir("freiburg-rae-rock-shpb")


def lanl_data_dir() -> Path:
    """``<data>/lanl-hoppybar-examples`` (LANL HopPyBar Kolsky-bar examples)."""
    return _source_dir("lanl-hoppybar-examples")


def yao_data_dir() -> Path:
    """``<data>/yao-shpb-shtb-metals-epoxy/impact_compression`` (H. Yao's SHPB compression records)."""
    path = _source_dir("yao-shpb-shtb-metals-epoxy") / "impact_compression"
    if not path.is_dir():
        raise FileNotFoundError(f"data folder not found: {path} ({_origin()[1]})")
    return path


def data_file(path: Path) -> Path:
    """``path`` if it is a file, else FileNotFoundError naming it and where the data folder comes from."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"data file not found: {path} ({_origin()[1]})")
    return Path(path)


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
            raise FileNotFoundError(f"no Freiburg raw records (*.txt) for lithology {lith!r} in {folder} "
                                    f"({_origin()[1]})")
        files.extend(found)
    return files
