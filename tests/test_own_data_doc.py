"""docs/own-data.md: every command of its `bash` blocks runs as written from the repository root (here a
folder whose entries link to the repository's, so that the outputs land in the test's folder), and
gives what the page says it gives."""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "own-data.md"


def doc_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", DOC.read_text(), flags=re.S)
    return [ln.strip() for b in blocks for ln in b.splitlines() if ln.strip() and not ln.startswith("#")]


def test_the_pages_commands_run_as_written(tmp_path):
    for entry in REPO.iterdir():
        if entry.name not in (".git", "results", "reduced", "my_sheets", ".snakemake"):
            (tmp_path / entry.name).symlink_to(entry)
    commands = doc_commands()
    assert [c.split()[:3] for c in commands] == [["python", "-m", "shpb"], ["python", "-m", "shpb"],
                                                 ["python", "-m", "shpb"], ["snakemake", "-n", "--cores"]]
    outputs = []
    for cmd in commands:
        argv = shlex.split(cmd)
        argv = [sys.executable, *argv[1:]] if argv[0] == "python" else [sys.executable, "-m", *argv]
        out = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300, env=dict(os.environ))
        assert out.returncode == 0, f"{cmd}\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}"
        outputs.append(out.stdout)
    # sheet-from-freiburg: the shipped example sheet, its signals path relative to the new sheet
    mine = yaml.safe_load((tmp_path / "my_sheets" / "CaMa_SHPB_004.yaml").read_text())
    shipped = yaml.safe_load((REPO / "data/examples/sheets/CaMa_SHPB_004.yaml").read_text())
    assert mine["specimen"] == shipped["specimen"] and mine["bars"] == shipped["bars"]
    # reduce: the printed checks and the files the page names
    checks = json.loads((tmp_path / "reduced/granite_disc/checks.json").read_text())
    assert all(checks[k]["ok"] for k in ("force_balance", "pulse_alignment", "noise"))
    assert abs(checks["peak_stress_Pa"] - 33.4e6) < 0.05e6
    page = DOC.read_text()
    for line in outputs[1].splitlines():
        assert line.strip().replace("/tmp", "") in page.replace("/tmp", ""), line
    assert (tmp_path / "reduced/granite_disc/force_balance.png").is_file()
    # init-config prints the line the page shows; the dry run of the config it wrote plans the 25 members of
    # granite_own's first ensemble (4 batch jobs of at most 8 fast runs, an even count) and nothing of twin_ref
    assert outputs[2].strip() in page
    batches = set(re.findall(r"results/granite_own/simulate/member/iter_0/batch_(\d+)\.json", outputs[3]))
    assert batches == {"0", "1", "2", "3"}, outputs[3][-3000:]
    assert "twin_ref" not in outputs[3] and "granite_own" in outputs[3]
    assert not (tmp_path / "results").exists()
