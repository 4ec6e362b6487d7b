"""Test-session settings.

One BLAS thread per process: the suite runs simulations and Snakemake jobs on both cores while the
analyses solve small dense systems, and OpenBLAS's own threads on a busy machine made those solves
tens of times slower (an RBF fit of 100 runs: 113 ms against 0.9 ms). Set before NumPy is imported;
an explicit setting in the environment wins.
"""
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
