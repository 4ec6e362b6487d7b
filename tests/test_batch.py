"""A batch of simulations in one job (calibration.batch.run_batch, rule simulate): each run keeps the
member contract, a crash is retried without re-running what finished, a configuration error stops the
batch, a run made by the same request is not simulated again, and the shipped simulator's runs fork
from a process that loaded the engine once (their results equal the subprocess's to the byte)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from calibration.batch import request_key, run_batch
from calibration.heal import MANIFEST, check_manifest
from calibration.job_log import THREAD_VARIABLES
from calibration.runner import DEFAULT_SIMULATOR, SimulatorCrash, SimulatorRejected
from test_workflow import write_stand_in

REPO = Path(__file__).resolve().parents[1]


def spec(tmp: Path, name: str, sigma_t: float, command: str, **over) -> dict:
    folder = tmp / "runs" / name
    sim = {"geometry": "brazilian_disc", "preset": "fast", "fixed": {}, "t_end": 5e-5, "sample_dt": 1e-6,
           "command": command}
    return {"sim": sim, "parameters": {"values": {"sigma_t": sigma_t, "E_t": 500.0}}, "record_file": None,
            "mesh_seed": None, "snapshots": None, "run": {"member": name}, "must_succeed": False,
            "outputs": {"curve": str(folder / "curve.csv"), "run": str(folder / "run.json")},
            "log": str(folder / "simulate.log"), "preset": "fast", "time_limit_s": 60, **over}


@pytest.fixture
def stand_in(tmp_path, monkeypatch):
    monkeypatch.setenv("STAND_IN_MARKERS", str(tmp_path))
    return write_stand_in(tmp_path)


def test_a_crash_is_retried_by_the_next_attempt_which_runs_only_what_did_not_finish(tmp_path, stand_in, monkeypatch):
    monkeypatch.setenv("STAND_IN_CRASH_ONCE_BELOW", "1.5e7")  # the second run crashes on its first call
    specs = [spec(tmp_path, "a", 3e7, stand_in), spec(tmp_path, "b", 1e7, stand_in), spec(tmp_path, "c", 4e7, stand_in)]
    batch = tmp_path / "batch_0.json"
    with pytest.raises(SimulatorCrash, match=r"1 of 3 simulations of the batch crashed \(attempt 1 of 2"):
        run_batch(specs, batch_path=batch, attempt=1, max_attempts=2, log_path=tmp_path / "batch_0.log")
    assert not batch.exists() and not (tmp_path / "runs/b/run.json").exists()
    assert (tmp_path / "runs/a/run.json").is_file() and (tmp_path / "runs/c/run.json").is_file()
    kept = (tmp_path / "runs/a/run.json").read_text()
    report = run_batch(specs, batch_path=batch, attempt=2, max_attempts=2, log_path=tmp_path / "batch_0.log")
    assert [(r["folder"][-1], r["status"]) for r in report["runs"]] == [("a", "ok"), ("b", "ok"), ("c", "ok")]
    assert json.loads(batch.read_text()) == report
    log = (tmp_path / "batch_0.log").read_text().splitlines()
    assert log[0] == "batch of 3 simulations, attempt 2 of 2; 2 made before by the same request"
    assert [ln.split(":")[0] for ln in log[1:]] == [str(tmp_path / "runs/b")]  # only the crashed one ran
    assert (tmp_path / "runs/a/run.json").read_text() == kept
    b = json.loads((tmp_path / "runs/b/run.json").read_text())
    assert b["status"] == "ok" and b["attempt"] == 2 and b["member"] == "b"
    for name in "abc":
        assert check_manifest(tmp_path / "runs" / name / MANIFEST)[1] is None


def test_a_crash_on_the_last_attempt_is_a_failed_run_and_the_batch_ends(tmp_path, stand_in, monkeypatch):
    monkeypatch.setenv("STAND_IN_CRASH_ONCE_BELOW", "1.5e7")
    specs = [spec(tmp_path, "a", 3e7, stand_in), spec(tmp_path, "b", 1e7, stand_in)]
    report = run_batch(specs, batch_path=tmp_path / "batch_0.json", attempt=2, max_attempts=2)
    assert [r["status"] for r in report["runs"]] == ["ok", "failed"]
    assert "crashed on every attempt" in report["runs"][1]["reason"]


def test_rejected_arguments_stop_the_batch_with_the_simulators_message(tmp_path, stand_in, monkeypatch):
    monkeypatch.setenv("STAND_IN_REJECT", "measured record data/missing.txt not found")
    specs = [spec(tmp_path, "a", 3e7, stand_in), spec(tmp_path, "b", 2e7, stand_in)]
    with pytest.raises(SimulatorRejected, match="data/missing.txt not found"):
        run_batch(specs, batch_path=tmp_path / "batch_0.json")
    assert not (tmp_path / "batch_0.json").exists() and not list((tmp_path / "runs").rglob("run.json"))


def test_a_numerical_failure_is_a_failed_run_unless_the_run_must_succeed(tmp_path, stand_in, monkeypatch):
    monkeypatch.setenv("STAND_IN_FAIL_BELOW", "5e6")
    report = run_batch([spec(tmp_path, "a", 4e6, stand_in), spec(tmp_path, "b", 3e7, stand_in)],
                       batch_path=tmp_path / "a.json")
    assert [r["status"] for r in report["runs"]] == ["failed", "ok"]
    assert report["runs"][0]["reason"].startswith("numerical failure")
    assert pd.read_csv(tmp_path / "runs/a/curve.csv").empty
    with pytest.raises(RuntimeError, match="the truth simulation .* failed: numerical failure"):
        run_batch([spec(tmp_path, "t", 4e6, stand_in, must_succeed=True)], batch_path=tmp_path / "b.json",
                  label="truth")
    assert not (tmp_path / "b.json").exists()


def test_a_run_is_simulated_again_when_its_request_or_its_files_change_and_only_then(tmp_path, stand_in):
    specs = [spec(tmp_path, "a", 3e7, stand_in), spec(tmp_path, "b", 2e7, stand_in)]
    batch = tmp_path / "batch_0.json"
    run_batch(specs, batch_path=batch, log_path=tmp_path / "log")
    assert open(tmp_path / "log").read().startswith("batch of 2 simulations, attempt 1 of 1; 0 made before")
    run_batch(specs, batch_path=batch, log_path=tmp_path / "log")  # a re-run of the same batch: nothing to do
    assert open(tmp_path / "log").read().splitlines() == [
        "batch of 2 simulations, attempt 1 of 1; 2 made before by the same request"]
    changed = [specs[0], spec(tmp_path, "b", 2.5e7, stand_in)]  # b's parameter changed
    (tmp_path / "runs/a/curve.csv").write_text("time_s,stress_Pa\n")  # a's curve altered
    run_batch(changed, batch_path=batch, log_path=tmp_path / "log")
    ran = [ln.split(":")[0] for ln in open(tmp_path / "log").read().splitlines()[1:]]
    assert ran == [str(tmp_path / "runs/a"), str(tmp_path / "runs/b")]
    assert json.loads((tmp_path / "runs/b/run.json").read_text())["params"]["sigma_t"] == 2.5e7
    # the key holds every input of a run: the mesh seed, the record, the run's entries, the command
    base = request_key(specs[0], {"sigma_t": 3e7, "E_t": 500.0})
    for over in ({"mesh_seed": 3}, {"record_file": "r.json"}, {"run": {"member": "z"}}, {"snapshots": 4}):
        assert request_key({**specs[0], **over}, {"sigma_t": 3e7, "E_t": 500.0}) != base
    other = {**specs[0], "sim": {**specs[0]["sim"], "command": "my_simulator"}}
    assert request_key(other, {"sigma_t": 3e7, "E_t": 500.0}) != base


def test_a_run_another_experiment_made_with_the_same_request_is_copied_and_nothing_else(tmp_path, stand_in):
    store, runs = tmp_path / "store", tmp_path / "runs"
    run_batch([spec(tmp_path, "fold_a", 3e7, stand_in, run={"member": 0})], batch_path=tmp_path / "a.json",
              store=store)
    same = spec(tmp_path, "fold_b", 3e7, stand_in, run={"member": 0})
    other_mesh = spec(tmp_path, "fold_c", 3e7, stand_in, run={"member": 0}, mesh_seed=7)
    run_batch([same, other_mesh], batch_path=tmp_path / "b.json", log_path=tmp_path / "log", store=store)
    log = (tmp_path / "log").read_text().splitlines()
    assert log[0].endswith("1 made before by the same request (1 of them copied from other experiments' runs)")
    assert log[1] == f"{runs / 'fold_b'}: copied from {runs / 'fold_a'}"
    assert log[2].startswith(f"{runs / 'fold_c'}: ok") and len(log) == 3  # a new mesh: simulated
    for name in ("curve.csv", "run.json", MANIFEST):
        assert (runs / "fold_b" / name).read_bytes() == (runs / "fold_a" / name).read_bytes()
    assert check_manifest(runs / "fold_b" / MANIFEST)[1] is None
    # a source altered after it was indexed is a miss: the run is made, not copied
    for folder in ("fold_a", "fold_b"):
        (runs / folder / "curve.csv").write_text("time_s,stress_Pa\n")
    run_batch([spec(tmp_path, "fold_d", 3e7, stand_in, run={"member": 0})], batch_path=tmp_path / "d.json",
              log_path=tmp_path / "log", store=store)
    log = (tmp_path / "log").read_text().splitlines()
    assert log[0].endswith("0 made before by the same request") and log[1].startswith(f"{runs / 'fold_d'}: ok")


def test_a_record_is_keyed_by_its_content_not_its_folder(tmp_path, stand_in):
    """The same record reduced into two experiments' folders is one input; a changed incident wave is not."""
    paths = []
    for exp in ("x", "y"):
        folder = tmp_path / exp / "observations" / "R1"
        folder.mkdir(parents=True)
        (folder / "record.json").write_text('{"source": "R1.txt"}')
        (folder / "incident.csv").write_text("time_s,strain\n0,0\n")
        paths.append(str(folder / "record.json"))
    key = [request_key({**spec(tmp_path, "a", 3e7, stand_in), "record_file": p}, {"sigma_t": 3e7}) for p in paths]
    assert key[0] == key[1]
    (Path(paths[1]).parent / "incident.csv").write_text("time_s,strain\n0,1e-6\n")
    assert request_key({**spec(tmp_path, "a", 3e7, stand_in), "record_file": paths[1]}, {"sigma_t": 3e7}) != key[0]


