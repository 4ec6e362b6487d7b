"""`python -m shpb init-config` (shpb.lab.init_config): a calibration experiment written from a lab's test
sheets. The window holds every record's onset, peak and fall, dt gives 100-200 observations, the prior box
is the rock class's (the marble cylinder's E_t reaches the ~26 kJ/m^2 its post-peak needs at `fast`, the
granite disc keeps the Table 2 box), every choice carries its reason, and the written configs pass the
workflow's validation and a Snakemake dry run; mixed or too small sets are refused with a message."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from calibration.config_check import validate_config
from shpb.__main__ import main
from shpb.lab.init_config import (InitConfigError, choose_dt, choose_window, init_config, record_times,
                                  rock_box)
from shpb.lab.sheet_freiburg import freiburg_sheet, write_sheet

REPO = Path(__file__).resolve().parents[1]
DISC = REPO / "data" / "examples" / "granite_disc" / "granite_disc.yaml"
CAMA = REPO / "data" / "freiburg-rae-rock-shpb" / "Rae2021" / "SHPBdata" / "CaMa"
DISC_NAME, MARBLE_NAME = "granite_godinez2021_brazilian_disc", "carrara_marble_cylinder"


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The configs of the granite disc and of config/config.yaml marble_loop's three marble records
    (CaMa_SHPB_006 held out, as there), written from a folder outside the repository."""
    tmp = tmp_path_factory.mktemp("init")
    sheets = [REPO / "data/examples/sheets/CaMa_SHPB_004.yaml"]
    for raw in ("CaMa_SHPB_014_Ti25_55b_Al12b_0_001.txt", "CaMa_SHPB_006_Ti25_70b_Al12b_0_001.txt"):
        sheets.append(tmp / f"{raw[:13]}.yaml")
        write_sheet(freiburg_sheet(CAMA / raw, tmp), sheets[-1])
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        # the granite disc's record was simulated at the model's own mesh (data/examples/granite_disc): no mesh
        # error to carry, as docs/own-data.md runs it; the marble records are measured: the default
        disc = init_config([DISC], approximation_error=False)
        marble = init_config(sheets, diagnosis=True, heldout="CaMa_SHPB_006")
    finally:
        os.chdir(cwd)
    (tmp / "disc.yaml").write_text(disc[0])
    (tmp / "marble.yaml").write_text(marble[0])
    return tmp, disc, marble


def _exp(doc):
    (exp,) = doc["experiments"].values()
    return exp


def _header_times(text: str) -> dict[str, tuple[float, float, float]]:
    """Onset / peak / fall [us] of each record, from the written file's header."""
    out = {}
    for ln in text.splitlines():
        if ln.startswith("#   ") and " / " in ln:
            name, rest = ln[4:].split(": ", 1)
            parts = [p.split()[0] for p in rest.split(" / ")]
            out[name] = tuple(float(p) for p in parts)
    return out


def test_the_granite_disc_gets_its_window_dt_and_table_2_box(written):
    _, (text, doc), _ = written
    exp = _exp(doc)
    assert doc["run"] == [DISC_NAME] and exp["geometry"] == "brazilian_disc" and exp["kind"] == "measured"
    # onset 29 us, peak 113 us, down to half the peak at 151 us: + 10 % = 166 us, rounded up to 170 us
    assert _header_times(text)["granite_disc"] == (29.0, 113.0, 151.0)
    obs = exp["observations"]
    assert obs["t_start"] == 0.0 and obs["t_end"] == pytest.approx(170e-6) and obs["dt"] == pytest.approx(1e-6)
    assert exp["simulation"]["t_end"] >= obs["t_end"]
    assert exp["parameters"] == {"sigma_t": [4.0e6, 6.0e7], "E_t": [200.0, 2400.0]}
    truth = {"sigma_t": 45e6, "E_t": 500.0}   # data/examples/granite_disc/truth.json: inside the box
    assert all(lo < truth[p] < hi for p, (lo, hi) in exp["parameters"].items())
    assert exp["method"] == "emulated_esmda" and exp["ensemble_size"] == 25 and "diagnosis" not in exp


