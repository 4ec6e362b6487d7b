"""Every experiment of the shipped configs as the workflow sees it (tests/test_process.py,
tests/test_one_posterior.py), and the default twin with settings of a test's own."""
from __future__ import annotations

import copy
from pathlib import Path

from snakemake.utils import update_config

from calibration.config_files import config_sources
from calibration.workflow_io import validate_config

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "config" / "schema.yaml"


def shipped_experiments() -> dict[str, tuple[str, dict]]:
    """Every experiment of the shipped configs (config.yaml alone and merged with each other config/*.yaml,
    as Snakemake merges them), validated; keyed ``file:experiment``."""
    out = {}
    extras = [None] + sorted(p.name for p in (REPO / "config").glob("*.yaml") if p.name not in ("config.yaml", "schema.yaml"))
    for extra in extras:
        sources = config_sources([REPO / "config" / "config.yaml"] + ([REPO / "config" / extra] if extra else []))
        merged: dict = {}
        for _, data in sources:
            update_config(merged, copy.deepcopy(data))
        cfg = validate_config(merged, SCHEMA, base_dir=REPO, sources=sources)
        for name, exp in cfg["experiments"].items():
            out[f"{extra or 'config.yaml'}:{name}"] = (name, exp)
    return out


def twin_ref(**settings) -> dict:
    """config.yaml's ``twin_ref`` with ``settings`` (its top-level keys, e.g. ``emulated`` or ``posterior``)
    replacing its own, validated as the workflow validates it (a bad value raises the workflow's error)."""
    from calibration.workflow_io import load_yaml

    cfg = load_yaml(REPO / "config" / "config.yaml")
    cfg["experiments"]["twin_ref"].update(settings)
    return validate_config(cfg, SCHEMA, base_dir=REPO)["experiments"]["twin_ref"]
