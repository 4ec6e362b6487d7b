# Global sensitivity analysis (issue 19, calibration.sensitivity): SALib's design over an experiment's
# `sensitivity.parameters` boxes -> one FDEM simulation per design row, an ordinary job exactly like
# `rule member` -> indices per time point and per curve feature, and the parameters worth calibrating.
# Target: results/<experiment>/sensitivity/report.json (in the default target with sensitivity.run).
#
# No checkpoint: the number of design rows follows from the method, N and the parameter count alone
# (SensitivitySpec.n_simulations; the design script checks SALib agrees), so the per-sample jobs are
# known when the DAG is built and a dry run lists them all. The values themselves are drawn once, by
# `sensitivity_design`, and each job reads its row from design.csv, so SALib runs in one place only.


# The sensitivity blocks are validated with the rest of the config (calibration.workflow_io.validate_config).
SENSITIVITY_RUN = [
    e for e in RUN if (EXPERIMENTS[e].get("sensitivity") or {}).get("run")
]


localrules:
    sensitivity_design,
    sensitivity_analysis,


rule sensitivity_design:
    output:
        design="results/{exp}/sensitivity/design.csv",
    log:
        "results/{exp}/logs/sensitivity_design.log",
    conda:
        CONDA_ENV
    params:
        settings=lambda wc: sensitivity_spec(wc.exp).settings(),
        exp=lambda wc: EXPERIMENTS[wc.exp],
    script:
        "../scripts/sensitivity_design.py"


# One FDEM simulation of a design row, the experiment's other estimated parameters held at their
# prior-box centres; the failure policy of `rule member`.
rule sensitivity_member:
    input:
        batch=lambda wc: batch_file("sensitivity_member", wc),
    output:
        curve="results/{exp}/sensitivity/members/{sample}/{record}/curve.csv",
        run="results/{exp}/sensitivity/members/{sample}/{record}/run.json",
    wildcard_constraints:
        sample="[0-9]+",
    params:
        parameters=lambda wc: {
            "row": wc.sample,
            "held": dict(sensitivity_spec(wc.exp).held),
        },
        run=lambda wc: {"sensitivity_sample": int(wc.sample), "record": wc.record},


rule sensitivity_analysis:
    input:
        unpack(
            lambda wc: {
                "design": f"results/{wc.exp}/sensitivity/design.csv",
                "runs": stage_batch_files(wc.exp, "sensitivity_member"),
                "record": [
                    p for p in [records(wc.exp)[sensitivity_spec(wc.exp).record]] if p
                ],
            }
        ),
    output:
        report=report(
            "results/{exp}/sensitivity/report.json",
            category="{exp}",
            subcategory="sensitivity",
        ),
        time="results/{exp}/sensitivity/indices_time.csv",
        features="results/{exp}/sensitivity/indices_features.csv",
        png=report(
            "results/{exp}/sensitivity/plots/sensitivity_indices.png",
            category="{exp}",
            subcategory="sensitivity",
            caption="../report/sensitivity_indices.rst",
        ),
    log:
        "results/{exp}/logs/sensitivity_analysis.log",
    conda:
        CONDA_ENV
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        settings=lambda wc: {
            **sensitivity_spec(wc.exp).settings(),
            "threshold": sensitivity_spec(wc.exp).threshold,
            "bootstrap": sensitivity_spec(wc.exp).bootstrap,
            "record": sensitivity_spec(wc.exp).record,
        },
        curves=lambda wc: sensitivity_files(wc.exp, "curve.csv"),
        runs=lambda wc: sensitivity_files(wc.exp, "run.json"),
    script:
        "../scripts/sensitivity_analysis.py"
