"""calibration.realrun, the selection on real runs in rounds, on a stand-in simulator whose truth is known.

The stand-in: three records at different "rates" c_r; a pulse whose amplitude is sigma_t (1 + mu c_r) with
the end friction mu, a post-peak decay set by E_t, a face gap that delays the onset of one record. A
friction the base model cannot absorb into sigma_t (its effect differs from record to record by c_r) must
be named and fitted near its truth; with none planted, nothing may be named.
"""
import json
import sys

import numpy as np
import pytest

from calibration import realrun as rr

T = np.linspace(0.0, 1.0, 60)
RECORDS = ["R1", "R2", "R3"]
RATE = {"R1": 0.5, "R2": 1.0, "R3": 1.6}
BOX = {"sigma_t": (4e6, 6e7), "E_t": (100.0, 5000.0), "interface_friction.mu": (0.0, 0.6),
       "face_gap.gap_m": (0.0, 4e-4), "rate_strength.k": (0.0, 0.6)}
NOISE_SD = 0.15     # MPa-scale units of the stand-in (0.5 % of a 30-unit peak)


def curve(p, record, seed):
    """The stand-in's response in MPa-like units; ``seed`` >= 0 adds a mesh realization's small scatter."""
    shift = p.get("face_gap.gap_m", 0.0) / 4e-4 * 0.1
    t = np.clip(T - shift, 0.0, None)
    # the stand-in's rate law acts exactly as its friction does: a sibling the data cannot tell apart
    amp = p["sigma_t"] / 1e6 * (1.0 + (p.get("interface_friction.mu", 0.0) + p.get("rate_strength.k", 0.0))
                                * RATE[record])
    pulse = np.sin(np.pi * np.clip(t / 0.6, 0.0, 1.0) / 2.0) ** 2
    decay = np.exp(-np.clip(t - 0.6, 0.0, None) * 400.0 / p["E_t"] * 10.0)
    out = amp * pulse * decay
    if seed >= 0:
        out = out * (1.0 + MESH_SD * np.random.default_rng(seed).standard_normal())
    return out


MESH_SD = 0.002     # a mesh realization's scatter of the whole curve (its strength), relative


def fine_curve(p, record, seed):
    """The stand-in at a finer preset: 4 % stronger in every record, the strength a coarse fit takes up
    (a resolution error the base parameters can absorb, as the `fast` mesh's is on FDEM)."""
    return 1.04 * curve(p, record, seed)


def simulate(rows, series=0):
    """The rows' runs; ``series`` offsets every mesh realization (a series of its own, as a workflow run's
    seed gives it)."""
    seeds = {"fit": 3100, "check": 3200, "coarse": 3300, "fine": 3400}
    return [(fine_curve if r.get("preset") else curve)(
        r["simulator"], r["record"], 10000 * series + seeds[r["kind"]] + 10 * r["mesh"] + RECORDS.index(r["record"]))
        for r in rows]


def data(truth, seed=7, model=curve, own_mesh=False):
    """The records: ``model`` at ``truth`` plus AR(1) noise; ``own_mesh``: each on a mesh realization of its
    own, as FDEM data made at a finer mesh are."""
    rng = np.random.default_rng(seed)
    y = {}
    for i, r in enumerate(RECORDS):
        e = np.zeros(T.size)
        for k in range(1, T.size):      # AR(1) noise, lag-1 correlation 0.6
            e[k] = 0.6 * e[k - 1] + np.sqrt(1 - 0.36) * rng.standard_normal()
        y[r] = model(truth, r, 10000 * seed + 9000 + i if own_mesh else -1) + NOISE_SD * e
    return y


NOISE = {r: (NOISE_SD, 0.02) for r in RECORDS}
TIMES = {r: T for r in RECORDS}
START = {"sigma_t": 3.5e7, "E_t": 2000.0}


def select(truth, candidates=("interface_friction", "face_gap")):
    state = rr.first_round(START, list(candidates), RECORDS, BOX, profile=3, check_meshes=8)
    states = [state]
    while state["phase"] != "done":
        state = rr.next_round(state, simulate(state["rows"]), data(truth), NOISE, TIMES)
        json.dumps(state)       # every state is JSON: the workflow keeps one file per round
        states.append(state)
    return state, states


