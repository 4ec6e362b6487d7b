# Closing the loop by the frozen protocol (docs/closing-the-loop.md, calibration.closing): after a measured
# experiment's calibration, a design of FDEM runs around its posterior (one job per design point and
# record, calibration and held-out records), the selection of effects by cross-validation within the
# calibration records on the emulator of those runs (a checkpoint: it decides which real runs the check
# needs), real FDEM runs at each cross-validation point and held-out prediction point (on
# diagnosis.check_replicates mesh realizations, common to every step), then the
# confirmation walk and, last, the held-out records' errors. With `diagnosis: {validation: loro}` the
# experiment's records are each held out once (one fold experiment `<exp>__<record>` each, added to the
# config by the Snakefile) and rule loro tabulates the folds.


rule diagnosis_heldout_observations:
    """The held-out records reduced (rule reduced_record) and corrected by their own approximation pairs
    like the calibration records: their curves are read by the final evaluation only; before it, their
    incident wave (the simulations) and noise level (their band).
    """
    input:
        unpack(heldout_observation_inputs),
    output:
        csv="results/{exp}/diagnosis/heldout/obs.csv",
        meta="results/{exp}/diagnosis/heldout/obs.json",
    log:
        "results/{exp}/logs/diagnosis_heldout_observations.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: {
            k: EXPERIMENTS[wc.exp][k]
            for k in ("kind", "seed", "preset", "observations")
        },
        records=lambda wc: {
            r: stored_record(wc.exp, r) for r in heldout_records(wc.exp)
        },
        approximation=lambda wc: approximation_folder(wc.exp),
    script:
        "../scripts/diagnosis_heldout.py"


rule diagnosis_design:
    input:
        posterior="results/{exp}/posterior.csv",
    output:
        design="results/{exp}/diagnosis/design/params.csv",
        meta="results/{exp}/diagnosis/design/design.json",
    log:
        "results/{exp}/logs/diagnosis_design.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_design.py"


# One FDEM run of the emulator design (failed runs are left out of the emulator).
rule diagnosis_member:
    input:
        batch=lambda wc: batch_file("diagnosis_member", wc),
    output:
        curve="results/{exp}/diagnosis/design/{point}/{record}/curve.csv",
        run="results/{exp}/diagnosis/design/{point}/{record}/run.json",
    wildcard_constraints:
        point="[0-9]+",
    params:
        parameters=lambda wc: {"row": wc.point},
        record_file=lambda wc: design_records(wc.exp)[wc.record],
        mesh_seed=lambda wc: run_mesh_seed(
            EXPERIMENTS[wc.exp],
            "design",
            0,
            design_mesh_point(EXPERIMENTS[wc.exp], wc.point),
            list(design_records(wc.exp)).index(wc.record),
        ),
        run=lambda wc: {"design_point": int(wc.point), "record": wc.record},


checkpoint diagnosis_select:
    """The selection on the emulator (calibration records only); lists the real FDEM runs of the check."""
    input:
        unpack(diagnosis_inputs),
        # the base model of the selection: the workflow's reported posterior (summary.json's draws)
        posterior="results/{exp}/posterior.csv",
    output:
        selection="results/{exp}/diagnosis/selection.pkl",
        rows="results/{exp}/diagnosis/check_runs.json",
        covariates="results/{exp}/diagnosis/covariates.csv",
    log:
        "results/{exp}/logs/diagnosis_select.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        candidates=lambda wc: candidate_effects(diagnosis_cfg(wc.exp)),
        design_records=lambda wc: list(design_records(wc.exp)),
        points=lambda wc: member_ids(design_size(EXPERIMENTS[wc.exp])),
    script:
        "../scripts/diagnosis.py"


# One real FDEM run of the check: a step's cross-validation point of a calibration record, or its
# prediction point of a held-out record (check_runs.json, row `row`).
rule diagnosis_check_member:
    input:
        batch=lambda wc: batch_file("diagnosis_check_member", wc),
    output:
        curve="results/{exp}/diagnosis/check/{row}/curve.csv",
        run="results/{exp}/diagnosis/check/{row}/run.json",
    wildcard_constraints:
        row="[0-9]+",
    params:
        parameters=lambda wc: {
            "values": check_rows_of(wc.exp)[int(wc.row)]["simulator"]
        },
        record_file=lambda wc: design_records(wc.exp)[
            check_rows_of(wc.exp)[int(wc.row)]["record"]
        ],
        # replicate k of every step of one record on the record's k-th mesh realization: two steps'
        # runs differ by their parameters, not their meshes (a paired comparison)
        mesh_seed=lambda wc: run_mesh_seed(
            EXPERIMENTS[wc.exp],
            "check",
            0,
            int(check_rows_of(wc.exp)[int(wc.row)].get("replicate", 0)),
            list(design_records(wc.exp)).index(
                check_rows_of(wc.exp)[int(wc.row)]["record"]
            ),
        ),
        run=lambda wc: {
            "check_row": int(wc.row),
            **{
                k: check_rows_of(wc.exp)[int(wc.row)][k]
                for k in ("step", "role", "record")
            },
        },


