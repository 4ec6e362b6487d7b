"""Which parameter variance the check's band discrepancy is read net of, chosen on calibration records only.

Why: a band's discrepancy ``D`` is the other calibration records' cross-validated residuals squared,
less the variance the band's other terms already count there (calibration.closing._cv_residuals). One
of those terms is the spread of the record's prediction over the posterior members x population draws
of its per-record effects (a face gap). A calibration record is predicted from a population of the
*other* calibration records (three in a five-record series), whose predictive is a Student t with
k - 2 degrees of freedom (one, for three records; enkf.diagnosis.population): a spread much wider than
the error its point prediction actually makes. Subtracting it leaves ``D`` near zero after the loop
(0.0-3.2 MPa rms on the gated sandstone folds, against 7-10 MPa of that parameter term), and a held-out
record, predicted from one more record (t with two degrees of freedom), then gets a band narrower than
its error. The forms compared, each building ``D`` at the shipped window from the other calibration
records' residuals:

* ``predictive`` (the shipped form): net of the t population draws' spread;
* ``plugin``: net of the spread of normal population draws (``df = inf``: the variance the record's
  value actually varies by if ``tau`` is right), the band still drawing from the t;
* ``lumped``: net of the posterior members' spread at the population's median only, the band likewise
  without population draws: the records' between-test variation read off the residuals instead of the
  population model.

Decision rule, fixed in this commit before the study runs: every calibration record's band at the
shipped step (after the loop; the base model has no per-record effect, so its bands do not depend on
the form) over every fold of the two gated leave-one-record-out series (sandstone 5 x 4 bands, marble
4 x 3), scored by its own curve (interval score, the proper score of the 90 % band). A form's score is
the mean over those bands of its interval score over the shipped form's on the same band (scale-free:
the marble's errors are larger). The form with the lowest score is adopted if that score is below 0.99;
otherwise the shipped form stays. Held-out records are not read.

    python studies/band_parameter_term.py <clone root> <series> [<clone root> <series> ...] --out F
"""
from __future__ import annotations

import json
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from calibration.closing import _mean_block, _window_samples  # noqa: E402
from calibration.observations import read_observations  # noqa: E402
from calibration.protocol import real_curves  # noqa: E402
from calibration.walk import check_runs_of  # noqa: E402
from studies.band_discrepancy import score_series  # noqa: E402
from enkf.diagnosis.band import plugin_draws, replicate_variance, residual_discrepancy, run_band  # noqa: E402
from enkf.diagnosis.crossval import seed_for  # noqa: E402
from enkf.diagnosis.population import record_name  # noqa: E402

FORMS = ("predictive", "plugin", "lumped")
ADOPT_BELOW = 0.99


def _members_draws(model, spec, fit, pred) -> np.ndarray:
    """The record's curves over the posterior members with its per-record values at the population median."""
    names = spec.shared + [record_name(p, pred.record) for p in spec.per_record]
    N = fit.params.shape[0]
    Xs = np.column_stack([fit.column(n) for n in spec.shared]
                         + [np.full(N, pred.point[record_name(p, pred.record)]) for p in spec.per_record])
    return np.asarray(model.forward(names, [pred.record])(Xs), dtype=float)


def _form_draws(form, model, spec, fold, seed) -> tuple[np.ndarray, np.ndarray]:
    """``(draws netted out of D, draws the band carries)`` of one calibration record's prediction."""
    pred = fold["prediction"]
    if form == "predictive" or not spec.per_record:
        return pred.draws, pred.draws
    if form == "plugin":
        return plugin_draws(model, spec, fold, seed=seed), pred.draws
    members = _members_draws(model, spec, fold["fit"], pred)
    return members, members


def score_fold(fold_dir: Path) -> dict:
    state = pickle.loads((fold_dir / "diagnosis" / "selection.pkl").read_bytes())
    rows, runs = check_runs_of(fold_dir / "diagnosis")
    obs = read_observations(fold_dir / "observations" / "obs.csv", fold_dir / "observations" / "obs.json")
    sel, model, noise = state["selection"], state["model"], state["noise"]
    real = real_curves(rows, runs, model)
    seed = int(sel.settings.get("seed", 0))
    # the shipped step (the walk also ran the steps it refuted)
    k = int(json.loads((fold_dir / "diagnosis" / "report.json").read_text())["shipped_step"])
    st = sel.step(k)
    calib = list(obs.records)
    pooled = _mean_block([np.diag(noise[r].dense()) for r in calib])
    window = _window_samples(obs.time[obs.record_slice(calib[0])])
    out = {"step": k, "model": st.spec.label(), "bands": {}}
    per_form = {}
    for form in FORMS:
        res, carry = {}, {}
        for r in calib:
            got = real["cv"][k].get(r)
            if got is None:
                continue
            Y = np.array(got, float, ndmin=2)
            fold = st.cv.folds[r]
            netted, carried = _form_draws(form, model, st.spec, fold, seed)
            S, _ = replicate_variance([c[r] for c in real["cv"].values() if c.get(r) is not None])
            S = np.zeros(Y.shape[1]) if S is None else S
            counted = np.var(netted - fold["prediction"].curve, axis=0) + S * (1 + 1 / Y.shape[0]) \
                + np.diag(noise[r].dense())
            res[r] = (obs.values[obs.record_slice(r)] - Y.mean(axis=0), counted, S)
            carry[r] = carried
        per_form[form] = (res, carry)
    for r in per_form["predictive"][0]:
        entry = {}
        for form, (res, carry) in per_form.items():
            others = [v for o, v in res.items() if o != r]
            D = residual_discrepancy([v[0] for v in others], [v[1] for v in others], window)
            pred = st.cv.folds[r]["prediction"]
            band = run_band(carry[r], pred.curve, real["cv"][k][r],
                            {"discrepancy": D, "noise": pooled, "simulator": res[r][2]},
                            rng=np.random.default_rng(seed_for(seed, "band", r, k)), level=0.90)
            y = obs.values[obs.record_slice(r)]
            entry[form] = {"coverage_90": band.coverage(y), "interval_score_Pa": band.score(y),
                           "width_rms_Pa": band.width_rms(), "discrepancy_rms_Pa": float(np.sqrt(np.mean(D))),
                           "parameters_rms_Pa": band.parts["parameters"]}
        out["bands"][r] = entry
    return out


def totals(result: dict) -> dict:
    rows = [b for s in result["series"].values() for f in s.values() for b in f["bands"].values()]
    out = {}
    for form in FORMS:
        ratio = [b[form]["interval_score_Pa"] / b["predictive"]["interval_score_Pa"] for b in rows]
        out[form] = {"bands": len(rows), "score_over_shipped": float(np.mean(ratio)),
                     "coverage_90": float(np.mean([b[form]["coverage_90"] for b in rows])),
                     "discrepancy_rms_Pa": float(np.mean([b[form]["discrepancy_rms_Pa"] for b in rows]))}
    best = min(FORMS, key=lambda f: out[f]["score_over_shipped"])
    adopt = best if out[best]["score_over_shipped"] < ADOPT_BELOW else "predictive"
    return {"forms": out, "lowest": best, "adopted": adopt, "rule": f"lowest mean score over the shipped form's, "
            f"adopted below {ADOPT_BELOW}"}


def main(argv) -> dict:
    scored, out_path = score_series(argv, score_fold)
    result = {"study": "band_parameter_term", "forms": list(FORMS), "series": scored}
    result["totals"] = totals(result)
    text = json.dumps(result, indent=1)
    if out_path:
        Path(out_path).write_text(text + "\n")
    print(json.dumps(result["totals"], indent=1))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
