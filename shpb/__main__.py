"""Command line: `python -m shpb simulate ...` runs one SHPB simulation into a folder
(`python -m shpb --version`: the package version); `python -m shpb reduce SHEET.yaml` reduces a test
sheet's record (curves.csv, force_balance.png, checks.json; docs/own-data.md); `python -m shpb
sheet-from-freiburg RAW --out SHEET.yaml` writes the sheet of a Freiburg record; `python -m shpb init-config
SHEET... --out my.yaml` writes a calibration experiment from a lab's sheets (shpb.lab.init_config).

simulate writes DIR/curve.csv and DIR/run.json (docs/workflow.md, "What goes where"). Exit codes: 0 ok, 3 the
simulation failed numerically (run.json says why), 2 bad arguments or input files (a bad sheet).
"""
from __future__ import annotations

import argparse
import sys

from . import contract


def _parse_params(items):
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--param expects NAME=VALUE, got {item!r}")
        name, value = item.split("=", 1)
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--param {name.strip()}: value {value!r} is not a number") from None
    return out


def _parse_snapshots(text):
    if text is None:
        return None
    text = text.strip()
    try:
        if "," not in text and "." not in text and "e" not in text.lower():
            return int(text)
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise ValueError(f"--snapshots expects a count N or comma-separated times in s, got {text!r}") from None


def _peak(stress) -> float:
    """The curve's largest stress; NaN when no value is a number (a failed run's empty curve)."""
    values = [v for v in stress.tolist() if v == v]
    return max(values) if values else float("nan")


def package_version() -> str:
    """The installed distribution's version (importlib.metadata), else pyproject.toml's beside the
    package (a source tree on the path without an install), else ``"unknown"``."""
    from importlib import metadata

    try:
        return metadata.version("fdem-enkf-shpb")
    except metadata.PackageNotFoundError:
        pass
    try:
        import tomllib
        from pathlib import Path

        with open(Path(__file__).resolve().parents[1] / "pyproject.toml", "rb") as fh:
            return str(tomllib.load(fh)["project"]["version"])
    except (OSError, KeyError, ValueError):
        return "unknown"


