# Global sensitivity analysis (issue 19, calibration.sensitivity): SALib's design over an experiment's
# `sensitivity.parameters` boxes -> one FDEM simulation per design row, an ordinary job exactly like
# `rule member` -> indices per time point and per curve feature, and the parameters worth calibrating.
# Target: results/<experiment>/sensitivity/report.json (in the default target with sensitivity.run).
#
# No checkpoint: the number of design rows follows from the method, N and the parameter count alone
# (SensitivitySpec.n_simulations; the design script checks SALib agrees), so the per-sample jobs are
# known when the DAG is built and a dry run lists them all. The values themselves are drawn once, by
# `sensitivity_design`, and each job reads its row from design.csv, so SALib runs in one place only.
from snakemake.exceptions import WorkflowError as _SensitivityWorkflowError

from calibration.sensitivity import SensitivitySpec

# The sensitivity blocks are validated with the rest of the config (calibration.workflow_io.validate_config).
SENSITIVITY_RUN = [e for e in RUN if (EXPERIMENTS[e].get("sensitivity") or {}).get("run")]

localrules: sensitivity_design, sensitivity_analysis


def sensitivity_spec(exp):
    if EXPERIMENTS[exp].get("sensitivity") is None:
        raise _SensitivityWorkflowError(f"experiment {exp!r} has no sensitivity block in the config "
                                        f"(experiments.{exp}.sensitivity; see config/schema.yaml)")
    return SensitivitySpec.from_config(exp, EXPERIMENTS[exp])


def sensitivity_files(exp, name):
    s = sensitivity_spec(exp)
    return expand("results/{exp}/sensitivity/members/{sample}/{record}/{name}", exp=exp,
                  sample=member_ids(s.n_simulations), record=s.record, name=name)


rule sensitivity_design:
    output:
        design="results/{exp}/sensitivity/design.csv",
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
        unpack(lambda wc: {"params": f"results/{wc.exp}/sensitivity/design.csv",
                           "record": [p for p in [records(wc.exp)[wc.record]] if p]}),
    output:
        curve="results/{exp}/sensitivity/members/{sample}/{record}/curve.csv",
        run="results/{exp}/sensitivity/members/{sample}/{record}/run.json",
    log:
        "results/{exp}/sensitivity/members/{sample}/{record}/simulate.log",
    wildcard_constraints:
        sample="[0-9]+",
    params:
        sim=lambda wc: sim_settings(wc.exp),
        held=lambda wc: dict(sensitivity_spec(wc.exp).held),
        record_file=lambda wc: records(wc.exp)[wc.record],
        max_attempts=config["member_retries"] + 1,
    threads: 1
    retries: config["member_retries"]
    group: lambda wc: simulation_group(wc.exp, "sensitivity", wc.sample, sensitivity_spec(wc.exp).n_simulations, wc.record, [wc.record])
    resources:
        attempt=lambda wc, attempt: attempt,
        time_limit_s=lambda wc: time_limit_s(wc.exp),
        runtime=lambda wc: runtime_min(wc.exp),
    script:
        "../scripts/sensitivity_member.py"


rule sensitivity_analysis:
    input:
        unpack(lambda wc: {"design": f"results/{wc.exp}/sensitivity/design.csv",
                           "curves": sensitivity_files(wc.exp, "curve.csv"),
                           "runs": sensitivity_files(wc.exp, "run.json"),
                           "record": [p for p in [records(wc.exp)[sensitivity_spec(wc.exp).record]] if p]}),
    output:
        report=report("results/{exp}/sensitivity/report.json", category="{exp}", subcategory="sensitivity"),
        time="results/{exp}/sensitivity/indices_time.csv",
        features="results/{exp}/sensitivity/indices_features.csv",
        png=report("results/{exp}/sensitivity/plots/sensitivity_indices.png", category="{exp}",
                   subcategory="sensitivity", caption="../report/sensitivity_indices.rst"),
    params:
        exp=lambda wc: EXPERIMENTS[wc.exp],
        settings=lambda wc: {**sensitivity_spec(wc.exp).settings(), "threshold": sensitivity_spec(wc.exp).threshold,
                             "bootstrap": sensitivity_spec(wc.exp).bootstrap, "record": sensitivity_spec(wc.exp).record},
    script:
        "../scripts/sensitivity_analysis.py"
