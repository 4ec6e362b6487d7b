"""Figure of the approximation error's paired runs cached by ``bench_coverage.py --approximation-pairs``.

    python studies/plot_approximation_pairs.py benchmarks/cache/coverage_v3/approx-24/pairs_41.json \
        --out benchmarks/results/approximation_pairs_seed41.png

Left: a few design points' curves at the finer preset and at the coarse one (mean of its
realizations). Right: every pair's difference, their mean (the offset subtracted from the data) and
the +-1.645 sd band of the pairs' raw scatter (the error model adds it less the coarse runs' own
variability, ``coarse_variability: subtracted``) (:func:`enkf.approximation.approximation_error`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_coverage import twin_experiment  # noqa: E402
from calibration.observations import observation_grid  # noqa: E402
from enkf.approximation import approximation_error  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pairs")
    ap.add_argument("--out", required=True)
    ap.add_argument("--shown", type=int, default=4)
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cached = json.loads(Path(args.pairs).read_text())
    o = twin_experiment()["observations"]
    t = observation_grid(o["t_start"], o["t_end"], o["dt"])
    Y = np.array(cached["curves"], float)
    n = len(cached["design"])
    Y = Y.reshape(n, -1, t.size)
    fine, coarse = Y[:, 0], Y[:, 1:].mean(axis=1)
    # the raw scatter of the pairs (before the coarse runs' own variability is taken off): what the figure shows
    offset, M, info = approximation_error(fine, Y[:, 1:], t, coarse_variability="counted")
    us = t * 1e6
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for i in range(min(args.shown, n)):
        line = a.plot(us, fine[i] / 1e6, lw=1.2, label=f"sigma_t {cached['design'][i][0] / 1e6:.0f} MPa")[0]
        a.plot(us, coarse[i] / 1e6, lw=1.0, ls="--", color=line.get_color())
    a.set(xlabel="time [us]", ylabel="disc stress [MPa]", title="fine (solid) and coarse mean (dashed)")
    a.legend(fontsize=8)
    b.plot(us, (fine - coarse).T / 1e6, color="0.7", lw=0.6)
    sd = M.std if M is not None else np.zeros_like(t)
    b.plot(us, offset / 1e6, color="C3", lw=2, label=f"mean (offset, rms {info['offset_rms_Pa'] / 1e6:.2f} MPa)")
    b.fill_between(us, (offset - 1.645 * sd) / 1e6, (offset + 1.645 * sd) / 1e6, color="C3", alpha=0.2,
                   label=f"90 % band of the scatter (rms {info['rms_Pa'] / 1e6:.2f} MPa, {info['corr_time_s'] * 1e6:.0f} us)")
    b.set(xlabel="time [us]", ylabel="fine - coarse [MPa]", title=f"{info['n_pairs_used']} pairs")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
