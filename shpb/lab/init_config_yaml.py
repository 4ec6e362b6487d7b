"""The YAML text of ``python -m shpb init-config`` (:mod:`shpb.lab.init_config`): one experiment, each
choice on its own line with a comment giving its reason (PyYAML drops comments, so the text is written
here line by line; :func:`experiment_yaml` also returns the same experiment as a dict)."""
from __future__ import annotations

import os
import textwrap
from pathlib import Path

import yaml

COMMENT_COLUMN = 40
LINE_WIDTH = 120


#: the coarse mesh's own error init-config writes (docs/own-data.md, section 8): the block the coverage
#: benchmarks validated (benchmarks/coverage_plan_approximation.json)
APPROXIMATION_ERROR = {"preset": "standard", "pairs": 24}


def number(v: float | int) -> str:
    """A YAML number that YAML 1.1 loaders (PyYAML, Snakemake) read as a number: ``1.0e+7`` not ``1e+07``."""
    if isinstance(v, int) or float(v) == 0.0:
        return repr(v)
    if 1e-3 <= abs(v) < 1e5:
        return repr(float(v))
    mant, exp = f"{v:.6e}".split("e")
    mant = mant.rstrip("0")
    return f"{mant}0e{int(exp):+d}" if mant.endswith(".") else f"{mant}e{int(exp):+d}"


