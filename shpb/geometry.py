"""Meshed 2D SHPB geometries: incident bar, specimen, transmission bar, along x.

Two set-ups (docs/shpb-models.md):

* ``brazilian_disc`` -- the paper's case (Godinez & Rougier 2021, Figure 1): a granite disc between two
  steel bars, loaded by a velocity history at the incident bar's free end.
* ``cylinder`` -- a uniaxial compression specimen (the Freiburg records' case) between titanium bars; the
  measured incident wave is injected at the incident gauge section through an absorbing boundary.

Conventions
-----------
* SI units. The specimen's centre is the origin; x runs from the incident bar through the specimen to the
  transmission bar; y is the diameter direction. The bodies touch along the loaded faces with zero gap:
  the incident bar's end face is the line ``x = x_front`` (the specimen's minimum x), the transmission
  bar's is ``x = x_back`` (its maximum x). A disc touches each bar at one node, its extreme node
  ``(+-R, 0)``; a cylinder touches along its whole end face. The one exception is the ``face_gap``
  effect (``face_gap_m > 0``): the incident bar's face is then at ``x_front - face_gap_m``. With the
  ``closure`` effect (``closure_range_m`` = Delta > 0) the specimen's front face is not parallel to the
  bar's: it is tilted so that the gap grows linearly across the face, from ``face_gap_m`` at its top
  edge (largest y, where contact starts) to ``face_gap_m + Delta`` at its bottom edge (``_tilt_front``;
  the catalogue's parameters, a mean gap and its spread, map onto these two by ``closure_faces``).
* Plane stress with a thickness per body chosen so that each cross-section area matches the 3D test:
  a bar of diameter ``D`` is a strip of height ``D`` and thickness ``t = pi D / 4`` (so ``D t = pi D^2/4``);
  the disc's thickness is its real thickness; a cylinder of diameter ``D`` is a rectangle of height ``D``
  and thickness ``pi D / 4``.
* Meshes come from Shewchuk's Triangle (minimum angle 30 degrees, maximum-area constraints from
  ``shpb.presets``). The specimen is uniform; each bar is refined near its specimen face and graded to a
  coarse size away from it. Boundary vertices are placed here and Triangle may not add any on the
  boundary (switch ``Y``), so the end faces are exactly straight and their node sets are exact.
  Triangle is deterministic: the same arguments give identical arrays.
* Mesh realizations (``mesh_seed``): by default the specimen is Triangle's mesh as it is. With a seed
  its interior nodes move at random (``shpb.meshing.perturb_interior_nodes``; boundary, contact faces
  and the ``centre`` probe's nodes stay), so that replicate runs that differ only in the mesh show
  how much one mesh's crack-path bias decides a result.

Bar-length rule (``window_s``)
------------------------------
``c = sqrt(E/rho)`` is the bar wave speed (a long-wavelength pulse in a plane-stress strip travels at
the 1D bar speed). The *recorded window* is ``[t_s, t_s + window_s]``, where ``t_s`` is the time the
incident front reaches the specimen. A strain gauge at distance ``d`` from the specimen sees the same
window shifted by ``d / c`` (this is how the data reduction time-shifts gauge records to the faces).

* Transmission bar (free far end): the transmitted front reaches the far end at ``t_s + L_t/c`` and its
  reflection comes back to the gauge at ``t_s + (2 L_t - d_t)/c``; the gauge's window ends at
  ``t_s + d_t/c + window_s``. Hence ``L_t >= d_t + c window_s / 2`` (and then the specimen, reached at
  ``t_s + 2 L_t / c``, is clean as well).
* Incident bar loaded at its free end (``brazilian_disc``): the wave reflected by the specimen goes back to
  the loaded end (a velocity-driven or free end reflects it) and returns to the gauge at
  ``t_s + (2 L_i - d_i)/c``; the gauge's window for the reflected wave ends at ``t_s + d_i/c + window_s``.
  Hence ``L_i >= d_i + c window_s / 2`` -- so in particular ``2 L_i / c >= window_s`` at the specimen.
* Incident bar loaded at the gauge section through an absorbing boundary (``cylinder``): the reflected
  wave leaves the model there, so the bar is exactly the gauge-to-specimen distance, ``L_i = d_i``.

Default gauge distances for the disc put each gauge at mid-length, ``d = c window_s / 2``, so ``L = c
window_s``: there the incident and reflected pulses of any incident pulse up to ``window_s`` long pass the
incident gauge one after the other (the reflected front arrives ``2 d / c = window_s`` after the incident
front). Steel bars and the 400 us default window give ``L = 2.019 m``, ``d = 1.010 m`` (compare Yan et al.
2023: 2.0 m / 1.5 m bars). Bar lengths shorter than the rule raise ``ValueError`` unless
``enforce_window=False`` (e.g. for a transmission bar that ends in an absorbing boundary).

Sets
----
Node sets (indices into the body's nodes):
  incident bar: ``load_end`` (all nodes of its x-min end face), ``specimen_face`` (all nodes of the end
  face at ``x_front``); transmission bar: ``specimen_face`` (at ``x_back``), ``free_end`` (its x-max end);
  specimen: ``front_face`` / ``back_face`` (nodes at ``x_front`` / ``x_back``: one node for a disc, the
  end-face nodes for a cylinder).
Element sets (indices into the body's triangles):
  bars: ``gauge`` -- triangles whose centroid lies within one local bar element size of the gauge
  section (``|x_c - x_gauge| <= h_bar(x_gauge)``); the engine averages the axial stress over them to mimic
  a strain gauge (a gauge also averages over its grid length, a few mm to a few cm). For the cylinder's
  incident bar the gauge section is the bar's end (the injection section), so its slab is one-sided.
  specimen: ``centre`` -- triangles whose centroid lies within ``r = D/20`` of the specimen centre
  (``min(L, D)/20`` for a cylinder), the radius grown if needed so the set holds at least 6 triangles.

Materials
---------
``GRANITE``: the paper's Table 1 (E 35 GPa, nu 0.16, rho 2550 kg/m^3). ``STEEL_BAR``: the paper does not
give its bar material; we take a generic high-strength bar steel (E 200 GPa, rho 7850 kg/m^3, nu 0.29,
typical of the maraging / 4340 steels used for SHPB bars; c = 5,048 m/s). ``TITANIUM_BAR``: the
Freiburg bars (E 110 GPa, rho 4430 kg/m^3 from the authors' processing script ``SHPB_v4.0.py``, see the
data's PROVENANCE.md; c = 4,983 m/s) with nu 0.32, a handbook value for Ti-6Al-4V (not in the source).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fdem.body import Body, Material
from shpb.presets import Preset, get_preset

from .meshing import (MESH_JITTER, _bars, _centre_set, _mesh_disc, _mesh_rectangle, _sizes,  # noqa: F401
                      _triangle_areas, bar_thickness, perturb_interior_nodes)

GRANITE = Material(E=35.0e9, nu=0.16, rho=2550.0)
STEEL_BAR = Material(E=200.0e9, nu=0.29, rho=7850.0)
TITANIUM_BAR = Material(E=110.0e9, nu=0.32, rho=4430.0)

#: Default recorded window at the specimen [s].
DEFAULT_WINDOW_S = 400e-6
#: Gauge-to-specimen distances of the Freiburg set-up [m] (incident, transmission).
FREIBURG_GAUGE_DISTANCES_M = (1.25, 1.00)
#: The specimen's ``centre`` set: radius as a fraction of the diameter (its minimum size: shpb.meshing).
CENTRE_RADIUS_FRACTION = 1.0 / 20.0
#: A specimen must be at least this many specimen element sizes across.
MIN_ELEMENTS_ACROSS = 5


def min_bar_length(gauge_distance_m: float, wave_speed_m_s: float, window_s: float) -> float:
    """Shortest bar [m] whose far-end reflection misses the gauge's window: ``d + c window / 2``.

    Applies to the transmission bar and to an incident bar loaded at its free end (module docstring).
    """
    return float(gauge_distance_m + 0.5 * wave_speed_m_s * window_s)


@dataclass
class Geometry:
    """A meshed SHPB set-up: three bodies plus the metadata the model and the data reduction need.

    kind: ``"brazilian_disc"`` or ``"cylinder"``; preset: the mesh preset's name.
    bodies: ``[incident bar, specimen, transmission bar]`` as ``fdem.body.Body``.
    incident_bar, specimen, transmission_bar: the names of the bodies playing these roles.
    specimen_face_x: ``(x_front, x_back)`` [m], the specimen's contact faces (the bar end faces).
    gauge_x: ``(incident, transmission)`` gauge x positions [m].
    gauge_distance_m: ``(d_i, d_t)`` gauge-to-specimen-face distances [m].
    specimen_dims: ``diameter_m``, ``thickness_m`` (plane-stress), and ``length_m`` for a cylinder [m].
    bar_material, bar_diameter_m, bar_thickness_m (= pi D / 4): the bars' properties.
    bar_length_m: ``(L_i, L_t)`` [m].
    window_s: recorded window [s] used for the bar-length rule (module docstring).
    loading: ``"free_end_velocity"`` (velocity at the incident ``load_end``) or ``"gauge_injection"``
        (measured incident wave injected at ``load_end``, which is the incident gauge section, with an
        absorbing boundary).
    element_size_m: the preset's sizes (``specimen``, ``bar``, ``bar_near``) [m].
    centre_radius_m: radius of the specimen's ``centre`` set [m].
    mesh_seed, mesh_jitter: the specimen mesh's realization (None: Triangle's mesh as it is; else its
        interior nodes are perturbed, ``shpb.meshing.perturb_interior_nodes``).
    """

    kind: str
    preset: str
    bodies: list[Body]
    incident_bar: str
    specimen: str
    transmission_bar: str
    specimen_face_x: tuple[float, float]
    gauge_x: tuple[float, float]
    gauge_distance_m: tuple[float, float]
    specimen_dims: dict[str, float]
    bar_material: Material
    bar_diameter_m: float
    bar_thickness_m: float
    bar_length_m: tuple[float, float]
    window_s: float
    loading: str
    element_size_m: dict[str, float] = field(default_factory=dict)
    centre_radius_m: float = 0.0
    mesh_seed: int | None = None
    mesh_jitter: float = MESH_JITTER
    closure_range_m: float = 0.0

    def body(self, name: str) -> Body:
        """The body called ``name`` (a body name or one of the roles' names)."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(f"no body named {name!r}; bodies: {[b.name for b in self.bodies]}")

    @property
    def element_counts(self) -> dict[str, int]:
        """Number of triangles per body name."""
        return {b.name: int(len(b.triangles)) for b in self.bodies}

    @property
    def node_counts(self) -> dict[str, int]:
        """Number of nodes per body name."""
        return {b.name: int(len(b.nodes)) for b in self.bodies}

    @property
    def bar_wave_speed_m_s(self) -> float:
        """1D bar wave speed sqrt(E / rho) of the bars [m/s]."""
        return self.bar_material.c_bar

    @property
    def arrival_time_s(self) -> float:
        """Time [s] for the incident front to travel from the loaded section to the specimen at ``c``.

        The recorded window is ``[arrival_time_s, arrival_time_s + window_s]`` if loading starts at t = 0.
        """
        return float(self.bar_length_m[0] / self.bar_wave_speed_m_s)

    def summary(self) -> dict:
        """JSON-ready description (plain floats, ints, strings, lists and dicts)."""
        roles = {self.incident_bar: "incident_bar", self.specimen: "specimen",
                 self.transmission_bar: "transmission_bar"}
        bodies = []
        for b in self.bodies:
            bodies.append({
                "name": b.name, "role": roles.get(b.name, ""),
                "n_nodes": int(len(b.nodes)), "n_triangles": int(len(b.triangles)),
                "thickness_m": float(b.thickness), "fracturable": bool(b.fracturable),
                "material": {"E": float(b.material.E), "nu": float(b.material.nu), "rho": float(b.material.rho)},
                "x_range_m": [float(b.nodes[:, 0].min()), float(b.nodes[:, 0].max())],
                "y_range_m": [float(b.nodes[:, 1].min()), float(b.nodes[:, 1].max())],
                "area_m2": float(_triangle_areas(b.nodes, b.triangles).sum()),
                "node_sets": {k: int(len(v)) for k, v in b.node_sets.items()},
                "element_sets": {k: int(len(v)) for k, v in b.element_sets.items()},
            })
        return {
            "kind": self.kind, "preset": self.preset, "loading": self.loading,
            "roles": {"incident_bar": self.incident_bar, "specimen": self.specimen,
                      "transmission_bar": self.transmission_bar},
            "specimen_dims_m": {k: float(v) for k, v in self.specimen_dims.items()},
            "specimen_face_x_m": [float(x) for x in self.specimen_face_x],
            "gauge_x_m": [float(x) for x in self.gauge_x],
            "gauge_distance_m": [float(x) for x in self.gauge_distance_m],
            "bar": {"E": float(self.bar_material.E), "nu": float(self.bar_material.nu),
                    "rho": float(self.bar_material.rho), "diameter_m": float(self.bar_diameter_m),
                    "thickness_m": float(self.bar_thickness_m),
                    "length_m": [float(x) for x in self.bar_length_m],
                    "wave_speed_m_s": float(self.bar_wave_speed_m_s)},
            "window_s": float(self.window_s), "arrival_time_s": float(self.arrival_time_s),
            "element_size_m": {k: float(v) for k, v in self.element_size_m.items()},
            "centre_radius_m": float(self.centre_radius_m),
            "mesh_seed": None if self.mesh_seed is None else int(self.mesh_seed),
            "mesh_jitter": float(self.mesh_jitter),
            "closure_range_m": float(self.closure_range_m),
            "element_counts": self.element_counts,
            "n_triangles_total": int(sum(self.element_counts.values())),
            "bodies": bodies,
        }


# --------------------------------------------------------------------------------------------------
# Public builders
# --------------------------------------------------------------------------------------------------

def brazilian_disc(preset: str | Preset = "standard", *,
                   diameter_m: float = 0.050, thickness_m: float = 0.025,
                   disc: Material = GRANITE, bar: Material = STEEL_BAR, bar_diameter_m: float = 0.050,
                   window_s: float = DEFAULT_WINDOW_S,
                   incident_gauge_m: float | None = None, transmission_gauge_m: float | None = None,
                   incident_length_m: float | None = None, transmission_length_m: float | None = None,
                   enforce_window: bool = True, flat_half_angle_deg: float = 0.0,
                   face_gap_m: float = 0.0, bar_face_h_m: float | None = None,
                   mesh_seed: int | None = None, mesh_jitter: float = MESH_JITTER,
                   closure_range_m: float = 0.0) -> Geometry:
    """Brazilian disc between an incident and a transmission bar (the paper's set-up), 2D along x.

    diameter_m, thickness_m: disc diameter and real thickness [m] (the plane-stress thickness).
    disc, bar: materials (defaults: the paper's granite, Table 1; bar steel, module docstring).
    bar_diameter_m: bar diameter [m]; the bars are strips of that height, thickness ``pi D / 4``.
    window_s: recorded window at the specimen [s]; sets the default gauge distances
        ``d = c window_s / 2`` and bar lengths ``L = d + c window_s / 2`` (module docstring).
    incident_gauge_m, transmission_gauge_m: gauge-to-specimen-face distances [m].
    incident_length_m, transmission_length_m: bar lengths [m]; checked against the rule unless
        ``enforce_window=False``.
    The incident bar is loaded by a velocity history on its ``load_end`` nodes.
    flat_half_angle_deg: > 0 gives a flattened Brazilian disc whose loaded faces are flats of
        half-angle alpha (chord x = +-R cos(alpha)); the bars then touch the flats.
    face_gap_m: initial gap between the incident bar's face and the specimen [m] (``face_gap`` effect);
        the gauge distance stays measured from the bar's face.
    bar_face_h_m: with flats, segment length of the bars' end faces where they meet them (|y| <=
        1.5 R sin(alpha)) [m] (default: half the specimen's element size, so that each specimen edge on a loaded flat is
        pressed by bar nodes, not by one bar node every few specimen elements).
    mesh_seed, mesh_jitter: None (default) keeps Triangle's disc mesh; a seed perturbs its interior
        nodes (``_realize``).
    closure_range_m: the ``closure`` effect's Delta [m]: the front flat is tilted so that its gap to the
        bar grows from ``face_gap_m`` to ``face_gap_m + Delta`` across it (``_tilt_front``; flats only).
    """
    p = get_preset(preset)
    _check_positive(diameter_m=diameter_m, thickness_m=thickness_m, bar_diameter_m=bar_diameter_m,
                    window_s=window_s)
    _check_material(disc=disc, bar=bar)
    _check_resolved("diameter_m", diameter_m, p)
    c = bar.c_bar
    d_i = 0.5 * c * window_s if incident_gauge_m is None else incident_gauge_m
    d_t = 0.5 * c * window_s if transmission_gauge_m is None else transmission_gauge_m
    _check_positive(incident_gauge_m=d_i, transmission_gauge_m=d_t)
    L_i = min_bar_length(d_i, c, window_s) if incident_length_m is None else incident_length_m
    L_t = min_bar_length(d_t, c, window_s) if transmission_length_m is None else transmission_length_m
    _check_bar_lengths(L_i, L_t, d_i, d_t, c, window_s, enforce_window, incident_free_end=True)

    R = 0.5 * diameter_m
    if not (0.0 <= flat_half_angle_deg < 30.0):
        raise ValueError(f"flat_half_angle_deg must be in [0, 30) degrees, got {flat_half_angle_deg}")
    alpha = np.radians(flat_half_angle_deg)
    x_front, x_back = (-R, R) if alpha == 0.0 else (-R * np.cos(alpha), R * np.cos(alpha))
    nodes, tris = _mesh_disc(R, p.specimen_h_m, p, alpha)
    centre, r_c = _centre_set(nodes, tris, (0.0, 0.0), CENTRE_RADIUS_FRACTION * diameter_m)
    on_axis = (nodes[:, 1] == 0.0) if alpha == 0.0 else np.ones(len(nodes), bool)
    front = np.flatnonzero((nodes[:, 0] == x_front) & on_axis)
    back = np.flatnonzero((nodes[:, 0] == x_back) & on_axis)
    nodes = _realize(nodes, tris, [front, back], [centre], mesh_seed, mesh_jitter)
    nodes = _tilt_front(nodes, front, x_front, x_back, closure_range_m)
    specimen = Body("disc", nodes, tris, disc, thickness=thickness_m, fracturable=True,
                    node_sets={"front_face": front, "back_face": back},
                    element_sets={"centre": centre})

    incident, transmission, gauge_x = _bars(p, bar, bar_diameter_m, x_front - _gap(face_gap_m), x_back,
                                            L_i, L_t, d_i, d_t, odd_face=True,
                                            face_h=None if alpha == 0.0 else
                                            (0.5 * p.specimen_h_m if bar_face_h_m is None else bar_face_h_m,
                                             1.5 * R * np.sin(alpha)))
    return Geometry(
        kind="brazilian_disc", preset=p.name, bodies=[incident, specimen, transmission],
        incident_bar=incident.name, specimen=specimen.name, transmission_bar=transmission.name,
        specimen_face_x=(x_front, x_back), gauge_x=gauge_x, gauge_distance_m=(float(d_i), float(d_t)),
        specimen_dims={"diameter_m": float(diameter_m), "thickness_m": float(thickness_m)},
        bar_material=bar, bar_diameter_m=float(bar_diameter_m), bar_thickness_m=bar_thickness(bar_diameter_m),
        bar_length_m=(float(L_i), float(L_t)), window_s=float(window_s), loading="free_end_velocity",
        element_size_m=_sizes(p), centre_radius_m=r_c, mesh_seed=mesh_seed, mesh_jitter=float(mesh_jitter),
        closure_range_m=float(closure_range_m))


def cylinder(preset: str | Preset, length_m: float, diameter_m: float, rock: Material, *, bar: Material = TITANIUM_BAR, bar_diameter_m: float = 0.050,
             window_s: float = DEFAULT_WINDOW_S,
             incident_gauge_m: float = FREIBURG_GAUGE_DISTANCES_M[0],
             transmission_gauge_m: float = FREIBURG_GAUGE_DISTANCES_M[1],
             transmission_length_m: float | None = None, enforce_window: bool = True,
             face_gap_m: float = 0.0, mesh_seed: int | None = None,
             mesh_jitter: float = MESH_JITTER, closure_range_m: float = 0.0) -> Geometry:
    """Cylindrical compression specimen between titanium bars (the Freiburg set-up), 2D along x.

    length_m, diameter_m: specimen length (along x) and diameter [m]; it is a rectangle of height D with
        plane-stress thickness ``pi D / 4`` (area match). D must not exceed the bar diameter.
    rock: the specimen's material. bar: bar material (default: Freiburg titanium, module docstring).
    incident_gauge_m, transmission_gauge_m: gauge-to-specimen distances [m] (Freiburg: 1.25 and 1.00).
    The incident bar starts exactly at the incident gauge section, ``x = x_front - incident_gauge_m``:
    the measured incident wave is injected there (``load_end``) through an absorbing boundary, so
    ``L_i = incident_gauge_m``. The transmission bar's default length is ``d_t + c window_s / 2``; a
    shorter bar needs ``enforce_window=False`` (e.g. with an absorbing boundary on ``free_end``).
    face_gap_m: initial gap between the incident bar's face and the specimen's front face [m] (the
        ``face_gap`` effect: closure the bar's face travels before the specimen takes load); the incident
        bar moves back by it, so the gauge stays ``incident_gauge_m`` from the bar's face.
    mesh_seed, mesh_jitter: None (default) keeps Triangle's rectangle mesh; a seed perturbs its interior
        nodes (``_realize``).
    closure_range_m: the ``closure`` effect's Delta [m] (a non-parallel front end): the front face is
        tilted so that its gap to the bar grows from ``face_gap_m`` at ``y = +D/2`` to ``face_gap_m +
        Delta`` at ``y = -D/2`` (``_tilt_front``).
    """
    p = get_preset(preset)
    _check_positive(length_m=length_m, diameter_m=diameter_m, bar_diameter_m=bar_diameter_m,
                    window_s=window_s, incident_gauge_m=incident_gauge_m,
                    transmission_gauge_m=transmission_gauge_m)
    _check_material(rock=rock, bar=bar)
    _check_resolved("length_m", length_m, p)
    _check_resolved("diameter_m", diameter_m, p)
    if diameter_m > bar_diameter_m:
        raise ValueError(f"diameter_m ({diameter_m} m) must not exceed bar_diameter_m ({bar_diameter_m} m): "
                         "the bar end face must cover the specimen's end face")
    c = bar.c_bar
    L_i = float(incident_gauge_m)
    L_t = min_bar_length(transmission_gauge_m, c, window_s) if transmission_length_m is None \
        else transmission_length_m
    _check_bar_lengths(L_i, L_t, incident_gauge_m, transmission_gauge_m, c, window_s, enforce_window,
                       incident_free_end=False)

    x_front, x_back = -0.5 * length_m, 0.5 * length_m
    nodes, tris = _mesh_rectangle(x_front, x_back, diameter_m, p.specimen_h_m, p)
    centre, r_c = _centre_set(nodes, tris, (0.0, 0.0), CENTRE_RADIUS_FRACTION * min(length_m, diameter_m))
    front, back = np.flatnonzero(nodes[:, 0] == x_front), np.flatnonzero(nodes[:, 0] == x_back)
    nodes = _realize(nodes, tris, [front, back], [centre], mesh_seed, mesh_jitter)
    nodes = _tilt_front(nodes, front, x_front, x_back, closure_range_m)
    specimen = Body("cylinder", nodes, tris, rock, thickness=bar_thickness(diameter_m), fracturable=True,
                    node_sets={"front_face": front, "back_face": back},
                    element_sets={"centre": centre})

    incident, transmission, gauge_x = _bars(p, bar, bar_diameter_m, x_front - _gap(face_gap_m), x_back, L_i, L_t,
                                            incident_gauge_m, transmission_gauge_m, odd_face=False)
    return Geometry(
        kind="cylinder", preset=p.name, bodies=[incident, specimen, transmission],
        incident_bar=incident.name, specimen=specimen.name, transmission_bar=transmission.name,
        specimen_face_x=(x_front, x_back), gauge_x=gauge_x,
        gauge_distance_m=(float(incident_gauge_m), float(transmission_gauge_m)),
        specimen_dims={"length_m": float(length_m), "diameter_m": float(diameter_m),
                       "thickness_m": bar_thickness(diameter_m)},
        bar_material=bar, bar_diameter_m=float(bar_diameter_m), bar_thickness_m=bar_thickness(bar_diameter_m),
        bar_length_m=(L_i, float(L_t)), window_s=float(window_s), loading="gauge_injection",
        element_size_m=_sizes(p), centre_radius_m=r_c, mesh_seed=mesh_seed, mesh_jitter=float(mesh_jitter),
        closure_range_m=float(closure_range_m))


def plot_geometry(geometry: Geometry, path, *, zoom_m: float | None = None) -> None:
    """Draw the meshes to an image file: the whole set-up (top) and a zoom on the specimen (bottom).

    zoom_m: half-width of the zoom window around the specimen [m] (default: 1.5 x the specimen's size).
    Uses matplotlib's Agg canvas directly (no global backend change).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7.5))
    FigureCanvasAgg(fig)
    ax_all, ax_zoom = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1, 3]})
    colours = {geometry.incident_bar: "tab:blue", geometry.specimen: "tab:brown",
               geometry.transmission_bar: "tab:green"}
    half = zoom_m if zoom_m is not None else 0.75 * max(geometry.specimen_dims.get("length_m", 0.0),
                                                         geometry.specimen_dims["diameter_m"],
                                                         geometry.bar_diameter_m)
    for ax, lw in ((ax_all, 0.2), (ax_zoom, 0.3)):
        for b in geometry.bodies:
            ax.triplot(b.nodes[:, 0], b.nodes[:, 1], b.triangles, color=colours.get(b.name, "k"), lw=lw)
        for xg in geometry.gauge_x:
            ax.axvline(xg, color="tab:red", lw=0.8, ls="--")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    for b in geometry.bodies:
        for name, idx in b.element_sets.items():
            c = b.nodes[b.triangles[idx]].mean(axis=1)
            ax_zoom.plot(c[:, 0], c[:, 1], ".", ms=2, color="tab:red" if name == "gauge" else "k")
    ax_all.set_aspect("auto")  # bars are ~80 diameters long: stretch y to see them
    ax_zoom.set_aspect("equal")
    ax_zoom.set_xlim(-half, half)
    ax_zoom.set_ylim(-0.6 * geometry.bar_diameter_m, 0.6 * geometry.bar_diameter_m)
    counts = geometry.element_counts
    ax_all.set_title(f"{geometry.kind}, preset {geometry.preset}: "
                     + ", ".join(f"{k} {v} triangles" for k, v in counts.items()), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=150)


# --------------------------------------------------------------------------------------------------
# Mesh realizations
# --------------------------------------------------------------------------------------------------

def _realize(nodes: np.ndarray, tris: np.ndarray, node_sets: list, element_sets: list,
             mesh_seed: int | None, jitter: float) -> np.ndarray:
    """The specimen's nodes for ``mesh_seed`` (None: unchanged). The sets were found on the
    unperturbed mesh and their nodes stay put: the contact faces are on the boundary anyway, and the
    ``centre`` probe keeps its triangles, so it averages over the same region in every realization."""
    if mesh_seed is None:
        return nodes
    keep = np.concatenate([np.asarray(s, np.int64).ravel() for s in node_sets]
                          + [tris[np.asarray(s, np.int64)].ravel() for s in element_sets])
    return perturb_interior_nodes(nodes, tris, keep, mesh_seed, jitter)


def closure_faces(gap_m: float, range_m: float) -> tuple[float, float]:
    """``(face_gap_m, closure_range_m)`` of the builders for the catalogue's ``face_gap.gap_m`` = g (the
    mean gap: the bar face's travel to half contact) and ``closure.range_m`` = Delta (the spread of the
    gap across the face): the face's gap runs from ``g_lo = max(0, g - Delta/2)`` (first touch) to
    ``g_hi = g + Delta/2`` (full contact), so the builders get ``(g_lo, g_hi - g_lo)``. Delta = 0 gives
    ``(g, 0)``, today's hard gap; g < Delta/2 clips the first touch at 0 (contact from the start)."""
    g, d = float(gap_m), float(range_m)
    if d == 0.0:
        return g, 0.0
    lo = max(0.0, g - 0.5 * d)
    return lo, g + 0.5 * d - lo