def test_a_planted_friction_is_named_and_fitted_near_its_truth():
    state, states = select({"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3})
    res = state["result"]
    assert res["named"] == "interface_friction"
    assert res["group"] == ["interface_friction"]
    fit = res["candidates"]["interface_friction"]["fit"]
    # the noise is 0.5 % of the peak over 60 correlated samples per record: mu to within 0.03, sigma_t 3 %
    assert fit["interface_friction.mu"] == pytest.approx(0.3, abs=0.03)
    assert fit["sigma_t"] == pytest.approx(2.5e7, rel=0.03)
    # the base model absorbs the friction into a higher strength, and loses on every record
    assert res["base"]["fit"]["sigma_t"] > 2.9e7
    assert all(z > 0 for z in res["candidates"]["interface_friction"]["per_record_z"].values())
    # base: 3 linearisations + check; friction: 4 profile steps, the profile's real runs, 3 steps, check
    assert len(states) - 1 == 4 + 1 + 3 + 1


def test_a_sibling_the_data_cannot_tell_apart_shares_the_group():
    state, _ = select({"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3},
                      candidates=("interface_friction", "rate_strength"))
    res = state["result"]
    assert res["candidates"]["rate_strength"]["p"] < rr.LEVEL
    assert res["versus"][next(e for e in res["versus"])]["z"] == pytest.approx(0.0, abs=1e-6)
    assert sorted(res["group"]) == ["interface_friction", "rate_strength"]


def test_nothing_is_named_on_a_null():
    state, _ = select({"sigma_t": 2.5e7, "E_t": 1200.0})
    assert state["result"]["named"] == "base_kept"
    assert state["result"]["group"] == []


def test_a_failed_run_is_left_out_of_its_mean():
    state = rr.first_round(START, ["face_gap"], RECORDS, BOX, profile=0, check_meshes=4)
    y = data({"sigma_t": 2.5e7, "E_t": 1200.0})
    curves = simulate(state["rows"])
    k = next(i for i, row in enumerate(state["rows"]) if row["kind"] == "fit" and row["name"] is None)
    curves[k] = None
    nxt = rr.next_round(state, curves, y, NOISE, TIMES)
    assert nxt["tracks"]["base"]["step"] == 1 and np.isfinite(nxt["tracks"]["base"]["theta"]["sigma_t"])
    with pytest.raises(ValueError, match="runs asked for"):
        rr.next_round(state, curves[:-1], y, NOISE, TIMES)


def test_the_rounds_are_reproducible():
    a, _ = select({"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3})
    b, _ = select({"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3})
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_naming_and_grouping_rules():
    assert rr.named({"a": (3.0, 0.01), "b": (5.0, 0.001), "c": (9.0, 0.004)}) == "c"
    assert rr.named({"a": (3.0, 0.01)}) == "base_kept"
    # the named effect beats b at the level but not d: d shares its group
    assert rr.grouped("c", {"b": (4.0, 1e-4), "d": (1.0, 0.2)}) == ["c", "d"]
    with pytest.raises(ValueError, match="at least 3"):
        rr.first_round(START, [], RECORDS, BOX, check_meshes=2)


def test_the_config_block_gets_its_defaults_and_a_wrong_candidate_is_named():
    import copy
    from pathlib import Path

    from calibration.workflow_io import ConfigError, load_yaml, validate_config

    repo = Path(__file__).resolve().parents[1]
    base = load_yaml(repo / "config" / "config.yaml")
    cfg = copy.deepcopy(base)
    cfg["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] = {}
    out = validate_config(cfg, repo / "config" / "schema.yaml", base_dir=repo)
    assert out["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] == {
        "candidates": ["rate_strength", "interface_friction", "seating", "face_gap"], "profile": 5, "check_meshes": 8,
        "resolution": None}
    # off unless asked for
    plain = validate_config(copy.deepcopy(base), repo / "config" / "schema.yaml", base_dir=repo)
    assert plain["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] is None
    cfg["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] = {"candidates": ["gauge_gain"]}
    with pytest.raises(ConfigError, match="realrun_selection.candidates.0: 'gauge_gain'"):
        validate_config(cfg, repo / "config" / "schema.yaml", base_dir=repo)
    cfg["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] = {}
    cfg["experiments"]["marble_loop"]["simulation"]["mesh_realizations"] = "shared"
    cfg["experiments"]["marble_loop"]["observations"]["records"] = cfg["experiments"]["marble_loop"]["observations"][
        "records"][:1]
    with pytest.raises(ConfigError) as err:
        validate_config(cfg, repo / "config" / "schema.yaml", base_dir=repo)
    assert "realrun_selection: needs at least 2 calibration records" in str(err.value)
    assert "mesh_realizations is 'shared'" in str(err.value)
    # a resolution preset no finer than the experiment's own
    cfg = copy.deepcopy(base)
    cfg["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] = {"resolution": {"preset": "standard"}}
    cfg["experiments"]["marble_loop"]["preset"] = "standard"
    with pytest.raises(ConfigError, match="resolution.preset: 'standard' is not finer than the experiment's preset"):
        validate_config(cfg, repo / "config" / "schema.yaml", base_dir=repo)
    cfg["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"] = {"resolution": {"preset": "paper"}}
    out = validate_config(cfg, repo / "config" / "schema.yaml", base_dir=repo)
    assert out["experiments"]["marble_loop"]["diagnosis"]["realrun_selection"]["resolution"] == {"preset": "paper",
                                                                                               "meshes": 4}


def _interval_scores(white: bool = False, seeds=range(100, 140), resolution=None, per_time=False,
                     own_mesh=True):
    """Per data realization of a planted friction: whether each parameter's 90 % interval holds its truth, and
    its interval score (width plus 20 x the miss, Gneiting & Raftery's at 90 %). ``resolution``: the data
    from the finer stand-in, the reported interval the resolution round's (``"round"``) or the fit's own
    (``"ignored"``); ``white``: the noise taken as white; ``per_time``: the mesh scatter taken as independent
    per sample (the interval recomputed from the fit's last linearisation); ``own_mesh``: the records on
    mesh realizations of their own. Each realization is a series of its own: its runs' meshes too."""
    truth = {"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3}
    noise = {r: (NOISE_SD, 0.0 if white else 0.02) for r in RECORDS}
    hits, scores = [], []
    for seed in seeds:
        state = rr.first_round(START, ["interface_friction"], RECORDS, BOX, profile=3, check_meshes=8,
                               resolution={"preset": "fine", "meshes": 4} if resolution == "round" else None)
        y = data(truth, seed, fine_curve if resolution else curve, own_mesh=own_mesh)
        state = rr.run_rounds(state, lambda rows: simulate(rows, seed), y, noise, TIMES)
        iv = state["result"]["candidates"]["interface_friction"]["interval_90"]
        if resolution == "round":
            assert state["result"]["resolution"]["track"] == "interface_friction"
            iv = state["result"]["resolution"]["interval_90"]
        if per_time:
            t, w = state["tracks"]["interface_friction"], {r: np.asarray(v) for r, v in state["weights"].items()}
            lin = t["lin"]
            iv = rr.fit_interval(t["theta"], lin["last"], {r: np.asarray(v) for r, v in lin["base"].items()},
                                 {r: np.asarray(v) for r, v in lin["jac"].items()}, lin["allnames"], w, y, RECORDS,
                                 BOX, noise, TIMES, mesh=None)
        hits.append([iv["q05"][n] <= truth[n] <= iv["q95"][n] for n in truth])
        scores.append([iv["q95"][n] - iv["q05"][n] + 20 * max(iv["q05"][n] - truth[n], 0, truth[n] - iv["q95"][n])
                       for n in truth])
    return np.mean(hits, axis=0), np.mean(scores, axis=0)


BOX_WIDTH = np.array([BOX["sigma_t"][1] - BOX["sigma_t"][0], BOX["E_t"][1] - BOX["E_t"][0],
                      BOX["interface_friction.mu"][1] - BOX["interface_friction.mu"][0]])


def test_the_fits_90_intervals_hold_the_truth_at_their_level_and_an_over_confident_form_does_not():
    # 40 series: the stand-in's AR(1) noise (lag-1 correlation 0.6), each record on a mesh of its own, the
    # runs on the series' own meshes: sigma_t, E_t, mu
    cover, score = _interval_scores()
    assert np.all(cover >= 0.8), cover                  # measured 0.875, 0.95, 0.90
    # the same fit with the noise taken as white and the mesh scatter as independent per sample: the
    # weighted sum's variance is read several times too small
    white, _ = _interval_scores(white=True, per_time=True)
    assert np.all(white[[0, 2]] <= 0.6), white          # measured 0.525, 0.70, 0.50
    # informative: the prior box holds the truth every time, but its interval score is its width; the fit's
    # is a small fraction of it for every parameter
    assert np.all(score / BOX_WIDTH < 0.05), score / BOX_WIDTH


def test_where_the_mesh_scatter_dominates_the_intervals_hold_and_a_per_sample_mesh_term_does_not(monkeypatch):
    # as on FDEM (a few MPa of mesh scatter against about 1 MPa of noise): a realization moves the stand-in's
    # whole curve by 3 %, the records each carry their own; the shipped interval holds the covariance over
    # time of the check runs, the per-sample form averages the scatter away
    monkeypatch.setattr(sys.modules[__name__], "MESH_SD", 0.03)
    cover, score = _interval_scores(seeds=range(100, 130))
    assert np.all(cover >= 0.8), cover                  # measured 0.93, 1.0, 0.90
    per_time, _ = _interval_scores(seeds=range(100, 130), per_time=True)
    assert np.all(per_time[[0, 2]] <= 0.4), per_time    # measured 0.23, 0.97, 0.17
    # three records each 3 % off by their own mesh leave the friction loosely fixed, but still inside the box:
    # interval scores 0.11, 0.004, 0.53 of the box's
    assert np.all(score / BOX_WIDTH < 0.6), score / BOX_WIDTH


def test_the_resolution_round_corrects_what_a_coarse_fit_takes_up_and_its_intervals_hold_the_truth():
    # data from the finer stand-in (4 % stronger): the coarse fit's sigma_t comes out about 4 % high, far
    # outside its interval; the resolution round's correction puts it back
    cover, score = _interval_scores(seeds=range(100, 120), resolution="round")
    assert np.all(cover >= 0.8), cover                  # measured 1.0, 0.95, 1.0
    ignored, _ = _interval_scores(seeds=range(100, 120), resolution="ignored")
    assert ignored[0] <= 0.2, ignored                   # measured 0.0: sigma_t's interval misses without it


def test_the_resolution_round_runs_the_reported_fit_at_both_presets():
    truth = {"sigma_t": 2.5e7, "E_t": 1200.0}
    state = rr.first_round(START, ["face_gap"], RECORDS, BOX, profile=0, check_meshes=4,
                           resolution={"preset": "fine", "meshes": 3})
    while state["phase"] != "done":
        last = state
        state = rr.next_round(state, simulate(state["rows"]), data(truth, model=fine_curve), NOISE, TIMES)
    # the last round: the base (nothing named) linearised at its fit, and 3 + 3 runs there per record
    assert state["result"]["named"] == "base_kept"
    rows = last["rows"]
    assert {r["track"] for r in rows} == {"base"}
    assert sum(r["kind"] == "fine" and r["preset"] == "fine" for r in rows) == 3 * len(RECORDS)
    assert sum(r["kind"] == "coarse" and r["preset"] is None for r in rows) == 3 * len(RECORDS)
    res = state["result"]["resolution"]
    assert res["preset"] == "fine" and res["meshes"] == 3
    # the records' resolution error: 4 % of a peak near 25
    assert all(0.3 < v < 1.5 for v in res["bias_rms"].values()), res["bias_rms"]
    assert res["fit"]["sigma_t"] == pytest.approx(2.5e7, rel=0.02)
    assert state["result"]["base"]["fit"]["sigma_t"] == pytest.approx(1.04 * 2.5e7, rel=0.02)


def test_the_held_out_records_are_predicted_at_the_reported_fits_with_the_population_value():
    from calibration.realrun_files import heldout_errors, heldout_rows, summary_of

    truth = {"sigma_t": 2.5e7, "E_t": 1200.0, "interface_friction.mu": 0.3}
    state = rr.run_rounds(rr.first_round(START, ["interface_friction", "face_gap"], RECORDS[:2], BOX, profile=3,
                                         check_meshes=4), simulate, data(truth), NOISE, TIMES)
    summary = summary_of(state)
    assert summary["named"] == "interface_friction"
    rows = heldout_rows(summary, ["R3"], 4)
    # R3 was neither fitted nor run by the rounds; here it is run at the base's fit and the friction's
    assert state["records"] == ["R1", "R2"]
    assert [r["model"] for r in rows] == ["before"] * 4 + ["after"] * 4 and {r["record"] for r in rows} == {"R3"}
    assert rows[4]["simulator"] == summary["candidates"]["interface_friction"]["fit"]
    y = data(truth)
    err = heldout_errors(rows, simulate([{**r, "kind": "check"} for r in rows]), {"R3": y["R3"]}, {"R3": T})
    # the friction's fit predicts the unseen record better than the base's (its strength set by two rates)
    assert err["R3"]["after"]["rmse"] < 0.5 * err["R3"]["before"]["rmse"]
    assert err["R3"]["after"]["replicates"] == 4
    # a per-record effect at the calibration records' mean; a failed run left out; base kept: before only
    gap = {"named": "face_gap", "base": {"fit": {"sigma_t": 2e7, "E_t": 900.0}},
           "candidates": {"face_gap": {"fit": {"sigma_t": 2.1e7, "E_t": 1000.0, "face_gap.gap_m@R1": 1e-4,
                                               "face_gap.gap_m@R2": 3e-4}}}}
    rows = heldout_rows(gap, ["R3"], 2)
    assert rows[-1]["simulator"] == pytest.approx({"sigma_t": 2.1e7, "E_t": 1000.0, "face_gap.gap_m": 2e-4})
    curves = simulate([{**r, "kind": "check"} for r in rows])
    curves[-1] = None
    assert heldout_errors(rows, curves, {"R3": y["R3"]}, {"R3": T})["R3"]["after"]["replicates"] == 1
    assert {r["model"] for r in heldout_rows({**gap, "named": "base_kept"}, ["R3"], 2)} == {"before"}
