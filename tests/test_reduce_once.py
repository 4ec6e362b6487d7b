"""Each measured record reduced once: the stored reduction (shpb.lab.reduced_store, written by the
observations stage) gives the simulations and the observations exactly what the raw record gives, and the
Snakefile's parse-time check (calibration.record_check) reduces a record once per content."""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from calibration import record_check
from calibration.observations import (ObservationFileError, cached_check_record, check_record,
                                      measured_observations, reduce_measured_record, stored_observations,
                                      write_reduced_record)
from calibration.record_check import record_key
from shpb.lab.lab_reduce import reduce_sheet
from shpb.lab.reduced_store import pretrigger_stress, read_reduced
from shpb.lab.sheet_readers import check_sheet
from shpb.simulate import simulate

REPO = Path(__file__).resolve().parents[1]
FREIBURG = REPO / "data/freiburg-rae-rock-shpb/Rae2021"
CAMA004 = FREIBURG / "SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
DISC = REPO / "data/examples/granite_disc/granite_disc.yaml"


@pytest.mark.parametrize("record, geometry", [(CAMA004, "cylinder"), (DISC, "brazilian_disc")])
def test_a_member_of_the_stored_record_is_the_member_of_the_raw_record_bit_for_bit(tmp_path, record, geometry):
    """The stored incident wave is written with 17 significant digits, which read back to the same
    float64 (IEEE 754 round trip), and the set-up is the same numbers through JSON's repr of floats: the
    engine gets identical inputs and is deterministic, so the curve is identical, not merely close."""
    folder = tmp_path / "observations" / record.stem
    write_reduced_record(record, folder)
    stored = read_reduced(folder)
    red = reduce_measured_record(record)[0]
    for a, b in zip(red.incident_wave_at_gauge(), stored["incident"].incident_wave_at_gauge()):
        assert np.array_equal(a, b)
    # 30 us after the wave reaches the specimen: the load is on (a cylinder's stress at 12 MPa, the
    # disc's at 2 MPa), enough to carry any difference of the wave into the curve
    raw = simulate(geometry, "fast", record=record, t_end=30e-6)
    red_run = simulate(geometry, "fast", record=folder / "record.json", t_end=30e-6)
    assert raw.run["status"] == red_run.run["status"] == "ok"
    assert np.max(raw.columns["stress_Pa"]) > 1.0e6
    for c, v in raw.columns.items():
        assert np.array_equal(v, red_run.columns[c], equal_nan=True), c
    assert red_run.run["record"] == raw.run["record"] == str(record)  # run.json names the raw record


@pytest.mark.parametrize("record", [CAMA004, DISC])
def test_stored_observations_are_the_measured_observations_number_for_number(tmp_path, record):
    write_reduced_record(record, tmp_path / "rec")
    kw = {"t_start": 0.0, "t_end": 1.0e-4, "dt": 1.0e-6, "error_kind": "ar1", "sigma_scale": 1.5}
    fresh, _ = measured_observations({"r": record}, **kw)
    stored = stored_observations({"r": tmp_path / "rec"}, **kw)
    pd.testing.assert_frame_equal(fresh.frame, stored.frame, check_exact=True)
    assert fresh.corr_time == stored.corr_time
    assert json.dumps(fresh.to_meta(), default=repr) == json.dumps(stored.to_meta(), default=repr)


def test_the_disc_noise_is_the_cylinder_factor_times_d_over_2t():
    """The disc's stress is 2F/(pi D t), the cylinder's F/(pi D^2/4): the same force gives D/(2t) times the
    cylinder's stress (granite disc: D = 0.05 m, t = 0.025 m, so exactly 1.0; a 0.02 m disc gives 1.25)."""
    sheet, raw = check_sheet(DISC)
    red = reduce_sheet(sheet, raw)
    D = red.specimen_diameter
    cyl = pretrigger_stress(raw, red)
    for t in (float(sheet.specimen["thickness"]), 0.02):
        disc = pretrigger_stress(raw, red, disc_thickness_m=t)
        assert np.allclose(disc, cyl * D / (2.0 * t), rtol=1e-14, atol=0.0)
    assert D / (2.0 * 0.02) == pytest.approx(1.25)
    assert cyl.size > 100 and np.std(cyl) > 0  # the pre-trigger part is there and noisy


def _freiburg_copy(tmp_path) -> Path:
    """CaMa_SHPB_004 with its spreadsheet in the Freiburg layout (Rae2021/SHPBdata/CaMa/<record>)."""
    root = tmp_path / "Rae2021"
    (root / "SHPBdata/CaMa").mkdir(parents=True)
    shutil.copy(FREIBURG / "CaMa.xlsx", root / "CaMa.xlsx")
    return Path(shutil.copy(CAMA004, root / "SHPBdata/CaMa" / CAMA004.name))