#: A batch job as Snakemake starts it: a fresh, single-threaded process (the pytest workers hold threads,
#: so the shipped simulator would not fork in them); argv: specs JSON, batch file, log, "subprocess" to
#: turn the fork off (the old path, a second interpreter per run).
JOB = """
import json, sys
from calibration import runner
from calibration.batch import run_batch
if sys.argv[4] == "subprocess":
    runner._forkable = lambda command: False
run_batch(json.loads(open(sys.argv[1]).read()), batch_path=sys.argv[2], log_path=sys.argv[3])
"""


def test_the_shipped_simulators_runs_fork_from_one_loaded_process_and_equal_the_subprocesss(tmp_path):
    sim = {"geometry": "brazilian_disc", "preset": "fast", "fixed": {}, "t_end": 2e-5, "sample_dt": 1e-6,
           "command": DEFAULT_SIMULATOR}
    logs = {}
    for mode, folder in (("fork", "runs"), ("subprocess", "sub")):
        specs = [spec(tmp_path / folder, name, s, DEFAULT_SIMULATOR, sim=sim) for name, s in (("a", 3e7), ("b", 4.5e7))]
        (tmp_path / f"{mode}.json").write_text(json.dumps(specs))
        subprocess.run([sys.executable, "-c", JOB, str(tmp_path / f"{mode}.json"), str(tmp_path / f"{mode}_batch.json"),
                        str(tmp_path / f"{mode}.log"), mode], check=True, cwd=REPO,
                       env={**os.environ, "PYTHONPATH": str(REPO), **dict.fromkeys(THREAD_VARIABLES, "1")})
        logs[mode] = (tmp_path / f"{mode}.log").read_text().splitlines()
        assert [r["status"] for r in json.loads((tmp_path / f"{mode}_batch.json").read_text())["runs"]] == ["ok", "ok"]
    # the forking batch loaded the engine once, before its first run; the subprocess path has nothing to load
    assert logs["fork"][1].startswith("engine loaded in") and len(logs["fork"]) == 4
    assert not any("engine loaded" in ln for ln in logs["subprocess"])
    for name in "ab":  # the same curves to the byte
        fork, sub = (tmp_path / d / "runs" / name / "curve.csv" for d in ("runs", "sub"))
        assert fork.read_bytes() == sub.read_bytes() and os.path.getsize(fork) > 100


