"""iter_<k>/params.csv: the analysis ensemble stored by iteration k-1's analysis."""
from calibration.experiment import params_frame
from calibration.workflow_io import atomic_write_csv, read_json

nxt = read_json(snakemake.input.analysis)["next_params"]
if nxt is None:
    raise RuntimeError(f"{snakemake.input.analysis} holds no analysis ensemble (the ES-MDA schedule is complete)")
atomic_write_csv(params_frame(nxt["values"], nxt["names"]), snakemake.output.params)
