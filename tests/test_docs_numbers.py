"""Every result number in README.md and docs/*.md is generated (tests/test_docs_tables.py) or quoted here
with the committed JSON it came from: each quote below is the doc's words with the numbers filled in from
that JSON, rounded as the doc rounds them, and must stand in the doc as written. tools/docs_numbers.py lists
the result-looking numbers that are neither; that list must be empty.

A quote's numbers are filled in by ``values(J)``, ``J(path)`` reading a committed JSON; a quote whose numbers
another test already derives from the JSON names that test in ``by`` and gives the words as they stand. One quote
(the marble records' peak times) has no JSON and reads the repository's raw records through init-config."""

from __future__ import annotations

import functools
import json
import os
import re
import tempfile
from statistics import NormalDist
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from enkf.diagnosis.protocol import step_summary
from enkf.scores import interval_score
from shpb import effects as fx
from tools import coverage_table, docs_numbers

ROOT = Path(__file__).resolve().parents[1]
RUN = "benchmarks/results/default_run"
SHPB = "benchmarks/results/bench_shpb.json"
ENGINE = "benchmarks/results/bench_engine.json"
ENGINE_JOINTS = "benchmarks/results/bench_engine_joints.json"
VAR = "benchmarks/results/bench_sim_variability.json"
BLAS = "benchmarks/results/bench_blas_kernel.json"
BITS = "studies/results/engine_bits.json"
IDLE = "benchmarks/results/bench_default_run_sleeping.json"


def _informative_e_t(J) -> dict:
    """The one-posterior benchmark's well-specified twins whose E_t the product calls informative: of their
    90 % misses, how many stopped on the iteration budget; the converged ones' coverage."""
    from scipy import stats

    from benchmarks import bench_coverage as bc
    from benchmarks.scores import score_over_prior_of
    from calibration.experiment import ExperimentSpec
    from enkf.scores import INFORMATIVE_RATIO

    bench = J("benchmarks/results/coverage_one_posterior.json")
    spec = ExperimentSpec.from_config(bc.EXPERIMENT, bc.twin_experiment())
    j = list(spec.names).index("E_t")
    lo, hi = float(spec.lower[j]), float(spec.upper[j])
    rows = [(t, t["emulator_mcmc"]["params"]["E_t"]) for t in bench["well_specified"]["twins"]]
    inf = [(t, r) for t, r in rows if score_over_prior_of(r, lo, hi)[0] <= INFORMATIVE_RATIO]
    miss = [t for t, r in inf if not r["q05"] <= t["truth"]["E_t"] <= r["q95"]]
    conv = [(t, r) for t, r in inf if t["converged"]]
    k = sum(r["q05"] <= t["truth"]["E_t"] <= r["q95"] for t, r in conv)
    budget = sum(t["stop_reason"] == "max_iterations" for t in miss)
    if (len(miss), budget) != (6, 2):
        return {}
    return {"k": k, "n": len(conv), "p": stats.binomtest(k, len(conv), 0.9).pvalue}


def _location_decision(J) -> dict:
    """The location benchmark's decision (benchmarks/location_decision.py): the candidate's and the shipped
    form's well-specified sigma_t median over truth and standard-mesh sigma_t coverage, the candidate refused."""
    d = J("benchmarks/results/coverage_location_decision.json")
    sc = {f: d["scores"][f] for f in ("candidate", "shipped")}
    n = len(J("benchmarks/results/coverage_location.json")["misspecified"]["twins"])
    if d["adopt_candidate"] or d["failed"] != ["misspecified coverage_90 sigma_t"]:
        return {}
    return {"c": sc["candidate"]["well_specified"]["sigma_t"]["mean_over_truth_median"],
            "s": sc["shipped"]["well_specified"]["sigma_t"]["mean_over_truth_median"], "n": n,
            **{k: round(sc[f]["misspecified"]["sigma_t"]["coverage_90"] * n) for k, f in (("kc", "candidate"),
                                                                                         ("ks", "shipped"))}}


def _pooled_learned(J, name: str) -> dict:
    """The shipped form's well-specified twins on which the product calls ``name`` learned, in the README's two
    benchmarks: the second's 90 % coverage and both pooled (calibration.scored.SCORED's learned_holds)."""
    from benchmarks.scores import pooled_learned_coverage

    benches = [J(f"benchmarks/results/{f}") for f in ("coverage_one_posterior.json", "coverage_location.json")]
    both, second = pooled_learned_coverage(benches, name), pooled_learned_coverage(benches[1:], name)
    return {"k": both["covered"], "n": both["n"], "p": both["p"], "k2": second["covered"], "n2": second["n"],
            "p2": second["p"]}


def _misspecified_90() -> dict:
    """calibration.scored.SCORED's misspecified counts of the shipped form and of it with the approximation
    error (tests/test_one_posterior.py keeps them equal to their JSONs)."""
    from calibration.scored import SCORED

    plain = next(e for e in SCORED if e["benchmark"].endswith("coverage_one_posterior.json"))["misspecified_90"]
    term = next(e for e in SCORED if "approximation_error" in e["form"])["misspecified_90"]
    return {"s": plain["sigma_t"], "e": plain["E_t"], "sa": term["sigma_t"], "ea": term["E_t"]}


def _approximation(J) -> dict:
    """The shipped posterior's standard-mesh twins with the approximation error (the planned benchmark's pooled
    JSON) and without it (the location benchmark's): 90 % coverage and WIS over the prior's per parameter."""
    with_ = J("benchmarks/results/coverage_approximation.json")
    without = J("benchmarks/results/coverage_location.json")["misspecified"]
    if with_["set"] != "misspecified" or with_["approximation_pairs"] != 24:
        return {}
    out = {"n": with_["n_twins"], "n0": without["summary_emulator_mcmc"]["n_twins"]}
    for tag, q in (("a", with_["summary_emulator_mcmc"]), ("b", without["summary_emulator_mcmc"])):
        out.update(_cov90_wis(q, tag, "c", "w"))
    return out


def _cov90_wis(summary: dict, tag: str, cov: str, wis: str | None = None) -> dict:
    """A reported posterior's 90 % coverage [%] (failed samplers as misses) and WIS over the prior's, per
    parameter, named ``<tag><s|e><cov>`` and ``<tag><s|e><wis>``."""
    out = {}
    for p, k in (("sigma_t", "s"), ("E_t", "e")):
        out[f"{tag}{k}{cov}"] = 100 * summary["params"][p]["coverage_90"]["fraction_counting_failures_as_misses"]
        if wis:
            out[f"{tag}{k}{wis}"] = summary["params"][p]["wis_over_prior"]
    return out


def _rate_approximation(J) -> dict:
    """The recommended form (the approximation error) on standard-mesh twins with an undeclared rate dependence
    (the planned benchmark's pooled JSON), and over every misspecified twin of the form (the plan's primary bar):
    90 % coverage per parameter, sigma_t's median over the truth, the counts."""
    rate = J("benchmarks/results/coverage_rate_approximation.json")
    every = J("benchmarks/results/coverage_misspecified_approximation.json")
    if rate["set"] != "misspecified_rate" or rate["rate_data_preset"] != "standard" or rate["approximation_pairs"] != 24:
        return {}
    out = {"n": rate["n_twins"], "N": every["n_twins"],
           "up": 100 * (rate["summary_emulator_mcmc"]["params"]["sigma_t"]["mean_over_truth_median"] - 1)}
    for tag, q in (("r", rate["summary_emulator_mcmc"]), ("p", every["summary_emulator_mcmc"])):
        out.update(_cov90_wis(q, tag, ""))
    return out


def _approximation_cost(J) -> dict:
    """The approximation pairs' time per record on 2 cores [min] and a standard run over a fast one, disc and cylinder."""
    d = J("benchmarks/results/bench_approximation_cost.json")
    c = d["cases"]
    if d["cores"] != 2:
        return {}
    return {"dm": c["disc"]["pairs_on_cores_s"] / 60, "cm": c["cylinder"]["pairs_on_cores_s"] / 60,
            "dr": c["disc"]["standard_over_model_preset"], "cr": c["cylinder"]["standard_over_model_preset"]}


def _planted_gap(J) -> dict:
    """The shipped planted-gap series through the loop (the default run's planted_gap): the walk's
    confirmed steps (the planted face gap first, then a rate law nobody planted), the identification gate
    that dropped the rate law (its k re-fitted on real runs), the held-out errors, and the planted values
    against the shipped model's intervals (the selection's fit)."""
    run, truth = f"{RUN}/planted_gap", J("data/examples/planted_gap/truth.json")
    rep, chk, ref = (J(f"{run}/diagnosis/{f}.json") for f in ("report", "check", "refit"))
    step = [s for s in rep["confirmation"]["steps"] if s["confirmed"]]
    post = step_summary(rep["selection"], rep["shipped_step"])["posterior"]
    planted = {t["name"]: t["planted"]["face_gap.gap_m"] for t in truth["tests"]}
    held = chk["heldout"]["PlantGap_03"]
    lo_h, hi_h = held["after"]["intervals"]["face_gap.gap_m@PlantGap_03"]
    inside = [post[f"face_gap.gap_m@{r}"]["q05"] <= planted[r] <= post[f"face_gap.gap_m@{r}"]["q95"]
              for r in rep["calib_records"]]
    [dropped] = ref["gated"]
    sig, k = post["sigma_t"], dropped["posterior"]["rate_strength.k"]
    if not (rep["added"] == ["face_gap"] and [s["effect"] for s in step] == ["face_gap", "rate_strength"]
            and truth["effect"] == ["face_gap"] and not dropped["identification"]["identified"]
            and lo_h <= planted["PlantGap_03"] <= hi_h and not sig["q05"] <= truth["params"]["sigma_t"] <= sig["q95"]):
        return {}
    return {"z": step[0]["z"], "p2": step[1]["p"], "l2": step[1]["level"], "d2": step[1]["dof"],
            "k": k["mean"], "klo": k["q05"], "khi": k["q95"],
            "rb": _mpa(held["before"]["rmse"]), "ra": _mpa(held["after"]["rmse"]),
            "c": held["after"]["predictive_coverage_90"], "n_in": sum(inside), "n": len(inside),
            "m": _mpa(sig["mean"]), "lo": _mpa(sig["q05"]), "hi": _mpa(sig["q95"]), "t": truth["params"]["sigma_t"] / 1e6}


def _planted_gap_approximation(J) -> dict:
    """The default run's planted series run with the approximation error (studies/results/
    planted_gap_approximation.json): the walk's two steps, the second addition's fitted shifts, the gaps and
    sigma_t against their truths, the held-out record's errors; nothing unless the refit's shifts hold zero."""
    d = J("studies/results/planted_gap_approximation.json")
    st, sel, ref, held = d["steps"], d["selection_posterior"], d["refit_posterior"], d["heldout"]["PlantGap_03"]
    e2 = st[1]["effect"]
    shifts = [k for k in sel if k.startswith(e2)]
    if not (all(ref[k]["inside"] for k in shifts) and d["workflow_posterior"]["sigma_t"]["inside"]
            and ref["sigma_t"]["inside"] and not sel["sigma_t"]["inside"]):
        return {}
    return {"z1": st[0]["z"], "e2": e2, "z2": st[1]["z"], "s1": abs(sel[shifts[0]]["mean"]) * 1e6,
            "s2": abs(sel[shifts[1]]["mean"]) * 1e6, "gi": sum(v["inside"] for k, v in sel.items() if k.startswith("face_gap")),
            "rb": held["rmse_before_Pa"] / 1e6, "ra": held["rmse_after_Pa"] / 1e6, "c": held["predictive_coverage_90_after"]}


def _planted_gap_gated(J) -> dict:
    """The same series with the approximation error, run again with the identification gate
    (studies/results/planted_gap_approximation_gated.json): the dropped shift's intervals, the refit's gaps and
    sigma_t against their truths, the held-out errors; nothing unless the walk is the earlier run's."""
    d, before = J("studies/results/planted_gap_approximation_gated.json"), J("studies/results/planted_gap_approximation.json")
    [g] = d["gated"]
    ref, held = d["refit_posterior"], d["heldout"]["PlantGap_03"]
    gaps = [ref[f"face_gap.gap_m@PlantGap_0{i}"] for i in (1, 2)]
    if not ([(s["effect"], round(s["z"], 2)) for s in d["steps"]] == [(s["effect"], round(s["z"], 2)) for s in before["steps"]]
            and d["added"] == ["face_gap"] and g["effect"] == "trigger_shift" and [q["inside"] for q in gaps] == [True, False]
            and ref["sigma_t"]["inside"]):
        return {}
    us = [(p["lower"] * 1e6, p["upper"] * 1e6) for p in g["parameters"]]
    return {"a0": us[0][0], "a1": us[0][1], "b0": us[1][0], "b1": us[1][1],
            **{f"{k}{i}": gaps[i - 1][q] * 1e6 for i in (1, 2) for k, q in (("g", "mean"), ("l", "q05"), ("h", "q95"))},
            "p1": gaps[0]["truth"] * 1e6, "p2": gaps[1]["truth"] * 1e6,
            "s": ref["sigma_t"]["mean"] / 1e6, "sl": ref["sigma_t"]["q05"] / 1e6, "sh": ref["sigma_t"]["q95"] / 1e6,
            "t": ref["sigma_t"]["truth"] / 1e6, "rb": held["rmse_before_Pa"] / 1e6, "ra": held["rmse_after_Pa"] / 1e6,
            "c": held["predictive_coverage_90_after"]}


