# The input functions (and the names they share) of the rules in rules/*.smk, kept apart from the rules
# as Snakemake's linter asks: one section per rule file, in the order the Snakefile includes them.
# Included by rules/common.smk after the names they use.
from snakemake.exceptions import WorkflowError as _SensitivityWorkflowError

from calibration.diagnosis_config import (
    candidate_effects,
    design_mesh_point,
    design_size,
    diagnosis_settings,
)
from calibration.sensitivity import SensitivitySpec
from calibration.workflow_io import record_name


# rules/observations.smk
def approximation_point(exp, run):
    """The run's design point {parameter: value} (a param, so that a new box or seed re-runs the pairs)."""
    names = spec(exp).names
    return dict(
        zip(
            names,
            map(
                float,
                approximation_design(exp, EXPERIMENTS[exp])[approximation_run(run)[1]],
            ),
        )
    )


def approximation_preset(exp, run):
    return (
        approximation_settings(EXPERIMENTS[exp])["preset"]
        if run.startswith("fine")
        else EXPERIMENTS[exp]["preset"]
    )


def observation_inputs(wc):
    e = EXPERIMENTS[wc.exp]
    # the approximation runs (none when observations.model_error.approximation_error is off)
    out = {
        "approximation": stage_batch_files(
            approximation_owner(wc.exp), "approximation_run"
        )
    }
    if e["kind"] == "twin":
        return {**out, "truth": f"results/{wc.exp}/truth/synthetic/curve.csv"}
    return {**out, "records": [stored_record(wc.exp, r) for r in records(wc.exp)]}


def raw_record(exp, record):
    """The raw file (Freiburg record or test sheet) of a calibration or held-out record."""
    held = heldout_records(exp) if diagnosis_cfg(exp) else {}
    return {**records(exp), **held}[record]


def approximation_records(exp):
    """The records the approximation pairs run on, the calibration records then the held-out ones: a
    held-out record's data are corrected by the mesh offset of its own incident wave, as the calibration
    records' are (its input, not its response: docs/closing-the-loop.md). A leave-one-record-out fold
    runs none: its series runs each record's pairs once, and every fold reads them
    (approximation_owner)."""
    if EXPERIMENTS[exp].get("loro_of"):
        return []
    held = heldout_records(exp) if diagnosis_cfg(exp) else {}
    return list({**records(exp), **held})


def approximation_owner(exp):
    """The experiment whose approximation runs `exp` reads: a fold's series (the pairs depend on the box,
    the seed, the presets and each record's incident wave, which the folds share), else `exp`.
    """
    return EXPERIMENTS[exp].get("loro_of") or exp


def approximation_folder(exp):
    return f"results/{approximation_owner(exp)}/approximation"


# rules/simulate.smk
#: The rules that declare one simulation each (no job of their own: rules/simulate.smk); a batch's stage.
SIMULATION_STAGES = (
    "member",
    "replicate",
    "refine_member",
    "forecast",
    "truth",
    "approximation_run",
    "sensitivity_member",
    "diagnosis_member",
    "diagnosis_check_member",
    "diagnosis_refit_member",
    "diagnosis_realrun_member",
    "diagnosis_realrun_heldout_member",
)


def stage_key(stage, wc):
    """The folder of one instance of a stage: the ensemble iteration, or `all`."""
    return (
        f"iter_{wc.it}"
        if stage
        in ("member", "replicate", "diagnosis_refit_member", "diagnosis_realrun_member")
        else "all"
    )


