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


rule sensitivity_member:
    """One FDEM simulation of a design row; the failure policy of `rule member` (exit 3 or the time limit:
    failed run.json and empty curve; exit 2: the job fails with the simulator's message; a crash is
    retried, then recorded as failed)."""
    input:
        unpack(
            lambda wc: {
                "params": f"results/{wc.exp}/sensitivity/design.csv",
                "record": [p for p in [records(wc.exp)[wc.record]] if p],
            }
        ),
    output:
        curve="results/{exp}/sensitivity/members/{sample}/{record}/curve.csv",
        run="results/{exp}/sensitivity/members/{sample}/{record}/run.json",
    log:
        "results/{exp}/sensitivity/members/{sample}/{record}/simulate.log",
    wildcard_constraints:
        sample="[0-9]+",
    retries: config["member_retries"]
    group:
        lambda wc: simulation_group(
            wc.exp,
            "sensitivity",
            wc.sample,
            sensitivity_spec(wc.exp).n_simulations,
            wc.record,
            [wc.record],
        )
    conda:
        CONDA_ENV
    threads: 1
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp),
        runtime=lambda wc: runtime_min(wc.exp),
    params:
        sim=lambda wc: sim_settings(wc.exp),
        held=lambda wc: dict(sensitivity_spec(wc.exp).held),
        record_file=lambda wc: records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    script:
        "../scripts/sensitivity_member.py"


rule sensitivity_analysis:
    input:
        unpack(
            lambda wc: {
                "design": f"results/{wc.exp}/sensitivity/design.csv",
                "curves": sensitivity_files(wc.exp, "curve.csv"),
                "runs": sensitivity_files(wc.exp, "run.json"),
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
    script:
        "../scripts/sensitivity_analysis.py"