def _planted_refit(J) -> dict:
    """The default run's planted-gap series re-fitted on real runs (diagnosis/refit.json): the calibration
    records' gaps against their planted values, sigma_t, and the spread of the check meshes' fits."""
    ref, truth = J(f"{RUN}/planted_gap/diagnosis/refit.json"), J("data/examples/planted_gap/truth.json")
    planted = {t["name"]: t["planted"]["face_gap.gap_m"] for t in truth["tests"]}
    post, recs = ref["posterior"], ref["records"]
    gap = {r: post[f"face_gap.gap_m@{r}"] for r in recs}
    spread = next(h for h in ref["history"] if h["phase"] == "spread")
    verify = next(h for h in ref["history"] if h["phase"] == "verify")
    per_mesh = [p["face_gap.gap_m@PlantGap_02"]["mean"] for p in spread["posterior_per_mesh"]]
    out = {"runs": ref["runs"], "rounds": ref["rounds"], "k": sum(g["q05"] <= planted[r] <= g["q95"] for r, g in gap.items()),
           "n": len(gap), "s": _mpa(post["sigma_t"]["mean"]), "sl": _mpa(post["sigma_t"]["q05"]),
           "sh": _mpa(post["sigma_t"]["q95"]), "ml": min(per_mesh) * 1e6, "mh": max(per_mesh) * 1e6,
           "q1": min(verify["chi2_per_dof_real_per_mesh"]), "q2": max(verify["chi2_per_dof_real_per_mesh"]),
           "qs": verify["fit_misfit_scale"], "f": verify["inflation"], "kn": len(ref["history"]),
           "kr": ref["runs"] - sum(g["runs"] for g in ref["gated"]), "dr": sum(g["runs"] for g in ref["gated"])}
    def score(q, x):  # the 90 % interval score, um
        return float(interval_score(q["q05"], q["q95"], x, 0.1)) * 1e6

    for i, r in enumerate(("PlantGap_01", "PlantGap_02"), 1):
        out.update({f"g{i}": gap[r]["mean"] * 1e6, f"l{i}": gap[r]["q05"] * 1e6, f"h{i}": gap[r]["q95"] * 1e6,
                    f"p{i}": planted[r] * 1e6, f"is{i}": score(ref["selection_posterior"][f"face_gap.gap_m@{r}"], planted[r]),
                    f"ir{i}": score(gap[r], planted[r]),
                    f"s{i}": ref["selection_posterior"][f"face_gap.gap_m@{r}"]["mean"] * 1e6})
    return out if ref["converged"] and recs == ["PlantGap_01", "PlantGap_02"] else {}


def _refit_check(J) -> dict:
    """The refit check on fresh face_gap series (bench_planted_refit_check.json, refit_check_scores.json)."""
    b, d = J("benchmarks/results/bench_planted_refit_check.json"), J("studies/results/refit_check_scores.json")
    rows = [(n, r) for s in d["series"].values() for n, r in (s.get("params") or {}).items()]
    gaps = [r for n, r in rows if n.startswith("face_gap.gap_m@")]
    verify = [s["verify"] for s in d["series"].values() if s.get("verify")]
    real = [q for v in verify for q in v["chi2_per_dof_real_per_mesh"]]
    widest = max(gaps, key=lambda r: r["refit"]["q95"] - r["refit"]["q05"])["refit"]
    return {"nf": b["scores"]["confusion"]["face_gap"]["face_gap"], "n": b["scores"]["series"],
            "gi": sum(r["refit"]["inside"] for r in gaps), "si": sum(r["selection"]["inside"] for r in gaps),
            "gn": len(gaps), "ri": d["totals"]["refit"]["inside"], "ai": d["totals"]["selection"]["inside"],
            "rn": d["totals"]["refit"]["of"], "rs": d["totals"]["refit"]["mean_interval_score_over_planted"],
            "ss": d["totals"]["selection"]["mean_interval_score_over_planted"], "q0": min(real), "q1": max(real),
            "f0": min(v["inflation"] for v in verify), "f1": max(v["inflation"] for v in verify),
            "wl": widest["q05"] * 1e6, "wh": widest["q95"] * 1e6}


def _interactions(J) -> dict:
    """The second-order term's development study (studies/anchored_interactions.py,
    interactions_rediagnosis.py): the emulators' worst error at the planted point on the friction series'
    calibration records, and the re-diagnosed selection's friction fit."""
    d = J("studies/results/anchored_interactions_interface_friction_5302.json")
    cal = [r["at_planted_base"]["effect_planted"] for r in d["records"].values() if r["data"] == "calibration"]
    fit = J("studies/results/interactions_rediagnosis.json")["series"]["planted_interface_friction_5302"]
    return {"first": max(c["first"]["rmse_Pa"] for c in cal) / 1e6, "second": max(c["second"]["rmse_Pa"] for c in cal) / 1e6,
            "mu": fit["interactions"]["fitted"]["base + interface_friction"]["interface_friction.mu"][1],
            "planted": fit["plant"]["interface_friction.mu"]}


def _series_walls(J, series: str) -> dict:
    """The wall times of the planted benchmark's series of one kind (cylinder or disc) run so far, but for a
    series that shared the machine (``wall_is_cost`` false) or also ran the selection on real runs (its
    ``realrun`` field: a second selection, about 1,250 more runs)."""
    walls = [d["wall_s"] for d in (J(str(f.relative_to(ROOT))) for f in
                                   (ROOT / "benchmarks/results/bench_planted_records").glob("*.json"))
             if d["series"][0]["case"]["series"] == series and d.get("wall_is_cost", True)
             and not d["series"][0].get("realrun")]
    return {"lo": min(walls), "hi": max(walls)}


@functools.lru_cache(maxsize=None)
def _interval_forms(J) -> dict:
    d = J("studies/results/realrun_interval_forms.json")
    f, errs = d["forms"], d["sigma_t_rel_error"]
    assert all(e < 0 for e in errs)
    return {"n": f["before"]["series"], "m": f["before"]["parameters"], "b": f["before"]["planted_inside"],
            "p": f["per_sample"]["planted_inside"], "a": f["after"]["planted_inside"],
            "bp": f["before"]["parameters_inside"], "pp": f["per_sample"]["parameters_inside"],
            "ap": f["after"]["parameters_inside"], "lo": -100 * max(errs), "hi": -100 * min(errs)}


def J(path: str):
    return json.loads((ROOT / path).read_text())


def _series_approximation(J) -> dict:
    """The marble series with the approximation error (studies/series_approximation.py) against its committed
    run without, read from that run's own files (the source docs/closing-the-loop.md quotes too)."""
    d = J("studies/results/series_approximation.json")
    t = d["with_term"]["totals"]
    u = J("benchmarks/results/loro_rerun_marble/marble_unseen.json")["totals"]
    return {"a": t["mean_rmse_after"] / 1e6, "b": u["mean_rmse_after"] / 1e6,
            "ca": t["mean_predictive_coverage_90_after"], "cb": u["mean_predictive_coverage_90_after"],
            "wa": d["wall_s_with_term"] / 60, "wb": J("benchmarks/results/loro_rerun_marble/run.json")["wall_s"] / 60}


def _heldout_approximation(J) -> dict:
    """The default run's marble with the approximation error, its held-out record corrected by its own
    pairs (studies/marble_approximation.py), against the run before that fix and the run without the term."""
    d = J("studies/results/marble_approximation_heldout.json")
    h = {k: d[k]["diagnosis"]["heldout"]["CaMa_SHPB_006"] for k in ("with_term", "without_term")}
    return {"o": h["with_term"]["offset_rms_Pa"] / 1e6, "om": h["with_term"]["offset_max_abs_Pa"] / 1e6,
            "a": h["with_term"]["rmse_after"] / 1e6, "b": h["without_term"]["rmse_after"] / 1e6,
            "u": d["previous"]["heldout"]["CaMa_SHPB_006"]["rmse_after"] / 1e6,
            "dm": (d["wall_s_with_term"] - J("studies/results/marble_approximation.json")["wall_s_with_term"]) / 60}


def _sleep() -> dict:
    """The engine's sleeping bodies: bench_engine_sleep.json (before and after, one run) and sleep_check.json
    (sleeping against all awake and against rounding-level perturbations); nothing unless every fracture
    check agreed."""
    b = J("benchmarks/results/bench_engine_sleep.json")["cases"]
    c = J("studies/results/sleep_check.json")
    m, sm = c["members"], c["summary"]

    def d(k, w="sleeping", at="to_peak_over_peak"):
        return m[k][f"{w}_vs_awake"][at]

    discs = [v["speedup_solver"] for k, v in b.items() if k.startswith("disc_fast")]
    calm = [d(k) for k in m if "SeeSst" not in k and k != "disc_strong_tough"]
    cyl = [k for k in m if k.startswith("cylinder")]
    rounded = [d(k, w, "window_over_peak") for k in cyl for w in ("awake_rounded", "awake_bar_rounded")]
    def e(x):  # 3.5e-07 as the docs write it, 3.5e-7
        return f"{x:.1e}".replace("e-0", "e-")

    if not all(v["fracture_checks_agree"] for v in b.values()):
        return {}
    return {"dlo": min(discs), "dhi": max(discs), "m": b["marble_fast"]["speedup_solver"],
            "p": b["disc_paper_reference"]["speedup_solver"],
            "agree": e(max(v["agreement"]["max_diff_to_peak_over_peak"] for v in b.values())),
            "clo": 100 * min(sm["cylinder_solver_saved"]), "chi": 100 * max(sm["cylinder_solver_saved"]),
            "xlo": 100 * min(sm["disc_solver_saved"]), "xhi": 100 * max(sm["disc_solver_saved"]),
            "calm": e(max(calm)), "st": e(d("disc_strong_tough")), "stx": e(d("disc_strong_tough", "awake_rounded")),
            "s23": 100 * d("cylinder_SeeSst_SHPB_023"), "s24": 100 * d("cylinder_SeeSst_SHPB_024"),
            "b23": 100 * d("cylinder_SeeSst_SHPB_023", "awake_bar_rounded"), "rw": 100 * max(rounded),
            "sw": 100 * max(d(k, at="window_over_peak") for k in cyl)}


def _time_step() -> dict:
    """What a longer time step would buy and cost: studies/results/time_step_answers.json (one run per case and
    step, and the paired peaks over eight meshes)."""
    d = J("studies/results/time_step_answers.json")
    c, pr = {r["case"]: r for r in d["cases"]}, d["paired"]
    sp = [r["longer_step"]["1.5"]["speedup"] for r in c.values()]
    s28, today = pr["sandstone028_fast"], pr["sandstone028_fast"]["today"]
    return {"r125": 100 * max(r["longer_step"]["1.25"]["rms_to_peak_rel"] for r in c.values() if "1.25" in r["longer_step"]),
            "slo": min(sp), "shi": max(sp), "w0": 100 * c["discweak_fast"]["energy_balance_today"],
            "w15": 100 * c["discweak_fast"]["longer_step"]["1.5"]["energy_balance_rel"],
            "s15": 100 * s28["1.5"]["paired_change_rel_mean"], "ssd": 100 * today["peak_sd_Pa"] / today["peak_mean_Pa"],
            "s2e": 100 * s28["2"]["energy_max"], "m15": 100 * pr["marble_fast"]["1.5"]["paired_change_rel_mean"],
            "m2": 100 * pr["marble_fast"]["2"]["paired_change_rel_mean"]}


@dataclass(frozen=True)
class Quote:
    doc: str
    words: str  # the doc's words, ``{name}`` where ``values`` fills in a number
    values: Callable | None = None  # J -> {name: formatted number}
    by: str = ""  # or: the test that derives these numbers from their JSON, "tests/file.py::test_name"

    def text(self) -> str:
        return self.words.format(**self.values(J)) if self.values else self.words


def _oracle(J) -> dict:
    """studies/oracle_power.py: per planted physical case, how often the walk's test passes at the effect's truth."""
    c = J("studies/results/oracle_power.json")["cases"]
    out = {}
    for key, case in (("rs", "rate_strength"), ("dr", "disc_rate_strength"), ("fr", "interface_friction"),
                      ("se", "seating"), ("fg", "face_gap")):
        out[key + "p"], out[key + "n"], out[key + "z"] = c[case]["passes"], c[case]["realizations"], c[case]["z_median"]
    assert c["seating"]["passes"] == c["seating"]["realizations"] == out["frp"] == out["frn"], "the doc says 8 of 8"
    assert c["face_gap"]["passes"] == c["face_gap"]["realizations"] == out["frp"], "the doc says 8 of 8"
    out["rsig"] = _mpa(c["rate_strength"]["base_fit_all_records"]["sigma_t"])
    return out

def _oracle_standard(J) -> dict:
    """studies/oracle_power.py --data-preset standard: the oracle on the benchmark's own data mesh."""
    c = J("studies/results/oracle_power.json")["standard_data"]["cases"]
    rest = [c[k] for k in ("interface_friction", "seating", "face_gap")]
    assert len({(x["passes"], x["realizations"]) for x in rest}) == 1, "the doc gives one count for the three"
    return {"rp": c["rate_strength"]["passes"], "rn": c["rate_strength"]["realizations"],
            "rz": c["rate_strength"]["z_median"], "fp": rest[0]["passes"], "fn": rest[0]["realizations"],
            "fz": c["interface_friction"]["z_median"], "sz": c["seating"]["z_median"], "gz": c["face_gap"]["z_median"]}

def _span(xs, fmt) -> str:
    return f"{fmt(min(xs))}-{fmt(max(xs))}"


def _mpa(x) -> str:
    return f"{x / 1e6:.1f}"


def _twin():
    return J(f"{RUN}/twin_ref/summary.json")


def _marble():
    return J(f"{RUN}/marble_loop/summary.json")


def _walk_step(i=0):
    return J(f"{RUN}/marble_loop/diagnosis/report.json")["confirmation"]["steps"][i]


def _heldout(record="CaMa_SHPB_006"):
    return J(f"{RUN}/marble_loop/diagnosis/check.json")["heldout"][record]


SM = "docs/shpb-models.md"


def _shpb(preset, point):
    return J(SHPB)["presets"][preset][point]


def _shpb_runs():
    return [(p, k, r) for p, pts in J(SHPB)["presets"].items() for k, r in pts.items()]


def _onset(sigma_n_mpa, sigma_t_mpa):
    cases = J(f"studies/results/disc_onset_theory_sigma_n_{sigma_n_mpa}MPa.json")["cases"]
    return next(c for c in cases if c["sigma_t_Pa"] == sigma_t_mpa * 1e6)


def _var(case):
    return J(VAR)["cases"][case]


def _dt_ratios(case):
    return [r["dt_s"] / _var(case)["unperturbed"]["dt_s"] for r in _var(case)["replicates"]]


def _step(preset):
    return J("studies/results/bench_time_step.json")["presets"][preset]


def _synthetic_likelihood(J) -> dict:
    """studies/identification_ceiling.py's oracle: its meshes per grid point and how many twins' 90 %
    intervals held each truth."""
    d = J("studies/results/identification_ceiling_dev70.json")
    held = {p: sum(t[p]["q05"] <= t["truth"][p] <= t[p]["q95"] for t in d["twins"]) for p in ("sigma_t", "E_t")}
    return {"m": d["meshes"], "st": held["sigma_t"], "et": held["E_t"], "n": len(d["twins"])}


