# Calibration workflow: LHS ensemble -> one FDEM simulation per member (and record) -> curves on the
# observation grid -> checkpoint analysis (ES-MDA / paper EnKF) -> next iteration or stop -> forecast
# with the posterior mean -> plots, tables, summary.json. See README.md, "Running the workflow".
#
# The config is validated (config/schema.yaml + calibration.workflow_io.validate_config) and the measured
# observation files are checked before any job runs; a bad key, value or file stops here with a message
# naming it. A record is reduced for that check once per content (calibration.record_check keeps the
# verdict's summary under .snakemake/fdem-records/), and once more by its observations job, which stores
# the reduction that every simulation of it reads.
import gc
from pathlib import Path

from snakemake.exceptions import WorkflowError
from snakemake.utils import min_version

from calibration.config_files import config_sources
from calibration.observations import ObservationFileError, cached_check_record
from calibration.record_check import code_digest
from calibration.workflow_io import ConfigError, validate_config

min_version("9.0")

# What Snakemake built before reading this file (its modules, plugins, command line) lives as long as the
# process: frozen out of the cyclic garbage collector, whose full passes over it were about 1 s of every
# dry run (issue 54; objects are still freed by reference counting, only cycles among them are never
# looked for again).
gc.freeze()


# The config files in merge order (config/config.yaml, each --configfile, --config), read again so that
# messages name them: a YAML syntax error in config/config.yaml with its line (Snakemake's own message
# names neither; a --configfile with one fails in Snakemake before this file runs: --verbose shows the
# line), a schema error with the file that set the key.
try:
    _config_sources = config_sources(
        (["config/config.yaml"] if Path("config/config.yaml").exists() else [])
        + [str(p) for p in workflow.overwrite_configfiles],
        overrides=getattr(workflow.config_settings, "config", None),
    )
except ConfigError as exc:
    raise WorkflowError(str(exc)) from None


configfile: "config/config.yaml"


try:
    _validated = validate_config(
        config,
        Path(workflow.basedir) / "config" / "schema.yaml",
        base_dir=".",
        sources=_config_sources,
    )
except ConfigError as exc:
    raise WorkflowError(str(exc)) from None
config.clear()
config.update(_validated)
# `diagnosis: {validation: loro}`: one fold experiment per record, that record held out (calibration.closing)
for _name, _exp in list(config["experiments"].items()):
    if (
        _exp.get("kind") == "measured"
        and (_exp.get("diagnosis") or {}).get("validation") == "loro"
    ):
        from calibration.diagnosis_config import loro_folds

        config["experiments"].update(loro_folds(_name, _exp))

if workflow.is_main_process:
    _code = code_digest()
    for _name, _exp in config["experiments"].items():
        _paths = list(_exp["observations"].get("records") or [])
        if _exp["observations"].get("incident_record"):
            _paths.append(_exp["observations"]["incident_record"])
        _paths += list((_exp.get("diagnosis") or {}).get("heldout_records") or [])
        for _path in _paths:
            try:
                # an invalid test (shpb.lab.validity) is refused as a calibration record unless allow_invalid
                cached_check_record(
                    _path,
                    (
                        _exp["observations"]["t_end"]
                        if _exp["kind"] == "measured"
                        else None
                    ),
                    refuse_invalid=_exp["kind"] == "measured"
                    and _path in (_exp["observations"].get("records") or [])
                    and not _exp["observations"].get("allow_invalid", False),
                    code=_code,
                )
            except ObservationFileError as exc:
                raise WorkflowError(f"experiment {_name!r}: {exc}") from None
    # stale temporaries of killed jobs are removed, member files that no longer match their manifest.json
    # (truncated, altered) put out of date to be simulated again: docs/workflow.md, after a kill
    from calibration.heal import heal_results

    heal_results("results")

from calibration.heal import mark_job_parent

mark_job_parent()  # every Snakemake process reading this (also a cluster job step): its jobs die with it


report: "report/workflow.rst"


include: "rules/common.smk"
include: "rules/observations.smk"
include: "rules/ensemble.smk"
include: "rules/assimilate.smk"
include: "rules/forecast.smk"
include: "rules/report.smk"
include: "rules/diagnosis.smk"
include: "rules/sensitivity.smk"


rule all:
    default_target: True
    input:
        expand("results/{exp}/summary.json", exp=calibrated_experiments()),
        expand("results/{exp}/summary.html", exp=calibrated_experiments()),
        expand(
            "results/{exp}/plots/{plot}.png", exp=calibrated_experiments(), plot=PLOTS
        ),
        expand("results/{exp}/diagnosis/report.json", exp=diagnosed_experiments()),
        expand("results/{exp}/diagnosis/check.json", exp=diagnosed_experiments()),
        expand("results/{exp}/diagnosis/refit.json", exp=refitted_experiments()),
        expand("results/{exp}/diagnosis/realrun.json", exp=realrun_experiments()),
        expand("results/{exp}/loro/summary.json", exp=loro_experiments()),
        expand("results/{exp}/sensitivity/report.json", exp=SENSITIVITY_RUN),


# At the end of a run (not a dry run): each experiment's verdict, stop reason, posterior mean with its
# 90 % interval and the path of its summary.json (calibration.run_summary; never fails the run).
onsuccess:
    try:
        from calibration.run_summary import experiments_of_run, run_summary

        _targets = (
            getattr(getattr(workflow, "dag_settings", None), "targets", None) or ()
        )
        print(
            run_summary(
                experiments_of_run(
                    _targets, list(EXPERIMENTS), calibrated_experiments()
                ),
                "results",
            ),
            flush=True,
        )
    except Exception as exc:  # noqa: BLE001
        print(f"(no run summary: {type(exc).__name__}: {exc})", flush=True)