def test_a_run_stopped_at_its_time_limit_or_crashed_on_every_attempt_is_tried_again_by_a_rerun(tmp_path, stand_in,
                                                                                               monkeypatch):
    # their outcome is not the simulator's own (the machine's speed, a crash that need not recur): their
    # manifests carry no request, so a batch that runs again simulates them again; a success it keeps
    monkeypatch.setenv("STAND_IN_HANG_RANGE", "1.5e7,2.5e7")
    monkeypatch.setenv("STAND_IN_CRASH_ONCE_BELOW", "5e6")
    specs = [spec(tmp_path, "ok", 3e7, stand_in), spec(tmp_path, "hang", 2e7, stand_in, time_limit_s=1),
             spec(tmp_path, "crash", 4e6, stand_in)]
    report = run_batch(specs, batch_path=tmp_path / "b.json", attempt=1, max_attempts=1)
    assert [r["status"] for r in report["runs"]] == ["ok", "failed", "failed"]
    assert report["runs"][1]["reason"].startswith("time limit") and "crashed" in report["runs"][2]["reason"]
    requests = {n: "request" in json.loads((tmp_path / "runs" / n / MANIFEST).read_text()) for n in ("ok", "hang", "crash")}
    assert requests == {"ok": True, "hang": False, "crash": False}
    monkeypatch.delenv("STAND_IN_HANG_RANGE")
    report = run_batch(specs, batch_path=tmp_path / "b.json", log_path=tmp_path / "log")
    assert [r["status"] for r in report["runs"]] == ["ok", "ok", "ok"]  # the crash marker is spent: it runs now
    assert open(tmp_path / "log").read().splitlines()[0].endswith("1 made before by the same request")