def _tilt_front(nodes: np.ndarray, front: np.ndarray, x_front: float, x_back: float,
                closure_range_m: float) -> np.ndarray:
    """The specimen's nodes with its front face tilted by ``closure_range_m`` = Delta (``closure`` effect).

    With ``eta(y) = (y_hi - y) / (y_hi - y_lo)`` clipped to [0, 1] (``y_lo``, ``y_hi`` the front face's
    extent), every node moves by ``Delta eta(y) (x_back - x) / (x_back - x_front)`` along +x: the front
    face becomes the straight line ``x = x_front + Delta eta(y)`` (its gap to a flat bar face grows
    linearly across it, 0 extra at ``y_hi``), the back face stays, and the strain of the map (at most
    Delta / L, 1 % for 400 um on 40 mm) is spread over the specimen. Delta = 0 returns ``nodes``
    itself (the base model's mesh, bit for bit)."""
    d = float(closure_range_m)
    if not (math.isfinite(d) and d >= 0.0):
        raise ValueError(f"closure_range_m must be a finite range >= 0 m, got {closure_range_m}")
    if d == 0.0:
        return nodes
    y_f = nodes[np.asarray(front, np.int64), 1]
    y_lo, y_hi = float(y_f.min()), float(y_f.max())
    if not y_hi > y_lo:
        raise ValueError("closure_range_m > 0 needs a flat front face (a round disc touches the bar at one node)")
    eta = np.clip((y_hi - nodes[:, 1]) / (y_hi - y_lo), 0.0, 1.0)
    out = nodes.copy()
    out[:, 0] += d * eta * (x_back - nodes[:, 0]) / (x_back - x_front)
    return out


