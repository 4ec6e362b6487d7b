# Closing the loop (README, "Closing the loop"): after a measured experiment's calibration, a design of
# FDEM runs around its posterior (one job per design point and record, calibration and held-out
# records), then the discrepancy loop (calibration.diagnose on enkf.diagnosis) on an emulator of those runs:
# residual structure, candidate ranking, re-calibration, accept/reject, error before and after.
from calibration.experiment import diagnosis_settings
from calibration.workflow_io import record_name


def diagnosis_cfg(exp):
    return diagnosis_settings(EXPERIMENTS[exp])


def diagnosed_experiments():
    return [e for e in RUN if diagnosis_cfg(e)]


def heldout_records(exp):
    return {record_name(p): str(p) for p in diagnosis_cfg(exp)["heldout_records"]}


def design_records(exp):
    """Every record a design point is simulated for: the calibration records, then the held-out ones."""
    return {**records(exp), **heldout_records(exp)}


def design_files(exp, name):
    return expand("results/{exp}/diagnosis/design/{point}/{record}/{name}", exp=exp,
                  point=member_ids(diagnosis_cfg(exp)["design_points"]), record=list(design_records(exp)),
                  name=name)


rule diagnosis_heldout_observations:
    input:
        lambda wc: list(heldout_records(wc.exp).values()),
    output:
        csv="results/{exp}/diagnosis/heldout/obs.csv",
        meta="results/{exp}/diagnosis/heldout/obs.json",
    params:
        obs=lambda wc: EXPERIMENTS[wc.exp]["observations"],
        records=lambda wc: heldout_records(wc.exp),
    script:
        "../scripts/diagnosis_heldout.py"


rule diagnosis_design:
    input:
        posterior="results/{exp}/posterior.csv",
    output:
        design="results/{exp}/diagnosis/design/params.csv",
        meta="results/{exp}/diagnosis/design/design.json",
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_design.py"


rule diagnosis_member:
    """One FDEM run of the emulator design (failed runs are left out of the emulator)."""
    input:
        unpack(lambda wc: {"params": f"results/{wc.exp}/diagnosis/design/params.csv",
                           "record": [design_records(wc.exp)[wc.record]]}),
    output:
        curve="results/{exp}/diagnosis/design/{point}/{record}/curve.csv",
        run="results/{exp}/diagnosis/design/{point}/{record}/run.json",
    log:
        "results/{exp}/diagnosis/design/{point}/{record}/simulate.log",
    wildcard_constraints:
        point="[0-9]+",
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: design_records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "diagnosis", wc.point, diagnosis_cfg(wc.exp)["design_points"], wc.record, design_records(wc.exp))
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp),
        runtime=lambda wc: runtime_min(wc.exp),
    script:
        "../scripts/diagnosis_member.py"


def diagnosis_inputs(wc):
    files = {"design": f"results/{wc.exp}/diagnosis/design/params.csv",
             "design_meta": f"results/{wc.exp}/diagnosis/design/design.json",
             "curves": design_files(wc.exp, "curve.csv"),
             "obs": f"results/{wc.exp}/observations/obs.csv",
             "obs_meta": f"results/{wc.exp}/observations/obs.json"}
    if heldout_records(wc.exp):
        files["heldout"] = f"results/{wc.exp}/diagnosis/heldout/obs.csv"
        files["heldout_meta"] = f"results/{wc.exp}/diagnosis/heldout/obs.json"
    return files


rule diagnosis:
    input:
        unpack(diagnosis_inputs),
    output:
        report=report("results/{exp}/diagnosis/report.json", category="{exp}", subcategory="diagnosis"),
        candidates="results/{exp}/diagnosis/candidates.csv",
        params="results/{exp}/diagnosis/params.csv",
        errors="results/{exp}/diagnosis/errors.csv",
        covariates="results/{exp}/diagnosis/covariates.csv",
        fit=report("results/{exp}/diagnosis/fit.png", category="{exp}", subcategory="diagnosis",
                   caption="../report/diagnosis_fit.rst"),
        candidates_png=report("results/{exp}/diagnosis/candidates.png", category="{exp}", subcategory="diagnosis",
                              caption="../report/diagnosis_candidates.rst"),
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        records=lambda wc: list(records(wc.exp)),
        heldout=lambda wc: list(heldout_records(wc.exp)),
        design_records=lambda wc: list(design_records(wc.exp)),
        points=lambda wc: member_ids(diagnosis_cfg(wc.exp)["design_points"]),
    script:
        "../scripts/diagnosis.py"


rule diagnosis_check_member:
    """The FDEM check of the loop's answer: one real run per record (calibration and held-out) at the
    posterior mean before the loop (base model) and after it (with the effects it added), so the errors
    before and after are stated on FDEM, not only on the emulator."""
    input:
        unpack(lambda wc: {"report": f"results/{wc.exp}/diagnosis/report.json",
                           "record": [design_records(wc.exp)[wc.record]]}),
    output:
        curve="results/{exp}/diagnosis/check/{which}/{record}/curve.csv",
        run="results/{exp}/diagnosis/check/{which}/{record}/run.json",
    log:
        "results/{exp}/diagnosis/check/{which}/{record}/simulate.log",
    wildcard_constraints:
        which="before|after",
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: design_records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "check", ["before", "after"].index(wc.which), 2, wc.record, design_records(wc.exp))
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp),
        runtime=lambda wc: runtime_min(wc.exp),
    script:
        "../scripts/diagnosis_check_member.py"


def diagnosis_check_inputs(wc):
    files = {k: v for k, v in diagnosis_inputs(wc).items() if k in ("obs", "obs_meta", "heldout", "heldout_meta")}
    files["report"] = f"results/{wc.exp}/diagnosis/report.json"
    files["curves"] = expand("results/{exp}/diagnosis/check/{which}/{record}/curve.csv", exp=wc.exp,
                             which=["before", "after"], record=list(design_records(wc.exp)))
    return files


rule diagnosis_check:
    input:
        unpack(diagnosis_check_inputs),
    output:
        check=report("results/{exp}/diagnosis/check.json", category="{exp}", subcategory="diagnosis"),
        png=report("results/{exp}/diagnosis/check.png", category="{exp}", subcategory="diagnosis",
                   caption="../report/diagnosis_check.rst"),
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_check.py"
