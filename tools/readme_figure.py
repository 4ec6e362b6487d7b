"""A default run's figure (``docs/img/default_run_twin_ref.png``): its paper-style ensemble plot above
its forecast's curve and fracture.

Run after ``snakemake --cores 2``:

    python tools/readme_figure.py results/twin_ref docs/img/default_run_twin_ref.png

Stacks ``plots/ensemble_curves.png`` (the stress curves of every iteration against the observations,
the paper's Figs. 6-7) and ``forecast/<record>/snapshots/fracture.png`` (the run at the posterior mean:
its curve and the joint damage at the failure peak and at the end) into one PNG, without resampling
either beyond the figure's scale.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.image import imread


def compose(result_dir: Path, out: Path) -> Path:
    result_dir = Path(result_dir)
    ensemble = result_dir / "plots" / "ensemble_curves.png"
    fractures = sorted((result_dir / "forecast").glob("*/snapshots/fracture.png"))
    missing = [str(p) for p in (ensemble,) if not p.is_file()] + ([] if fractures else
                                                                 [str(result_dir / "forecast/*/snapshots/fracture.png")])
    if missing:
        raise SystemExit(f"readme_figure: {', '.join(missing)} not found: run the workflow first")
    images = [imread(ensemble), imread(fractures[0])]
    width = max(im.shape[1] for im in images)
    heights = [im.shape[0] * width / im.shape[1] for im in images]
    dpi = 110
    fig = Figure(figsize=(width / dpi, sum(heights) / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    bottom = 1.0
    for im, h in zip(images, heights):
        frac = h / sum(heights)
        bottom -= frac
        ax = fig.add_axes((0.0, bottom, 1.0, frac))
        ax.imshow(im, interpolation="antialiased")
        ax.set_axis_off()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=dpi, metadata={"Software": None})
    tmp.replace(out)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("result_dir", type=Path, help="results/<experiment> of a finished run")
    ap.add_argument("out", type=Path, help="the PNG to write")
    a = ap.parse_args()
    print(compose(a.result_dir, a.out))


if __name__ == "__main__":
    main()