rule diagnosis_check:
    """The confirmation walk on the real cross-validation runs; then, last, the held-out records."""
    input:
        unpack(diagnosis_check_inputs),
    output:
        report=report(
            "results/{exp}/diagnosis/report.json",
            category="{exp}",
            subcategory="diagnosis",
        ),
        check=report(
            "results/{exp}/diagnosis/check.json",
            category="{exp}",
            subcategory="diagnosis",
        ),
        # every record's 90 % predictive band of the check (calibration.closing.predictive_bands)
        band="results/{exp}/diagnosis/check_band.csv",
        png=report(
            "results/{exp}/diagnosis/check.png",
            category="{exp}",
            subcategory="diagnosis",
            caption="../report/diagnosis_check.rst",
        ),
    log:
        "results/{exp}/logs/diagnosis_check.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_check.py"


# The shipped model's parameters re-fitted on real FDEM runs around its fit (calibration.refit;
# diagnosis.refit_rounds): each round a checkpoint that fits the last round's runs and lists the next
# round's, on the calibration records only; the walk and the held-out errors above are not changed.
checkpoint diagnosis_refit_round:
    input:
        unpack(refit_round_inputs),
    output:
        state="results/{exp}/diagnosis/refit/round_{r}.json",
    log:
        "results/{exp}/logs/diagnosis_refit_round_{r}.log",
    wildcard_constraints:
        r="[0-9]+",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_refit_round.py"


# One real FDEM run of a refit round: a record's anchor or one parameter moved, on the record's k-th check
# mesh (the check's own realizations).
rule diagnosis_refit_member:
    input:
        batch=lambda wc: batch_file("diagnosis_refit_member", wc),
    output:
        curve="results/{exp}/diagnosis/refit/iter_{it}/{row}/curve.csv",
        run="results/{exp}/diagnosis/refit/iter_{it}/{row}/run.json",
    wildcard_constraints:
        it="[0-9]+",
        row="[0-9]+",
    params:
        parameters=lambda wc: {"values": refit_row(wc)["simulator"]},
        record_file=lambda wc: design_records(wc.exp)[refit_row(wc)["record"]],
        mesh_seed=lambda wc: run_mesh_seed(
            EXPERIMENTS[wc.exp],
            "check",
            0,
            int(refit_row(wc)["replicate"]),
            list(design_records(wc.exp)).index(refit_row(wc)["record"]),
        ),
        run=lambda wc: {
            "refit_round": int(wc.it),
            "refit_row": int(wc.row),
            **{k: refit_row(wc)[k] for k in ("record", "replicate", "axis")},
        },


rule diagnosis_refit:
    """refit.json: the shipped model's parameters on real runs, beside the selection's surrogate fit."""
    input:
        last=lambda wc: refit_last_round(wc.exp),
    output:
        refit=report(
            "results/{exp}/diagnosis/refit.json",
            category="{exp}",
            subcategory="diagnosis",
        ),
    log:
        "results/{exp}/logs/diagnosis_refit.log",
    conda:
        CONDA_ENV
    script:
        "../scripts/diagnosis_refit.py"


# The selection on real runs (calibration.realrun; diagnosis.realrun_selection): each round a checkpoint
# that takes the last round's runs and lists the next round's, on the calibration records only; beside
# the walk, whose verdict it does not change.
checkpoint diagnosis_realrun_round:
    input:
        unpack(realrun_round_inputs),
    output:
        state="results/{exp}/diagnosis/realrun/round_{r}.json",
    log:
        "results/{exp}/logs/diagnosis_realrun_round_{r}.log",
    wildcard_constraints:
        r="[0-9]+",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/diagnosis_realrun_round.py"


# One real FDEM run of a round of the selection on real runs: a fit's linearisation (the selection's own
# mesh realizations), a cross-validation point (the check's realizations), or a run of the resolution
# round (its own realizations; at the finer preset where the row names one).
rule diagnosis_realrun_member:
    input:
        batch=lambda wc: batch_file("diagnosis_realrun_member", wc),
    output:
        curve="results/{exp}/diagnosis/realrun/iter_{it}/{row}/curve.csv",
        run="results/{exp}/diagnosis/realrun/iter_{it}/{row}/run.json",
    wildcard_constraints:
        it="[0-9]+",
        row="[0-9]+",
    params:
        sim=lambda wc: sim_settings(wc.exp, realrun_row(wc).get("preset")),
        parameters=lambda wc: {"values": realrun_row(wc)["simulator"]},
        record_file=lambda wc: design_records(wc.exp)[realrun_row(wc)["record"]],
        mesh_seed=realrun_mesh_seed,
        run=lambda wc: {
            "realrun_round": int(wc.it),
            "realrun_row": int(wc.row),
            **{k: realrun_row(wc)[k] for k in ("record", "track", "kind", "mesh")},
        },


