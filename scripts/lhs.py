"""iter_0/params.csv: Latin hypercube sample of the prior box (calibration.experiment.initial_ensemble)."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.experiment import ExperimentSpec, initial_ensemble
from calibration.workflow_io import atomic_write_csv

exp = snakemake.wildcards.exp
spec = ExperimentSpec.from_config(exp, snakemake.config["experiments"][exp],
                                  sensitivity_report=snakemake.input.get("sensitivity"))
atomic_write_csv(initial_ensemble(spec), snakemake.output.params)