def stage_runs(exp, stage, key):
    """The runs of one stage instance, each as its wildcards without `exp`, run by run (member, design
    point, ...) and record by record within a run: the order the batches cut."""
    recs = list(records(exp))
    if stage in ("member", "replicate"):
        it = key.removeprefix("iter_")
        ids = (
            member_ids(EXPERIMENTS[exp]["ensemble_size"])
            if stage == "member"
            else replicate_ids(exp)
        )
        return [{"it": it, "member": m, "record": r} for m in ids for r in recs]
    if stage == "refine_member":
        ids = member_ids(refine_runs(exp))
        return [{"member": m, "record": r} for m in ids for r in recs]
    if stage in ("forecast", "truth"):
        return [{"record": r} for r in recs]
    if stage == "approximation_run":
        ids = approximation_run_ids(EXPERIMENTS[exp])
        return [
            {"run": a, "record": r} for a in ids for r in approximation_records(exp)
        ]
    if stage == "sensitivity_member":
        s = sensitivity_spec(exp)
        return [{"sample": m, "record": s.record} for m in member_ids(s.n_simulations)]
    if stage == "diagnosis_member":
        ids = member_ids(design_size(EXPERIMENTS[exp]))
        return [{"point": p, "record": r} for p in ids for r in design_records(exp)]
    if stage == "diagnosis_check_member":
        return [{"row": str(i)} for i in range(len(check_rows_of(exp)))]
    if stage == "diagnosis_refit_member":
        it = key.removeprefix("iter_")
        return [{"it": it, "row": str(i)} for i in range(len(refit_rows_of(exp, it)))]
    if stage == "diagnosis_realrun_member":
        it = key.removeprefix("iter_")
        return [{"it": it, "row": str(i)} for i in range(len(realrun_rows_of(exp, it)))]
    if stage == "diagnosis_realrun_heldout_member":
        return [{"row": str(i)} for i in range(len(realrun_heldout_rows_of(exp)))]
    raise ValueError(f"not a simulation stage: {stage!r}")


