"""iter_<k>/analysis.json: misfit, failed members, stop decision and the next ensemble (checkpoint): the
experiment's calibration process rebuilt from the iteration files and told this iteration's runs."""
from calibration.job_log import log_to

_console = log_to(snakemake.log[0])  # the job's output to its log; the analysis line also to the run's stdout

import pandas as pd

from calibration.experiment import ExperimentSpec, analysis_step
from calibration.observations import read_observations
from calibration.run_summary import analysis_line
from calibration.workflow_io import atomic_write_json, read_responses

exp = snakemake.wildcards.exp
spec = ExperimentSpec.from_config(exp, snakemake.config["experiments"][exp])
status, Y = read_responses(snakemake.input.responses)
obs = read_observations(snakemake.input.obs, snakemake.input.obs_meta)
history = [(pd.read_csv(p), read_responses(r)[1])
           for p, r in zip(snakemake.input.history_params, snakemake.input.history_responses)]
_, replicates = read_responses(snakemake.input.replicates)
result = analysis_step(spec, int(snakemake.wildcards.it), pd.read_csv(snakemake.input.params), Y, status, obs,
                       pd.read_csv(snakemake.input.prior), history, replicates=replicates)
atomic_write_json(snakemake.output.analysis, result)
line = analysis_line(result)
print(line, flush=True)
print(line, file=_console, flush=True)  # the misfit of this iteration on the run's output too