class _Version(argparse.Action):
    """``--version``: the package version, looked up only when asked. Every simulation of a batch is a
    forked child that runs this entry, and the metadata lookup (importlib.metadata and the email parser
    it imports) cost each child 10-40 ms, against about 55 ms that a forked run costs beyond its solver."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs):
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help="show the package version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"fdem-enkf-shpb {package_version()}")  # on stdout, as argparse's own version action
        parser.exit()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m shpb", description=__doc__)
    ap.add_argument("--version", action=_Version)
    sub = ap.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="run one SHPB simulation")
    sim.add_argument("--geometry", required=True, choices=["brazilian_disc", "cylinder"])
    sim.add_argument("--preset", default="fast", choices=["fast", "standard", "paper"])
    sim.add_argument("--record", help="Freiburg raw record (cylinder: its incident wave drives the model)")
    sim.add_argument("--param", action="append", metavar="NAME=VALUE",
                     help="model parameter in SI units (repeatable), e.g. sigma_t=45e6")
    sim.add_argument("--t-end", type=float, help="end of the recorded window after the incident wave "
                     "reaches the specimen [s]")
    sim.add_argument("--sample-dt", type=float, default=0.5e-6, help="output interval [s]")
    sim.add_argument("--out", required=True, help="output folder")
    sim.add_argument("--snapshots", metavar="N|T1,T2,...",
                     help="write the mesh with joint damage (VTK) at N times spread over the window or at "
                     "the given times [s] after the wave reaches the specimen, plus the failure peak and "
                     "the window's end with PNG damage maps, to OUT/snapshots/")
    sim.add_argument("--mesh-seed", type=int, metavar="N",
                     help="a realization of the specimen mesh: its interior nodes move at random (seed N >= 0; "
                     "default: the unperturbed mesh)")
    red = sub.add_parser("reduce", help="reduce a test sheet's record and run the lab checks")
    red.add_argument("sheet", help="the test sheet (YAML)")
    red.add_argument("--out", help="output folder (default: reduced/<test name>)")
    fb = sub.add_parser("sheet-from-freiburg", help="write the test sheet of a Freiburg raw record")
    fb.add_argument("raw", help="Freiburg raw record Rae2021/SHPBdata/<lith>/<name>.txt")
    fb.add_argument("--out", required=True, help="the sheet to write (YAML)")
    ic = sub.add_parser("init-config", help="write a calibration experiment from test sheets of one rock")
    ic.add_argument("sheets", nargs="+", metavar="SHEET", help="test sheets (YAML) of one rock and geometry")
    ic.add_argument("--out", required=True, help="the config to write (YAML; snakemake --configfile it)")
    ic.add_argument("--name", help="the experiment's name (default: <lithology>_<geometry>)")
    ic.add_argument("--diagnosis", action="store_true",
                    help="close the loop: hold one record out (the last by test order) and predict it at the end")
    ic.add_argument("--heldout", metavar="NAME", help="with --diagnosis: the sheet (file stem) to hold out")
    ic.add_argument("--allow-invalid", action="store_true",
                    help="calibrate on records graded invalid by the lab checks (observations.allow_invalid)")
    ic.add_argument("--approximation-error", action=argparse.BooleanOptionalAction, default=True,
                    help="carry the coarse mesh's own error (24 runs paired at standard per record; on by default, "
                         "as a lab's records come from a specimen with no mesh; --no-approximation-error for "
                         "records simulated at the model's own mesh; docs/own-data.md, section 8)")
    args = ap.parse_args(argv)
    if args.command == "init-config":
        return _init_config(args)
    if args.command == "reduce":
        return _reduce(args)
    if args.command == "sheet-from-freiburg":
        return _sheet_from_freiburg(args)

    from .simulate import simulate
    try:
        params = _parse_params(args.param)
        out = simulate(args.geometry, args.preset, params=params, record=args.record,
                       out_dir=args.out, t_end=args.t_end, sample_dt=args.sample_dt,
                       snapshots=_parse_snapshots(args.snapshots), mesh_seed=args.mesh_seed)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"python -m shpb simulate: error: {exc}", file=sys.stderr)
        return contract.EXIT_BAD_INPUT
    r = out.run
    print(f"{r['status']}: {r['geometry']} {r['preset']}, {r['n_triangles']} triangles, "
          f"{r['n_joints']} joints, {r['steps']} steps, {r['wall_s']:.1f} s, "
          f"peak {_peak(out.columns['stress_Pa']) / 1e6:.1f} MPa -> {args.out}")
    if r["status"] != "ok":
        print(f"simulation failed: {r['reason']}", file=sys.stderr)
        return contract.EXIT_NUMERICAL
    return contract.EXIT_OK


def _reduce(args) -> int:
    from pathlib import Path

    from .lab.lab_reduce import lab_checks, reduce_sheet, transit_time, write_reduction
    from .lab.sheet_readers import check_sheet
    try:
        sheet, raw = check_sheet(args.sheet)
        red = reduce_sheet(sheet, raw, check_stated=True)
    except (ValueError, FileNotFoundError) as exc:
        print(f"python -m shpb reduce: error: {exc}", file=sys.stderr)
        return contract.EXIT_BAD_INPUT
    checks = lab_checks(red, transit_time(sheet))
    out = Path(args.out) if args.out else Path("reduced") / sheet.name
    write_reduction(red, checks, out, title=sheet.name)
    fb, al, nz = checks["force_balance"], checks["pulse_alignment"], checks["noise"]
    word = {True: "ok", False: "CHECK"}
    print(f"{sheet.name}: peak {red.peak_stress / 1e6:.1f} MPa at {red.peak_time * 1e6:.1f} us -> {out}\n"
          f"  force balance: mean R {fb['mean_R_half_peak_to_peak']:.3f} from half peak to peak "
          f"(limit {fb['limit']}) {word[fb['ok']]}"
          + ("" if fb["ok"] or sheet.reduction.get("dispersion_correction", False) else
             " (the specimen out of equilibrium, a bar's constants off, or the bars' dispersion: try "
             "reduction: {dispersion_correction: true} in the sheet, docs/own-data.md)")
          + "\n"
          f"  pulse alignment: best shift of F2 {al['best_shift_back_s'] * 1e6:+.2f} us "
          f"(limit +-{al['limit_s'] * 1e6:.2f} us) {word[al['ok']]}\n"
          f"  noise: {nz['noise_over_peak']:.2%} of the peak (limit {nz['limit']:.0%}) {word[nz['ok']]}\n"
          f"  validity: {checks['validity']['class']}"
          + "".join(f"\n    {r}" for r in checks["validity"]["reasons"]))
    if sheet.reduction.get("dispersion_correction", False):
        print(f"  dispersion: bar signals corrected to the faces (Pochhammer-Chree, first mode, nu {sheet.bar_nu:g})")
    return contract.EXIT_OK


def _sheet_from_freiburg(args) -> int:
    from pathlib import Path

    from .lab.sheet_freiburg import freiburg_sheet, write_sheet
    try:
        doc = freiburg_sheet(args.raw, Path(args.out).parent)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"python -m shpb sheet-from-freiburg: error: {exc}", file=sys.stderr)
        return contract.EXIT_BAD_INPUT
    write_sheet(doc, args.out, header=f"Test sheet of the Freiburg record {Path(args.raw).name}, generated from "
                                      f"its spreadsheets (python -m shpb sheet-from-freiburg)")
    print(f"{doc['name']} -> {args.out}")
    return contract.EXIT_OK


def _init_config(args) -> int:
    from pathlib import Path

    from .atomic import atomic_write_text
    from .lab.init_config import InitConfigError, init_config
    try:
        text, doc = init_config(args.sheets, name=args.name, diagnosis=args.diagnosis, heldout=args.heldout,
                                allow_invalid=args.allow_invalid, approximation_error=args.approximation_error)
    except (ValueError, FileNotFoundError, InitConfigError) as exc:
        print(f"python -m shpb init-config: error: {exc}", file=sys.stderr)
        return contract.EXIT_BAD_INPUT
    atomic_write_text(Path(args.out), text.replace("THIS_FILE", args.out))
    (name, exp), = doc["experiments"].items()
    obs = exp["observations"]
    (s_lo, s_hi), (e_lo, e_hi) = exp["parameters"]["sigma_t"], exp["parameters"]["E_t"]
    held = (exp.get("diagnosis") or {}).get("heldout_records") or []
    print(f"{name}: {exp['geometry']}, {len(obs['records'])} record(s)"
          + (f" + {Path(held[0]).stem} held out" if held else "")
          + f", window 0-{obs['t_end'] * 1e6:.0f} us every {obs['dt'] * 1e6:g} us, sigma_t {s_lo / 1e6:g}-{s_hi / 1e6:g} "
          f"MPa, E_t {e_lo:g}-{e_hi:g} J/m^2 -> {args.out}")
    return contract.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
