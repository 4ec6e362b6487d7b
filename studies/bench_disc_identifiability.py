"""What the Brazilian disc's stress curve says about its parameters, locally around the Table 2
reference (sigma_t 45 MPa, E_t 500 J/m^2): each parameter is changed by a few per cent, one at a time,
and the curve's change is measured in units of the twin experiments' noise (1 % of the reference
peak), separately before the failure peak (0 to t_peak - 5 us) and after it, with the change of the
failure peak itself. A smooth, informative response changes in proportion to the parameter change;
a chaotic one changes by many noise sd for any small change, in no order.

Prints one JSON object. Usage: python studies/bench_disc_identifiability.py [--preset standard]
[--extra sigma_t=47.995e6,E_t=447.3 ...] (extra points, e.g. a calibration's posterior mean).
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np

#: (label, parameter changes) around the reference, as fractions of the reference values.
CHANGES = [("sigma_t", f) for f in (0.005, -0.005, 0.01, -0.01, 0.02, -0.02, 0.2)] + \
          [("E_t", f) for f in (0.05, -0.05, 0.10, -0.10, 0.5)] + \
          [("sigma_n", f) for f in (0.05, -0.05, 0.2)]


def _on_grid(out, grid):
    """The curve on the 1 us grid, as the workflow puts simulations on the observation grid."""
    from calibration.observations import curve_on_grid
    return curve_on_grid(out.columns["time_s"], out.columns["stress_Pa"], grid)


def main():
    from shpb.parameters import defaults
    from shpb.simulate import simulate

    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="standard")
    ap.add_argument("--extra", action="append", default=[],
                    help="comma-separated name=value parameter set to compare with the reference")
    args = ap.parse_args()
    t_end = 160e-6
    ref_params = defaults("brazilian_disc")
    ref = simulate("brazilian_disc", args.preset, t_end=t_end)
    grid = np.arange(0.0, t_end + 0.5e-6, 1e-6)
    y0 = _on_grid(ref, grid)
    sd = 0.01 * float(y0.max())
    t_peak = ref.run["fracture"]["peak_t_s"]
    pre = grid <= t_peak - 5e-6
    post = ~pre
    points = [(f"{name} {frac:+.1%}", {name: ref_params[name] * (1.0 + frac)}) for name, frac in CHANGES]
    for text in args.extra:
        p = {k: float(v) for k, v in (kv.split("=") for kv in text.split(","))}
        points.append((text, p))
    rows = []
    for label, p in points:
        out = simulate("brazilian_disc", args.preset, params=p, t_end=t_end)
        d = (_on_grid(out, grid) - y0) / sd
        f = out.run["fracture"]
        rows.append({"change": label, "params": p, "status": out.run["status"],
                     "rms_change_before_peak_sd": float(np.sqrt(np.mean(d[pre] ** 2))),
                     "rms_change_after_peak_sd": float(np.sqrt(np.mean(d[post] ** 2))),
                     "peak_Pa": f["peak_stress_Pa"], "peak_change_sd": (f["peak_stress_Pa"] - ref.run["fracture"]["peak_stress_Pa"]) / sd,
                     "peak_t_s": f["peak_t_s"]})
    print(json.dumps({"benchmark": "disc_identifiability", "preset": args.preset, "cores_on_machine": os.cpu_count(),
                      "noise_sd_Pa": sd, "reference_peak_Pa": ref.run["fracture"]["peak_stress_Pa"],
                      "reference_peak_t_s": t_peak, "window_s": t_end, "changes": rows}, indent=1))


if __name__ == "__main__":
    main()