checkpoint diagnosis_realrun:
    """realrun.json: what the selection on real runs names, each candidate's fit and test, the group; and
    the held-out records' prediction runs at the fits it reports (calibration.realrun_files.heldout_rows).
    """
    input:
        last=lambda wc: realrun_last_round(wc.exp),
    output:
        realrun=report(
            "results/{exp}/diagnosis/realrun.json",
            category="{exp}",
            subcategory="diagnosis",
        ),
        heldout_rows="results/{exp}/diagnosis/realrun_heldout_rows.json",
    log:
        "results/{exp}/logs/diagnosis_realrun.log",
    conda:
        CONDA_ENV
    params:
        heldout=lambda wc: list(heldout_records(wc.exp)),
        check_meshes=lambda wc: diagnosis_cfg(wc.exp)["realrun_selection"][
            "check_meshes"
        ],
    script:
        "../scripts/diagnosis_realrun.py"


# One held-out record's prediction at a fit the selection on real runs reports, on the k-th check mesh of
# the record (the walk's held-out runs' realization k).
rule diagnosis_realrun_heldout_member:
    input:
        batch=lambda wc: batch_file("diagnosis_realrun_heldout_member", wc),
    output:
        curve="results/{exp}/diagnosis/realrun_heldout/{row}/curve.csv",
        run="results/{exp}/diagnosis/realrun_heldout/{row}/run.json",
    wildcard_constraints:
        row="[0-9]+",
    params:
        parameters=lambda wc: {"values": realrun_heldout_row(wc)["simulator"]},
        record_file=lambda wc: design_records(wc.exp)[realrun_heldout_row(wc)["record"]],
        mesh_seed=lambda wc: run_mesh_seed(
            EXPERIMENTS[wc.exp],
            "check",
            0,
            int(realrun_heldout_row(wc)["mesh"]),
            list(design_records(wc.exp)).index(realrun_heldout_row(wc)["record"]),
        ),
        run=lambda wc: {
            "realrun_heldout_row": int(wc.row),
            **{
                k: realrun_heldout_row(wc)[k]
                for k in ("record", "model", "track", "mesh")
            },
        },


rule diagnosis_realrun_heldout:
    """realrun_heldout.json: the held-out records' errors before (the base's fit) and after (the named
    effect's), from fits made on the calibration records alone."""
    input:
        rows="results/{exp}/diagnosis/realrun_heldout_rows.json",
        runs=lambda wc: stage_batch_files(wc.exp, "diagnosis_realrun_heldout_member"),
        obs="results/{exp}/diagnosis/heldout/obs.csv",
        obs_meta="results/{exp}/diagnosis/heldout/obs.json",
    output:
        heldout=report(
            "results/{exp}/diagnosis/realrun_heldout.json",
            category="{exp}",
            subcategory="diagnosis",
        ),
    log:
        "results/{exp}/logs/diagnosis_realrun_heldout.log",
    conda:
        CONDA_ENV
    script:
        "../scripts/diagnosis_realrun_heldout.py"


rule loro:
    """Leave one record out over a series: the folds' held-out errors before and after, per fold and in
    total, the series' page (summary.html) and the figure."""
    input:
        reports=lambda wc: expand(
            "results/{fold}/diagnosis/report.json", fold=loro_fold_names(wc.exp)
        ),
        obs=lambda wc: expand(
            "results/{fold}/diagnosis/heldout/obs.json", fold=loro_fold_names(wc.exp)
        ),
        summaries=lambda wc: expand(
            "results/{fold}/summary.json", fold=loro_fold_names(wc.exp)
        ),
    output:
        summary="results/{exp}/loro/summary.json",
        html=report(
            "results/{exp}/loro/summary.html",
            category="0 Summary",
            caption="../report/series.rst",
            labels={"experiment": "{exp}", "page": "leave one record out"},
        ),
        png=report(
            "results/{exp}/loro/folds.png",
            category="{exp}",
            subcategory="leave one record out",
        ),
    log:
        "results/{exp}/logs/loro.log",
    conda:
        CONDA_ENV
    params:
        folds=lambda wc: loro_fold_names(wc.exp),
    script:
        "../scripts/loro.py"
