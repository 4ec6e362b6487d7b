"""The disc's validity and mesh-convergence table and the simulator-variability table of docs/shpb-models.md,
generated from the committed benchmark JSON.

    python tools/shpb_table.py            # print both blocks
    python tools/shpb_table.py --docs     # write them between their markers in docs/shpb-models.md

The first block is ``benchmarks/bench_shpb.py``'s ``benchmarks/results/bench_shpb.json``, the second
``benchmarks/bench_sim_variability.py``'s ``benchmarks/results/bench_sim_variability.json``;
tests/test_docs_tables.py checks that the doc holds what this tool makes of them.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "shpb-models.md"
SHPB = "benchmarks/results/bench_shpb.json"
VARIABILITY = "benchmarks/results/bench_sim_variability.json"
PRESET_START, PRESET_END = "<!-- shpb-presets-table:start -->", "<!-- shpb-presets-table:end -->"
VAR_START, VAR_END = "<!-- variability-table:start -->", "<!-- variability-table:end -->"
POINTS = {"reference": "reference", "weak_brittle": "weak-brittle", "strong_tough": "strong-tough"}


def _load(path: str) -> dict:
    return json.loads((ROOT / path).read_text())


def preset_rows(bench: dict) -> list[str]:
    rows = ["| preset (specimen triangles) | point (`sigma_t`, `E_t`) | first joint (x, y)/R | broken in band at peak "
            "| F_front/F_back at peak | failure peak | vs `paper` |",
            "|---|---|---|---|---|---|---|"]
    for i, (preset, points) in enumerate(bench["presets"].items()):
        for j, (key, r) in enumerate(points.items()):
            head = f"`{preset}` ({r['specimen_triangles']:,})" if j == 0 else ""
            point = POINTS.get(key, key)
            if i == 0:  # the first preset's rows name the points' values once
                point += f" ({r['sigma_t'] / 1e6:.0f} MPa, {r['E_t']:.0f})"
            x, y = r["first_joint_xy_over_R"]
            band = round(r["band_fraction_at_peak"] * r["broken_at_peak"])
            diff = r.get("peak_rel_diff_to_paper")
            vs = "-" if preset == "paper" or diff is None else f"{100 * diff:+.1f} %"
            rows.append(f"| {head} | {point} | ({x:+.2f}, {y:+.2f}) | {band}/{r['broken_at_peak']} "
                        f"({100 * r['band_fraction_at_peak']:.0f} %) | {r['force_ratio_at_peak']:.3f} | "
                        f"{r['peak_stress_Pa'] / 1e6:.1f} MPa at {r['peak_t_s'] * 1e6:.0f} us | {vs} |")
    return rows


def _energy(e: float) -> str:
    return f"{e:.0f} J/m^2" if e < 1000 else f"{e / 1000:.3g} kJ/m^2"


def _name(label: str, c: dict) -> str:
    p = c["case"]["params"]
    where = "disc" if c["case"]["geometry"] == "brazilian_disc" else Path(c["case"]["record"]).name[:13]
    return f"{label} ({where}, {p['sigma_t'] / 1e6:.4g} MPa, {_energy(p['E_t'])})"


def variability_rows(bench: dict) -> list[str]:
    cases = bench["cases"]
    mv = {k: c["mesh_variability"] for k, c in cases.items()}

    def cells(fn):
        return " | ".join(fn(k, cases[k], mv[k]) for k in cases)

    def us(t):
        return f"{t * 1e6:.0f}"

    rows = ["| | " + " | ".join(_name(k, c) for k, c in cases.items()) + " |", "|---|" + "---|" * len(cases)]
    rows.append(f"| elastic part (before the first joint's onset, {' / '.join(us(m['elastic_until_s']) for m in mv.values())}"
                " us): RMS std | " + cells(lambda k, c, m: f"{m['std_rms_elastic_Pa'] / 1e3:.2g} kPa "
                                           f"({100 * m['std_rms_elastic_over_peak']:.1g} % of the peak)") + " |")
    rows.append(f"| up to the peak ({' / '.join(us(m['mean_curve_peak_t_s']) for m in mv.values())} us): RMS std | "
                + cells(lambda k, c, m: f"{m['std_rms_pre_peak_Pa'] / 1e6:.2g} MPa "
                                        f"({100 * m['std_rms_pre_peak_over_peak']:.2g} %)") + " |")
    rows.append("| after the peak: RMS std; largest std | "
                + cells(lambda k, c, m: f"{m['std_rms_post_peak_Pa'] / 1e6:.3g} MPa "
                                        f"({100 * m['std_rms_post_peak_over_peak']:.2g} %); "
                                        f"{m['std_max_Pa'] / 1e6:.3g} MPa at {us(m['std_max_t_s'])} us") + " |")
    rows.append("| failure peak: mean, std (min-max) | "
                + cells(lambda k, c, m: f"{m['peak_stress_Pa']['mean'] / 1e6:.1f} MPa, "
                                        f"{m['peak_stress_Pa']['std'] / 1e6:.3g} MPa = "
                                        f"{100 * m['peak_stress_Pa']['std'] / m['peak_stress_Pa']['mean']:.2g} % "
                                        f"({m['peak_stress_Pa']['min'] / 1e6:.1f}-{m['peak_stress_Pa']['max'] / 1e6:.1f})")
                + " |")
    rows.append("| peak time: std (min-max) | "
                + cells(lambda k, c, m: f"{m['peak_t_s']['std'] * 1e6:.2g} us "
                                        f"({m['peak_t_s']['min'] * 1e6:.1f}-{m['peak_t_s']['max'] * 1e6:.1f})") + " |")
    rows.append("| unperturbed mesh's peak | "
                + cells(lambda k, c, m: f"{c['unperturbed']['peak_stress_Pa'] / 1e6:.1f} MPa at "
                                        f"{c['unperturbed']['peak_t_s'] * 1e6:.1f} us") + " |")
    rows.append("| correlation time of the deviations after the peak (1/e) | "
                + cells(lambda k, c, m: f"{m['post_peak_correlation_time_s'] * 1e6:.3g} us "
                                        f"({m['post_peak_correlation_time_s'] / c['case']['grid_s'][2]:.3g} grid steps)")
                + " |")
    return rows


def preset_block(path: str = SHPB) -> str:
    return "\n".join([PRESET_START, f"From `{path}` (one member per preset and point, one core, warm JIT cache):", "",
                      *preset_rows(_load(path)), PRESET_END])


def variability_block(path: str = VARIABILITY) -> str:
    bench = _load(path)
    return "\n".join([VAR_START, f"From `{path}` ({bench['replicates']} realizations per case; std over them; the "
                      "failure peak is the replicate mean's, `shpb.fracture.first_peak`):", "",
                      *variability_rows(bench), VAR_END])


def _replace(text: str, start: str, end: str, block: str) -> str:
    i, j = text.index(start), text.index(end) + len(end)
    return text[:i] + block + text[j:]


def main(argv: list[str]) -> int:
    if argv == ["--docs"]:
        text = DOC.read_text()
        text = _replace(text, PRESET_START, PRESET_END, preset_block())
        text = _replace(text, VAR_START, VAR_END, variability_block())
        DOC.write_text(text)
    else:
        print(preset_block(), variability_block(), sep="\n\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
