"""The workflow's config files, read the way Snakemake merges them, for messages that name them.

Snakemake deep-merges ``config/config.yaml`` (the Snakefile's ``configfile:``), then each
``--configfile`` in order, then ``--config`` overrides, and the workflow validates the merged dict
(:func:`calibration.config_check.validate_config`). Given :func:`config_sources`, a schema error names
the files and, after each problem, the file that set the key; a YAML syntax error in a file read here
names the file, line and column (Snakemake's own message names neither).
"""
from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from .contracts import ConfigError

__all__ = ["safe_load", "load_config_file", "config_sources", "error_origin", "coerce_numbers"]


def safe_load(text: str):
    """``yaml.safe_load(text)``, parsed by libyaml where PyYAML was built with it: the same Python
    constructor and resolver build the same data, several times faster (config/schema.yaml: 0.14 s
    of every workflow start in pure Python, 0.02 s with libyaml; issue 54). A document libyaml refuses
    is read again by the pure-Python parser, so an error reads exactly as ``yaml.safe_load``'s."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", None)
    if loader is not None:
        try:
            return yaml.load(text, Loader=loader)
        except yaml.YAMLError:
            pass
    return yaml.safe_load(text)


def load_config_file(path: str | Path):
    """A config file as Snakemake reads it (JSON, else YAML). A YAML syntax error is a
    :class:`ConfigError` naming the file, line and column."""
    import yaml

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config file: {exc.strerror or exc}") from None
    try:
        return json.loads(text)
    except ValueError:
        pass
    try:
        return safe_load(text)
    except yaml.YAMLError as exc:
        mark, cmark = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
        mark = mark or cmark
        where = f"{path}, line {mark.line + 1}, column {mark.column + 1}" if mark is not None else str(path)
        context = getattr(exc, "context", None)
        if context and cmark is not None and cmark is not mark:
            context += f" (from line {cmark.line + 1}, column {cmark.column + 1})"
        what = ", ".join(str(p) for p in (context, getattr(exc, "problem", None)) if p)
        raise ConfigError(f"{where}: YAML syntax error: {what or exc}") from None


def config_sources(paths: Sequence[str | Path], overrides: Mapping | None = None) -> list[tuple[str, dict]]:
    """``[(name, data)]`` of the config files, lowest precedence first (``config/config.yaml``, then each
    ``--configfile``; ``--config`` overrides last, named ``--config``): ``validate_config``'s ``sources``.
    Raises :class:`ConfigError` for a file that cannot be read or parsed (file, line, column)."""
    seen, kept = set(), []
    for p in reversed(list(paths)):  # a file given twice counts where it wins the merge: its last place
        if Path(p).resolve() not in seen:
            seen.add(Path(p).resolve())
            kept.insert(0, p)
    out = [(_shown(p), load_config_file(p)) for p in kept]
    if overrides:
        out.append(("--config", dict(overrides)))
    return [(name, data if isinstance(data, Mapping) else {}) for name, data in out]


def _shown(path: str | Path) -> str:
    """The path as the user would write it: relative to the working folder when inside it."""
    p = Path(path)
    if p.is_absolute():
        try:
            return str(p.relative_to(Path.cwd()))
        except ValueError:
            pass
    return str(path)


def _set_keys(data: Mapping, prefix: str = "") -> list[tuple[str, bool]]:
    """``[(dotted key, value is a mapping)]`` of every key a file sets."""
    keys = []
    for k, v in data.items():
        keys.append((f"{prefix}{k}", isinstance(v, Mapping)))
        if isinstance(v, Mapping):
            keys += _set_keys(v, f"{prefix}{k}.")
    return keys


def error_origin(message: str, sources: Sequence[tuple[str, Mapping]]) -> str:
    """``" (set in FILE)"`` for a problem ``key.path: ...``: the last file that sets the key's value
    (or a list or scalar above it), which wins the merge; for a mapping, every file that sets keys in
    it; ``""`` if no file does."""
    key = message.split(": ", 1)[0]
    if ": " not in message or " " in key:
        return ""
    keys = [(name, _set_keys(data)) for name, data in sources]
    value = [n for n, ks in keys if any((k == key or key.startswith(k + ".")) and not block for k, block in ks)]
    inside = [n for n, ks in keys if any(k == key or k.startswith(key + ".") for k, _ in ks)]
    names = value[-1:] or inside
    return f" (set in {', '.join(names)})" if names else ""


def coerce_numbers(instance, schema: Mapping):
    """Numbers given as strings where the schema wants a number, recursively.

    Snakemake's ``--config key={"paper": 14400}`` hands the inner values over as strings ('14400'),
    so without this a documented override fails as "'14400' is not of type 'integer'". Only fields
    whose schema type is integer or number (and not string) are converted, and only when the whole
    string is the number; everything else is left for the schema to judge.
    """
    if not isinstance(schema, Mapping):
        return instance
    if isinstance(instance, dict):
        props = schema.get("properties", {})
        extra = schema.get("additionalProperties")
        return {k: coerce_numbers(v, props.get(k, extra if isinstance(extra, Mapping) else {}))
                for k, v in instance.items()}
    if isinstance(instance, list) and isinstance(schema.get("items"), Mapping):
        return [coerce_numbers(v, schema["items"]) for v in instance]
    types = schema.get("type")
    types = [types] if isinstance(types, str) else list(types or [])
    if isinstance(instance, str) and "string" not in types:
        text = instance.strip()
        if "integer" in types:
            try:
                return int(text)
            except ValueError:
                pass
        if "number" in types:
            try:
                return float(text)
            except ValueError:
                pass
    return instance
