"""The workflow's file contracts in one import: a re-export of the modules that hold them.

* :mod:`calibration.config_check`: :func:`validate_config` (schema, defaults, the checks a schema
  cannot express; every problem names its key and the config file that set it), :func:`load_yaml`,
  :func:`coerce_yaml_floats`.
* :mod:`calibration.runner`: :func:`run_member` (one ``python -m shpb simulate`` run with the
  exit-code contract 0 / 2 / 3, its ``curve.csv`` and ``run.json`` written atomically),
  :data:`CURVE_COLUMNS`, :func:`simulator_command`, :func:`simulate_argv`.
* :mod:`calibration.ensemble_files`: member folder names, a member's parameters, ``responses.csv``.
* :mod:`calibration.contracts`: the atomic writes and the base contracts.

The rule adapters in ``scripts/``, the ``Snakefile`` and the tests import from here; new code may
import the module that holds the name. Nothing here imports Snakemake.
"""

from __future__ import annotations

from .config_check import (ConfigError, apply_defaults, coerce_yaml_floats, config_sources,  # noqa: F401
                           load_config_file, load_yaml, validate_config)
from .contracts import (PARAM_NAMES, atomic_write_bytes, atomic_write_csv, atomic_write_json, atomic_write_text,  # noqa: F401
                        experiment_records, known_parameters, read_json, record_name)
from .ensemble_files import (combine_member_runs, member_ids, member_params, read_responses,  # noqa: F401
                             write_responses)
from .runner import (CURVE_COLUMNS, DEFAULT_SIMULATOR, SimulatorCrash, SimulatorRejected,  # noqa: F401
                     failed_curve_text, failure_card, run_member, simulate_argv, simulator_command)

__all__ = [
    "PARAM_NAMES", "CURVE_COLUMNS", "ConfigError", "SimulatorCrash", "SimulatorRejected", "load_yaml",
    "load_config_file", "config_sources", "validate_config",
    "apply_defaults", "atomic_write_text", "atomic_write_json", "atomic_write_csv", "read_json",
    "member_ids", "record_name", "experiment_records", "run_member", "simulator_command",
    "simulate_argv", "failed_curve_text", "failure_card", "member_params", "combine_member_runs",
    "write_responses", "read_responses", "known_parameters", "coerce_yaml_floats", "DEFAULT_SIMULATOR",
]