def test_the_marble_cylinder_gets_a_box_its_post_peak_fits_in_and_a_window_past_every_fall(written):
    _, _, (text, doc) = written
    exp = _exp(doc)
    assert doc["run"] == [MARBLE_NAME] and exp["geometry"] == "cylinder"
    lo, hi = exp["parameters"]["E_t"]
    assert lo <= 200.0 and hi >= 40e3              # ~26 kJ/m^2 at `fast` (docs/closing-the-loop.md)
    assert exp["parameters"]["sigma_t"] == [1.0e7, 1.2e8]
    times = _header_times(text)
    assert set(times) == {"CaMa_SHPB_004", "CaMa_SHPB_006", "CaMa_SHPB_014"}
    window = exp["observations"]["t_end"] * 1e6
    latest = max(f for _, _, f in times.values())
    assert all(on < pk < f for on, pk, f in times.values())
    assert latest < window <= 1.1 * latest + 10.0 + 1e-6 and window % 10 < 1e-6
    n = window / (exp["observations"]["dt"] * 1e6)
    assert 100 <= n <= 200 and abs(n - round(n)) < 1e-9
    # --heldout: marble_loop's split; the held-out record is in diagnosis, not among the records
    held = exp["diagnosis"]["heldout_records"]
    assert [Path(p).stem for p in held] == ["CaMa_SHPB_006"] and exp["diagnosis"]["validation"] == "holdout"
    assert [Path(p).stem for p in exp["observations"]["records"]] == ["CaMa_SHPB_004", "CaMa_SHPB_014"]
    assert exp["method"] == "esmda" and exp["observations"]["model_error"] == {
        "simulator_replicates": 3, "approximation_error": {"preset": "standard", "pairs": 24}}


def test_the_approximation_error_is_written_by_default_with_its_reason(tmp_path):
    """init-config writes the coarse mesh's own error block the coverage benchmark found needed on finer data
    (benchmarks/coverage_plan_approximation.json) unless told not to, with its reason, and the config
    validates; --no-approximation-error writes no such block."""
    text, doc = init_config([DISC])
    exp = _exp(doc)
    assert exp["observations"]["model_error"] == {"approximation_error": {"preset": "standard", "pairs": 24}}
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.strip().startswith("model_error:"))
    j = i
    while lines[j - 1].strip().startswith("#"):  # a long reason is wrapped above its key
        j -= 1
    reason = " ".join(ln.strip().lstrip("# ") for ln in lines[j:i + 1])
    assert "--no-approximation-error" in reason and "section 8" in reason
    (tmp_path / "disc.yaml").write_text(text)
    validate_config(yaml.safe_load((tmp_path / "disc.yaml").read_text()), REPO / "config" / "schema.yaml",
                    base_dir=REPO)
    off = init_config([DISC], approximation_error=False)[1]
    assert "approximation_error" not in _exp(off)["observations"].get("model_error", {})
    # the command line: on by default, off with --no-approximation-error
    out = tmp_path / "cli.yaml"
    assert main(["init-config", str(DISC), "--out", str(out)]) == 0
    assert _exp(yaml.safe_load(out.read_text()))["observations"]["model_error"]["approximation_error"]["pairs"] == 24
    assert main(["init-config", str(DISC), "--out", str(out), "--no-approximation-error"]) == 0
    assert "approximation_error" not in (_exp(yaml.safe_load(out.read_text()))["observations"].get("model_error") or {})


def test_every_choice_carries_its_reason(written):
    for text in (written[1][0], written[2][0]):
        lines = text.splitlines()
        start = lines.index("experiments:")
        bare = []
        for i, ln in enumerate(lines[start + 2:], start + 2):
            s = ln.strip()
            if (not s or s.startswith(("#", "- ")) or s.endswith(":") or s == "description: >-"
                    or lines[i - 1].strip() == "description: >-"):
                continue
            if "#" not in ln and not lines[i - 1].strip().startswith("#"):
                bare.append(ln)
        assert not bare, bare


def test_the_written_configs_pass_the_validation_and_a_dry_run(written):
    tmp, _, _ = written
    for f in ("disc.yaml", "marble.yaml"):
        validate_config(yaml.safe_load((tmp / f).read_text()), REPO / "config" / "schema.yaml", base_dir=tmp)
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--snakefile", str(REPO / "Snakefile"),
                          "--directory", str(tmp), "--workflow-profile", "none", "--cores", "2",
                          "--configfile", str(tmp / "disc.yaml"), str(tmp / "marble.yaml"),
                          "--config", f"run=[{DISC_NAME}, {MARBLE_NAME}]"],
                         capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-3000:]
    jobs = dict(ln.split()[:2] for ln in out.stdout.splitlines() if ln.split()[:1] and ln.split()[0].isidentifier()
                and len(ln.split()) == 2 and ln.split()[1].isdigit())
    # the first ensembles' batch jobs (at most 8 fast runs each, an even count): the disc's 25 members in 4
    # and its 6 replicates in 2, the marble's 8 members x 2 records in 2 and 6 replicates x 2 records in 2;
    # their declaring rules are no jobs (rules/inputs.smk, stage_batch_files); the marble's approximation pairs
    # (its two calibration records and its held-out one, 24 standard and 48 fast runs each: 216 runs in
    # 2 ceil(216 / 16) = 28 batches of at most 8); the marble's diagnosis check
    assert int(jobs["simulate"]) == (4 + 2) + (2 + 2) + 28 and "member" not in jobs
    assert int(jobs["aggregate"]) == 2
    assert int(jobs["diagnosis_check"]) == 1 and int(jobs["lhs"]) == 2
    assert not (tmp / "results").exists()


