#!/usr/bin/env bash
# Installs this checkout's packages (fdem, shpb, enkf, calibration; pyproject.toml) into the conda
# environment Snakemake has just created from workflow.yaml, without touching its dependencies.
# Snakemake runs this script inside that environment from the run's working directory, which is in
# the checkout (the repository root, or .test with --directory .test).
set -euo pipefail
python -m pip install --no-deps --no-build-isolation -e "$(git rev-parse --show-toplevel)"
