"""The shipped simulator run by ``calibration.runner.run_member`` in a forked child of the job process
instead of a second interpreter: the same files, exit codes, failures and log as the subprocess path.

Each run is a fresh job process (``python -c JOB``), single-threaded as a member job is, run once with the
fork (the default for ``python -m shpb simulate``) and once with the subprocess path (the fork turned off).
The failures are the real simulator's, provoked by a ``sitecustomize`` that both the job process and a
simulator subprocess load (so the forked child inherits the same change): an unstable time step (exit
code 3), a segmentation fault, an uncaught exception, a run that sleeps past the time limit."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PATCH = textwrap.dedent('''
    import os, signal, time
    import shpb.simulate as sim

    _real = sim.simulate

    def install(mode):
        def simulate(*args, **kw):
            if mode == "unstable":  # three times the stable step: the energy guard stops the run (exit 3)
                from fdem import stable_time_step
                kw["dt"] = 3.0 * stable_time_step(sim.build(args[0], args[1])["model"], 1.0)
            elif mode == "segv":
                os.kill(os.getpid(), signal.SIGSEGV)
            elif mode == "raise":
                raise RuntimeError("boom from the simulator")
            elif mode == "sleep":
                pidfile = os.environ.get("SIMPATCH_PIDFILE")
                if pidfile:
                    open(pidfile + ".part", "w").write(str(os.getpid()))
                    os.replace(pidfile + ".part", pidfile)
                time.sleep(60.0)
            return _real(*args, **kw)
        sim.simulate = simulate
''')
SITE = "import os\nif os.environ.get('SIMPATCH'):\n    import simpatch\n    simpatch.install(os.environ['SIMPATCH'])\n"

# one member job; prints what run_member returned or raised and whether the fork ran it
JOB = textwrap.dedent('''
    import json, sys
    from calibration import runner
    how, folder, kw = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    forked = []
    if how == "subprocess":
        runner._forkable = lambda command: False
    else:
        real = runner._fork_with_limit
        runner._fork_with_limit = lambda *a: forked.append(1) or real(*a)
    try:
        out = {"run": runner.run_member(command=runner.simulator_command(), curve_path=folder + "/curve.csv",
                                        run_path=folder + "/run.json", log_path=folder + "/simulate.log", **kw)}
    except Exception as exc:
        out = {"raised": type(exc).__name__, "message": str(exc)}
    out["forked"] = bool(forked)
    print(json.dumps(out))
''')

DISC = dict(geometry="brazilian_disc", preset="fast", params={"sigma_t": 4.5e7, "E_t": 500.0}, t_end=4e-5,
            sample_dt=1e-6)
THREADS = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}
TIMINGS = ("wall_s", "solver_wall_s", "element_updates_per_s")


def _env(tmp_path: Path, patch: str | None, **extra) -> dict:
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / "simpatch.py").write_text(PATCH)
    (site / "sitecustomize.py").write_text(SITE)
    env = {**os.environ, **THREADS, **extra,
           "PYTHONPATH": os.pathsep.join([str(site), str(ROOT), os.environ.get("PYTHONPATH", "")])}
    env.pop("SIMPATCH", None)
    if patch:
        env["SIMPATCH"] = patch
    return env


def _job(tmp_path: Path, how: str, patch: str | None = None, **kw) -> dict:
    folder = tmp_path / how
    proc = subprocess.run([sys.executable, "-c", JOB, how, str(folder), json.dumps({**DISC, **kw})], cwd=ROOT,
                          env=_env(tmp_path, patch), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["forked"] == (how == "fork"), out  # the path under test is the one that ran
    out["folder"] = folder
    return out


def _same(text: str, folder: Path) -> str:
    """A log or message with what legitimately differs between two runs masked: the member folder, the
    temporary folder's random name, wall times."""
    text = text.replace(str(folder), "<member>")
    text = re.sub(r"\.sim-[A-Za-z0-9_]+", ".sim-X", text)
    return re.sub(r"\d+\.\d s\b", "T s", text)


def _run_json(folder: Path) -> dict:
    run = json.loads((folder / "run.json").read_text())
    return {k: v for k, v in run.items() if k not in TIMINGS}


def _both(tmp_path: Path, patch: str | None = None, **kw) -> tuple[dict, dict]:
    return _job(tmp_path, "subprocess", patch, **kw), _job(tmp_path, "fork", patch, **kw)


def test_a_forked_member_writes_the_files_and_log_of_the_subprocess(tmp_path):
    old, new = _both(tmp_path)
    a, b = old["folder"], new["folder"]
    assert new["run"]["status"] == "ok" and new["run"]["exit_code"] == 0
    assert (a / "curve.csv").read_bytes() == (b / "curve.csv").read_bytes()
    times = [float(line.split(",")[0]) for line in (b / "curve.csv").read_text().splitlines()[1:]]
    # sampled every 1e-6 s (rounded to whole time steps: within 2 %) up to the window's end, 4e-5 s after the
    # wave reaches the disc (within one sample): a whole curve, not a stub
    assert 4e-5 <= times[-1] < 4e-5 + 1.02e-6
    assert all(abs(t1 - t0 - 1e-6) < 0.02e-6 for t0, t1 in zip(times, times[1:]))
    assert _run_json(a) == _run_json(b)
    assert set(json.loads((b / "run.json").read_text())) == set(json.loads((a / "run.json").read_text()))
    assert json.loads((a / "manifest.json").read_text())["files"]["curve.csv"] == \
        json.loads((b / "manifest.json").read_text())["files"]["curve.csv"]
    log_a, log_b = (_same((f / "simulate.log").read_text(), f) for f in (a, b))
    assert log_a == log_b and "--- stdout\nok: brazilian_disc fast" in log_b
    assert sorted(p.name for p in b.iterdir()) == ["curve.csv", "manifest.json", "run.json", "simulate.log"]


