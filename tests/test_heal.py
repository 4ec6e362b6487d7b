"""Runs that heal (calibration.heal): a member file altered between runs is re-simulated, stale
temporaries are removed when a run starts, and a simulator dies with its job (and the job with its
Snakemake), so that a killed run writes nothing after the kill.

The workflow test drives the stand-in simulator of test_workflow.py (an analytic pulse through the same
command-line contract) up to the first analysis only; the process tests use a dummy simulator that
sleeps, through run_member's ``command``.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from calibration.heal import MANIFEST, PARENT_ENV, check_manifest, heal_results, is_dry_invocation, write_manifest
from test_workflow import snakemake, twin_config, write_config, write_stand_in

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")


# --------------------------------------------------------------------------------------------------
# (a) a member file truncated, altered or removed between runs is re-simulated; the posterior is unchanged
# --------------------------------------------------------------------------------------------------
def test_a_truncated_altered_or_removed_member_is_resimulated_and_the_posterior_is_unchanged(tmp_path):
    cfg = twin_config(ensemble_size=4, esmda={"steps": 1})
    cfg["experiments"]["twin"]["observations"]["model_error"] = {"simulator_replicates": 0}  # fewer jobs
    cfg["simulator"] = write_stand_in(tmp_path)
    write_config(tmp_path, cfg)
    target = "results/twin/iter_0/analysis.json"
    first = snakemake(tmp_path, "--cores", "2", target)
    assert first.returncode == 0, first.stderr[-4000:]
    analysis = tmp_path / target
    uninterrupted = json.loads(analysis.read_text())
    members = tmp_path / "results/twin/iter_0/members"
    curves = {m: members / f"{m:03d}/synthetic/curve.csv" for m in range(4)}
    # what each run wrote: a kept run keeps its files (Snakemake touches them, so not their modification time)
    written = {m: (c.parent / "run.json").read_text() for m, c in curves.items()}
    text = curves[1].read_text()
    size, truncated = len(text), len(text) // 2
    curves[1].write_text(text[:truncated])
    text = curves[2].read_text()
    i = text.index("\n") + 5
    curves[2].write_text(text[:i] + ("1" if text[i] != "1" else "2") + text[i + 1:])  # same size, altered
    stale = [members / "000/synthetic/.sim-0123abcd", members.parent / ".responses.csv.0123abcd.tmp"]
    stale[0].mkdir()
    (stale[0] / "curve.csv").write_text("half a curve")
    stale[1].write_text("half a table")
    assert len(list(members.rglob(MANIFEST))) == 4
    shutil.rmtree(members / "003")  # no rule asks for a member's files: its batch file must be dated back
    again = snakemake(tmp_path, "--cores", "2", target)
    assert again.returncode == 0, again.stderr[-4000:]
    lines = [ln for ln in again.stderr.splitlines() if ln.startswith("results")]
    assert lines[0] == "results: removed 2 stale temporaries of killed jobs (.sim-* folders, .*.tmp files)"
    assert lines[1] == (f"results/twin/iter_0/members/001/synthetic: curve.csv has {truncated} bytes, its manifest "
                        f"says {size} (truncated or altered); re-queued: curve.csv, run.json, batch_0.json dated back to 1970, "
                        "out of date, so a run that needs them simulates the member again")
    assert "members/002/synthetic: the sha256 of curve.csv does not match its manifest (altered)" in lines[2]
    assert lines[3] == ("results/twin/iter_0/members/003/synthetic: curve.csv, run.json missing; re-queued: "
                        "batch_1.json dated back to 1970, out of date, so a run that needs them simulates the member again")
    assert len(lines) == 4 and not any(p.exists() for p in stale)
    assert json.loads(analysis.read_text()) == uninterrupted
    # 1, 2 and 3 simulated again; 0, in its batch (0 and 1; 2 and 3), kept: made by the same request
    for b, kept, again in ((0, 1, [1]), (1, 0, [2, 3])):
        log = (tmp_path / f"results/twin/simulate/member/iter_0/batch_{b}.log").read_text().splitlines()
        assert log[0] == f"batch of 2 simulations, attempt 1 of 2; {kept} made before by the same request"
        assert [ln.split(":")[0] for ln in log[1:]] == [str(curves[m].parent.relative_to(tmp_path)) for m in again]
    for m, c in curves.items():
        assert m != 0 or (c.parent / "run.json").read_text() == written[m], m
        assert check_manifest(c.parent / MANIFEST)[1] is None and os.path.getmtime(c) > 1.0  # not left in 1970


# --------------------------------------------------------------------------------------------------
# (b) stale temporaries and bad manifests at the start of a run; what counts as a dry run
# --------------------------------------------------------------------------------------------------
def _member(folder: Path, curve: str = "time_s,stress_Pa\n0.0,1.0\n") -> Path:
    folder.mkdir(parents=True)
    (folder / "curve.csv").write_text(curve)
    (folder / "run.json").write_text('{"status": "ok"}')
    write_manifest(folder, [folder / "curve.csv", folder / "run.json"])
    return folder


def test_stale_temporaries_are_removed_at_start_except_in_a_dry_run_or_under_a_lock(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    m = _member(tmp_path / "results/x/iter_0/members/000/synthetic")
    (m / ".sim-abc123").mkdir()
    (m / ".sim-abc123" / "curve.csv").write_text("partial")
    (m / ".sim-abc123" / "manifest.json").write_text("not read: inside a temporary")
    (m.parent / ".run.json.0a1b2c.tmp").write_text("partial")
    keep = [m / "curve.csv", m / "run.json", m / MANIFEST, tmp_path / "results/x/.hidden.csv", tmp_path / "results/x/a.tmp"]
    for p in keep[3:]:
        p.write_text("not a temporary of ours")
    (tmp_path / ".snakemake/locks").mkdir(parents=True)
    (tmp_path / ".snakemake/locks/0.input.lock").write_text("")
    locked = heal_results("results", ["snakemake", "--cores", "2"], out=io.StringIO())
    assert len(locked) == 1 and ".snakemake/locks holds a lock" in locked[0]
    assert (m / ".sim-abc123").is_dir()
    (tmp_path / ".snakemake/locks/0.input.lock").unlink()
    assert heal_results("results", ["snakemake", "-np"], out=io.StringIO()) == [
        "results: would remove 2 stale temporaries of killed jobs (.sim-* folders, .*.tmp files) (dry run)"]
    assert (m / ".sim-abc123").is_dir() and (m.parent / ".run.json.0a1b2c.tmp").is_file()
    out = io.StringIO()
    lines = heal_results("results", ["snakemake", "--cores", "2"], out=out)
    assert lines == ["results: removed 2 stale temporaries of killed jobs (.sim-* folders, .*.tmp files)"]
    assert out.getvalue() == lines[0] + "\n"
    assert not (m / ".sim-abc123").exists() and not (m.parent / ".run.json.0a1b2c.tmp").exists()
    assert all(p.is_file() for p in keep)
    assert heal_results("results", ["snakemake"], out=io.StringIO()) == []  # nothing left to say
    assert heal_results("no_such_folder", ["snakemake"], out=io.StringIO()) == []


def test_a_member_is_put_out_of_date_when_its_manifest_fails_and_a_missing_file_is_not_flagged(tmp_path):
    ok = _member(tmp_path / "results/a")
    gone = _member(tmp_path / "results/b")
    (gone / "curve.csv").unlink()  # Snakemake notices a missing output itself
    unreadable = _member(tmp_path / "results/c")
    (unreadable / MANIFEST).write_text('{"files": ')
    altered = _member(tmp_path / "results/d")
    (altered / "run.json").write_text('{"status": "no"}')  # the same size, another sha256
    dry = heal_results(tmp_path / "results", ["snakemake", "-n"], out=io.StringIO())
    assert [ln.split(":")[0] for ln in dry] == [str(unreadable), str(altered)]
    assert all(ln.endswith("a run would re-simulate it (dry run)") for ln in dry)
    assert {p.stat().st_mtime > 1e9 for d in (unreadable, altered) for p in d.iterdir()} == {True}
    lines = heal_results(tmp_path / "results", ["snakemake"], out=io.StringIO())
    assert [ln.split(":")[0] for ln in lines] == [str(unreadable), str(altered)]
    assert "manifest.json is unreadable (JSONDecodeError)" in lines[0]
    assert "the sha256 of run.json does not match its manifest (altered)" in lines[1]
    # older than any input of the job that wrote them: Snakemake's mtime trigger runs the job again
    for d in (unreadable, altered):
        assert {p.name: p.stat().st_mtime for p in d.iterdir() if p.name != MANIFEST} == {"curve.csv": 0, "run.json": 0}
    assert all(p.stat().st_mtime > 1e9 for d in (ok, gone) for p in d.iterdir())
    assert sorted(p.name for p in gone.iterdir()) == [MANIFEST, "run.json"]
    assert len(heal_results(tmp_path / "results", ["snakemake"], out=io.StringIO())) == 2  # still bad: said again


@pytest.mark.parametrize("argv, dry", [
    (["snakemake", "--cores", "2"], False), (["snakemake", "-j", "2", "--directory", "/tmp/nt"], False),
    (["snakemake", "-p", "-c2", "results/twin/summary.json"], False), (["snakemake", "-n"], True),
    (["snakemake", "-pn"], True), (["snakemake", "--dry-run"], True), (["snakemake", "--dryrun"], True),
    (["snakemake", "--unlock"], True), (["snakemake", "-t"], True), (["snakemake", "--list-changes", "code"], True),
    (["snakemake", "--report", "r.html"], True), (["snakemake", "--dag"], True),
])
def test_an_invocation_that_runs_no_job_removes_nothing(argv, dry):
    assert is_dry_invocation(argv) is dry


# --------------------------------------------------------------------------------------------------
# (c) a simulator dies with its job, the job with its Snakemake; an orphan writes nothing
# --------------------------------------------------------------------------------------------------
DUMMY = textwrap.dedent('''
    import os, sys, time
    pidfile, sleep_s = sys.argv[1], float(sys.argv[2])
    open(pidfile + ".part", "w").write(str(os.getpid()))
    os.replace(pidfile + ".part", pidfile)
    time.sleep(sleep_s)
    out = sys.argv[sys.argv.index("--out") + 1]
    open(os.path.join(out, "curve.csv"), "w").write("time_s,stress_Pa\\n0.0,1.0\\n")
    open(os.path.join(out, "run.json"), "w").write('{"status": "ok"}')
''')

JOB = textwrap.dedent('''
    import sys
    if sys.argv[2] == "1":  # what Snakemake's preamble leaves in a script job's __main__
        from snakemake.script import Snakemake
        snakemake = Snakemake.__new__(Snakemake)
    import calibration  # arms the death signal in a Snakemake script job, nowhere else
    from calibration.runner import run_member
    dummy, pidfile, sleep_s, member = sys.argv[3:7]
    run_member(command=[sys.executable, dummy, pidfile, sleep_s], geometry="brazilian_disc", preset="fast",
               params={"sigma_t": 1.0e7}, curve_path=member + "/curve.csv", run_path=member + "/run.json")
''')

# a stand-in for Snakemake: starts the job script as its child and waits for it
PARENT = "import subprocess, sys; subprocess.run([sys.executable, '-c'] + sys.argv[1:])"


def _alive(pid: int) -> bool:
    """Running (a zombie nobody reaped yet counts as dead)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