# --------------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------------

def _gap(face_gap_m: float) -> float:
    g = float(face_gap_m)
    if not (math.isfinite(g) and g >= 0.0):
        raise ValueError(f"face_gap_m must be a finite gap >= 0 m, got {face_gap_m}")
    return g


def _check_positive(**values) -> None:
    for name, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name} must be a finite positive number (SI units), got {v!r}")


def _check_material(**materials) -> None:
    for name, m in materials.items():
        if not isinstance(m, Material):
            raise TypeError(f"{name} must be a fdem.body.Material, got {type(m).__name__}")


def _check_resolved(name: str, size: float, p: Preset) -> None:
    if size < MIN_ELEMENTS_ACROSS * p.specimen_h_m:
        raise ValueError(f"{name} = {size} m is too small for preset {p.name!r}: expected at least "
                         f"{MIN_ELEMENTS_ACROSS} elements of {p.specimen_h_m} m across, i.e. "
                         f">= {MIN_ELEMENTS_ACROSS * p.specimen_h_m} m")


def _check_bar_lengths(L_i, L_t, d_i, d_t, c, window_s, enforce, incident_free_end) -> None:
    _check_positive(incident_length_m=L_i, transmission_length_m=L_t)
    if d_i > L_i * (1 + 1e-12):
        raise ValueError(f"incident_gauge_m ({d_i} m) must lie on the incident bar (length {L_i} m)")
    if d_t >= L_t:
        raise ValueError(f"transmission_gauge_m ({d_t} m) must be less than transmission_length_m ({L_t} m)")
    if not enforce:
        return
    rules = [("transmission_length_m", L_t, min_bar_length(d_t, c, window_s))]
    if incident_free_end:
        rules.append(("incident_length_m", L_i, min_bar_length(d_i, c, window_s)))
    for name, L, L_min in rules:
        if L < L_min * (1 - 1e-12):
            raise ValueError(f"{name} = {L} m is too short for window_s = {window_s} s: expected >= "
                             f"gauge distance + c*window_s/2 = {L_min:.6g} m (c = {c:.1f} m/s); "
                             "shorten window_s or pass enforce_window=False")
