"""Input description of one deformable body: a triangle mesh with its material and thickness.

A body is what a geometry builder (e.g. ``shpb.geometry``) hands to the engine. The engine
(``fdem.model.build_model``) splits fracturable bodies so that every triangle owns its nodes and
inserts a cohesive joint on every interior edge.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic solid.

    E: Young's modulus [Pa]; nu: Poisson's ratio [-]; rho: density [kg/m^3].
    """

    E: float
    nu: float
    rho: float

    def __post_init__(self):
        if not (self.E > 0 and self.rho > 0 and -1.0 < self.nu < 0.5):
            raise ValueError(f"invalid material E={self.E}, nu={self.nu}, rho={self.rho}: "
                             "expected E > 0, rho > 0, -1 < nu < 0.5")

    @property
    def c_plane_stress(self) -> float:
        """P-wave speed of a plane-stress sheet, sqrt(E / (rho (1 - nu^2))) [m/s]."""
        return float(np.sqrt(self.E / (self.rho * (1.0 - self.nu**2))))

    @property
    def c_bar(self) -> float:
        """1D bar wave speed sqrt(E / rho) [m/s]."""
        return float(np.sqrt(self.E / self.rho))


@dataclass
class Body:
    """A meshed 2D body.

    nodes: (n, 2) coordinates [m]; triangles: (m, 3) node indices, counter-clockwise;
    thickness: plane-stress thickness [m]; fracturable: insert cohesive joints between its triangles.
    node_sets / element_sets: named index arrays into this body's nodes / triangles (e.g. the loaded
    end of a bar, the triangles of a strain gauge); the engine maps them to global indices.
    """

    name: str
    nodes: np.ndarray
    triangles: np.ndarray
    material: Material
    thickness: float
    fracturable: bool = False
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    element_sets: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        self.nodes = np.ascontiguousarray(self.nodes, dtype=np.float64)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int64)
        if self.nodes.ndim != 2 or self.nodes.shape[1] != 2:
            raise ValueError(f"body {self.name!r}: nodes must have shape (n, 2), got {self.nodes.shape}")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3:
            raise ValueError(f"body {self.name!r}: triangles must have shape (m, 3), got {self.triangles.shape}")
        if self.thickness <= 0:
            raise ValueError(f"body {self.name!r}: thickness must be > 0 m, got {self.thickness}")
        p = self.nodes[self.triangles]
        cross = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                 - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
        flip = cross < 0
        if np.any(flip):  # orient every triangle counter-clockwise
            self.triangles[flip] = self.triangles[flip][:, [0, 2, 1]]
        if np.any(np.abs(cross) <= 1e-30):
            raise ValueError(f"body {self.name!r}: degenerate (zero-area) triangle")