def _wait_for(path: Path, timeout: float = 30.0) -> int:
    deadline = time.time() + timeout
    while not path.is_file():
        assert time.time() < deadline, f"{path} never appeared"
        time.sleep(0.05)
    return int(path.read_text())


@pytest.mark.parametrize("killed, die_with_parent, sleep_s", [
    ("job", False, 30.0),  # the simulator dies with the job script that started it
    ("snakemake", True, 30.0),  # a Snakemake script job dies with its Snakemake, the simulator with it
    ("snakemake", False, 1.0),  # a job left alive (not a script job) finishes its simulation, moves nothing
])
def test_a_killed_job_leaves_no_process_and_writes_nothing_after_the_kill(tmp_path, killed, die_with_parent, sleep_s):
    dummy = tmp_path / "dummy_simulator.py"
    dummy.write_text(DUMMY)
    member, pidfile = tmp_path / "member", tmp_path / "sim.pid"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    job_argv = [JOB, "job", "1" if die_with_parent else "0", str(dummy), str(pidfile), str(sleep_s), str(member)]
    argv = [sys.executable, "-c", *job_argv] if killed == "job" else [sys.executable, "-c", PARENT, *job_argv]
    proc = subprocess.Popen(argv, env=env, stderr=subprocess.PIPE, text=True)
    sim = _wait_for(pidfile)
    job = int(Path(f"/proc/{sim}/stat").read_text().rsplit(")", 1)[1].split()[1])  # the simulator's parent
    assert job == proc.pid if killed == "job" else job != proc.pid
    t_kill = time.time()
    proc.kill()
    proc.wait()
    deadline = t_kill + sleep_s + 10.0
    while (_alive(sim) or _alive(job)) and time.time() < deadline:
        time.sleep(0.05)
    assert not _alive(sim) and not _alive(job)
    assert time.time() - t_kill < (2.0 if sleep_s > 5 else sleep_s + 5.0)  # died with it, not at its end
    files = [p for p in member.rglob("*") if p.is_file()]
    assert not [p for p in files if p.stat().st_mtime >= t_kill], "a file was written after the kill"
    assert not [p for p in files if p.parent == member]  # no output moved into place
    # a job killed outright leaves its (empty) .sim-* folder for the next run's start to remove
    assert [p.name[:5] for p in member.iterdir()] == ([] if killed == "snakemake" and not die_with_parent else [".sim-"])


@pytest.mark.parametrize("script_job, snakemake_alive, returncode", [
    (True, False, 137),  # its Snakemake died while the job was still starting: it ends at once
    (True, True, 0), (False, False, 0),  # a live Snakemake; not a Snakemake script job (never armed)
])
def test_a_job_whose_snakemake_died_before_it_armed_the_death_signal_exits(script_job, snakemake_alive, returncode):
    gone = subprocess.Popen(["true"])
    gone.wait()  # reaped: its pid names no process
    code = ("from snakemake.script import Snakemake\nsnakemake = Snakemake.__new__(Snakemake)\n" if script_job else "") + \
        "import calibration\nprint('still here')"
    env = {**os.environ, PARENT_ENV: str(os.getpid() if snakemake_alive else gone.pid)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == returncode, out.stderr[-2000:]
    assert (out.stdout == "still here\n") == (returncode == 0)
