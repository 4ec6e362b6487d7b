"""Figure of the closure laws on one measured record (issue 32 item 5, ``docs/img/closure_laws.png``).

One fast cylinder member on CaMa_SHPB_004 (its measured incident wave, injected at the lab's gauge):
the base model (faces in contact from the start), the hard gap (``face_gap``, the record's own face
travel before load), the linear seating (``seating``, the top of its box) and the gradual closure
(``closure``: the mean gap spread over Delta across the face, first touch at g - Delta/2,
full contact at g + Delta/2), against the record; with a zoom on the
closure and the stress rise per sample. The parameters are set by hand, not
fitted (they are in the legend). ``python -m tools.closure_curves [--out PNG]`` (about 15 s on one core).
"""
from __future__ import annotations

import argparse

import numpy as np

RECORD = "freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
BASE = {"sigma_t": 34.9e6, "E_t": 27.5e3}  # the default run's calibration of the marble (docs/closing-the-loop.md)


def cases(closure_before_load: float) -> dict[str, dict]:
    return {"base model (no gap)": {},
            f"hard gap {closure_before_load * 1e6:.0f} um": {"face_gap.gap_m": closure_before_load},
            "linear seating 2e-12 m/Pa": {"seating.compliance_m_per_Pa": 2e-12},
            "gradual closure: mean gap 250 um, spread 200 um": {"face_gap.gap_m": 250e-6, "closure.range_m": 200e-6}}


def main(argv=None) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from calibration.observations import reduce_measured_record
    from shpb.paths import data_dir, data_file
    from shpb.simulate import simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/img/closure_laws.png")
    ap.add_argument("--t-end", type=float, default=300e-6)
    args = ap.parse_args(argv)
    record = data_file(data_dir() / RECORD)
    red = reduce_measured_record(record)[0]
    closure = float(red.closure_before_load(0.02))
    fig = Figure(figsize=(11, 8.5))
    FigureCanvasAgg(fig)
    ax, zoom, inc = fig.subplots(3, 1, gridspec_kw={"height_ratios": [3, 2, 1.4]})
    sel = red.time <= args.t_end
    for a in (ax, zoom):
        a.plot(red.time[sel] * 1e6, red.stress[sel] / 1e6, color="k", lw=2.2, label="CaMa_SHPB_004 (record)")
    colours = ["0.6", "tab:red", "tab:green", "tab:blue"]
    for (label, params), colour in zip(cases(closure).items(), colours):
        out = simulate("cylinder", "fast", params={**BASE, **params}, record=record, t_end=args.t_end,
                       sample_dt=0.5e-6)
        t, s = out.columns["time_s"], out.columns["stress_Pa"]
        keep = t >= 0.0
        t, s = t[keep], s[keep]
        ds = np.diff(s)
        win = (t[1:] > 60e-6) & (t[1:] < 200e-6)
        print(f"{label}: peak {s.max() / 1e6:.1f} MPa, largest rise per 0.5 us sample before 200 us "
              f"{ds[win].max() / 1e6:.2f} MPa at {t[1:][win][np.argmax(ds[win])] * 1e6:.1f} us")
        for a in (ax, zoom):
            a.plot(t * 1e6, s / 1e6, color=colour, lw=1.2, label=label)
        inc.plot(t[1:] * 1e6, ds / 1e6, color=colour, lw=0.9)
    ax.set_title("fast cylinder member on CaMa_SHPB_004: closure laws (parameters set by hand, base: "
                 f"sigma_t {BASE['sigma_t'] / 1e6:.1f} MPa, E_t {BASE['E_t'] / 1e3:.1f} kJ/m^2)", fontsize=9)
    ax.set_ylabel("specimen stress [MPa]")
    ax.legend(fontsize=8, loc="upper left")
    zoom.set_xlim(80, 220)
    zoom.set_ylim(-5, 110)
    zoom.set_ylabel("zoom [MPa]")
    inc.set_xlim(80, 220)
    inc.set_ylabel("rise per sample [MPa]")
    inc.set_xlabel("time after the incident wave reaches the specimen [us]")
    for a in (ax, zoom, inc):
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}; the record's face travel before 2 % of its peak: {closure * 1e6:.0f} um")


if __name__ == "__main__":
    main()
