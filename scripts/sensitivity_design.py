"""sensitivity/design.csv: SALib's design (calibration.sensitivity.design), one row per simulation."""
from calibration.job_log import log_to

log_to(snakemake.log[0])  # the job's output goes to its log (rules/*.smk)

from calibration.sensitivity import SensitivitySpec, design
from calibration.workflow_io import atomic_write_csv

exp = snakemake.wildcards.exp
spec = SensitivitySpec.from_config(exp, snakemake.params.exp)
frame = design(spec)
# The DAG was built from spec.n_simulations (rules/sensitivity.smk): a sampler that disagrees would
# leave rows without a job or jobs without a row.
if len(frame) != spec.n_simulations:
    raise RuntimeError(f"experiment {exp!r}: SALib's {spec.method} design has {len(frame)} rows, the workflow "
                       f"expected {spec.n_simulations}")
frame.insert(0, "member", range(len(frame)))  # the column calibration.workflow_io.member_params reads
atomic_write_csv(frame, snakemake.output.design)
