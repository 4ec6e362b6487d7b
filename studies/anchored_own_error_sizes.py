"""How large the anchored model's own error is (issue 53): per record of a run's diagnosis, the rms of
its leave-one-out error along the axes (enkf.emulator.AnchoredEmulator.loo_residuals, as
calibration.protocol.emulator_errors carries it) against the instrument noise and the mesh scatter S,
and per axis the rms over times of that axis' leave-one-out residuals.

    python studies/anchored_own_error_sizes.py RESULTS/<experiment>/diagnosis/selection.pkl --out JSON
"""
from __future__ import annotations

import argparse
import json
import pickle

import numpy as np

from calibration.protocol import emulator_errors


def _rms_diag(err) -> np.ndarray:
    return np.sqrt(np.diag(err.dense()))


def sizes(selection_pkl: str) -> dict:
    with open(selection_pkl, "rb") as fh:
        d = pickle.load(fh)
    model = d["model"]
    records = list(model.emulators)
    E = emulator_errors(model, records)
    out = {}
    for r in records:
        em = model.emulators[r]
        per_axis = {name: round(float(np.sqrt(np.mean(res ** 2))) / 1e6, 2)
                    for name, res in em.loo_residuals_by_axis().items()}
        sd = _rms_diag(E[r])
        out[r] = {"E_rms_MPa": round(float(np.sqrt(np.mean(sd ** 2))) / 1e6, 2),
                  "E_max_MPa": round(float(sd.max()) / 1e6, 2),
                  "noise_sd_MPa": round(float(np.sqrt(np.mean(_rms_diag(d["noise"][r]) ** 2))) / 1e6, 2),
                  "S_rms_MPa": round(float(np.sqrt(np.mean(_rms_diag(d["simulator"][r]) ** 2))) / 1e6, 2),
                  "axis_rms_MPa": per_axis}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("selection")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    doc = {"what": "the anchored model's own error (leave-one-out along each axis) against the noise and the "
                   "mesh scatter S per record, and per axis (rms over times and that axis' runs); MPa",
           "records": sizes(args.selection)}
    with open(args.out, "w") as fh:
        fh.write(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
