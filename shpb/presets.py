"""Mesh-resolution presets of the SHPB geometries (docs/shpb-models.md).

A preset fixes element sizes, not triangle counts: the specimen's target mean edge length, the bars'
edge length far from the specimen and near it. The counts then follow from the specimen's size. For the
paper's Brazilian disc (50 mm granite disc between 50 mm steel bars, ``shpb.geometry.brazilian_disc``
with its defaults) the presets give

============ =============== ============================ ====================
preset       specimen size h disc triangles (band)        bar triangles (sum)
============ =============== ============================ ====================
``fast``     1.7 mm          1,528 (1,000-2,000)          1,904
``standard`` 0.95 mm         4,968 (4,000-6,000)          3,610
``paper``    0.5 mm          17,820 (paper: 17,500)       5,016 (paper: ~5,000)
============ =============== ============================ ====================

(``tests/test_geometry.py`` asserts the bands.) The paper (Godinez & Rougier 2021,
section 3) meshes the disc with 17,500 triangles "with an average size of 0.5 mm" and the bars with
about 5,000 triangles.

Size-to-area rule: the mesher (Shewchuk's Triangle, minimum angle 30 degrees) gets a maximum triangle
area of ``AREA_FACTOR`` times the area of the equilateral triangle of edge ``h``. Quality refinement
leaves most triangles well below the cap; with ``AREA_FACTOR = 1.6`` the mean edge length comes out
within about 5% of ``h`` (measured: 1.04 h on the disc), which is what "element size h" means here.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: Maximum triangle area handed to Triangle, in units of the equilateral area sqrt(3)/4 h^2.
AREA_FACTOR = 1.6

#: Minimum angle [degrees] requested from Triangle's quality refinement (switch ``q``).
MIN_ANGLE_DEG = 30.0


@dataclass(frozen=True)
class Preset:
    """Element sizes of one mesh resolution [m].

    specimen_h_m: target mean edge length in the specimen (disc or cylinder), uniform.
    bar_near_h_m: edge length in each bar within ``bar_near_length_m`` of its specimen face.
    bar_h_m: edge length in the bars far from the specimen. Between the two the size grows
        linearly with the distance from the face, by ``bar_grading`` metres per metre.
    """

    name: str
    specimen_h_m: float
    bar_h_m: float
    bar_near_h_m: float
    bar_near_length_m: float
    bar_grading: float = 0.25
    description: str = ""

    def __post_init__(self):
        sizes = {"specimen_h_m": self.specimen_h_m, "bar_h_m": self.bar_h_m,
                 "bar_near_h_m": self.bar_near_h_m, "bar_near_length_m": self.bar_near_length_m,
                 "bar_grading": self.bar_grading}
        for key, value in sizes.items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"preset {self.name!r}: {key} must be a finite positive number, got {value}")
        if self.bar_near_h_m > self.bar_h_m:
            raise ValueError(f"preset {self.name!r}: bar_near_h_m ({self.bar_near_h_m}) must not exceed "
                             f"bar_h_m ({self.bar_h_m})")

    def max_area(self, h: float) -> float:
        """Triangle's maximum-area constraint [m^2] for a target edge length ``h`` [m]."""
        return AREA_FACTOR * np.sqrt(3.0) / 4.0 * h * h

    def to_dict(self) -> dict:
        return asdict(self)


PRESETS: dict[str, Preset] = {
    "fast": Preset("fast", specimen_h_m=1.7e-3, bar_h_m=18e-3, bar_near_h_m=5e-3,
                   bar_near_length_m=25e-3, description="tests and CI, ~1,000-2,000 specimen triangles"),
    "standard": Preset("standard", specimen_h_m=0.95e-3, bar_h_m=12e-3, bar_near_h_m=3.5e-3,
                       bar_near_length_m=25e-3, description="default run, ~4,000-6,000 specimen triangles"),
    "paper": Preset("paper", specimen_h_m=0.5e-3, bar_h_m=10.5e-3, bar_near_h_m=2.5e-3,
                    bar_near_length_m=25e-3,
                    description="the paper's resolution: ~17,500 disc triangles of 0.5 mm, ~5,000 bar triangles"),
}


def get_preset(preset: str | Preset) -> Preset:
    """Return the ``Preset`` named ``preset`` (or ``preset`` itself if it already is one)."""
    if isinstance(preset, Preset):
        return preset
    if isinstance(preset, str) and preset in PRESETS:
        return PRESETS[preset]
    raise ValueError(f"preset must be one of {sorted(PRESETS)} (or a shpb.presets.Preset), got {preset!r}")