def flow(value) -> str:
    """``value`` in YAML flow style with :func:`number` for numbers."""
    if isinstance(value, bool) or value is None:
        return yaml.safe_dump(value).split("\n")[0]
    if isinstance(value, (int, float)):
        return number(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(flow(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {flow(v)}" for k, v in value.items()) + "}"
    return yaml.safe_dump(str(value), default_style=None, width=1000).split("\n")[0]


def line(indent: int, key: str, value=None, why: str = "") -> str:
    """``key: value  # why``; a reason too long for one line goes above the key, wrapped."""
    text = " " * indent + (f"{key}: {flow(value)}" if value is not None else f"{key}:")
    if not why:
        return text
    if len(text.ljust(COMMENT_COLUMN)) + 4 + len(why) <= LINE_WIDTH:
        return f"{text.ljust(COMMENT_COLUMN)}  # {why}"
    wrapped = textwrap.wrap(why, LINE_WIDTH - indent - 2, break_on_hyphens=False)
    return "\n".join([*(" " * indent + "# " + w for w in wrapped), text])


def record_path(path: Path) -> str:
    """The sheet's path as the workflow (run from the current folder) will find it."""
    absolute = os.path.abspath(path)       # not resolve(): a path through a link stays as the user gave it
    rel = os.path.relpath(absolute, os.getcwd())
    return absolute if rel.startswith("..") else rel


def _method_lines(heldout: str | None) -> list[str]:
    if heldout is None:
        return [line(4, "ensemble_size", 25, "as config/own_data.yaml: enough for two parameters (N >= 10 per "
                     "parameter) at ~5 s a `fast` run"),
                line(4, "method", "emulated_esmda", "as config/own_data.yaml and twin_ref: each analysis an ES-MDA "
                     "on an emulator of every run so far (docs/inference.md)"),
                line(4, "max_iterations", 3, "as config/own_data.yaml: three analyses, then the stop rule decides")]
    return [line(4, "ensemble_size", 8, "as config/diagnosis.yaml: the closing-the-loop design adds runs of its own"),
            line(4, "method", "esmda", "as config/diagnosis.yaml"),
            line(4, "esmda", {"steps": 2}, "two analyses, three ensembles (config/diagnosis.yaml)"),
            line(4, "max_rank", 3, "n_params + 1 directions per analysis (docs/inference.md)")]


def _diagnosis_lines(heldout_path: str, seed: int) -> list[str]:
    return [line(4, "diagnosis", why="closing the loop (docs/closing-the-loop.md), settings of config/diagnosis.yaml"),
            line(6, "validation", "holdout", "the held-out record is predicted once, at the end"),
            line(6, "heldout_records", [heldout_path], "not used to calibrate, select or estimate anything"),
            line(6, "exclude", ["damping", "seating"], "as config/diagnosis.yaml: damping did nothing for the "
                 "post-peak; a linear seating layer cannot carry a record's closure (face_gap and closure do)"),
            line(6, "base_min_rel_width", 0.45, "as config/diagnosis.yaml"),
            line(6, "selection_model", "anchored", "the selection re-calibrates on real FDEM runs moved one "
                 "parameter at a time from the posterior mean (docs/closing-the-loop.md); the real runs of the check "
                 "confirm"),
            line(6, "physical_upper", {"rate_strength.k": 0.6, "interface_friction.mu": 0.5},
                 "as config/diagnosis.yaml"),
            line(6, "members", 60, "as config/diagnosis.yaml"),
            line(6, "seed", seed, "the experiment's")]


def experiment_yaml(*, name, geometry, lithology, times, window, why_window, dt, boxes, why_box, heldout,
                    seed, invalid=(), approximation: bool = False) -> tuple[str, dict]:
    """``(text, parsed experiment)``; ``times`` in test order, ``heldout`` a record name or None;
    ``approximation``: the coarse mesh's own error learned from runs paired at ``standard``."""
    calib = [t for t in times if t.name != heldout]
    held = [t for t in times if t.name == heldout]
    sample_dt = min(5.0e-7, dt)
    head = [f"# Written by python -m shpb init-config from {len(times)} test sheet(s) of "
            f"{lithology or 'an unnamed rock'} ({geometry}); edit any line, its comment says why it is what it is.",
            "# Check it (no job runs):  snakemake -n --cores 2 --configfile THIS_FILE",
            "# Run it:                  snakemake --cores 2 --configfile THIS_FILE",
            "# Each record (onset / peak / fall at half the peak, face time):"]
    head += [f"#   {t.name}: {t.onset * 1e6:.0f} / {t.peak * 1e6:.0f} us ({t.peak_stress / 1e6:.1f} MPa) / "
             + (f"{t.fall * 1e6:.0f} us" if t.fall is not None else "no fall in its reduced window")
             + f", {t.validity}" + (" (held out)" if t.name == heldout else "") for t in times]
    what = "closing the loop with one record held out" if heldout else "a calibration"
    body = [line(0, "run", [name], "only this experiment, not config/config.yaml's default run"), "",
            "experiments:", f"  {name}:",
            "    description: >-",
            f"      {geometry} model of {lithology or 'the rock'} from {len(calib)} record(s), {what}"
            f" (python -m shpb init-config).",
            line(4, "kind", "measured", "lab records, not a twin"),
            line(4, "geometry", geometry, "every sheet's specimen.geometry"),
            line(4, "preset", "fast", "the shipped calibrations' mesh; the E_t box below is for it"),
            line(4, "seed", seed, "fixes the design and the perturbations: a rerun gives the same result"),
            *_method_lines(heldout),
            "    parameters:",
            line(6, "sigma_t", boxes["sigma_t"], why_box["sigma_t"]),
            line(6, "E_t", boxes["E_t"], why_box["E_t"]),
            "    simulation:",
            line(6, "t_end", window, "the observation window: simulating longer costs time and shows nothing"),
            line(6, "sample_dt", sample_dt, "the simulator's output step, a divisor of observations.dt"),
            "    observations:",
            line(6, "t_start", 0.0, "the incident wave's arrival at the specimen's front face (the reduction's 0)"),
            line(6, "t_end", window, why_window),
            line(6, "dt", dt, f"{round(window / dt)} observations: the rise, peak and fall resolved, the misfit's "
                 f"covariance still small"),
            line(6, "records", why="the sheets, in test order"),
            *[f"        - {flow(record_path(t.path))}" for t in calib],
            line(6, "error", {"kind": "ar1", "sigma_scale": 1.0}, "each record's pre-trigger noise level and its "
                 "AR(1) correlation in time")]
    if invalid:
        body.append(line(6, "allow_invalid", True, f"--allow-invalid: {', '.join(invalid)} graded invalid by "
                         f"python -m shpb reduce, calibrated on anyway"))
    model_error, why = {}, []
    if heldout:
        model_error["simulator_replicates"] = 3
        why.append("the mesh's own scatter, as config/diagnosis.yaml")
    if approximation:
        model_error["approximation_error"] = dict(APPROXIMATION_ERROR)
        why.append(f"the coarse mesh's own error from {APPROXIMATION_ERROR['pairs']} runs paired at "
                   f"{APPROXIMATION_ERROR['preset']} per record (held-out records alike), which the coverage benchmark "
                   "found needed on data finer than the model (docs/own-data.md, section 8; "
                   "--no-approximation-error leaves it out)")
    if model_error:
        body.append(line(6, "model_error", model_error, "; ".join(why)))
    if heldout:
        body += _diagnosis_lines(record_path(held[0].path), seed)
    text = "\n".join(head + [""] + body) + "\n"
    return text, yaml.safe_load(text)