def test_the_cache_reduces_once_checks_a_changed_file_again_and_ignores_a_bad_entry(tmp_path):
    rec = _freiburg_copy(tmp_path)
    cache = tmp_path / "cache"
    n0 = record_check.REDUCTIONS["count"]
    first = cached_check_record(rec, 3.0e-4, refuse_invalid=True, cache_dir=cache)
    assert record_check.REDUCTIONS["count"] == n0 + 1
    assert cached_check_record(rec, 3.0e-4, refuse_invalid=True, cache_dir=cache) == first
    assert record_check.REDUCTIONS["count"] == n0 + 1  # the second check reduced nothing
    assert first["validity"]["class"] == "valid" and math.isclose(first["end_time_s"], 5.016e-4, rel_tol=1e-9)
    # the verdict on a cached summary is the fresh one: the window's end past the record's is refused
    with pytest.raises(ObservationFileError, match="ends at 0.0005016 s, before the observation window's end 0.001"):
        cached_check_record(rec, 1.0e-3, cache_dir=cache)
    with pytest.raises(ObservationFileError, match="ends at 0.0005016 s"):
        check_record(rec, 1.0e-3)
    assert record_check.REDUCTIONS["count"] == n0 + 1
    # a corrupted entry (cut in half) is ignored and computed again
    entry = cache / f"{record_key(rec)}.json"
    entry.write_text(entry.read_text()[:40])
    assert cached_check_record(rec, 3.0e-4, cache_dir=cache) == first
    assert record_check.REDUCTIONS["count"] == n0 + 2
    # an entry under another key is ignored too
    doc = json.loads(entry.read_text())
    entry.write_text(json.dumps({**doc, "key": "0" * 64}))
    cached_check_record(rec, 3.0e-4, cache_dir=cache)
    assert record_check.REDUCTIONS["count"] == n0 + 3
    # the same record named by another path shares the entry: nothing reduced
    assert cached_check_record(rec.parent / ".." / rec.parent.name / rec.name, cache_dir=cache) == first
    assert record_check.REDUCTIONS["count"] == n0 + 3
    # a changed file is a new key: checked again, and its problem reported
    lines = rec.read_text().splitlines(keepends=True)
    rec.write_text("".join(lines[:40]))
    with pytest.raises(ObservationFileError, match=f"observation file {rec}"):
        cached_check_record(rec, 3.0e-4, cache_dir=cache)
    assert record_check.REDUCTIONS["count"] == n0 + 4
    assert len(list(cache.glob("*.json"))) == 1  # a failed check leaves no entry


def test_the_key_follows_the_spreadsheet_and_the_code(tmp_path):
    rec = _freiburg_copy(tmp_path)
    key = record_key(rec)
    assert record_key(rec) == key and len(key) == 64
    xlsx = rec.parents[2] / "CaMa.xlsx"
    xlsx.write_bytes(xlsx.read_bytes() + b"\0")
    assert record_key(rec) != key
    assert record_key(rec, code=b"another reduction") != record_key(rec)


def _dry_run(workdir: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--quiet", "--snakefile",
                           str(REPO / "Snakefile"), "--directory", str(workdir)],
                          cwd=REPO, capture_output=True, text=True, timeout=300)


def test_a_second_dry_run_reduces_no_record_and_a_changed_record_is_stopped(tmp_path):
    """Every reduction for the check writes its entry (atomically, a new file): a dry run that leaves
    every entry as it was reduced no record."""
    rec = _freiburg_copy(tmp_path / "data")
    (tmp_path / "config").mkdir()
    cfg = {"run": ["m"], "experiments": {"m": {
        "kind": "measured", "geometry": "cylinder", "preset": "fast", "seed": 1, "ensemble_size": 4,
        "method": "esmda", "esmda": {"steps": 1}, "posterior": "ensemble", "parameters": {"sigma_t": [4.0e+6, 6.0e+7]},
        "simulation": {"t_end": 3.0e-4, "sample_dt": 1.0e-6},
        "observations": {"records": [str(rec)], "t_end": 3.0e-4, "dt": 2.0e-6}}}}
    (tmp_path / "config/config.yaml").write_text(json.dumps(cfg))
    first = _dry_run(tmp_path)
    assert first.returncode == 0, first.stderr[-3000:]
    entries = {p: p.stat().st_mtime_ns for p in (tmp_path / ".snakemake/fdem-records").glob("*.json")}
    assert len(entries) == 1
    second = _dry_run(tmp_path)
    assert second.returncode == 0, second.stderr[-3000:]
    assert {p: p.stat().st_mtime_ns for p in entries} == entries
    assert len(list((tmp_path / ".snakemake/fdem-records").glob("*.json"))) == 1
    assert "reduced_record" in _dry_run_jobs(tmp_path)  # the record's one reduction for the jobs
    # a NaN written into the record: a new content, checked again, stopped before any job with the file
    lines = rec.read_text().splitlines(keepends=True)
    i = len(lines) // 2
    fields = lines[i].split(";")
    lines[i] = ";".join(fields[:2] + ["NaN"] + fields[3:])  # a gauge channel
    rec.write_text("".join(lines))
    third = _dry_run(tmp_path)
    assert third.returncode != 0
    assert f"experiment 'm': observation file {rec}" in third.stdout + third.stderr, third.stdout[-2000:]


def _dry_run_jobs(workdir: Path) -> str:
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--snakefile",
                          str(REPO / "Snakefile"), "--directory", str(workdir)],
                         cwd=REPO, capture_output=True, text=True, timeout=300)
    return out.stdout + out.stderr