# --------------------------------------------------------------------------------------------------
# the rules, on made-up curves
# --------------------------------------------------------------------------------------------------
def _triangle(peak_us: float, fall_us: float, end_us: float, name: str = "r"):
    t = np.arange(0.0, end_us + 0.5, 0.5) * 1e-6
    s = np.interp(t, [0.0, 50e-6, peak_us * 1e-6, fall_us * 1e-6, 1.0], [0.0, 0.0, 100e6, 0.0, 0.0])
    return record_times(name, Path(f"{name}.yaml"), t, s)


def test_the_window_is_the_latest_fall_plus_the_margin_rounded_up():
    a, b = _triangle(200, 300, 500, "a"), _triangle(150, 250, 500, "b")
    assert (a.onset, a.peak, a.fall) == pytest.approx((57.5e-6, 200e-6, 250e-6), abs=0.51e-6)   # 0.5 us samples
    t_end, why = choose_window([a, b])                 # 250 + 25 = 275 -> 280 us
    assert t_end == pytest.approx(280e-6) and "a: down to 50% of its peak at 250 us" in why
    t_end, why = choose_window([_triangle(100, 140, 500)])   # 120 + 12 = 132 -> 140 us
    assert t_end == pytest.approx(140e-6)
    t_end, why = choose_window([_triangle(50.5, 60, 500)])   # a short fall: the 10 us minimum margin
    assert t_end == pytest.approx(70e-6)


def test_the_window_stops_where_the_shortest_record_does():
    a, short = _triangle(200, 300, 500, "a"), _triangle(150, 250, 262, "short")
    t_end, why = choose_window([a, short])
    assert t_end == pytest.approx(260e-6) and "cut to 260 us, where short's reduced record ends" in why
    never = _triangle(200, 2000, 400, "never")         # still above half its peak at the record's end
    assert never.fall is None
    t_end, why = choose_window([never])
    assert t_end == pytest.approx(400e-6) and "['never'] do not fall that far" in why
    with pytest.raises(InitConfigError, match="ends at 120 us, before the peak of another record"):
        choose_window([a, _triangle(100, 110, 120, "cut")])


@pytest.mark.parametrize("window_us, dt_us", [(170, 1.0), (280, 2.0), (390, 2.5), (3000, 20.0), (60, 0.5)])
def test_dt_is_a_round_step_with_100_to_200_observations(window_us, dt_us):
    dt = choose_dt(window_us * 1e-6)
    assert dt == pytest.approx(dt_us * 1e-6) and 100 <= window_us / dt_us <= 200


def test_a_rock_without_a_class_gets_the_stated_wide_box():
    boxes, why = rock_box("Savonnieres_Limestone", "cylinder")
    assert boxes == {"sigma_t": [4.0e6, 1.2e8], "E_t": [100.0, 5.0e4]} and "no rock class known" in why["sigma_t"]
    boxes, _ = rock_box(None, "brazilian_disc")
    assert boxes["E_t"] == [200.0, 2400.0]


def test_a_rock_without_a_class_gets_sigma_t_from_its_calibration_peaks():
    """The new-user trial's limestone (peaks 27-29 MPa) ended box_limited at sigma_t 5.0 MPa [4.5, 6.0]
    against the union box's 4 MPa end; from its peak the box is 1.4-29 MPa, that interval well inside.
    The classes keep their shipped boxes whatever the peaks."""
    boxes, why = rock_box("Savonnieres_Limestone", "cylinder", 28.6e6)
    assert boxes["sigma_t"] == [1.4e6, 2.9e7] and "highest calibration peak (28.6 MPa)" in why["sigma_t"]
    lo, hi = boxes["sigma_t"]
    assert lo < 0.5 * 4.5e6 and 6.0e6 < 0.25 * hi
    # the granite disc's own ratio (sigma_t 45 MPa, splitting peak 33 MPa) lies inside a no-class disc box
    lo, hi = rock_box(None, "brazilian_disc", 33.4e6)[0]["sigma_t"]
    assert lo < 45e6 < hi
    assert rock_box("Carrara_marble", "cylinder", 28.6e6)[0]["sigma_t"] == [1.0e7, 1.2e8]