def _bank(J) -> dict:
    """studies/bank_ceiling.py's likelihood-free yardstick: its held-out bank runs and the smaller banks."""
    d = J("studies/results/bank_ceiling.json")
    loo = d["bank_leave_one_out"][str(d["k"])]
    quoted = (1000, 3000)  # the smaller banks the doc quotes, each at its best k
    best = {p: [min(r[p]["wis_over_prior"] for r in d["bank_sizes"] if r["runs"] == n) for n in quoted]
            for p in ("sigma_t", "E_t")}
    parts = loo["parts"]
    return {"cs": parts["no_post_peak"]["sigma_t"]["wis_over_prior"], "ce": parts["no_post_peak"]["E_t"]["wis_over_prior"],
            "ps": parts["post_peak"]["sigma_t"]["wis_over_prior"], "pe": parts["post_peak"]["E_t"]["wis_over_prior"],
            "N": d["bank_runs"], "n": d["reference_runs"], "r1": quoted[0], "r3": quoted[1], "c1": loo["sigma_t"]["coverage_90"], "c2": loo["E_t"]["coverage_90"],
            "s": loo["sigma_t"]["wis_over_prior"], "e": loo["E_t"]["wis_over_prior"],
            "l": loo["E_t"]["called_learned"]["coverage_90"]["fraction"],
            "s1": best["sigma_t"][0], "s3": best["sigma_t"][1], "e1": best["E_t"][0], "e3": best["E_t"][1]}


def _planted_score(J) -> dict:
    """The planted-effect benchmark's null and physical-effect counts (benchmarks/results/bench_planted.json)."""
    from benchmarks.bench_planted import bar_counts

    c = bar_counts(J("benchmarks/results/bench_planted.json")["series"])
    (n_ok, n), (k, K) = c["null_adds_nothing"], c["physical_named_top"]
    return {"n_ok": n_ok, "n": n, "k": k, "K": K}


def _error_models(experiment):
    return next(e for e in J("studies/results/error_models.json")["experiments"] if e["experiment"] == experiment)


CL = "docs/closing-the-loop.md"
REFUTED = "benchmarks/results/loro_seen/refuted_steps.json"


def _one(values) -> str:
    """The one value all of ``values`` share (the doc quotes it once)."""
    (v,) = set(values)
    return v


def _loro(rock):
    return J(f"benchmarks/results/loro_unseen_{rock}/{rock}_unseen.json")["totals"]


def _fold003():
    rows = J("benchmarks/results/loro_unseen_sandstone/sandstone_unseen.json")["rows"]
    return next(r for r in rows if r["heldout"] == "SeeSst_SHPB_003")


def _gaps_003():
    rows = J("benchmarks/results/loro_unseen_sandstone/sandstone_unseen.json")["rows"]
    return [r["estimates"]["face_gap.gap_m@SeeSst_SHPB_003"]["mean"] for r in rows
            if "face_gap.gap_m@SeeSst_SHPB_003" in r["estimates"]]


RERUN = "benchmarks/results/loro_rerun_sandstone"


def _rerun(rock="sandstone", kind="rerun") -> dict:
    """A re-run series' table (``kind``: ``rerun``, or ``gated``, the run with every fold re-fitted and gated)."""
    return J(f"benchmarks/results/loro_{kind}_{rock}/{rock}_unseen.json")


def _rerun_bands(rock="sandstone", kind="rerun") -> list[dict]:
    """Each re-run fold's held-out record's band, before and after (its check.json)."""
    return [J(f"benchmarks/results/loro_{kind}_{rock}/{r['heldout']}_check.json")["predictive_band"]["records"]
            [r["heldout"]][w] for r in _rerun(rock, kind)["rows"] for w in ("before", "after")]


def _gated_edges(J) -> dict:
    """The gated folds' second effects at their box's edge: every gauge gain's gate interval starting at the
    catalogue's lowest gain, every lowpass time constant's ending at its largest ({} unless each does)."""
    folds = J("benchmarks/results/loro_gated_sandstone/run.json")["refit_per_fold"].values()
    gains = [p for f in folds if f["identification"]["effect"] == "gauge_gain" for p in f["identification"]["parameters"]]
    taus = [p for f in folds if f["identification"]["effect"] == "lowpass" for p in f["identification"]["parameters"]]
    g_lo, t_hi = fx.get_effect("gauge_gain").params[0].lower, fx.get_effect("lowpass").params[0].upper
    edges = (gains and taus and all(fx.catalogue_edge(p["name"], p["lower"]) == "lower" for p in gains)
             and all(fx.catalogue_edge(p["name"], p["upper"]) == "upper" for p in taus))
    levels = {round(100 * (1 - (1 - f["identification"]["level"]) / len(f["identification"]["parameters"])), 6)
              for f in folds}
    return {"g": g_lo, "t": t_hi * 1e6, "lv": levels.pop()} if edges and len(levels) == 1 else {}


def _marble_fold_skew() -> dict:
    """Which way every re-run marble fold's sigma_t posterior is skewed: "high" when each fold's upper tail
    (q95 - q50) is longer than its lower (q50 - q05), "low" when each is shorter, else "mixed"."""
    tails = []
    for r in _rerun("marble")["rows"]:
        s = J(f"benchmarks/results/loro_rerun_marble/{r['heldout']}_summary.json")["posterior"]["sigma_t"]
        tails.append(s["q95"] - s["q50"] > s["q50"] - s["q05"])
    return {"dir": "high" if all(tails) else "low" if not any(tails) else "mixed"}


def _marble_high_peaks() -> dict:
    """The re-run marble folds' base-model peak errors [%] of the two folds predicted over 20 % high ({} unless
    exactly two are: the docs say "two")."""
    errs = sorted(100 * r["peak_rel_error_before"] for r in _rerun("marble")["rows"])
    return {"lo": errs[-2], "top": errs[-1]} if sum(e > 20 for e in errs) == 2 else {}


def _rerun_peaks(rock="sandstone", kind="rerun") -> list[float]:
    """The held-out records' observed peaks [MPa]: the peak error over the relative peak error."""
    return [r["peak_error_before"] / r["peak_rel_error_before"] / 1e6 for r in _rerun(rock, kind)["rows"]]


def _rerun_band_values(when: str, what: str, rock="sandstone", kind="rerun") -> list[float]:
    """The re-run folds' held-out bands' ``what`` [MPa] (``band_width_rms_Pa``, or a part's rms sd)."""
    return [(b[what] if what.endswith("_Pa") else b["parts_rms_Pa"][what]) / 1e6
            for b in _rerun_bands(rock, kind)[(0 if when == "before" else 1)::2]]


def _calib_over_box(rock: str) -> float:
    """The mean interval score over the design box's of the re-run folds' calibration records' bands, after."""
    vals = [e["after"]["interval_score_over_box"] for r in _rerun(rock)["rows"]
            for e in J(f"benchmarks/results/loro_rerun_{rock}/{r['heldout']}_check.json")["predictive_band"]["records"].values()
            if e["data"].startswith("calibration") and e["after"]]
    return sum(vals) / len(vals)


def _band_window_us() -> float:
    """The product's averaging time of the bands' discrepancy, and the study's window it came from (81
    samples of the series' 2 us: cv81) must agree."""
    from calibration.closing import BAND_DISCREPANCY_WINDOW_S

    assert 81 in J("studies/results/band_discrepancy.json")["windows"]
    return BAND_DISCREPANCY_WINDOW_S * 1e6


def _study_band(form: str) -> dict:
    """studies/band_discrepancy.json's totals of one form, the scores in MPa."""
    t = J("studies/results/band_discrepancy.json")["totals"][form]
    return {k: (v / 1e6 if k.endswith("_Pa") else v) for k, v in t.items()}


def _emulator_ratios(over: str) -> list[float]:
    folds = J("benchmarks/results/bench_loro.json")["runs"]["new"]["emulator_against_noise"]
    return [x["emulator_rms_Pa"] / x[over] for f in folds.values() for x in f.values()]


def _loro_costs(name: str = "new", refine: bool = False) -> dict:
    """A bench_loro.json run's wall [min] and its simulating rules' shares of the job time [%];
    ``refine``: the run has the refinement batch (runs made before it do not)."""
    run = J("benchmarks/results/bench_loro.json")["runs"][name]
    rules, total = run["job_times"]["rules"], run["job_times"]["job_time_sum_s"]

    def share(*names):
        return 100 * sum(rules[f"simulate[{n}]"]["sum_s"] for n in names) / total

    return {"m": run["wall_s"] / 60, "d": share("diagnosis_member"), "c": share("member", "replicate"),
            "k": share("diagnosis_check_member"), **({"r": share("refine_member")} if refine else {}),
            "cp": sum(v["copied"] for v in run["fdem_runs"].values()),
            "n": sum(v["runs"] for v in run["fdem_runs"].values())}


def _loro_idle(J, name: str = "anchored_idle") -> dict:
    """An idle run of the shipped series (bench_loro.json ``name``): its wall [min] and the refinement runs'
    share of its job time [%], refused unless its answers are those of run ``anchored``."""
    runs = J("benchmarks/results/bench_loro.json")["runs"]
    idle, busy = runs[name], runs["anchored"]
    jt = idle["job_times"]
    r = 100 * jt["rules"]["simulate[refine_member]"]["sum_s"] / jt["job_time_sum_s"]
    return {"m": idle["wall_s"] / 60, "r": r} if idle["answers"] == busy["answers"] and idle["exit_code"] == 0 else {}


def _loro_sleeping(J, name: str = "sleeping") -> dict:
    """A series run with sleeping bodies against `current_idle` (bench_loro.json): wall [min], solver seconds
    per simulated run over the other's, the paper disc's time before sleeping bodies on its machine over
    the engine table's, the effects its folds kept and its held-out bands' mean coverage after and before."""
    runs = J("benchmarks/results/bench_loro.json")["runs"]

    def per_run(name):
        f = runs[name]["fdem_runs"].values()
        return sum(v["solver_s"] for v in f) / sum(v["runs"] - v["copied"] for v in f)

    totals = runs[name]["answers"]["totals"]
    kept = totals["effects_kept"]
    paper = J("benchmarks/results/bench_engine_sleep.json")["cases"]["disc_paper_reference"]["baseline"]["solver_wall_s"]
    return {"m": runs[name]["wall_s"] / 60, "r": per_run(name) / per_run("current_idle"),
            "ca": totals["mean_predictive_coverage_90_after"], "cb": totals["mean_predictive_coverage_90_before"],
            "p": paper / J("benchmarks/results/bench_engine.json")["cases"]["disc_paper_reference"]["new"]["solver_wall_s"],
            "fg": kept["face_gap"], "lp": kept["lowpass"], "gg": kept["gauge_gain"]}


def _pop():
    return J("studies/results/population_average_cv.json")


@functools.lru_cache(maxsize=None)
def _marble_peak_times() -> dict:
    """``{record: peak time [s]}`` of marble_loop's records, in the workflow's time frame, as init-config
    reads them from the repository's raw Freiburg files (no JSON holds them; about a second)."""
    from shpb.lab.init_config import init_config
    from shpb.lab.sheet_freiburg import freiburg_sheet, write_sheet
    cama = ROOT / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa"
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        sheets = [ROOT / "data/examples/sheets/CaMa_SHPB_004.yaml", Path(tmp) / "CaMa_SHPB_014.yaml"]
        write_sheet(freiburg_sheet(cama / "CaMa_SHPB_014_Ti25_55b_Al12b_0_001.txt", Path(tmp)), sheets[1])
        os.chdir(tmp)
        try:
            text = init_config(sheets)[0]
        finally:
            os.chdir(cwd)
    # the header's "#   name: onset / peak us (... MPa) / fall us" lines
    return {m[1]: float(m[2]) * 1e-6 for m in re.finditer(r"^#\s+(\S+): \d+ / (\d+) us", text, re.M)}


OD = "docs/own-data.md"
OWN = "benchmarks/results/own_data_run"


def _own():
    return J(f"{OWN}/summary.json")


def _off_centre():
    return [r for r in _var("twin")["replicates"] if not r["checks"]["starts_central"]]


HARNESS = "tests/test_harness_informative.py::test_the_committed_verdicts_are_the_readme_s"
CENSORED_PROSE = "tests/test_docs_tables.py::test_the_censored_twins_table_is_generated_from_the_readme_table_s_json"
FLAG_SPLIT = "tests/test_docs_tables.py::test_the_flag_split_table_is_generated_and_its_prose_is_its_rows"
FLAG_BAR = "tests/test_calibration_verdict.py::test_the_flag_falls_where_a_gaussian_posterior_expects_the_bar"
GAUSSIAN = "tests/test_parameter_scores.py::test_a_gaussian_posterior_expects_its_closed_form"
README_RUN = "tests/test_docs_tables.py::test_the_readme_quotes_the_default_runs_time_from_its_idle_run"
KILL = "tests/test_docs_tables.py::test_the_workflow_docs_kill_figures_are_the_committed_benchmarks"

