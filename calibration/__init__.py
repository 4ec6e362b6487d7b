"""The calibration application: the only package that joins the SHPB model (:mod:`shpb`) and the
inference (:mod:`enkf`).

Observations from twins and measured records (:mod:`.observations`), the experiment's inference
settings and its analysis steps, stop decision and summary (:mod:`.experiment`), the reported
posterior (:mod:`.posterior`), the verdict (:mod:`.verdict`), the global sensitivity stage
(:mod:`.sensitivity`), closing the loop on SHPB experiments (the frozen protocol: :mod:`.closing`,
:mod:`.protocol`, the emulated FDEM model :mod:`.diagnose`, test covariates :mod:`.covariates`), the config
validation (:mod:`.config_check`), the member runner (:mod:`.runner`), the ensemble files
(:mod:`.ensemble_files`; the three re-exported by :mod:`.workflow_io`) and the plots (:mod:`.plots`). The Snakemake
rules call these through the adapters in ``scripts/``.
"""
import sys as _sys

# A Snakemake job script (Snakemake's preamble puts its `snakemake` object, snakemake.script.Snakemake,
# in __main__ before the script's imports) dies with the Snakemake process that started it: a SIGKILLed
# Snakemake then leaves no job running on to write its outputs after the kill (calibration.heal).
_job = type(getattr(_sys.modules.get("__main__"), "snakemake", None))
if _job.__name__ == "Snakemake" and _job.__module__.startswith("snakemake."):
    from .heal import die_with_parent as _die_with_parent

    _die_with_parent()