def stage_batches(exp, stage, key):
    """The runs of a stage instance cut into min(n, 2 ceil(n / 2k)) contiguous batches of nearly equal
    size (at most k each), k the config's `simulations_per_job` for the experiment's preset: an even
    count, so that two cores finish a stage together. The cut depends on the config alone (not on
    --cores), so a re-run with other resources finds the same batches.
    """
    runs = stage_runs(exp, stage, key)
    n = len(runs)
    k = int(config["simulations_per_job"][EXPERIMENTS[exp]["preset"]])
    nb = min(n, 2 * -(-n // (2 * k)))  # none for a stage without runs
    return [runs[b * n // nb : (b + 1) * n // nb] for b in range(nb)]


#: The batch file of rule simulate, spelled out there too (the conventions test reads the rule's text)
BATCH_FILE = "results/{exp}/simulate/{stage}/{key}/batch_{batch}.json"


def batch_file(stage, wc):
    """The batch job's file of the run with wildcards `wc` (rule simulate)."""
    key = stage_key(stage, wc)
    run = {k: v for k, v in wc.items() if k != "exp"}
    for b, runs in enumerate(stage_batches(wc.exp, stage, key)):
        if run in runs:
            return BATCH_FILE.format(exp=wc.exp, stage=stage, key=key, batch=b)
    raise ValueError(f"{stage} {run} of {wc.exp} is in no batch")


def stage_batch_files(exp, stage, key="all"):
    """Every batch file of a stage instance: what a rule collecting the stage's runs takes as input.
    Why not the runs' own files: each would make a job of its stage rule, which runs nothing, at about
    0.07 s a simulation (benchmarks/results/bench_batch.json); the batch file is written after every
    run of the batch (calibration.batch.run_batch), and calibration.heal dates it back when one of its
    runs is altered or missing, so that the batch runs again."""
    n = len(stage_batches(exp, stage, key))
    return [BATCH_FILE.format(exp=exp, stage=stage, key=key, batch=b) for b in range(n)]


#: The file a stage's simulations take their parameters from (batch_inputs; `{key}` the stage's
#: folder); the truth and the approximation runs are given theirs, the check reads its rows.
STAGE_PARAMETERS = {
    "member": "results/{exp}/{key}/params.csv",
    "replicate": "results/{exp}/{key}/params.csv",
    "refine_member": "results/{exp}/refine/params.csv",
    "forecast": "results/{exp}/forecast/params.json",
    "sensitivity_member": "results/{exp}/sensitivity/design.csv",
    "diagnosis_member": "results/{exp}/diagnosis/design/params.csv",
}


def batch_inputs(wc):
    """What the runs of a batch read: the stage's parameter file (the check's rows) and the reduced
    records (the truth: the raw records its twin is driven by)."""
    exp = wc.exp
    if wc.stage == "truth":
        return {"record": [p for p in records(exp).values() if p]}
    runs = stage_batches(exp, wc.stage, wc.key)[int(wc.batch)]
    if wc.stage == "diagnosis_check_member":
        rows = check_rows_of(exp)
        names = {rows[int(r["row"])]["record"] for r in runs}
        files = {"rows": f"results/{exp}/diagnosis/check_runs.json"}
    elif wc.stage == "diagnosis_refit_member":
        it = wc.key.removeprefix("iter_")
        rows = refit_rows_of(exp, it)
        names = {rows[int(r["row"])]["record"] for r in runs}
        files = {"rows": refit_round_file(exp, it)}
    elif wc.stage == "diagnosis_realrun_member":
        it = wc.key.removeprefix("iter_")
        rows = realrun_rows_of(exp, it)
        names = {rows[int(r["row"])]["record"] for r in runs}
        files = {"rows": realrun_round_file(exp, it)}
    elif wc.stage == "diagnosis_realrun_heldout_member":
        rows = realrun_heldout_rows_of(exp)
        names = {rows[int(r["row"])]["record"] for r in runs}
        files = {"rows": f"results/{exp}/diagnosis/realrun_heldout_rows.json"}
    else:
        names = {r["record"] for r in runs}
        pattern = STAGE_PARAMETERS.get(wc.stage)
        files = {"params": pattern.format(exp=exp, key=wc.key)} if pattern else {}
    return {**files, "record": [p for r in sorted(names) for p in record_input(exp, r)]}


def stage_run_wildcards(exp, run):
    from snakemake.iocontainers import Wildcards

    return Wildcards(fromdict={"exp": exp, **run})


def batch_runtime_min(wc):
    """Scheduler wall time [min] of a batch job: its runs' time limits in series (runtime_min)."""
    runs = stage_batches(wc.exp, wc.stage, wc.key)[int(wc.batch)]
    return runtime_min(
        sum(
            time_limit_s(
                wc.exp, simulation_preset(wc.stage, stage_run_wildcards(wc.exp, r))
            )
            for r in runs
        )
    )


def batch_runs(wc):
    """Every run of a batch as scripts/simulate.py takes it: its outputs, its stage rule's params
    evaluated for its wildcards over the defaults below (rules/simulate.smk says what each means), its
    time limit."""
    from snakemake.io import apply_wildcards

    declared = getattr(rules, wc.stage)
    out = []
    for run in stage_batches(wc.exp, wc.stage, wc.key)[int(wc.batch)]:
        values = {"exp": wc.exp, **run}
        w = stage_run_wildcards(wc.exp, run)
        params = {
            "sim": sim_settings(wc.exp),
            "parameters": {"values": {}},
            "record_file": (
                stored_record(wc.exp, run["record"]) if "record" in run else None
            ),
            "mesh_seed": None,
            "snapshots": None,
            "run": {},
            "must_succeed": False,
        }
        params.update(
            {k: (v(w) if callable(v) else v) for k, v in declared.params.items()}
        )
        files = {k: apply_wildcards(str(p), values) for k, p in declared.output.items()}
        out.append(
            {
                **params,
                "outputs": files,
                "log": os.path.join(os.path.dirname(files["curve"]), "simulate.log"),
                "time_limit_s": time_limit_s(wc.exp, simulation_preset(wc.stage, w)),
            }
        )
    return out


def batch_group(wc):
    """Group id of one batch job (docs/cluster.md): the n runs of one stage instance, numbered in
    stage_runs' order, cut into max(1, n // k) contiguous groups, k the config's
    `simulations_per_cluster_job` for the experiment's preset; a batch goes with its first run, so a
    group holds whole batches, never mixing stages, iterations or experiments. A cluster run with
    `--group-components simulations=1000` (profiles/slurm) submits each group as one job; local runs
    ignore groups."""
    batches = stage_batches(wc.exp, wc.stage, wc.key)
    n = sum(len(b) for b in batches)
    i = sum(len(b) for b in batches[: int(wc.batch)])
    k = int(config["simulations_per_cluster_job"][EXPERIMENTS[wc.exp]["preset"]])
    gid = f"sim-{wc.exp}-{wc.stage}-{wc.key}-{i * max(1, n // k) // n}"
    workflow.parent_groupids[gid] = SIMULATION_GROUPS
    return gid


# rules/ensemble.smk
# rules/assimilate.smk
def iteration_batch_files(exp, it):
    """The batch files of an iteration's members and replicates (scripts/aggregate.py reads their runs)."""
    key = f"iter_{it}"
    return stage_batch_files(exp, "member", key) + stage_batch_files(
        exp, "replicate", key
    )


def earlier_iterations(wc, name):
    """`name` of iterations 0..it-1: the runs an emulated_esmda analysis builds its emulator on."""
    if EXPERIMENTS[wc.exp]["method"] != "emulated_esmda":
        return []
    return [f"results/{wc.exp}/iter_{k}/{name}" for k in range(int(wc.it))]


# rules/forecast.smk
def posterior_sample_files(exp):
    """The emulator MCMC posterior's files, for `posterior: emulator_mcmc` (calibration.posterior)."""
    if EXPERIMENTS[exp].get("posterior", "ensemble") != "emulator_mcmc":
        return {}
    return {
        "samples": f"results/{exp}/posterior/samples.csv",
        "sampler": f"results/{exp}/posterior/sampler.json",
    }


def refine_runs(exp):
    """How many refinement runs the reported emulator posterior is measured at (emulated.refine_runs)."""
    return int((EXPERIMENTS[exp].get("emulated") or {}).get("refine_runs", 0))


def refine_files(exp):
    """The refinement batch's design and curves (calibration.posterior.refine_design), where it has one."""
    if not posterior_sample_files(exp) or refine_runs(exp) < 1:
        return {}
    return {
        "refine_params": f"results/{exp}/refine/params.csv",
        "refine_responses": f"results/{exp}/refine/responses.csv",
    }


# rules/report.smk
def final_inputs(wc):
    exp = wc.exp
    recs = list(records(exp))
    files = {
        "params": iteration_files(exp, "params.csv"),
        "responses": iteration_files(exp, "responses.csv"),
        "analyses": iteration_files(exp, "analysis.json"),
        "obs": f"results/{exp}/observations/obs.csv",
        "obs_meta": f"results/{exp}/observations/obs.json",
        "forecast_curves": expand(
            "results/{exp}/forecast/{record}/curve.csv", exp=exp, record=recs
        ),
        "forecast_runs": expand(
            "results/{exp}/forecast/{record}/run.json", exp=exp, record=recs
        ),
        "forecast_params": f"results/{exp}/forecast/params.json",
    }
    files.update(posterior_sample_files(exp))
    if EXPERIMENTS[exp]["kind"] == "twin":
        files["truth_run"] = f"results/{exp}/truth/synthetic/run.json"
    return files


def report_summary_inputs(wc):
    files = {"summary": f"results/{wc.exp}/summary.json"}
    if diagnosis_cfg(
        wc.exp
    ):  # the diagnosis's FDEM check: errors before and after, held-out records too
        files["check"] = f"results/{wc.exp}/diagnosis/check.json"
    if refit_on(wc.exp):  # the shipped model's parameters on real runs
        files["refit"] = f"results/{wc.exp}/diagnosis/refit.json"
    if realrun_on(wc.exp):  # the selection on real runs, beside the walk
        files["realrun"] = f"results/{wc.exp}/diagnosis/realrun.json"
        if heldout_records(wc.exp):  # its fits' held-out errors
            files["realrun_heldout"] = (
                f"results/{wc.exp}/diagnosis/realrun_heldout.json"
            )
    return files


# rules/diagnosis.smk
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
    return [e for e in RUN if not is_loro(e)] + [
        f for e in loro_experiments() for f in loro_fold_names(e)
    ]


def diagnosed_experiments():
    return [e for e in calibrated_experiments() if diagnosis_cfg(e)]


def heldout_records(exp):
    return {record_name(p): str(p) for p in diagnosis_cfg(exp)["heldout_records"]}


def heldout_observation_inputs(wc):
    """The held-out records' reduced files and the approximation pairs (none without the term)."""
    return {
        "records": [stored_record(wc.exp, r) for r in heldout_records(wc.exp)],
        "approximation": stage_batch_files(
            approximation_owner(wc.exp), "approximation_run"
        ),
    }


def design_records(exp):
    """Every record a design point is simulated for, the calibration records then the held-out ones:
    {name: its reduced record's record.json} (rule reduced_record)."""
    return {r: stored_record(exp, r) for r in {**records(exp), **heldout_records(exp)}}


def reported_analysis(exp):
    """The analysis.json of the calibration's reported ensemble (its error terms: noise, S, D)."""
    return iteration_files(exp, "analysis.json")


def diagnosis_inputs(wc):
    files = {
        "design": f"results/{wc.exp}/diagnosis/design/params.csv",
        "design_meta": f"results/{wc.exp}/diagnosis/design/design.json",
        # the design's runs (scripts/diagnosis.py reads them from the design's folder)
        "design_runs": stage_batch_files(wc.exp, "diagnosis_member"),
        "obs": f"results/{wc.exp}/observations/obs.csv",
        "obs_meta": f"results/{wc.exp}/observations/obs.json",
        "analyses": reported_analysis(wc.exp),
        "summary": f"results/{wc.exp}/summary.json",
    }
    if heldout_records(wc.exp):
        files["heldout"] = f"results/{wc.exp}/diagnosis/heldout/obs.csv"
        files["heldout_meta"] = f"results/{wc.exp}/diagnosis/heldout/obs.json"
    return files


def check_rows_of(exp):
    return read_json(checkpoints.diagnosis_select.get(exp=exp).output.rows)["rows"]


def diagnosis_check_inputs(wc):
    files = {k: v for k, v in diagnosis_inputs(wc).items() if k not in ("summary",)}
    files["selection"] = f"results/{wc.exp}/diagnosis/selection.pkl"
    files["rows"] = f"results/{wc.exp}/diagnosis/check_runs.json"
    files["check_runs"] = stage_batch_files(wc.exp, "diagnosis_check_member")
    if refit_on(wc.exp):
        # the refit's identification gate decides the shipped step (calibration.walk.gated)
        files["refit"] = f"results/{wc.exp}/diagnosis/refit.json"
    return files


def refit_on(exp):
    """Whether the experiment re-fits its shipped model on real runs (diagnosis.refit_rounds > 0). A
    leave-one-record-out fold does too, on its own calibration records: its refit's identification gate
    decides what the fold ships, as it does for a held-out experiment, so the series' table scores that.
    """
    d = diagnosis_cfg(exp)
    return bool(d) and int(d["refit_rounds"]) > 0


def refitted_experiments():
    return [e for e in diagnosed_experiments() if refit_on(e)]


def refit_round_file(exp, r):
    return f"results/{exp}/diagnosis/refit/round_{r}.json"


#: Round states already read, by (path, mtime, size): a stage's every run asks for its round's rows several
#: times while the DAG is built (each param of its declaring rule, its batch), and a round of the selection on
#: real runs carries its check curves (hundreds of kB)
_ROUND_STATES = {}


def round_state(path):
    """A checkpoint round's state (the refit's, the selection on real runs'), parsed once per file version."""
    st = os.stat(path)
    key = (str(path), st.st_mtime_ns, st.st_size)
    if key not in _ROUND_STATES:
        _ROUND_STATES[key] = read_json(path)
    return _ROUND_STATES[key]


def refit_state(exp, r):
    """Refit round `r`'s state: its checkpoint's file."""
    return round_state(checkpoints.diagnosis_refit_round.get(exp=exp, r=r).output.state)


def refit_rows_of(exp, r):
    """The runs of refit round `r`."""
    return refit_state(exp, r)["rows"]


def refit_row(wc):
    return refit_rows_of(wc.exp, wc.it)[int(wc.row)]


def refit_round_inputs(wc):
    """Round r reads the check's runs, on which it walks (round 0), or every earlier round's file and runs."""
    r = int(wc.r)
    files = {
        "selection": f"results/{wc.exp}/diagnosis/selection.pkl",
        "obs": f"results/{wc.exp}/observations/obs.csv",
        "obs_meta": f"results/{wc.exp}/observations/obs.json",
    }
    if r == 0:
        files["rows"] = f"results/{wc.exp}/diagnosis/check_runs.json"
        files["check_runs"] = stage_batch_files(wc.exp, "diagnosis_check_member")
    else:
        files["rounds"] = [refit_round_file(wc.exp, k) for k in range(r)]
        files["runs"] = [
            b
            for k in range(r)
            for b in stage_batch_files(wc.exp, "diagnosis_refit_member", f"iter_{k}")
        ]
    return files


def refit_last_round(exp):
    """Walk the refit's checkpoints until a round says it is done; that round's file."""
    r = 0
    while refit_state(exp, r)["phase"] != "done":
        r += 1
    return refit_round_file(exp, r)


def realrun_on(exp):
    """Whether the experiment runs the selection on real runs (diagnosis.realrun_selection, calibration.realrun)."""
    d = diagnosis_cfg(exp)
    return bool(d) and d.get("realrun_selection") is not None


def realrun_experiments():
    return [e for e in diagnosed_experiments() if realrun_on(e)]


def realrun_round_file(exp, r):
    return f"results/{exp}/diagnosis/realrun/round_{r}.json"


def realrun_state(exp, r):
    """Round `r` of the selection on real runs: its checkpoint's file."""
    return round_state(
        checkpoints.diagnosis_realrun_round.get(exp=exp, r=r).output.state
    )


def realrun_rows_of(exp, r):
    return realrun_state(exp, r)["rows"]


def realrun_row(wc):
    return realrun_rows_of(wc.exp, wc.it)[int(wc.row)]


def realrun_mesh_seed(wc):
    """A fit run on the selection's own realizations; a check run on the check's (its k-th mesh of the
    record), so that the check meshes are the confirmation walk's where they overlap; the resolution
    round's runs at each preset on realizations of their own."""
    row = realrun_row(wc)
    stage = {"check": "check", "fit": "realrun"}.get(
        row["kind"], f"realrun_{row['kind']}"
    )
    index = list(design_records(wc.exp)).index(row["record"])
    return run_mesh_seed(EXPERIMENTS[wc.exp], stage, 0, int(row["mesh"]), index)


def realrun_round_inputs(wc):
    """Round 0 reads the calibration's observations and posterior; round r also every earlier round's file
    and runs."""
    r = int(wc.r)
    files = {
        "obs": f"results/{wc.exp}/observations/obs.csv",
        "obs_meta": f"results/{wc.exp}/observations/obs.json",
        "summary": f"results/{wc.exp}/summary.json",
    }
    if r > 0:
        files["rounds"] = [realrun_round_file(wc.exp, k) for k in range(r)]
        files["runs"] = [
            b
            for k in range(r)
            for b in stage_batch_files(wc.exp, "diagnosis_realrun_member", f"iter_{k}")
        ]
    return files


def realrun_heldout_rows_of(exp):
    """The held-out prediction runs of the selection on real runs (its checkpoint's rows file)."""
    return round_state(checkpoints.diagnosis_realrun.get(exp=exp).output.heldout_rows)[
        "rows"
    ]


def realrun_heldout_row(wc):
    return realrun_heldout_rows_of(wc.exp)[int(wc.row)]


def realrun_last_round(exp):
    """Walk the selection's checkpoints until a round says it is done; that round's file."""
    r = 0
    while realrun_state(exp, r)["phase"] != "done":
        r += 1
    return realrun_round_file(exp, r)


# rules/sensitivity.smk
def sensitivity_spec(exp):
    if EXPERIMENTS[exp].get("sensitivity") is None:
        raise _SensitivityWorkflowError(
            f"experiment {exp!r} has no sensitivity block in the config "
            f"(experiments.{exp}.sensitivity; see config/schema.yaml)"
        )
    return SensitivitySpec.from_config(exp, EXPERIMENTS[exp])


def sensitivity_files(exp, name):
    s = sensitivity_spec(exp)
    return expand(
        "results/{exp}/sensitivity/members/{sample}/{record}/{name}",
        exp=exp,
        sample=member_ids(s.n_simulations),
        record=s.record,
        name=name,
    )
