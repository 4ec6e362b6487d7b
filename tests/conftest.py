"""Test-session settings.

One BLAS thread per process: the suite runs simulations and Snakemake jobs on both cores while the
analyses solve small dense systems, and OpenBLAS's own threads on a busy machine made those solves
tens of times slower (an RBF fit of 100 runs: 113 ms against 0.9 ms). Set before NumPy is imported;
an explicit setting in the environment wins.
"""
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


# The two xdist workers take whole files (--dist loadfile) in the order of the collection
# (--no-loadscope-reorder). Longest first: with the files in name order the end-to-end file
# test_workflow.py (about 400 s) started last and one worker idled for minutes (876 s against 685 s
# longest-first, from one run's per-file times). The seconds below are that run's, rounded; a file
# not listed runs after these, in name order. Re-measure with `pytest --durations=0 --junitxml=...`.
_SECONDS_PER_FILE = {
    "test_workflow.py": 410, "test_own_data.py": 165, "test_sensitivity.py": 95,
    "test_calibration_verdict.py": 80, "test_ces.py": 60, "test_protocol_selection.py": 55,
    "test_approximation_error.py": 60, "test_shpb_models.py": 47, "test_report_summary.py": 42,
    "test_fdem_fracture.py": 42, "test_disc_fracture.py": 34, "test_slurm_grouping.py": 30,
    "test_planted_closure_fdem.py": 30, "test_first_contact.py": 26, "test_heal.py": 22,
    "test_covariates.py": 21,
}


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(sorted(_SECONDS_PER_FILE, key=lambda f: -_SECONDS_PER_FILE[f]))}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: file order kept within a rank
