"""Every simulation job (rules/simulate.smk, `rule simulate`): one batch of runs of one stage, in this
process (calibration.batch.run_batch). What differs between the stages comes in each run's params
(rules/inputs.smk, batch_runs): where the parameters are read (calibration.ensemble_files.simulation_params),
the record, the mesh seed, the fracture snapshots, the entries added to run.json and whether a failed run
fails the job. A run another experiment already made with the same request is copied from it
(calibration.run_store)."""
# the batch's own module, not calibration.workflow_io: that one also loads the config checks, which a
# simulation job never runs (0.09-0.17 s of every job's start, measured with python -X importtime)
from calibration.batch import run_batch
from calibration.run_store import STORE

run_batch(snakemake.params.runs, batch_path=snakemake.output.batch, attempt=snakemake.resources.attempt,
          max_attempts=snakemake.params.max_attempts, params_file=snakemake.input.get("params"),
          experiments=snakemake.config["experiments"], label=snakemake.wildcards.stage,
          log_path=snakemake.log[0], store=STORE)
# Every file of the batch is written and closed (run_batch returned): leave without the interpreter's
# teardown, which with the engine loaded took 0.3 s of each job (its modules' and the compiled code's
# finalizers; nothing of ours runs at exit). A failed batch raised above and exits as Python does.
import os  # noqa: E402
import sys  # noqa: E402

sys.stdout.flush()
sys.stderr.flush()
os._exit(0)