QUOTES: list[Quote] = [
    # README: the default run and the coverage harness
    Quote("README.md", "the default run took {run_s} s, {fdem_runs} FDEM runs", lambda J: {
        "run_s": J(f"{RUN}/run.json")["run_s"], "fdem_runs": J(f"{RUN}/run.json")["fdem_runs"]}, by=README_RUN),
    Quote("docs/workflow.md", "On an idle machine the code before the identification gate ({g} refit runs\nfewer) took "
          "{new_s} s, and in the same sitting the earlier default run (the twin and the marble loop only, {old_runs} FDEM\n"
          "runs) took {old_s} s", lambda J: {"old_runs": J(IDLE)["runs"]["old"]["fdem_runs"],
                                            "old_s": J(IDLE)["runs"]["old"]["wall_s"], "new_s": J(IDLE)["runs"]["new"]["wall_s"],
                                            "g": J(f"{RUN}/planted_gap/diagnosis/refit.json")["runs"]
                                            - J(f"{RUN}/planted_gap/diagnosis/refit.json")["gated"][0]["runs"]}),
    Quote("docs/workflow.md", "{k:.2f} times the runs\nat {r:.2f} of the time per run", lambda J: (lambda n, o: {
        "k": n["fdem_runs"] / o["fdem_runs"],
        "r": n["wall_s"] / n["fdem_runs"] / (o["wall_s"] / o["fdem_runs"])})(J(IDLE)["runs"]["new"], J(IDLE)["runs"]["old"])),
    Quote("docs/workflow.md", "The five-record `config/validation.yaml` took {m:.1f} min on 2 cores "
          "(`benchmarks/results/bench_loro.json`). Of its job time, {d:.0f} % went to the selection's emulator design, "
          "{c:.0f} % to the calibrations' ensembles and replicates and {k:.0f} % to the real-run check. {cp} of its "
          "{n} FDEM runs were copied from another fold", lambda J: _loro_costs()),
    Quote("docs/workflow.md", "the same series took {m:.0f} min (`benchmarks/results/bench_loro.json`, run `anchored`; "
          "an upper bound: a development study ran beside it at the lowest priority). Of its job time, {d:.0f} % went "
          "to the selection's design, {r:.0f} % to the refinement runs, {c:.0f} % to the calibrations' ensembles and "
          "replicates and {k:.0f} % to the real-run check", lambda J: _loro_costs("anchored", refine=True)),
    Quote("docs/workflow.md", "On an idle machine, with later code that gave the same answers,\n  it took {m:.0f} min (run `anchored_idle`)",
          lambda J: _loro_idle(J)),
    Quote("docs/workflow.md", "on another machine, it took {m:.0f} min (run\n  `sleeping`): per FDEM run its solver time "
          "was {r:.2f} times `current_idle`'s, on a machine where the\n  paper disc member took {p:.2f} times the engine "
          "table's time with the engine before sleeping bodies, and\n  its chaotic runs walked other steps (its folds kept "
          "`face_gap` {fg} times, `lowpass` {lp}, `gauge_gain` {gg})", lambda J: _loro_sleeping(J)),
    Quote("docs/workflow.md", "On a machine like the earlier runs' (AVX-512) the same code took {m:.0f} min (run "
          "`sleeping_avx512`): per FDEM\n  run {r:.2f} times `current_idle`'s solver time; its folds kept `face_gap` {fg} "
          "times, `gauge_gain` {gg}, `lowpass` {lp}.", lambda J: _loro_sleeping(J, "sleeping_avx512")),
    Quote("docs/workflow.md", "and {m:.0f} min with the code before sleeping bodies (run `current_idle`, the same answers "
          "again), of whose job time the refinement runs are {r:.0f} %", lambda J: _loro_idle(J, "current_idle")),
    Quote("docs/inference.md", "draws {N} twins as the\n  harness does", _bank),
    Quote("docs/inference.md", "post-peak the yardstick scores {cs:.3f} / {ce:.3f}", _bank),
    Quote("docs/inference.md", "and the shipped form 0.33 / 0.96 and 0.29 / 0.56 on the two benchmarks (the table above)",
          by=CENSORED_PROSE),
    Quote("docs/inference.md", "holds the post-peak {ps:.3f} / {pe:.3f}", _bank),
    Quote("docs/inference.md", "against 0.25 / 0.62 and 0.22 / 0.72.", by=CENSORED_PROSE),
    Quote("docs/inference.md", "(WIS 0.96 of the prior's, against 0.62 where the window holds the post-peak); on the "
          "second's it is learned better than on the others (0.56 against 0.72)", by=CENSORED_PROSE),
    Quote("docs/inference.md", "these twins' `E_t` intervals cover 88 % at 90 %", by=CENSORED_PROSE),
    Quote("docs/inference.md", "Held out run by run over its {n}\n  reference runs it covers {c1:.3f} / {c2:.3f} at 90 % "
          "and scores {s:.3f} (`sigma_t`) and {e:.3f} (`E_t`) of the\n  prior's, and where it would call `E_t` learned "
          "its intervals hold {l:.3f}; banks of {r1} to {r3} runs\n  score {s1:.3f}-{s3:.3f} and {e1:.3f}-{e3:.3f} "
          "on common twins", _bank),
    Quote("README.md", "a calibrated posterior without a likelihood, from {N} runs of the\n  same twin: "
          "{s:.2f} and {e:.2f}", _bank),
    Quote("README.md", "covers 90 % with uniform ranks", by=HARNESS),
    Quote("docs/closing-the-loop.md", "prediction by the walk's weighted paired test. An effect is named where its real runs "
          "predict better at\np < {l}, the largest z", lambda J: {"l": __import__("calibration.realrun").realrun.LEVEL}),
    Quote("docs/closing-the-loop.md", "planted parameter lay inside its interval in {b} of {n} ({p} of {n} with the "
          "per-sample form), every reported\nparameter in {bp} of {m} ({pp} of {m})", _interval_forms),
    Quote("docs/closing-the-loop.md", "`sigma_t` came out {lo:.0f}-{hi:.0f} % low on every series", _interval_forms),
    Quote("docs/closing-the-loop.md", "on the same series it held {ap} of {m} but the planted parameter in only {a} of {n}",
          _interval_forms),
    Quote("README.md", "about {n} FDEM runs for three records", lambda J: {
        "n": f"{round(J('studies/results/realrun_selection_seating_5392_profile5_k8.json')['runs'], -1):,}"}),
    Quote("docs/closing-the-loop.md", "about {n} runs for\nthree records and four candidates", lambda J: {
        "n": f"{round(J('studies/results/realrun_selection_seating_5392_profile5_k8.json')['runs'], -1):,}"}),
    Quote("README.md", "the walk's level in {p} of {n} simulated data sets", lambda J: {
        "p": J("studies/results/oracle_power.json")["cases"]["rate_strength"]["passes"],
        "n": J("studies/results/oracle_power.json")["cases"]["rate_strength"]["realizations"]}),
    Quote("README.md", "`sigma_t` covers 94 % and 96 % (bar 85-95 %), `E_t` 85 % and 87 %;", by=HARNESS),
    Quote("README.md", "ranks fail the first (p = 0.003:", by=HARNESS),
    Quote("README.md", "pass the second (p = 0.077)", by=HARNESS),
    Quote("README.md", "on the planted-effect benchmark the nulls added nothing in {n_ok} of {n} series, but a physical effect "
          "beyond the mesh scatter was named first in {k} of {K}", lambda J: _planted_score(J)),
    Quote("README.md", "sits above the truth in 53 of 64 twins below 40 MPa, by a median 7 %, and below it in 17 of 18 "
          "above 50 MPa", by=HARNESS),
    Quote("README.md", "WIS over the prior's `sigma_t` 0.26 and 0.23 against 0.25, `E_t` 0.67 and 0.69 against 0.55",
          by=HARNESS),
    Quote("README.md", "span a median 0.71 and 0.74 of the box", by=HARNESS),
    Quote("README.md", "data from the finer mesh are held 83 % / 83 % and 77 % / 73 %, data with an undeclared rate "
          "dependence 90 % / 75 % and 75 % / 85 %: the 80 % bar is met on neither of the two", by=HARNESS),
    Quote("README.md", "hold less (78 % / 71 % and 73 % / 72 % well-specified)", by=HARNESS),
    Quote("README.md", "learned from 24 paired runs per record (a third benchmark), finer-mesh data are held {asc:.0f} % / "
          "{aec:.0f} % at a WIS of {asw:.2f} / {aew:.2f}", _approximation),
    Quote("docs/own-data.md", "held the truth in its 90 % intervals in {bsc:.0f} % and {bec:.0f} % of {n0} twins\n(`sigma_t`, "
          "`E_t`; `benchmarks/results/coverage_location.json`, under the 80 % bar), with it in {asc:.0f} % and {aec:.0f} %\n"
          "of {n} others, each set of ten with its own pairs, at a weighted interval score of {asw:.2f} and {aew:.2f} of the\n"
          "prior's against {bsw:.2f} and {bew:.2f}", _approximation),
    Quote("README.md", "finer-mesh data with an undeclared rate dependence {rs:.0f} % / {re:.0f} % (a fourth); over all "
          "{N} of these twins {ps:.0f} % / {pe:.0f} %, the bar met", _rate_approximation),
    Quote("docs/own-data.md", "the held-out record's mesh offset was {o:.1f} MPa rms, up to {om:.1f} MPa; its RMSE after "
          "the loop\n{a:.1f} MPa against {b:.1f} MPa without the term; scored against its data as observed it read {u:.1f} MPa\n"
          "([studies](../studies/README.md), `marble_approximation.py`; its pairs added {dm:.1f} min to the run's wall time)",
          _heldout_approximation),
    Quote("docs/own-data.md", "the held-out records' RMSE after the loop averaged {a:.1f} MPa\nagainst {b:.1f} MPa without "
          "it and their bands covered {ca:.2f} of their curves on average against {cb:.2f}; the series took\n{wa:.0f} min on 2 cores "
          "against {wb:.0f} min for an earlier version's run without it", _series_approximation),
    Quote("docs/own-data.md", "about {dm:.1f} min per disc record and {cm:.1f} min per marble cylinder record on 2 cores\n"
          "(a `standard` run takes {dr:.1f} and {cr:.1f} times a `fast` one", _approximation_cost),
    Quote("README.md", "an undeclared rate dependence moves `sigma_t` (median {up:.0f} % above the truth)", _rate_approximation),
    Quote("docs/own-data.md", "on {n} standard-mesh twins\nthat also carried a rate dependence nobody declared, it held the "
          "truth in {rs:.0f} % (`sigma_t`) and {re:.0f} %\n(`E_t`) of them, `sigma_t`'s median {up:.0f} % above the truth\n"
          "(`benchmarks/results/coverage_rate_approximation.json`); over all {N} standard-mesh twins of both kinds\n"
          "{ps:.0f} % and {pe:.0f} %", _rate_approximation),
    Quote("docs/inference.md", "60 misspecified twins of the form, is met "
          "(`benchmarks/results/coverage_misspecified_approximation.json`:\n    90 % coverage {ps:.0f} % / {pe:.0f} %)",
          _rate_approximation),
    Quote("README.md", "those the verdict calls informative held the truth in 10 of 16 and 13 of 15 twins at 90 %",
          by=FLAG_SPLIT),
    Quote("docs/inference.md", "it informative on 16 of the 100 well-specified twins and those 90 % intervals hold the truth "
          "in 10 (binomial p = 0.003 against 90 %); the 84 it flags cover at their level but score 0.75 of the prior's",
          by=FLAG_SPLIT),
    Quote("docs/inference.md", "Two of the six misses stopped on the iteration budget, which the verdict flags "
          "`not_converged`; the converged ones hold {k} of {n} (p = {p:.3f})", lambda J: _informative_e_t(J)),
    Quote("docs/inference.md", "moved the well-specified `sigma_t` median nearer the truth (median over truth {c:.3f} against "
          "{s:.3f}) and\n  met the well-specified bars, but held the `standard`-mesh data's `sigma_t` in {kc} of {n} twins "
          "against the\n  shipped form's {ks}, under the plan's bar (0.80, or the shipped form's)", lambda J: _location_decision(J)),
    Quote("docs/inference.md", "(the two benchmarks pooled: {k} of\n  {n}, p = {p:.3f} against 90 %)",
          lambda J: _pooled_learned(J, "sigma_t")),
    Quote("docs/inference.md", "The second benchmark does not repeat the miss: {k2} of {n2}\n  (p = {p2:.3f}). Pooled, "
          "they hold {k} of {n} (p = {p:.4f}), rejected at the 1 % level", lambda J: _pooled_learned(J, "E_t")),
    Quote("docs/inference.md", "The\n  shipped form without the approximation error held the truth in {s[0]} of {s[1]} (`sigma_t`) and "
          "{e[0]} of {e[1]}\n  (`E_t`) over both benchmarks' misspecified sets; with it, {sa[0]} of {sa[1]} and {ea[0]} of "
          "{ea[1]}.", lambda J: _misspecified_90()),
    Quote("docs/inference.md", "within 0.025 of the product's own on the default run's six posteriors, with the same flag",
          by="tests/test_harness_informative.py::test_the_flag_estimated_from_quantiles_is_the_product_s"),
    # docs/workflow.md: the default run
    Quote("docs/workflow.md", "on an idle 2-core machine\n(run {run_s} s, exit {exit_code}; "
          "{fdem_runs} FDEM runs, {refine_runs} of them the refinement batches (25 per calibration record) and {refit} the\n"
          "refits on real runs; install {install_s} s",
          lambda J: (lambda r, c: {**r, "refit": sum(st.get("refit", {}).get("runs", 0) for st in c["fdem_runs"].values())}
                     if r["machine_idle"] and r["run_s"] == c["wall_s"] and r["commit"] == c["commit"] else {})(
              J(f"{RUN}/run.json"), J("benchmarks/results/default_run_costs.json"))),
    Quote("docs/workflow.md", "the default twin's `sigma_t` means {ds:.2f} posterior sd apart", lambda J: {
        "ds": J(BLAS)["posterior"]["sigma_t"]["mean_difference_over_sd"]}),
    Quote("docs/workflow.md", "Its FDEM runs took {s:.0f} solver-seconds: {m:.0f} in `marble_loop`, {p:.0f} in\n`planted_gap`, "
          "{t:.0f} in `twin_ref`, the refits {r:.0f} of them (`benchmarks/results/default_run_costs.json`), so no\nschedule on 2 "
          "cores ends before {b:.0f} s", lambda J: (lambda d: {
              "s": d["solver_s"], "b": d["solver_bound_s"],
              "r": sum(st.get("refit", {}).get("solver_s", 0.0) for st in d["fdem_runs"].values()),
              **{k: sum(v["solver_s"] for v in d["fdem_runs"][e].values())
                 for k, e in (("m", "marble_loop"), ("p", "planted_gap"), ("t", "twin_ref"))}})(
              J("benchmarks/results/default_run_costs.json"))),
    Quote("docs/workflow.md", "is {stat} against the statistic's target {target}", lambda J: {
        "stat": f"{_twin()['verdict']['chi2_per_obs']['reported_against_noise_and_simulator']:.2f}",
        "target": f"{_twin()['verdict']['chi2_per_obs']['stop_target']:.2f}"}),
    Quote("docs/workflow.md", "its predictive coverage is {cov}", lambda J: {
        "cov": f"{_twin()['predictive_coverage_90']['synthetic']:.2f}"}),
    Quote(CL, "A cylinder series costs {lo:.0f}-{hi:.0f} s on 2 cores", lambda J: _series_walls(J, "cylinder")),
    Quote(CL, "real runs at the planted point by up to {first:.1f} MPa RMSE, with the term by at most {second:.1f} MPa",
          _interactions),
    Quote(CL, "the friction at {mu:.2f} for {planted} planted", _interactions),
    Quote(CL, "(z = {z:.2f}). The next round proposed `rate_strength` on top of it, which real runs confirmed at the edge of "
          "its\nlevel (p = {p2:.4f} against {l2:.4f}, t on {d2:.1f} degrees of freedom), though no rate law was planted. The\n"
          "identification gate (step 6) dropped it: re-fitted on real runs its `k` is {k:.3f} [{klo:.3f}, {khi:.3f}], its "
          "interval\nholding the law's null. So the loop ships the face gap alone. The held-out record's RMSE fell from {rb} "
          "to {ra} MPa,\nits 90 % predictive band covering {c:.2f} of its curve. The selection's fit of the shipped model holds "
          "{n_in} of the {n}\ncalibration records' planted gaps in its 90 % intervals, and the held-out record's predicted "
          "interval holds its\nown; its `sigma_t` interval misses its truth ({m} [{lo}, {hi}] MPa for {t:.0f})", _planted_gap),
    Quote(CL, "the same series confirms `face_gap` (z = {z1:.2f}) and then\n`{e2}` (z = {z2:.2f}), per-record shifts of "
          "{s1:.2f} and {s2:.2f} us whose intervals, re-fitted on real runs, hold\nzero; the fitted gaps' intervals hold {gi} "
          "of the 2 planted gaps, the workflow's and the refit's `sigma_t`\nintervals hold its truth (the selection's does "
          "not), and the held-out\nrecord's RMSE falls from {rb:.1f} to {ra:.1f} MPa, its band covering {c:.2f} of its curve",
          _planted_gap_approximation),
    Quote(CL, "the walk is the same and the gate drops the shift: its re-fitted intervals, {a0:.1f} to {a1:.1f} us and "
          "{b0:.1f} to\n{b1:.1f} us, hold zero. The face gap is shipped alone, its gaps re-fitted on real runs at {g1:.1f} "
          "[{l1:.1f}, {h1:.1f}] and\n{g2:.1f} [{l2:.1f}, {h2:.1f}] um for the planted {p1:.1f} and {p2:.1f} (the second "
          "missed), `sigma_t` at {s:.1f} [{sl:.1f}, {sh:.1f}] MPa,\nholding its {t:.0f}. The held-out record's RMSE falls "
          "from {rb:.1f} to {ra:.1f} MPa, its band covering {c:.2f} of its curve", _planted_gap_gated),
    Quote(CL, "in an earlier run of this series, whose surrogate put PlantGap_02's\ngap at {lo:.0f}-{hi:.0f} um, real `fast` "
          "runs at its `sigma_t` and `E_t` fit the record\nbest at a gap of {best:.0f} um", lambda J: (lambda r: {
              "best": r["least_rmse_gap_m"] * 1e6, "lo": r["reported_90_m"][0] * 1e6, "hi": r["reported_90_m"][1] * 1e6})(
              J("studies/results/added_parameter_real_runs.json")["records"]["PlantGap_02"])),
    Quote(CL, "Re-fitted on real runs (step 6; {kr} runs in {kn} rounds, after the {dr} of the dropped model), the gaps are\n"
          "{g1:.1f} [{l1:.1f}, {h1:.1f}] and {g2:.1f} [{l2:.1f}, {h2:.1f}] um for the planted {p1:.1f} and {p2:.1f}, and "
          "`sigma_t` {s} [{sl}, {sh}] MPa:\nnearer, and {k} of the {n} planted gaps inside; `sigma_t` still misses. The three "
          "check meshes give {ml:.1f}-{mh:.1f} um for\nPlantGap_02", _planted_refit),
    Quote(CL, "falls, from {is1:.0f} to {ir1:.0f} um and from\n{is2:.0f} to {ir2:.0f} um", _planted_refit),
    Quote(CL, "by a chi-square per degree of freedom of {q1:.1f}-{q2:.1f} against the {qs:.1f} its surrogate claimed there, so the\n"
          "verify round widens its intervals {f:.2f} times", _planted_refit),
    Quote(CL, "(chi-square {t0:.0f}-{t1:.0f} against {r0:.0f}-{r1:.0f} per record)", lambda J: (lambda recs: {
        "t0": min(m["chi2"] for r in recs for m in r["real"]["planted"].values()),
        "t1": max(m["chi2"] for r in recs for m in r["real"]["planted"].values()),
        "r0": min(m["chi2"] for r in recs for m in r["real"]["refit"].values()),
        "r1": max(m["chi2"] for r in recs for m in r["real"]["refit"].values())}
        if all(max(m["chi2"] for m in r["real"]["planted"].values()) < min(m["chi2"] for m in r["real"]["refit"].values())
               for r in recs) else {})(list(J("studies/results/refit_real_misfit.json")["records"].values()))),
    Quote(CL, "the\nloop named `face_gap` first in {nf} of {n}, and the refit's 90 % intervals held {gi} of the {gn} planted gaps (the\n"
          "selection's {si} of {gn}) and {ri} of {rn} planted values with `sigma_t` and `E_t` (the selection's {ai} of {rn}); the\n"
          "interval score over the planted value averaged {rs:.2f} against the selection's {ss:.2f}", _refit_check),
    Quote(CL, "by a chi-square per degree of freedom of {q0:.1f}-{q1:.1f}, the intervals widened {f0:.2f}-{f1:.2f} times, one gap's\n"
          "interval spans {wl:.0f}-{wh:.0f} um", _refit_check),
    Quote(CL, "the same series made at `fast` is missed alike, its gaps at\n{a:.1f} and {b:.1f} um", lambda J: (
        lambda d: {"a": d["PlantGap_01"]["mean_m"] * 1e6, "b": d["PlantGap_02"]["mean_m"] * 1e6}
        if not any(v["inside_90"] for v in d.values()) else {})(
            J("studies/results/refit_resolution_bias.json")["sets"]["fast"]["records"])),
    Quote("README.md", "re-fitted on\nreal runs its gaps are {g1:.0f} [{l1:.0f}, {h1:.0f}] and {g2:.0f} [{l2:.0f}, {h2:.0f}] um, their 90 % "
          "intervals holding the planted {p1:.0f} and {p2:.0f} (the selection's surrogate put them at {s1:.0f} and {s2:.0f}",
          lambda J: (lambda r: r if r and r["k"] == r["n"] else {})(_planted_refit(J))),
    Quote("docs/workflow.md", "face gaps of {lo:.0f}-{hi:.0f} um that the calibration does not declare): `{e}` is proposed first "
          "and\n  confirmed on real FDEM runs; `{e2}`, which nobody planted, is confirmed next at the edge of its test's\n"
          "  level and dropped by the identification gate, its parameter re-fitted on real runs holding its null; the\n"
          "  held-out record's RMSE falls from {rb} to {ra} MPa", lambda J: (
              lambda g, rep, chk, ref: {"lo": min(g) * 1e6, "hi": max(g) * 1e6, "e": rep["added"][0],
                                        "e2": ref["gated"][0]["identification"]["effect"],
                                        "rb": _mpa(chk["heldout"]["PlantGap_03"]["before"]["rmse"]),
                                        "ra": _mpa(chk["heldout"]["PlantGap_03"]["after"]["rmse"])}
              if rep["added"] == [rep["selection"]["rounds"][0]["chosen"]] and len(ref["gated"]) == 1
              and not ref["gated"][0]["identification"]["identified"] else {})(
              [t["planted"]["face_gap.gap_m"] for t in J("data/examples/planted_gap/truth.json")["tests"]],
              J(f"{RUN}/planted_gap/diagnosis/report.json"), J(f"{RUN}/planted_gap/diagnosis/check.json"),
              J(f"{RUN}/planted_gap/diagnosis/refit.json"))),
    Quote(CL, "On the real runs `{kept}` predicts better than `{b}` (z = {zb:.2f}), one of its round's other\n"
          "proposals run for real, and `{a}`, another, predicts better than `{kept}` (z = {za:.2f}; the report says\nso)",
          lambda J: (lambda idn: (lambda ev: {
              "kept": idn["chosen"], "a": ev[0]["effect"], "za": -ev[0]["z"], "b": ev[1]["effect"], "zb": ev[1]["z"]}
              if [e["told_apart"] for e in ev] == [False, True] and ev[0]["other_better"] else {})(
              idn["real_evidence"]))(J(f"{RUN}/planted_gap/diagnosis/report.json")["identification"][-1])),
    Quote("README.md", "both gains' 90 % intervals reach the catalogue's lowest, {g:g}", lambda J: (
        lambda ends: {"g": fx.get_effect("gauge_gain").params[0].lower}
        if len(ends) == 2 and all(fx.catalogue_edge(k, v) == "lower" for k, v in ends.items()) else {})(
        {k: q["q05"] for k, q in J(f"{RUN}/marble_loop/diagnosis/refit.json")["posterior"].items()
         if k.startswith("gauge_gain.g@")})),
    Quote("README.md", "the held-out record's RMSE falls from {rb} to {ra} MPa", lambda J: {
        "rb": _mpa(J(f"{RUN}/planted_gap/diagnosis/check.json")["heldout"]["PlantGap_03"]["before"]["rmse"]),
        "ra": _mpa(J(f"{RUN}/planted_gap/diagnosis/check.json")["heldout"]["PlantGap_03"]["after"]["rmse"])}),
    Quote(CL, "face gap drawn\naround {g:.0f} um)", lambda J: {
        "g": J("data/examples/planted_gap/truth.json")["plant"]["face_gap.gap_m"] * 1e6}),
    Quote(CL, "four granite discs at {lo}-{hi} m/s carrying", lambda J: (lambda v: {"lo": v[0], "hi": v[-1]})(
        re.findall(r"\d+\.\d+", J("benchmarks/planted_plan.json")["series"]["disc"]["drivers"][0].split(" m/s")[0]))),
    Quote(CL, "the selection proposed\n`{named}` and real FDEM runs confirmed it (z = {z:.2f}), the held-out disc's RMSE falling "
              "from {rb:.1f}\nto {ra:.1f} MPa. A wrong name: the rate law, ranked {rank} of ten",
          lambda J: (lambda w, rec: {
              "named": w["named"], "z": w["walk"][0][1], "rb": w["heldout_rmse_MPa"]["PlantDiscRateStrength_04"]["before"],
              "ra": w["heldout_rmse_MPa"]["PlantDiscRateStrength_04"]["after"],
              "rank": {3: "third"}.get(rec["proposals"]["planted_rank"], rec["proposals"]["planted_rank"])})(
              J("studies/results/weighted_confirmation.json")["runs"]["planted_disc_rate_strength_5303"]["weighted"],
              J("benchmarks/results/bench_planted_records/disc_rate_strength_5303.json")["series"][0])),
    Quote(CL, "mesh scatter on the marble cylinder is {pre:.2f} % of the\n   peak before the failure peak and {post:.1f} % "
              "after it", lambda J: (lambda v: {"pre": 100 * v["std_rms_pre_peak_over_peak"],
                                                "post": 100 * v["std_rms_post_peak_over_peak"]})(
              J("benchmarks/results/bench_sim_variability.json")["cases"]["marble"]["mesh_variability"])),
    Quote(CL, "a planted seating it had proposed (z {zp:.2f})\n   that the weighted error confirms (z {zw:.1f})",
          lambda J: (lambda r: {"zp": r["plain"]["walk"][0][1], "zw": r["weighted"]["walk"][0][1]})(
              J("studies/results/weighted_confirmation.json")["runs"]["planted_seating_5302"])),
    Quote(CL, "the walk's weighted error: a gain on the rise under a post-peak mesh scatter 17x the rise's, mostly not "
              "shared by two steps' runs, 40 draws at 0.05 / 10; a null candidate, 1000 draws | weighted: confirmed in 40, "
              "the plain sum in none; the null rejected in 5.2 % at one-sided 5 %",
          by="tests/test_weighted_walk.py::test_the_weighted_comparison_holds_its_level_on_a_null_candidate"),
    Quote(CL, "the weighted test confirms it in 40 of 40 draws and\n   the plain sum in none",
          by="tests/test_weighted_walk.py::test_an_effect_on_the_rise_is_confirmed_weighted_where_the_post_peak_scatter_hides_it_from_the_plain_sum"),
    Quote(CL, "on the null and decoy\n   stand-ins, 0 of 20 confirmed each with the alternatives walked",
          by="tests/test_protocol_decoys.py::test_decoy_candidates_are_rejected_at_the_walks_level_on_null_series"),
    Quote(CL, "told apart from a model 4.5x as far off the data, not from one 1.05x as far (both at alpha / 2)",
          by="tests/test_protocol_selection.py::test_the_kept_effect_is_compared_on_real_runs_with_the_other_models_of_its_round"),
    Quote(CL, "a disc series {lo:.0f}-{hi:.0f} s", lambda J: _series_walls(J, "disc")),
    Quote(CL, "(per-record gaps of 50-150 um)",
          by="tests/test_anchored_selection.py::test_on_the_anchored_model_the_selection_names_a_planted_face_gap"),
    Quote(CL, "none of 12 covers its planted gap, with it 11 of 12 cover",
          by="tests/test_anchored_selection.py::test_the_anchored_models_own_error_makes_the_fitted_gaps_intervals_hold_the_planted_ones"),
    Quote("docs/workflow.md", "`sigma_t`'s interval holds its\n  truth; `E_t`'s posterior expects to score {r:.2f} of the "
          "prior's, so the verdict is `uninformative`, and its\n  interval misses the truth, {t:.0f} J/m^2", lambda J: {
              "r": _twin()["verdict"]["score_over_prior"]["E_t"], "t": _twin()["truth"]["E_t"]}
          if (_twin()["posterior"]["sigma_t"]["q05"] < _twin()["truth"]["sigma_t"] < _twin()["posterior"]["sigma_t"]["q95"]
              and not _twin()["posterior"]["E_t"]["q05"] < _twin()["truth"]["E_t"] < _twin()["posterior"]["E_t"]["q95"]
              and _twin()["verdict"]["flags"] == ["uninformative"]) else {}),
    Quote("README.md", "(`uninformative`: its\nposterior expects to score {r:.2f} of the prior's", lambda J: {
        "r": _twin()["verdict"]["score_over_prior"]["E_t"]}),
    Quote("docs/workflow.md", "({pre} MPa before the peak, {post} after", lambda J: {
        "pre": _span([x for r in _marble()["discrepancy"]["records"].values() for x in r["sigma_phases"][:2]],
                     lambda x: f"{x / 1e6:.0f}"),
        "post": _span([r["sigma_phases"][2] for r in _marble()["discrepancy"]["records"].values()],
                      lambda x: f"{x / 1e6:.0f}")}),
    Quote("docs/workflow.md", "is {stat} where the stop asks {target}", lambda J: {
        "stat": f"{_marble()['misfit'][-1]['stop_chi2_per_obs']:.2f}",
        "target": f"{_marble()['misfit'][-1]['stop_target']:.2f}"}),
    Quote("docs/workflow.md", "against `R` alone {chi2:.0f}", lambda J: {
        "chi2": _marble()["verdict"]["chi2_per_obs"]["final"]}),
    Quote("docs/workflow.md", "predictive coverage ({a}, {b})", lambda J: {
        "a": f"{_marble()['predictive_coverage_90']['CaMa_SHPB_004']:.2f}",
        "b": f"{_marble()['predictive_coverage_90']['CaMa_SHPB_014']:.2f}"}),
    Quote("docs/workflow.md", "at random points 0.5-18 s into a small twin", by=KILL),
    Quote("docs/workflow.md", "(failure peak {fast}, {standard} and {paper} MPa at `fast`, `standard` and `paper` for the "
          "reference parameters, at {t_fast}, {t_standard} and {t_paper} us", lambda J: {
              **{k: _mpa(v["reference"]["peak_stress_Pa"]) for k, v in J(SHPB)["presets"].items()},
              **{f"t_{k}": f"{v['reference']['peak_t_s'] * 1e6:.0f}" for k, v in J(SHPB)["presets"].items()}}),
    Quote("docs/engine.md", "at 1.25 times today's step no curve moves by more than\n{r125:.2f} % of its peak (rms up to "
          "the peak), so today's step is converged. At 1.5 times it (a safety\nof 0.9, still inside the bound) a member's "
          "solver takes {slo:.2f}-{shi:.2f}x less, but the weak-brittle\ndisc's energy balance goes from {w0:.2f} % to "
          "{w15:.2f} % after its peak (fragment impacts) and a\nfragmenting sandstone cylinder at 280 1/s peaks {s15:.2f} % "
          "higher over eight paired meshes (their peak\nsd {ssd:.2f} %); at 2 times its energy balance reaches {s2e:.1f} %. "
          "The marble cylinder is indifferent\nup to 2 times ({m15:+.2f} % and {m2:+.2f} % at the peak)",
          lambda J: _time_step()),
    Quote("docs/engine.md", "the `fast` discs {dlo:.2f}-{dhi:.2f}x faster, the `fast` marble cylinder\n{m:.2f}x, the "
          "paper disc {p:.2f}x (its disc wakes within the wave's first microseconds), every fracture check\nthe same, "
          "the transmitted stress up to the peak within {agree} of the peak", lambda J: _sleep()),
    Quote("docs/engine.md", "sleeping\ntook {clo:.0f}-{chi:.0f} % of a `fast` cylinder's solver time off and changed a disc's "
          "by {xlo:.0f}-{xhi:.0f} % (the machine's\nnoise). Up to the peak it moved the transmitted stress by at most "
          "{calm} of the peak on the discs and\nthe marble records but for the strong-tough disc ({st}, where "
          "moving its nodes by `1e-17` m moved it\n{stx}), and by {s23:.2f} % and {s24:.2f} % on the two sandstone "
          "records", lambda J: _sleep()),
    Quote("docs/engine.md", "moved SeeSst_SHPB_023 by the same\n{b23:.2f} %. Over the whole window those rounding "
          "perturbations moved the cylinders' curves by up to {rw:.1f} %\nof the peak, sleeping by up to {sw:.1f} %",
          lambda J: _sleep()),
    Quote("docs/engine.md", "the `fast` discs {lo:.2f}-{hi:.2f}x faster, the `fast` marble cylinder {m:.2f}x, the paper "
          "disc {p:.2f}x ({old:.1f} s to {new:.1f} s that day), every curve bit-identical", lambda J: {
              "lo": min(c["speedup_solver"] for k, c in J(ENGINE_JOINTS)["cases"].items() if k.startswith("disc_fast")),
              "hi": max(c["speedup_solver"] for k, c in J(ENGINE_JOINTS)["cases"].items() if k.startswith("disc_fast")),
              "m": J(ENGINE_JOINTS)["cases"]["marble_fast"]["speedup_solver"],
              "p": J(ENGINE_JOINTS)["cases"]["disc_paper_reference"]["speedup_solver"],
              "old": J(ENGINE_JOINTS)["cases"]["disc_paper_reference"]["baseline"]["solver_wall_s"],
              "new": J(ENGINE_JOINTS)["cases"]["disc_paper_reference"]["new"]["solver_wall_s"]}
          if all(c["agreement"]["bit_identical"] for c in J(ENGINE_JOINTS)["cases"].values()) else {}),
    Quote("docs/inference.md", "(WIS 0.96 of the prior's, against 0.62 where", by=CENSORED_PROSE),
    Quote("docs/inference.md", "its observed maximum lies in the window's last {us:.0f} us", lambda J: {
        "us": coverage_table.CENSOR_S * 1e6}),
    Quote("docs/workflow.md", "(a `fast` cylinder member about {wall:.0f} s there)", lambda J: {
        "wall": J(ENGINE)["cases"]["marble_fast"]["new"]["wall_s"]}),
    Quote("docs/workflow.md", "is predicted with\n  {rb} MPa RMSE and a peak {pb:.0f} % high by the base model, {ra} MPa "
          "and {pa:.0f} % with the face gap and the gauge\n  gain",
          lambda J: {"rb": _mpa(_heldout()["before"]["rmse"]), "pb": 100 * _heldout()["before"]["peak_rel_error"],
                     "ra": _mpa(_heldout()["after"]["rmse"]), "pa": 100 * _heldout()["after"]["peak_rel_error"]}),
    Quote("docs/workflow.md", "lowered the cross-validated RMSE from {b0} to {a0} MPa\n  with `{e0}`, and its weighted error "
          "(each time by its noise and mesh-scatter variance) fell by\n  far more than its sd (z = {z0:.2f} on {d0:.1f} "
          "degrees of freedom, against the level 0.05 / {k0}): confirmed.\n  The next round proposed `{e1}` on top of it, "
          "which lowered the RMSE to {a1} MPa (z = {z1:.2f}) and was\n  confirmed", lambda J: {
              "b0": _mpa(_walk_step(0)["real_cv_rmse_before"]), "a0": _mpa(_walk_step(0)["real_cv_rmse_after"]),
              "e0": _walk_step(0)["effect"], "z0": _walk_step(0)["z"], "d0": _walk_step(0)["dof"],
              "k0": round(0.05 / _walk_step(0)["level"]), "e1": _walk_step(1)["effect"],
              "a1": _mpa(_walk_step(1)["real_cv_rmse_after"]), "z1": _walk_step(1)["z"]}
          if _walk_step(0)["confirmed"] and _walk_step(1)["confirmed"] and _walk_step(1)["alternative_to"] is None else {}),
    Quote("docs/workflow.md", "On those runs `{e}` predicts better than the\n  other models of its round, `{a}` (z = {za:.2f}) "
          "and `{b}` (z = {zb:.2f})", lambda J: (lambda rep: (lambda ev: {
              "e": rep["added"][-1], "a": ev[0]["effect"], "za": ev[0]["z"], "b": ev[1]["effect"], "zb": ev[1]["z"]}
              if all(x["told_apart"] for x in ev) else {})(rep["identification"][-1]["real_evidence"]))(
              J(f"{RUN}/marble_loop/diagnosis/report.json"))),
    Quote("docs/workflow.md", "The weighted errors per observation, {b:.0f} before and {a:.0f} after", lambda J: {
        "b": J(f"{RUN}/marble_loop/diagnosis/report.json")["confirmation"]["real_cv_loss"]["0"],
        "a": J(f"{RUN}/marble_loop/diagnosis/report.json")["confirmation"]["real_cv_loss"]["2"]}),
    Quote("README.md", "the held-out record's RMSE fell from {rb}\nto {ra} MPa", lambda J: {
        "rb": _mpa(_heldout()["before"]["rmse"]), "ra": _mpa(_heldout()["after"]["rmse"])}),
    Quote("docs/workflow.md", "its 90 % band covers\n  {c:.2f} of its curve, scoring {s:.2f} of the design box's band", lambda J: {
        "c": J(f"{RUN}/marble_loop/diagnosis/check.json")["predictive_band"]["records"]["CaMa_SHPB_006"]["after"]
        ["predictive_coverage_90"],
        "s": J(f"{RUN}/marble_loop/diagnosis/check.json")["predictive_band"]["records"]["CaMa_SHPB_006"]["after"]
        ["interval_score_over_box"]}),
    # docs/shpb-models.md: bench_shpb.json, the onset theory, bench_sim_variability.json
    Quote(SM, "(-0.03, +0.03) R, {t:.0f} us after the incident wave's arrival", lambda J: {
        "t": _shpb("standard", "reference")["first_joint_t_s"] * 1e6}),
    Quote(SM, "is reached at {onset} MPa of Brazilian stress", lambda J: {"onset": _mpa(_onset(15, 45)["centre_onset_Pa"])}),
    Quote(SM, "the failure peak ({peak} MPa, {t:.0f} us, the first load maximum) the {n} broken joints all lie within "
          "0.15 R of the diameter and the two loaded faces carry the same force within {f:.1f} %", lambda J: {
              "peak": _mpa(_shpb("standard", "reference")["peak_stress_Pa"]),
              "t": _shpb("standard", "reference")["peak_t_s"] * 1e6, "n": _shpb("standard", "reference")["broken_at_peak"],
              "f": 100 * abs(_shpb("standard", "reference")["force_ratio_at_peak"] - 1)}),
    Quote(SM, "Energy balance within {others:.1f} % of the external work in every run but one (`fast`, weak-brittle: "
          "{wb:.1f} %", lambda J: {
              "others": 100 * max(r["energy_balance_rel"] for p, k, r in _shpb_runs() if (p, k) != ("fast", "weak_brittle")),
              "wb": 100 * _shpb("fast", "weak_brittle")["energy_balance_rel"]}),
    Quote(SM, "deepest contact penetration {span} % of the element size", lambda J: {
        "span": _span([100 * r["max_contact_penetration_over_h"] for *_, r in _shpb_runs()], lambda x: f"{x:.1f}")}),
    Quote(SM, "overlap by up to {o:.2f} of an element", lambda J: {
        "o": max(r["overlap_at_end_over_h"] for *_, r in _shpb_runs())}),
    Quote(SM, "the failure peak at `standard` is within {s_lo:+.1f} to {s_hi:+.1f} % of `paper` at all three points, "
          "`fast` within {f_lo:+.1f} to {f_hi:+.1f} %", lambda J: {
              **{f"{p[0]}_lo": 100 * min(r["peak_rel_diff_to_paper"] for q, _, r in _shpb_runs() if q == p)
                 for p in ("standard", "fast")},
              **{f"{p[0]}_hi": 100 * max(r["peak_rel_diff_to_paper"] for q, _, r in _shpb_runs() if q == p)
                 for p in ("standard", "fast")}}),
    Quote(SM, "the reference peak at `fast`, {peak} MPa, lies above", lambda J: {
        "peak": _mpa(_shpb("fast", "reference")["peak_stress_Pa"])}),
    Quote(SM, "the split at {t:.0f} us ({peak} MPa)", lambda J: {
        "t": _shpb("paper", "strong_tough")["peak_t_s"] * 1e6, "peak": _mpa(_shpb("paper", "strong_tough")["peak_stress_Pa"])}),
    Quote(SM, "put the weakest place at {x:.2f} R for joints {a:.0f} degrees off the diameter, in shear, {ref:.1f} % below "
          "the centre's tensile onset at the reference and {wb:.0f} % at the weak-brittle point", lambda J: {
              "x": _onset(25, 45)["weakest"]["x_over_R"], "a": _onset(25, 45)["weakest"]["joint_angle_deg"],
              "ref": 100 * (1 - _onset(25, 45)["weakest_over_centre"]), "wb": 100 * (1 - _onset(25, 30)["weakest_over_centre"])}),
    Quote(SM, "with onset at {onset} MPa of Brazilian stress", lambda J: {"onset": _mpa(_onset(15, 45)["centre_onset_Pa"])}),
    Quote(SM, "shorten the stable step to {disc} of the unperturbed mesh's (disc), {cyl} (cylinder)", lambda J: {
        "disc": _span(_dt_ratios("twin"), lambda x: f"{x:.2f}"), "cyl": _span(_dt_ratios("marble"), lambda x: f"{x:.2f}")}),
    Quote(SM, "one run at a time, {wall_s:.0f} s;", lambda J: J(VAR)),
    Quote(SM, "the peak's mesh std ({std:.2f} MPa) is three times the twin's observation noise (1 % of the peak) and equals "
          "the effect of a {eq:.1f} % change of `sigma_t` (8 runs on the unperturbed mesh with `sigma_t` spread evenly over "
          "+-1 %: peak std {pstd:.2f} MPa, d peak / d `sigma_t` = {slope:.2f}; up to the peak RMS std {pre:.0f} kPa, after it "
          "{post:.1f} MPa)", lambda J: {
              "std": _var("twin")["mesh_variability"]["peak_stress_Pa"]["std"] / 1e6,
              "eq": 100 * _var("twin")["sigma_t_pm_1pct"]["sigma_t_rel_equivalent_to_mesh_peak_std"],
              "pstd": _var("twin")["sigma_t_pm_1pct"]["peak_stress_Pa"]["std"] / 1e6,
              "slope": _var("twin")["sigma_t_pm_1pct"]["dpeak_dsigma_t"],
              "pre": _var("twin")["sigma_t_pm_1pct"]["std_rms_pre_peak_Pa"] / 1e3,
              "post": _var("twin")["sigma_t_pm_1pct"]["std_rms_post_peak_Pa"] / 1e6}),
    Quote(SM, "{n} of the {runs} discs start their first joint just outside the central region (|y| {y} R) and {unb} misses "
          "the 10 % force balance at the peak", lambda J: {
              "n": len(_off_centre()), "runs": len(_var("twin")["replicates"]),
              "y": _span([abs(r["first_joint_xy_over_R"][1]) for r in _off_centre()], lambda x: f"{x:.2f}"),
              "unb": {1: "one"}.get(sum(not r["checks"]["faces_balanced"] for r in _var("twin")["replicates"]), "?")}),
    Quote(SM, "moves the disc's peak by {peak} MPa and its post-peak curve by {post} MPa RMS", lambda J: {
        "peak": _span([abs(d["peak_change_Pa"]) / 1e6 for d in _var("twin")["dt_control"]], lambda x: f"{x:.2f}"),
        "post": _span([d["rms_diff_post_peak_Pa"] / 1e6 for d in _var("twin")["dt_control"]], lambda x: f"{x:.1f}")}),
    Quote(SM, "the cylinder's peak moves by {hi:.1f} to {lo:.1f} MPa and its rise by {pre} MPa RMS", lambda J: {
        "hi": max(d["peak_change_Pa"] for d in _var("marble")["dt_control"]) / 1e6,
        "lo": min(d["peak_change_Pa"] for d in _var("marble")["dt_control"]) / 1e6,
        "pre": _span([d["rms_diff_pre_peak_Pa"] / 1e6 for d in _var("marble")["dt_control"]], lambda x: f"{x:.1f}")}),
    # docs/engine.md: the time step's bounds
    Quote("docs/engine.md", "gives a critical step {pf:.2f}x (`fast`) and {ps:.2f}x (`standard`) the Gershgorin bound "
          "without the contact term, and the contact budget (8 k per surface node, 4 k was unstable) takes another "
          "{cf:.2f}x / {cs:.2f}x", lambda J: {
              "pf": _step("fast")["power_over_gershgorin_no_contact"], "ps": _step("standard")["power_over_gershgorin_no_contact"],
              "cf": _step("fast")["contact_budget_factor"], "cs": _step("standard")["contact_budget_factor"]}),
    # docs/inference.md: the simulator's variability, the error models' comparison
    Quote("docs/inference.md", "the disc's stress varies with the mesh by {pre:.2f} MPa rms before the peak ({prer:.2f} % of it), "
          "its peak by {peak:.1f} % (the equivalent of {eq:.1f} % in `sigma_t`), and by {post:.2f} MPa ({postr:.0f} %) after it, "
          "correlated over {tau:.1f} us; a 1 % change of `sigma_t` on one mesh moves the post-peak by {one:.1f} MPa", lambda J: {
              "pre": _var("twin")["mesh_variability"]["std_rms_pre_peak_Pa"] / 1e6,
              "prer": 100 * _var("twin")["mesh_variability"]["std_rms_pre_peak_over_peak"],
              "peak": 100 * _var("twin")["mesh_variability"]["peak_stress_Pa"]["std"]
              / _var("twin")["mesh_variability"]["peak_stress_Pa"]["mean"],
              "eq": 100 * _var("twin")["sigma_t_pm_1pct"]["sigma_t_rel_equivalent_to_mesh_peak_std"],
              "post": _var("twin")["mesh_variability"]["std_rms_post_peak_Pa"] / 1e6,
              "postr": 100 * _var("twin")["mesh_variability"]["std_rms_post_peak_over_peak"],
              "tau": _var("twin")["mesh_variability"]["post_peak_correlation_time_s"] * 1e6,
              "one": _var("twin")["sigma_t_pm_1pct"]["std_rms_post_peak_Pa"] / 1e6}),
    Quote("docs/inference.md", "the marble records' 90 % predictive coverage stays about {cov:.2f}", lambda J: {
        "cov": sum(r["coverage_90_ar1"] for r in _error_models("marble_loop")["records"].values())
        / len(_error_models("marble_loop")["records"])}),
    # docs/closing-the-loop.md: the leave-one-record-out series and the population average's study
    Quote(CL, "(z {z} against {crit})", lambda J: {
        "z": _span([s["z"] for f in J(REFUTED) for s in f["walk"]], lambda x: f"{x:.2f}"),
        "crit": _one(f"{NormalDist().inv_cdf(1 - s['level']):.2f}" for f in J(REFUTED) for s in f["walk"])}),
    Quote(CL, "(SeeSst_SHPB_003: its own gap about {own:.2f} mm against the population's {pop:.2f} mm, held-out RMSE "
          "{before} -> {after} MPa", lambda J: {
              "own": 1e3 * sum(_gaps_003()) / len(_gaps_003()),
              "pop": 1e3 * _fold003()["heldout_values"]["face_gap.gap_m@SeeSst_SHPB_003"],
              "before": _mpa(_fold003()["rmse_before"]), "after": _mpa(_fold003()["rmse_after"])}),
    Quote(CL, "Measured: {sw} of {sr} (sandstone), {mw} of {mr} (marble); the held-out folds then gave {sf} of {sn} and "
          "{mf} of {mn} worse", lambda J: {
              "sw": _loro("sandstone")["cv_risk_worse_than_base"]["worse"],
              "sr": _loro("sandstone")["cv_risk_worse_than_base"]["records"],
              "mw": _loro("marble")["cv_risk_worse_than_base"]["worse"],
              "mr": _loro("marble")["cv_risk_worse_than_base"]["records"],
              "sf": _loro("sandstone")["folds_worse"], "sn": _loro("sandstone")["folds"],
              "mf": _loro("marble")["folds_worse"], "mn": _loro("marble")["folds"]}),
    Quote("README.md", "held-out 90 % bands covered {ca:.2f} of the curves after the loop, {w} MPa wide for peaks of {p} MPa, "
          "and scored no better than the same band over the design box ({r:.2f} of its interval score)",
          # "no better": at least the box band's interval score
          lambda J: (lambda q: q if q["r"] >= 0.995 else {})(
              {"ca": _rerun(kind="gated")["totals"]["mean_predictive_coverage_90_after"],
               "r": _rerun(kind="gated")["totals"]["mean_interval_score_over_box_after"],
               "w": _span(_rerun_band_values("after", "band_width_rms_Pa", kind="gated"), lambda x: f"{x:.0f}"),
               "p": _span(_rerun_peaks(kind="gated"), lambda x: f"{x:.0f}")})),
    Quote(CL, "The base model's held-out RMSE is {b} MPa on average against {first} MPa in the first run", lambda J: {
        "b": _mpa(_rerun()["totals"]["mean_rmse_before"]), "first": _mpa(_loro("sandstone")["mean_rmse_before"])}),
    Quote(CL, "The loop lowers the error to {a} MPa. The held-out 90 % bands cover {cb:.2f} -> {ca:.2f} of the held-out "
          "curves on average", lambda J: {
              "a": _mpa(_rerun()["totals"]["mean_rmse_after"]),
              "cb": _rerun()["totals"]["mean_predictive_coverage_90_before"],
              "ca": _rerun()["totals"]["mean_predictive_coverage_90_after"]}),
    Quote(CL, "They are {wb} MPa rms from edge to edge with the base model and {wa} MPa with the model each fold kept, "
          "against peaks of {p} MPa. The model discrepancy makes most of that width ({db} MPa sd with the base model, "
          "{da} MPa after)", lambda J: {
              "wb": _span(_rerun_band_values("before", "band_width_rms_Pa"), lambda x: f"{x:.0f}"),
              "wa": _span(_rerun_band_values("after", "band_width_rms_Pa"), lambda x: f"{x:.0f}"),
              "p": _span(_rerun_peaks(), lambda x: f"{x:.0f}"),
              "db": _span(_rerun_band_values("before", "discrepancy"), lambda x: f"{x:.0f}"),
              "da": _span(_rerun_band_values("after", "discrepancy"), lambda x: f"{x:.0f}")}),
    Quote("docs/workflow.md", "the same series\n  took {m:.0f} min on the same kind of machine (run `gated_folds`): the folds' refits made {n} "
          "FDEM runs, {sv:.0f}\n  solver-seconds, and every fold's gate kept the walk's model, so its walks and errors are\n  "
          "`sleeping_avx512`'s to the last digit", lambda J: (lambda runs: (lambda g, o: {
              "m": g["wall_s"] / 60, "n": g["fdem_runs"]["refit"]["runs"], "sv": g["fdem_runs"]["refit"]["solver_s"]}
              if g["answers"] == o["answers"] else {})(runs["gated_folds"], runs["sleeping_avx512"]))(
              J("benchmarks/results/bench_loro.json")["runs"])),
    Quote(CL, "`benchmarks/results/loro_gated_sandstone/`, {m:.0f} min on 2 cores): each fold's refit, on its own four\n"
          "calibration records, found every kept effect identified, so each fold shipped the walk's model", lambda J: (
              lambda run: {"m": run["wall_s"] / 60} if all(f["gated"] == [] and f["identification"]["identified"]
                                                             for f in run["refit_per_fold"].values()) else {})(
              J("benchmarks/results/loro_gated_sandstone/run.json"))),
    Quote(CL, "at {lv:g} % for each\nof a fold's four copies, every gauge gain's starts at {g:g}, the catalogue's lowest "
          "gain, and every\n`lowpass` time constant's ends at {t:g} us, its largest", lambda J: _gated_edges(J)),
    Quote(CL, "calibration drivers), the test passes on {rsp} of {rsn} data realizations for the cylinders' rate law "
          "(median z {rsz:.2f};\nthe base model absorbs it at `sigma_t` {rsig} MPa for the planted 25) and on {drp} of "
          "{drn} for the disc's (median z\n{drz:.2f}), but on {frp} of {frn} for the end friction (z {frz:.1f}), the "
          "seating (z {sez:.0f}) and the face gap (z {fgz:.0f}).", lambda J: _oracle(J)),
    Quote(CL, "the benchmark's `standard` mesh (the models still at `fast`) the rate law passes on {rp} of {rn} (median z "
          "{rz:.2f}),\nthe friction, seating and face gap on {fp} of {fn} again (z {fz:.1f}, {sz:.0f}, {gz:.0f})",
          lambda J: _oracle_standard(J)),
    Quote(CL, "at most {c:.2f} of the 18 series could\nbe named in expectation ({u:.2f} at the 95 % bounds of the "
          "passing shares)", lambda J: {"c": J("studies/results/oracle_power.json")["ceiling"]["share"],
                                        "u": J("studies/results/oracle_power.json")["ceiling"]["share_upper95"]}),
    Quote(CL, "After the loop the held-out RMSE is {r:.2f} times the calibration\nrecords' cross-validated RMSE, before it "
          "{b:.2f} times", lambda J: (lambda s: {"r": s["after"]["ratio"], "b": s["before"]["ratio"]})(
              J("studies/results/selection_optimism.json")["series"]["loro_gated_sandstone"])),
    Quote(CL, "The held-out RMSE falls\n{b} -> {a} MPa on average, and the held-out bands cover {cb:.2f} -> {ca:.2f} of the "
          "curves ({lo:.2f}-{hi:.2f} per fold\nafter the loop)", lambda J: {
              "b": _mpa(_rerun(kind="gated")["totals"]["mean_rmse_before"]),
              "a": _mpa(_rerun(kind="gated")["totals"]["mean_rmse_after"]),
              "cb": _rerun(kind="gated")["totals"]["mean_predictive_coverage_90_before"],
              "ca": _rerun(kind="gated")["totals"]["mean_predictive_coverage_90_after"],
              "lo": min(r["predictive_coverage_90_after"] for r in _rerun(kind="gated")["rows"]),
              "hi": max(r["predictive_coverage_90_after"] for r in _rerun(kind="gated")["rows"])}),
    Quote(CL, "`benchmarks/results/loro_rerun_sandstone/`, {m:.0f} min on 2 cores). Two", lambda J: {
              "m": J("benchmarks/results/loro_rerun_sandstone/run.json")["wall_s"] / 60}),
    Quote(CL, "`benchmarks/results/loro_rerun_marble/`, {m:.0f} min on 2 cores). Its held-out RMSE is {b} -> {a} MPa on "
          "average; one fold of four is worse", lambda J: {
              "m": J("benchmarks/results/loro_rerun_marble/run.json")["wall_s"] / 60,
              "b": _mpa(_rerun("marble")["totals"]["mean_rmse_before"]),
              "a": _mpa(_rerun("marble")["totals"]["mean_rmse_after"])}),
    Quote(CL, "held-out bands cover {cb:.2f} -> {ca:.2f} of the held-out curves on average, {lo:.2f}-{hi:.2f} per fold. "
          "They are {w} MPa rms wide after the loop against peaks of {p} MPa", lambda J: {
              "cb": _rerun("marble")["totals"]["mean_predictive_coverage_90_before"],
              "ca": _rerun("marble")["totals"]["mean_predictive_coverage_90_after"],
              "lo": min(b["predictive_coverage_90"] for b in _rerun_bands("marble")),
              "hi": max(b["predictive_coverage_90"] for b in _rerun_bands("marble")),
              "w": _span(_rerun_band_values("after", "band_width_rms_Pa", "marble"), lambda x: f"{x:.0f}"),
              "p": _span(_rerun_peaks("marble"), lambda x: f"{x:.0f}")}),
    Quote("README.md", "On a four-record marble series (eight members per fold) the loop left the held-out RMSE at "
          "{b} -> {a} MPa on average ({k} of {n} folds worse) and the held-out 90 % bands covered {ca:.2f} of the curves "
          "after it, {w} MPa wide", lambda J: (lambda t: {
              "b": _mpa(t["mean_rmse_before"]), "a": _mpa(t["mean_rmse_after"]), "k": t["folds_worse"], "n": t["folds"],
              "ca": t["mean_predictive_coverage_90_after"],
              "w": _span(_rerun_band_values("after", "band_width_rms_Pa", "marble", "gated"), lambda x: f"{x:.0f}")})(
              _rerun("marble", "gated")["totals"])),
    Quote(CL, "members the folds' posteriors of `sigma_t` are wide and skewed to {dir} values", lambda J: _marble_fold_skew()),
    Quote(CL, "`benchmarks/results/loro_gated_marble/`, {m:.0f} min on 2 cores): every fold's gate kept the walk's model.\n"
          "Its held-out RMSE is {b} -> {a} MPa on average, {k} folds of {n} worse after the loop, while\nnone of the {r} "
          "calibration records was predicted worse than the base on its real cross-validated runs;\nthe held-out bands "
          "cover {cb:.2f} -> {ca:.2f} of the curves ({lo:.2f}-{hi:.2f} per fold after the loop)", lambda J: (
              lambda t, run, rows: {"m": run["wall_s"] / 60, "b": _mpa(t["mean_rmse_before"]), "a": _mpa(t["mean_rmse_after"]),
                                    "k": t["folds_worse"], "n": t["folds"], "r": t["cv_risk_worse_than_base"]["records"],
                                    "cb": t["mean_predictive_coverage_90_before"], "ca": t["mean_predictive_coverage_90_after"],
                                    "lo": min(r["predictive_coverage_90_after"] for r in rows),
                                    "hi": max(r["predictive_coverage_90_after"] for r in rows)}
              if t["cv_risk_worse_than_base"]["worse"] == 0 and all(
                  f["gated"] == [] and f["identification"]["identified"] for f in run["refit_per_fold"].values()) else {})(
              _rerun("marble", "gated")["totals"], J("benchmarks/results/loro_gated_marble/run.json"),
              _rerun("marble", "gated")["rows"])),
    Quote(CL, "records it never read (their\nbands cover {c:.2f} after the loop)", lambda J: {
        "c": J("studies/results/selection_optimism.json")["series"]["loro_gated_marble"]["after"][
            "band_coverage_90_calibration"]}),
    Quote(CL, "Its base model differs from the re-run's ({g} against {r} MPa before the loop)", lambda J: {
        "g": _mpa(_rerun("marble", "gated")["totals"]["mean_rmse_before"]),
        "r": _mpa(_rerun("marble")["totals"]["mean_rmse_before"])}),
    Quote(CL, "the base model's, {w} MPa wide (its discrepancy term alone {d} MPa sd)", lambda J: {
        "w": _span(_rerun_band_values("before", "band_width_rms_Pa", "marble"), lambda x: f"{x:.0f}"),
        "d": _span(_rerun_band_values("before", "discrepancy", "marble"), lambda x: f"{x:.0f}")}),
    Quote(CL, "the 90 % interval of the CaMa_SHPB_007 fold reaches {hi:.0f} MPa), and a held-out record is predicted at "
          "the posterior mean: its peak comes out {lo:.0f}-{top:.0f} % high in two folds", lambda J: {
              "hi": J("benchmarks/results/loro_rerun_marble/CaMa_SHPB_007_summary.json")["posterior"]["sigma_t"]["q95"] / 1e6,
              **_marble_high_peaks()}),
    Quote(CL, "the form used before, gave an interval score of {a[interval_score_Pa]:.1f} MPa, coverage {a[coverage_90]:.2f} "
          "and bands {a[width_rms_Pa]:.1f} MPa wide; the cross-validated residuals averaged over {win:.0f} us gave "
          "{b[interval_score_Pa]:.1f} MPa, coverage {b[coverage_90]:.2f} and {b[width_rms_Pa]:.1f} MPa. Shorter averages "
          "(10-80 us) scored {s}, a 320 us one {w:.1f} MPa", lambda J: {
              "a": _study_band("calibration"), "b": _study_band("cv81"), "win": _band_window_us(),
              "s": _span([_study_band(f"cv{n}")["interval_score_Pa"] for n in (5, 11, 21, 41)], lambda x: f"{x:.1f}")
              + " MPa", "w": _study_band("cv161")["interval_score_Pa"]}),
    Quote(CL, "the held-out bands' interval score is {hs:.2f} of that box band's on the re-run sandstone series and\n"
          "{hm:.2f} on the re-run marble series on average (`score/box` in the table); the calibration records' cross-validated bands score {cs:.2f} "
          "and {cm:.2f}", lambda J: {
              "hs": _rerun()["totals"]["mean_interval_score_over_box_after"],
              "hm": _rerun("marble")["totals"]["mean_interval_score_over_box_after"],
              "cs": _calib_over_box("sandstone"), "cm": _calib_over_box("marble")}),
    Quote("docs/workflow.md", "a `fast` disc simulation in a batch of 8 costs {new:.2f} s, counting Snakemake's job, "
          "the interpreter, the engine's load, the mesh and the files (`benchmarks/results/bench_batch.json`, one core; "
          "{old:.2f} s before the rules collecting", lambda J: {
              "new": J("benchmarks/results/bench_batch.json")["new"]["overhead_per_member_s_median"],
              "old": J("benchmarks/results/bench_batch.json")["old"]["overhead_per_member_s_median"]}),
    Quote(CL, "residual less what (a), (b) and (d) already give it (in (a) the per-record values from the population's\n"
          "plug-in normal, whose spread is what a residual's expected square holds), averaged over {w:.0f} us and\nfloored at zero",
          lambda J: {"w": _band_window_us()}),
    Quote(CL, "so its curve scores it out of sample as well. The {w:.0f} us were chosen on the",
          lambda J: {"w": _band_window_us()}),
    Quote(CL, "series, each record's band built from the other calibration records' residuals ({n} bands over the",
          lambda J: {"n": _study_band("cv81")["n"]}),
    Quote(CL, "leave-one-out error is {n} times the records' noise and {s} times the simulator's own scatter", lambda J: {
        "n": _span(_emulator_ratios("noise_rms_Pa"), lambda x: f"{x:.0f}"),
        "s": _span(_emulator_ratios("simulator_rms_Pa"), lambda x: f"{x:.1f}")}),
    Quote(CL, "lowered the emulated cross-validated RMSE by {rel:.0f} % on the earlier series' calibration records "
          "(`studies/population_average_cv.py`, `studies/results/population_average_cv.json`: {point:.2f} -> {avg:.2f} MPa, "
          "se {se:.2f}, better in {better} of {n}, worse than the base in {worse} of {n} either way)", lambda J: {
              "rel": 100 * (1 - _pop()["mean_rmse_Pa"]["average"] / _pop()["mean_rmse_Pa"]["point"]),
              "point": _pop()["mean_rmse_Pa"]["point"] / 1e6, "avg": _pop()["mean_rmse_Pa"]["average"] / 1e6,
              "se": _pop()["average_minus_point_Pa"]["se"] / 1e6, "better": _pop()["average_minus_point_Pa"]["average_better"],
              "n": _pop()["predictions"],
              "worse": _one(str(_pop()["worse_than_base"][k]) for k in ("point", "average"))}),
    # docs/own-data.md: the example's run, and the dispersion correction's figures the suite asserts
    Quote(OD, "2 cores, {m} min {s} s, {fdem_runs} FDEM runs): sigma_t {st} MPa [{st5}, {st95}], E_t {et:.0f} J/m^2 "
          "[{et5:.0f}, {et95:.0f}] (90 % intervals)", lambda J: {
              "m": J(f"{OWN}/run.json")["run_s"] // 60, "s": J(f"{OWN}/run.json")["run_s"] % 60,
              "fdem_runs": J(f"{OWN}/run.json")["fdem_runs"],
              "st": _mpa(_own()["posterior"]["sigma_t"]["mean"]), "st5": _mpa(_own()["posterior"]["sigma_t"]["q05"]),
              "st95": _mpa(_own()["posterior"]["sigma_t"]["q95"]), "et": _own()["posterior"]["E_t"]["mean"],
              "et5": _own()["posterior"]["E_t"]["q05"], "et95": _own()["posterior"]["E_t"]["q95"]}),
    Quote(OD, "the observations inside the 90 % predictive band {cov:.2f}; verdict `{verdict}`", lambda J: {
        "cov": _own()["predictive_coverage_90"]["granite_disc"], "verdict": _own()["verdict"]["verdict"]}),
    Quote(OD, "misfit per observation {stat:.3f} against its target {target:.3f}", lambda J: {
        "stat": _own()["misfit"][-1]["stop_chi2_per_obs"], "target": _own()["misfit"][-1]["stop_target"]}),
    Quote(OD, "peaks at 173.5 MPa instead of 172.2 MPa, its mean force balance goes from 0.026 to 0.020",
          by="tests/test_dispersion.py::test_a_sheet_turns_the_correction_on"),
    Quote(OD, "within 0.0061 of c0", by="tests/test_dispersion.py::test_the_solver_reproduces_the_freiburg_table"),
    Quote(OD, "changes by 42 % of its amplitude over 1.25 m",
          by="tests/test_dispersion.py::test_a_dispersed_pulse_is_corrected_back"),
    # integers the inventory does not flag (tools/docs_numbers.py: an integer with a unit reads as an input),
    # quoted all the same where they are results
    Quote("docs/inference.md", "the data prefer the AR(1) discrepancy by {span} nats per record", lambda J: {
        "span": _span([r["loglik_ar1"] - r["loglik_inflated"] for e in J("studies/results/error_models.json")["experiments"]
                       for r in e["records"].values()], lambda x: f"{round(x, -1):.0f}")}),
    Quote(SM, "failure peak at {span} us, halves pushed apart", lambda J: {
        "span": _span([r["peak_t_s"] * 1e6 for *_, r in _shpb_runs()], lambda x: f"{x:.0f}")}),
    Quote("docs/workflow.md", "the failure peak at {span} us at the three check points", lambda J: {
        "span": _span([r["peak_t_s"] * 1e6 for *_, r in _shpb_runs()], lambda x: f"{x:.0f}")}),
    # the central crack's first joint at every check point, to the nearest 10 us as the docs say "about"
    Quote(SM, "central crack from about {t} us", lambda J: {
        "t": _one(f"{round(r['first_joint_t_s'] * 1e6, -1):.0f}" for *_, r in _shpb_runs())}),
    # the twin is the `fast` disc at the reference parameters
    Quote("docs/workflow.md", "the central crack from about {crack:.0f} us, the failure peak at about {peak:.0f} us",
          lambda J: {"crack": round(_shpb("fast", "reference")["first_joint_t_s"] * 1e6, -1),
                     "peak": round(_shpb("fast", "reference")["peak_t_s"] * 1e6, -1)}),
    Quote("docs/workflow.md", "each of the {completed_runs} runs that got to the end identical", lambda J: J(
        "benchmarks/results/bench_kill.json")),
    Quote(OD, "{fdem_runs} FDEM runs of the fast disc in the committed run", lambda J: J(f"{OWN}/run.json")),
    Quote("docs/workflow.md", "Cylinder: 0-360 us (the measured peaks at {span} us", lambda J: {
        "span": _span([_marble_peak_times()[r] for r in ("CaMa_SHPB_004", "CaMa_SHPB_014")],
                      lambda x: f"{round(x * 1e6, -1):.0f}")}),
    Quote(OD, "`init-config` gives 170 us",
          by="tests/test_init_config.py::test_the_granite_disc_gets_its_window_dt_and_table_2_box"),
    Quote("README.md", "posterior expects to score more than 0.55 of its prior box's", by=FLAG_BAR),
    Quote("README.md", "put its `sigma_t` means {ds:.2f} posterior\nsd apart", lambda J: {
        "ds": J(BLAS)["posterior"]["sigma_t"]["mean_difference_over_sd"]}),
    Quote("docs/inference.md", "iteration 1's parameters {p1:.0e} apart (relative), its runs' curves {r1:.0e}, iteration 3's\n"
          "  parameters {p3:.0e}; the reported `sigma_t` means {ds:.2f} of the posterior sd apart, `E_t`'s {de:.2f}",
          lambda J: (lambda d, it: {"p1": it[1]["params_max_rel_diff"], "r1": it[1]["responses_max_rel_diff"],
                                    "p3": it[3]["params_max_rel_diff"],
                                    "ds": d["posterior"]["sigma_t"]["mean_difference_over_sd"],
                                    "de": d["posterior"]["E_t"]["mean_difference_over_sd"]})(
              J(BLAS), {r["iteration"]: r for r in J(BLAS)["iterations"]})),
    Quote("docs/inference.md", "Across CPUs, {n} twins of the coverage harness run on two machines", lambda J: {
        "n": J(BITS)["summary"]["twins"]}),
    Quote("docs/inference.md", "the reported median moved by a\n  median {ms:.2f} of its 90 % interval's width for `sigma_t` and "
          "{me:.2f} for `E_t`, by more than {ps:.2f} and\n  {pe:.2f} in one twin in ten", lambda J: (lambda s, e: {
              "ms": s["median"], "me": e["median"], "ps": s["p90"], "pe": e["p90"]})(
              *(J(BITS)["summary"][p]["median_shift_over_width_abs"] for p in ("sigma_t", "E_t")))),
    Quote("docs/inference.md", "point of a grid from {m} mesh realizations with the other parameter at its truth and no emulator,\n"
          "  held the truth in {st} and {et} of {n} twins' 90 % intervals", lambda J: _synthetic_likelihood(J)),
    Quote("docs/inference.md", "posterior expects to score more than 0.55 of the prior box's", by=FLAG_BAR),
    Quote("docs/inference.md", "(0.144 of the box width)",
          by="tests/test_parameter_scores.py::test_the_uniform_prior_scores_0144_of_its_box_on_its_own_truths"),
    Quote("docs/inference.md", "a Gaussian posterior 3.45 sd over the box width, so the bar (0.55,", by=GAUSSIAN),
    Quote("docs/inference.md", "a Gaussian 90 % interval of about 0.53 of the box", by=FLAG_BAR),
]


