"""Would another rule for the self-calibration's lambda cover better? Checked out of sample on the
development runs only (issue 30; never the coverage benchmark's seeds 40 and 41).

``enkf.selfcal`` sets ``lambda = median(delta) / median(chi2_n)`` from the ``delta`` of the last
iteration's 25 runs used as data of known parameters. Here, from the ``delta_chi2`` lists that
``bench_emulated_likelihood`` stored for a development seed (50 and 51: 12 twins x 25 runs each), each rule
is scored leave-one-run-out: ``lambda`` from 24 runs, then whether the 25th run's ``delta / lambda`` lies
inside the chi-square 90 % and 50 % regions (300 checks per rule and seed; a calibrated rule gives 0.90
and 0.50; runs of one twin are not independent, so the binomial interval is a guide). The twins' truths
(12) are counted too, with ``lambda`` from all 25 runs. These are the joint regions of
both parameters; a marginal interval (what the README reports) can under-cover in one direction while
the joint region is calibrated.

    python studies/selfcal_rules.py studies/results/bench_emulated_likelihood_dev.json
"""

from __future__ import annotations

import json
import sys

import numpy as np
from scipy import stats

N_PARAMS = 2


def rules(n: int) -> dict:
    c50, c75, c90 = (stats.chi2.ppf(q, n) for q in (0.5, 0.75, 0.9))
    return {"median (enkf.selfcal)": lambda x: max(1.0, np.median(x) / c50),
            "75th percentile": lambda x: max(1.0, np.quantile(x, 0.75) / c75),
            "90th percentile": lambda x: max(1.0, np.quantile(x, 0.9) / c90),
            "larger of median and 90th": lambda x: max(1.0, np.median(x) / c50, np.quantile(x, 0.9) / c90)}


def score(twins: list, n: int = N_PARAMS) -> dict:
    c50, c90 = stats.chi2.ppf(0.5, n), stats.chi2.ppf(0.9, n)
    out = {}
    for name, rule in rules(n).items():
        in90, in50, truth90, lams = [], [], [], []
        for t in twins:
            delta = np.asarray(t["self_calibration"]["delta_chi2"], float)
            for i in range(delta.size):
                lam = rule(np.delete(delta, i))
                in90.append(delta[i] / lam <= c90)
                in50.append(delta[i] / lam <= c50)
            lam = rule(delta)
            lams.append(lam)
            truth90.append(t["delta_chi2_truth"] / lam <= c90)
        k = len(in90)
        out[name] = {"loo_runs": k, "loo_inside_90": float(np.mean(in90)),
                     "loo_inside_90_ci95": [float(v) for v in stats.binomtest(int(sum(in90)), k).proportion_ci()],
                     "loo_inside_50": float(np.mean(in50)), "truths_inside_90": int(sum(truth90)),
                     "twins": len(truth90), "median_lambda": float(np.median(lams))}
    return out


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    src = json.load(open(argv[0]))
    if src.get("seed") in (40, 41):
        raise SystemExit(f"{argv[0]}: seeds 40 and 41 are the coverage benchmark's: use a development seed")
    print(json.dumps({"benchmark": "selfcal_rules", "source": argv[0], "seed": src["seed"],
                      "rules": score(src["twins"])}, indent=1))


if __name__ == "__main__":
    main()
