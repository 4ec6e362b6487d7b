# Closing the loop by the frozen protocol (docs/closing-the-loop.md, calibration.closing): after a measured
# experiment's calibration, a design of FDEM runs around its posterior (one job per design point and
# record, calibration and held-out records), the selection of effects by cross-validation within the
# calibration records on the emulator of those runs (a checkpoint: it decides which real runs the check
# needs), real FDEM runs at each cross-validation point and held-out prediction point (on
# diagnosis.check_replicates mesh realizations, common to every step), then the
# confirmation walk and, last, the held-out records' errors. With `diagnosis: {validation: loro}` the
# experiment's records are each held out once (one fold experiment `<exp>__<record>` each, added to the
# config by the Snakefile) and rule loro tabulates the folds.
from calibration.closing import FOLD_SEPARATOR, candidate_effects
from calibration.experiment import diagnosis_settings
from calibration.workflow_io import record_name


def diagnosis_cfg(exp):
    return diagnosis_settings(EXPERIMENTS[exp])


def is_loro(exp):
    d = diagnosis_cfg(exp)
    return bool(d) and d.get("validation") == "loro"


def loro_experiments():
    return [e for e in RUN if is_loro(e)]


def loro_fold_names(exp):
    return [f for f, e in EXPERIMENTS.items() if e.get("loro_of") == exp]


def calibrated_experiments():
    """The experiments of the run that calibrate: a leave-one-record-out series runs its folds instead."""
    return [e for e in RUN if not is_loro(e)] + [f for e in loro_experiments() for f in loro_fold_names(e)]


def diagnosed_experiments():
    return [e for e in calibrated_experiments() if diagnosis_cfg(e)]


def heldout_records(exp):
    return {record_name(p): str(p) for p in diagnosis_cfg(exp)["heldout_records"]}


def design_records(exp):
    """Every record a design point is simulated for: the calibration records, then the held-out ones."""
    return {**records(exp), **heldout_records(exp)}


def design_files(exp, name):
    return expand("results/{exp}/diagnosis/design/{point}/{record}/{name}", exp=exp,
                  point=member_ids(diagnosis_cfg(exp)["design_points"]), record=list(design_records(exp)),
                  name=name)


def reported_analysis(exp):
    """The analysis.json of the calibration's reported ensemble (its error terms: noise, S, D)."""
    return iteration_files(exp, "analysis.json")


rule diagnosis_heldout_observations:
    """The held-out records reduced like the calibration records: their curves are read by the final
    evaluation only; before it, their incident wave (the simulations) and noise level (their band)."""
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
        mesh_seed=lambda wc: run_mesh_seed(EXPERIMENTS[wc.exp], "design", 0, int(wc.point),
                                           list(design_records(wc.exp)).index(wc.record)),
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
             "obs_meta": f"results/{wc.exp}/observations/obs.json",
             "analyses": reported_analysis(wc.exp),
             "summary": f"results/{wc.exp}/summary.json"}
    if heldout_records(wc.exp):
        files["heldout"] = f"results/{wc.exp}/diagnosis/heldout/obs.csv"
        files["heldout_meta"] = f"results/{wc.exp}/diagnosis/heldout/obs.json"
    return files


checkpoint diagnosis_select:
    """The selection on the emulator (calibration records only); lists the real FDEM runs of the check."""
    input:
        unpack(diagnosis_inputs),
    output:
        selection="results/{exp}/diagnosis/selection.pkl",
        rows="results/{exp}/diagnosis/check_runs.json",
        covariates="results/{exp}/diagnosis/covariates.csv",
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        candidates=lambda wc: candidate_effects(diagnosis_cfg(wc.exp)),
        design_records=lambda wc: list(design_records(wc.exp)),
        points=lambda wc: member_ids(diagnosis_cfg(wc.exp)["design_points"]),
    script:
        "../scripts/diagnosis.py"


def check_rows_of(exp):
    return read_json(checkpoints.diagnosis_select.get(exp=exp).output.rows)["rows"]


rule diagnosis_check_member:
    """One real FDEM run of the check: a step's cross-validation point of a calibration record, or its
    prediction point of a held-out record (check_runs.json, row `row`)."""
    input:
        rows="results/{exp}/diagnosis/check_runs.json",
        record=lambda wc: [design_records(wc.exp)[check_rows_of(wc.exp)[int(wc.row)]["record"]]],
    output:
        curve="results/{exp}/diagnosis/check/{row}/curve.csv",
        run="results/{exp}/diagnosis/check/{row}/run.json",
    log:
        "results/{exp}/diagnosis/check/{row}/simulate.log",
    wildcard_constraints:
        row="[0-9]+",
    params:
        sim=lambda wc: sim_settings(wc.exp),
        record_file=lambda wc: design_records(wc.exp)[check_rows_of(wc.exp)[int(wc.row)]["record"]],
        # replicate k of every step of one record on the record's k-th mesh realization: two steps'
        # runs differ by their parameters, not their meshes (a paired comparison)
        mesh_seed=lambda wc: run_mesh_seed(EXPERIMENTS[wc.exp], "check", 0,
                                           int(check_rows_of(wc.exp)[int(wc.row)].get("replicate", 0)),
                                           list(design_records(wc.exp)).index(check_rows_of(wc.exp)[int(wc.row)]["record"])),
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "check", int(wc.row), len(check_rows_of(wc.exp)), "all", ["all"])
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp),
        runtime=lambda wc: runtime_min(wc.exp),
    script:
        "../scripts/diagnosis_check_member.py"


def diagnosis_check_inputs(wc):
    files = {k: v for k, v in diagnosis_inputs(wc).items() if k not in ("summary",)}
    files["selection"] = f"results/{wc.exp}/diagnosis/selection.pkl"
    files["rows"] = f"results/{wc.exp}/diagnosis/check_runs.json"
    files["runs"] = [f"results/{wc.exp}/diagnosis/check/{i}/curve.csv" for i in range(len(check_rows_of(wc.exp)))]
    return files


rule diagnosis_check:
    """The confirmation walk on the real cross-validation runs; then, last, the held-out records."""
    input:
        unpack(diagnosis_check_inputs),
    output:
        report=report("results/{exp}/diagnosis/report.json", category="{exp}", subcategory="diagnosis"),
        check=report("results/{exp}/diagnosis/check.json", category="{exp}", subcategory="diagnosis"),
        png=report("results/{exp}/diagnosis/check.png", category="{exp}", subcategory="diagnosis",
                   caption="../report/diagnosis_check.rst"),
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_check.py"


rule loro:
    """Leave one record out over a series: the folds' held-out errors before and after, per fold and in
    total, and the figure."""
    input:
        reports=lambda wc: expand("results/{fold}/diagnosis/report.json", fold=loro_fold_names(wc.exp)),
        obs=lambda wc: expand("results/{fold}/diagnosis/heldout/obs.json", fold=loro_fold_names(wc.exp)),
    output:
        summary="results/{exp}/loro/summary.json",
        png=report("results/{exp}/loro/folds.png", category="{exp}", subcategory="leave one record out"),
    params:
        folds=lambda wc: loro_fold_names(wc.exp),
    script:
        "../scripts/loro.py"
