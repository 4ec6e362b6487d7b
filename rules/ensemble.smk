# The ensemble: the LHS prior (iteration 0), the analysis ensemble of the previous iteration
# (iterations >= 1), and one simulation job per member and record.


rule lhs:
    """`parameters: auto`: the sensitivity report decides which parameters the prior spans."""
    input:
        unpack(
            lambda wc: (
                {"sensitivity": f"results/{wc.exp}/sensitivity/report.json"}
                if EXPERIMENTS[wc.exp]["parameters"] == "auto"
                else {}
            )
        ),
    output:
        params="results/{exp}/iter_0/params.csv",
    log:
        "results/{exp}/logs/lhs.log",
    conda:
        CONDA_ENV
    params:
        prior=lambda wc: {
            k: EXPERIMENTS[wc.exp][k] for k in ("parameters", "ensemble_size", "seed")
        },
    script:
        "../scripts/lhs.py"


rule propose:
    input:
        analysis=lambda wc: f"results/{wc.exp}/iter_{int(wc.it) - 1}/analysis.json",
    output:
        params="results/{exp}/iter_{it}/params.csv",
    log:
        "results/{exp}/logs/iter_{it}/propose.log",
    wildcard_constraints:
        it="[1-9][0-9]*",
    conda:
        CONDA_ENV
    script:
        "../scripts/propose.py"


# One ensemble member: its row of the iteration's params.csv.
rule member:
    input:
        batch=lambda wc: batch_file("member", wc),
    output:
        curve="results/{exp}/iter_{it}/members/{member}/{record}/curve.csv",
        run="results/{exp}/iter_{it}/members/{member}/{record}/run.json",
    params:
        parameters=lambda wc: {"row": wc.member},
        mesh_seed=lambda wc: mesh_seed_of(wc.exp, "member", wc.it, wc.member, wc.record),
        run=lambda wc: {
            "member": int(wc.member),
            "iteration": int(wc.it),
            "record": wc.record,
        },


# One replicate run at the iteration's ensemble mean on its own mesh realization: the replicates of an
# iteration differ only in the mesh and measure the simulator's own variability S
# (calibration.model_error; observations.model_error.simulator_replicates).
rule replicate:
    input:
        batch=lambda wc: batch_file("replicate", wc),
    output:
        curve="results/{exp}/iter_{it}/replicates/{member}/{record}/curve.csv",
        run="results/{exp}/iter_{it}/replicates/{member}/{record}/run.json",
    params:
        parameters=lambda wc: {"ensemble_mean": wc.exp},
        mesh_seed=lambda wc: mesh_seed_of(
            wc.exp, "replicate", wc.it, wc.member, wc.record
        ),
        run=lambda wc: {
            "replicate": int(wc.member),
            "iteration": int(wc.it),
            "record": wc.record,
        },