def quotes_by_file() -> dict:
    """``{doc: [quote as it stands in the doc]}``."""
    out: dict = {}
    for q in QUOTES:
        out.setdefault(q.doc, []).append(q.text())
    return out


def _flat(path: str) -> str:
    return " ".join((ROOT / path).read_text().split())


def test_every_quote_stands_in_its_doc_with_its_json_numbers():
    missing = [(q.doc, q.text()) for q in QUOTES if " ".join(q.text().split()) not in _flat(q.doc)]
    assert not missing, missing


def test_a_quote_checked_elsewhere_names_a_test_that_exists():
    for q in QUOTES:
        if q.by:
            path, name = q.by.split("::")
            assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), re.M), q.by


def test_no_result_number_in_the_docs_is_unchecked():
    checked = quotes_by_file()
    found = []
    for path in docs_numbers.docs():
        name = str(path.relative_to(ROOT))
        found += [(name, *u) for u in docs_numbers.unchecked(name, path.read_text(), checked.get(name, []))]
    assert not found, "\n".join(f"{n}:{line} {num!r} in '{ctx}'" for n, line, num, ctx in found)


def test_the_inventory_flags_a_new_result_and_not_an_input():
    text = ("The run took 731 s, 230 simulations, and covered 87 % of the twins (z = 2.71); the crack starts at 70 us "
            "in the window 0-160 us at `sigma_t` 45 MPa.")
    flagged = [num for _, num, _ in docs_numbers.unchecked("docs/x.md", text)]
    # an integer with a unit is a result unless NOT_RESULTS names it: the window and the parameter's value are
    assert flagged == ["731 s", "230 simulations", "87 %", "2.71", "70 us"]
    # the same words inside a generated block, inline code or a checked quote are not flagged
    assert not docs_numbers.unchecked("docs/x.md", f"<!-- t:start -->\n{text}\n<!-- t:end -->")
    assert not docs_numbers.unchecked("docs/x.md", f"`{text}`")
    assert not docs_numbers.unchecked("docs/x.md", text, ["took 731 s, 230 simulations, and covered 87 %", "(z = 2.71)",
                                                          "starts at 70 us"])


def test_every_pending_result_still_stands_in_its_doc():
    """A pending entry excuses a result until its doc is rewritten; one whose words are gone is stale."""
    for doc, rx, _ in docs_numbers.PENDING:
        text = docs_numbers.masked((ROOT / doc).read_text())
        assert re.search(rx.replace(" ", r"\s+"), text), (doc, rx)