# --------------------------------------------------------------------------------------------------
# refused sets
# --------------------------------------------------------------------------------------------------
def test_the_command_refuses_mixed_rocks_and_geometries(tmp_path, capsys):
    code = main(["init-config", str(DISC), str(REPO / "data/examples/sheets/CaMa_SHPB_004.yaml"),
                 "--out", str(tmp_path / "x.yaml")])
    err = capsys.readouterr().err
    assert code == 2 and not (tmp_path / "x.yaml").exists()
    assert "python -m shpb init-config: error: the sheets mix specimen.geometry values" in err
    assert "granite_disc.yaml" in err and "CaMa_SHPB_004.yaml" in err
    assert "run init-config once per rock and geometry" in err


@pytest.mark.parametrize("kwargs, message", [
    ({"diagnosis": True}, "--diagnosis: expected at least 3 sheets"),
    ({"heldout": "granite_disc"}, "--heldout: only with --diagnosis"),
    ({"name": "2disc"}, "--name: expected letters"),
])
def test_a_set_that_cannot_make_the_experiment_is_refused(kwargs, message):
    with pytest.raises(InitConfigError, match=message):
        init_config([DISC], **kwargs)


def test_an_unknown_heldout_name_is_refused(written):
    tmp = written[0]
    sheets = [REPO / "data/examples/sheets/CaMa_SHPB_004.yaml", tmp / "CaMa_SHPB_014.yaml", tmp / "CaMa_SHPB_006.yaml"]
    with pytest.raises(InitConfigError, match=r"--heldout: expected the file stem of one of the sheets .*'CaMa_SHPB_4'"):
        init_config(sheets, diagnosis=True, heldout="CaMa_SHPB_4")
    text, doc = init_config(sheets, diagnosis=True)     # default: the last by test order
    assert [Path(p).stem for p in _exp(doc)["diagnosis"]["heldout_records"]] == ["CaMa_SHPB_014"]


def test_a_heldout_records_response_never_sets_the_window():
    # the held-out record falls last; the window is the calibration records' (their latest fall 250 us)
    a, b, held = _triangle(200, 250, 600, "a"), _triangle(150, 240, 600, "b"), _triangle(400, 500, 600, "h")
    window, why = choose_window([a, b, held], heldout="h")
    assert window == pytest.approx(choose_window([a, b])[0]) and window < 400e-6
    assert "h, held out, is not read" in why
    # its reduced length (its bars, not its response) still caps the window
    short = _triangle(150, 240, 200, "h")
    assert choose_window([a, b, short], heldout="h")[0] <= 200e-6 + 1e-12


def test_invalid_calibration_records_are_refused_unless_allowed(tmp_path):
    """Savonnieres limestone SaLi_SHPB_004 and _007 grade invalid (force balance mean R 0.105 and 0.145 > 0.10):
    init-config says so instead of writing a config the dry run refuses; --allow-invalid writes it with
    observations.allow_invalid and names them; an invalid held-out record is not refused."""
    sali = REPO / "data/freiburg-rae-rock-shpb/Rae2021/SHPBdata/SaLi"
    sheets = []
    for raw in ("SaLi_SHPB_004_Ti25_25b_Al16b_0_001.txt", "SaLi_SHPB_007_Ti25_35b_Al16b_0_001.txt",
                "SaLi_SHPB_009_Ti25_45b_Al12b_0_001.txt"):
        sheets.append(tmp_path / f"{raw[:13]}.yaml")
        write_sheet(freiburg_sheet(sali / raw, tmp_path), sheets[-1])
    with pytest.raises(InitConfigError, match=r"invalid as calibration records.*SaLi_SHPB_004.*force_balance invalid"):
        init_config(sheets)
    text, doc = init_config(sheets, allow_invalid=True)
    exp = _exp(doc)
    assert exp["observations"]["allow_invalid"] is True
    (why,) = [ln for ln in text.splitlines() if "graded invalid" in ln]
    assert "SaLi_SHPB_004, SaLi_SHPB_007 graded invalid" in why and "SaLi_SHPB_009" not in why
    assert "SaLi_SHPB_009: " in text and ", questionable" in text and ", invalid" in text
    # held out, the invalid records are not refused: only calibration records are gated
    with pytest.raises(InitConfigError, match=r"SaLi_SHPB_007") as refused:
        init_config(sheets, diagnosis=True, heldout="SaLi_SHPB_004")
    assert "SaLi_SHPB_004.yaml" not in str(refused.value)