def test_a_numerical_failure_is_a_failed_member_as_with_the_subprocess(tmp_path):
    old, new = _both(tmp_path, "unstable")
    for out in (old, new):
        assert out["run"]["status"] == "failed" and out["run"]["exit_code"] == 3
        assert out["run"]["reason"].startswith("numerical failure: ")
        assert out["run"]["reason"].endswith("(numerical instability)")  # the engine's own stop
        assert (out["folder"] / "curve.csv").read_text().count("\n") == 1  # the header alone
    assert _run_json(old["folder"]) == _run_json(new["folder"])
    assert _same((old["folder"] / "simulate.log").read_text(), old["folder"]) == \
        _same((new["folder"] / "simulate.log").read_text(), new["folder"])


def test_rejected_arguments_raise_the_same_message_and_leave_nothing(tmp_path):
    old, new = _both(tmp_path, params={"sigma_q": 1.0})
    assert old["raised"] == new["raised"] == "SimulatorRejected"
    assert "exit code 2" in new["message"] and "sigma_q" in new["message"]
    assert _same(old["message"], old["folder"]) == _same(new["message"], new["folder"])
    for out in (old, new):  # the log alone: no curve, run.json, manifest or temporary folder
        assert sorted(p.name for p in out["folder"].iterdir()) == ["simulate.log"]


@pytest.mark.parametrize("patch, what", [("segv", "simulator killed by signal 11"),
                                         ("raise", "simulator exited with code 1")])
def test_a_crash_is_retried_then_recorded_on_the_last_attempt(tmp_path, patch, what):
    old, new = _both(tmp_path, patch, attempt=1, max_attempts=2)
    for out in (old, new):
        assert out["raised"] == "SimulatorCrash" and what in out["message"], out
        assert not (out["folder"] / "run.json").exists() and not (out["folder"] / "curve.csv").exists()
    if patch == "raise":  # the traceback's end reaches the message as from a subprocess
        assert "RuntimeError: boom from the simulator" in new["message"]
    old, new = _both(tmp_path, patch, attempt=2, max_attempts=2)
    for out in (old, new):
        assert out["run"]["status"] == "failed" and out["run"]["reason"].startswith("crashed on every attempt")
        assert what in out["run"]["reason"] and out["run"]["exit_code"] == (-11 if patch == "segv" else 1)
    if patch == "segv":
        assert _run_json(old["folder"]) == _run_json(new["folder"])


def test_the_time_limit_stops_a_forked_run_as_a_failed_member(tmp_path):
    t0 = time.time()
    old, new = _both(tmp_path, "sleep", time_limit_s=3.0)
    assert time.time() - t0 < 40.0  # neither waited for the 60 s sleep
    for out in (old, new):
        assert out["run"]["status"] == "failed" and out["run"]["reason"].startswith("time limit")
        assert 3.0 <= out["run"]["wall_s"] < 8.0 and out["run"]["exit_code"] is None
    assert _run_json(old["folder"]) == _run_json(new["folder"])
    log = _same((new["folder"] / "simulate.log").read_text(), new["folder"])
    assert log == _same((old["folder"] / "simulate.log").read_text(), old["folder"])
    assert "# killed after the time limit of 3 s" in log


def test_a_killed_job_takes_its_forked_simulator_with_it(tmp_path):
    member, pidfile = tmp_path / "fork", tmp_path / "sim.pid"
    job = subprocess.Popen([sys.executable, "-c", JOB, "fork", str(member), json.dumps(DISC)], cwd=ROOT,
                           env=_env(tmp_path, "sleep", SIMPATCH_PIDFILE=str(pidfile)),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 120.0
    while not pidfile.is_file():
        assert time.time() < deadline and job.poll() is None, job.stderr.read()[-2000:] if job.poll() else ""
        time.sleep(0.05)
    sim = int(pidfile.read_text())
    assert int(Path(f"/proc/{sim}/stat").read_text().rsplit(")", 1)[1].split()[1]) == job.pid  # a forked child
    t_kill = time.time()
    job.send_signal(signal.SIGKILL)
    job.communicate()

    def alive(pid):
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except (OSError, IndexError):
            return False
    while alive(sim) and time.time() - t_kill < 5.0:
        time.sleep(0.05)
    assert not alive(sim) and time.time() - t_kill < 2.0  # died with the job, not at the sleep's end
    assert [p.name[:5] for p in member.iterdir()] == [".sim-"]  # nothing moved into place


def test_only_the_shipped_command_in_a_single_threaded_process_is_forked():
    """A user's simulator command, another interpreter, or a caller running a second thread (whose locks
    a fork would copy held) keep the subprocess path."""
    import threading

    from calibration import runner

    assert not runner._forkable([sys.executable, "my_simulator.py"])
    assert not runner._forkable(["/usr/bin/python3-other", "-m", "shpb", "simulate"])
    assert not runner._forkable([*runner.simulator_command(), "--preset", "fast"])  # not the bare prefix
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert not runner._forkable(runner.simulator_command())
    finally:
        stop.set()
        thread.join()
