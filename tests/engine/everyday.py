"""Everyday, non-prismatic models for the engine tier, built with manifold3d (a test-only CSG library).

Every builder returns a :class:`manifold3d.Manifold` in model coordinates: centred on X/Y = 0,
resting on z = 0, within about 60 x 60 mm and at most 20 mm tall (mm throughout).  ``MODELS`` maps
a name to its builder; ``CASES`` slices them (one model or several placed apart) with varied Cura
settings at the densities ``DENSITIES``.

Each case is sliced twice by CuraEngine (:func:`slice_everyday`): the sparse slice under test, and a
*reference* slice with the same settings but dense ``lines`` infill (line distance = infill line
width) whose FILL lines fill Cura's sparse-infill area: an independent record of where infill may go.
``EverydaySlice.section_at(z)`` gives manifold3d's own section of the placed models in G-code
coordinates: the independent truth of where there is material.

Command line::

    python3 -m tests.engine.everyday --render OUT_DIR     # one PNG of all models (for the README)
    python3 -m tests.engine.everyday --slice-all OUT_DIR  # slice the corpus, print the timings
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from manifold3d import CrossSection, FillRule, Manifold
from shapely.geometry import MultiPolygon, Polygon

SEGMENTS = 64  # facets round a full circle (cylinders, spheres)
TEXT = "CURA"
TEXT_HEIGHT = 9.0  # mm, cap height of the lettering
DENSITIES = (10, 20, 40)  # infill_sparse_density, %
BED_CENTRE = (110.0, 110.0)  # where model (0, 0) is printed with the default 220 x 220 bed


# --------------------------------------------------------------------------- primitives


def block(size_x: float, size_y: float, size_z: float, x: float = 0.0, y: float = 0.0,
          z: float = 0.0) -> Manifold:
    """A box centred on (x, y) in X/Y whose bottom is at height z (mm)."""
    return Manifold.cube((size_x, size_y, size_z)).translate((x - size_x / 2, y - size_y / 2, z))


def cylinder(diameter: float, height: float, x: float = 0.0, y: float = 0.0, z: float = 0.0,
             top_diameter: float | None = None, segments: int = SEGMENTS) -> Manifold:
    """A vertical cylinder (or cone frustum with `top_diameter`) on (x, y), bottom at z (mm)."""
    top = diameter if top_diameter is None else top_diameter
    return Manifold.cylinder(height, diameter / 2, top / 2, segments).translate((x, y, z))


def above_ground(solid: Manifold) -> Manifold:
    """The part of `solid` at z >= 0."""
    return solid.trim_by_plane((0.0, 0.0, 1.0), 0.0)


def union(solids: Sequence[Manifold]) -> Manifold:
    """Boolean union of several solids."""
    result = solids[0]
    for solid in solids[1:]:
        result = result + solid
    return result


# --------------------------------------------------------------------------- lettering


def glyph_contours(text: str = TEXT, height: float = TEXT_HEIGHT,
                   samples_per_curve: int = 8) -> list[np.ndarray]:
    """Closed outlines of `text` in DejaVu Sans Bold, centred on the origin.

    Parameters
    ----------
    text : str
    height : float
        Height of the text's bounding box, mm.
    samples_per_curve : int
        Points per quadratic/cubic Bezier segment of the font outline.

    Returns
    -------
    list of (n, 2) float arrays
        Outer contours and counters (the holes of A, R...) alike; read them with the even-odd rule.
    """
    from matplotlib.font_manager import FontProperties
    from matplotlib.path import Path
    from matplotlib.textpath import TextPath

    path = TextPath((0.0, 0.0), text, size=10.0, prop=FontProperties(family="DejaVu Sans", weight="bold"))
    contours: list[np.ndarray] = []
    current: list[np.ndarray] = []
    for segment, code in path.iter_bezier():
        if code == Path.MOVETO:
            if len(current) > 2:
                contours.append(np.array(current))
            current = [segment.control_points[0]]
            continue
        steps = 1 if segment.degree == 1 else samples_per_curve
        current.extend(np.atleast_2d(segment(np.linspace(0.0, 1.0, steps + 1)[1:])))
    if len(current) > 2:
        contours.append(np.array(current))
    points = np.concatenate(contours)
    low, high = points.min(axis=0), points.max(axis=0)
    scale = height / (high[1] - low[1])
    return [(c - (low + high) / 2) * scale for c in contours]


def text_section(text: str = TEXT, height: float = TEXT_HEIGHT, mirror_x: bool = False) -> CrossSection:
    """The lettering as a manifold3d cross-section (holes where the letters have counters), mm."""
    contours = glyph_contours(text, height)
    if mirror_x:
        contours = [c * np.array([-1.0, 1.0]) for c in contours]
    return CrossSection([c[:-1] if np.allclose(c[0], c[-1]) else c for c in contours], FillRule.EvenOdd)


def text_solid(depth: float, text: str = TEXT, height: float = TEXT_HEIGHT,
               mirror_x: bool = False) -> Manifold:
    """The lettering extruded from z = 0 to z = `depth` (mm), reading along +X."""
    return Manifold.extrude(text_section(text, height, mirror_x), depth)


# --------------------------------------------------------------------------- holes and cavities


def hidden_cavity() -> Manifold:
    """40 x 40 x 16 block with a closed vertical hole (diameter 14) from z = 5 to z = 12."""
    return block(40, 40, 16) - cylinder(14, 7, z=5)


def through_hole() -> Manifold:
    """40 x 40 x 10 block with a round (diameter 14) and a square (8 mm) through hole."""
    return block(40, 40, 10) - cylinder(14, 12, x=-7, z=-1) - block(8, 8, 12, x=12, y=8, z=-1)


def bushing() -> Manifold:
    """Flanged bushing: flange diameter 36 x 3, tube diameter 24 up to 16 mm, bore 14 (ring sections)."""
    return cylinder(36, 3) + cylinder(24, 13, z=3) - cylinder(14, 18, z=-1)


def hollow_box() -> Manifold:
    """40 x 40 x 16 box with 3 mm walls, floor and roof round a closed 34 x 34 x 10 cavity."""
    return block(40, 40, 16) - block(34, 34, 10, z=3)


def cup() -> Manifold:
    """Cup: diameter 40, 18 tall, 4 mm wall, 3 mm floor, open top."""
    return cylinder(40, 18) - cylinder(32, 16, z=3)


# --------------------------------------------------------------------------- curved solids


def dome() -> Manifold:
    """Hemisphere of radius 20 standing on its flat face."""
    return above_ground(Manifold.sphere(20, 2 * SEGMENTS))


def sphere() -> Manifold:
    """Sphere of radius 11 whose bottom is cut flat (a 12.6 mm disc) so that it rests at z = 0; 20 tall."""
    return above_ground(Manifold.sphere(11, 2 * SEGMENTS).translate((0, 0, 9)))


def cone_up() -> Manifold:
    """Inverted cone: a diameter 10 x 2 foot, then a frustum growing to diameter 40 at z = 18."""
    return cylinder(10, 2) + cylinder(10, 16, z=2, top_diameter=40)


def cone_down() -> Manifold:
    """Cone shrinking from diameter 40 at z = 0 to diameter 4 at z = 18."""
    return cylinder(40, 18, top_diameter=4)


def stairs() -> Manifold:
    """Four steps 10 mm deep, 30 wide, 4, 8, 12, 16 mm tall (skin beside infill in one layer)."""
    return union([block(10, 30, 4 * (i + 1), x=-15 + 10 * i) for i in range(4)])


# --------------------------------------------------------------------------- lettering on faces


def raised_text() -> Manifold:
    """54 x 24 x 4 plate with "CURA" standing 1.2 mm proud on its top face."""
    return block(54, 24, 4) + text_solid(1.2).translate((0, 0, 4))


def engraved_text() -> Manifold:
    """54 x 24 x 6 plate with "CURA" engraved 1.2 mm deep into its top face."""
    return block(54, 24, 6) - text_solid(2.2).translate((0, 0, 6 - 1.2))


def bottom_text() -> Manifold:
    """54 x 24 x 6 plate with "CURA" engraved 1 mm into its bottom face (mirrored: reads from below)."""
    return block(54, 24, 6) - text_solid(2.0, mirror_x=True).translate((0, 0, -1))


def side_text() -> Manifold:
    """54 x 16 x 16 block with "CURA" engraved 1 mm deep into its -Y face (reads from the front)."""
    depth = 1.0
    cutter = text_solid(depth + 1.0).rotate((90.0, 0.0, 0.0))  # text in X/Z, extruded towards -Y
    return block(54, 16, 16) - cutter.translate((0, -8 + depth, 8))


# --------------------------------------------------------------------------- overhangs


def bridge() -> Manifold:
    """Two 10 x 20 x 10 pillars 20 mm apart carrying a 40 x 20 x 4 deck (a 20 mm bridge)."""
    return block(10, 20, 10, x=-15) + block(10, 20, 10, x=15) + block(40, 20, 4, z=10)


def arch() -> Manifold:
    """44 x 20 x 16 block with a half-round tunnel of radius 11 along Y (a table-like arch)."""
    tunnel = Manifold.cylinder(24, 11, 11, 2 * SEGMENTS).rotate((90.0, 0.0, 0.0)).translate((0, 12, 0))
    return block(44, 20, 16) - tunnel


# --------------------------------------------------------------------------- thin features


def pillars_fins() -> Manifold:
    """50 x 30 x 2 base plate with square pillars of 3, 4, 6 mm, round ones of the same diameters
    and fins 2 and 3 mm thick, all 14 mm tall."""
    parts = [block(50, 30, 2)]
    for i, width in enumerate((3.0, 4.0, 6.0)):
        x = -18 + 9 * i
        parts.append(block(width, width, 14, x=x, y=7, z=2))
        parts.append(cylinder(width, 14, x=x, y=-7, z=2))
    parts.append(block(2, 24, 14, x=12, z=2))
    parts.append(block(3, 24, 14, x=19, z=2))
    return union(parts)


def perforated_plate() -> Manifold:
    """50 x 50 x 5 plate with a 6 x 6 grid of round holes, 3, 4 and 5 mm across (by row pairs)."""
    plate = block(50, 50, 5)
    for row in range(6):
        diameter = (3.0, 4.0, 5.0)[row // 2]
        for column in range(6):
            plate = plate - cylinder(diameter, 7, x=-20 + 8 * column, y=-20 + 8 * row, z=-1, segments=32)
    return plate


# --------------------------------------------------------------------------- organic shapes


def ellipse(semi_x: float, semi_y: float, degrees: float = 0.0) -> CrossSection:
    """An ellipse centred on the origin with semi-axes `semi_x`, `semi_y` (mm), turned by `degrees`."""
    return CrossSection.circle(1.0, 2 * SEGMENTS).scale((semi_x, semi_y)).rotate(degrees)


def lofted_hull() -> Manifold:
    """Convex hull of rotated ellipses at five heights (0-18 mm): smooth sections, many facets."""
    levels = [  # (z, semi-axis x, semi-axis y, rotation in degrees)
        (0.0, 12.0, 8.0, 0.0), (4.5, 20.0, 12.0, 20.0), (9.0, 22.0, 14.0, 45.0),
        (13.5, 16.0, 13.0, 70.0), (18.0, 8.0, 6.0, 90.0),
    ]
    rings = [
        Manifold.extrude(ellipse(a, b, angle), 0.01).translate((0, 0, z))
        for z, a, b, angle in levels
    ]
    return above_ground(Manifold.batch_hull(rings))


def lobed_vase(height: float = 18.0) -> Manifold:
    """A twisted five-lobed vase (diameter about 36) with a bulging belly: non-convex sections that
    change every layer, thousands of small facets."""
    start = Manifold.extrude(CrossSection.circle(12.0, 3 * SEGMENTS), height, n_divisions=48)

    def shape(points: np.ndarray) -> np.ndarray:
        x, y, z = points[:, 0], points[:, 1], points[:, 2]
        angle = np.arctan2(y, x)
        belly = 1.0 + 0.35 * np.sin(np.pi * z / height)
        lobes = 1.0 + 0.15 * np.cos(5 * angle + z / 6.0)
        factor = belly * lobes
        return np.column_stack([x * factor, y * factor, z])

    return start.warp_batch(shape)


def low_disc() -> Manifold:
    """A low disc: diameter 20, 4 mm tall (the short part of a plate of several heights)."""
    return cylinder(20, 4)


def post() -> Manifold:
    """A 12 x 12 x 20 post (the tall part of a plate of several heights)."""
    return block(12, 12, 20)


def modifier_box() -> Manifold:
    """A 16 x 16 x 30 box: a modifier (infill mesh, cutting mesh) over a model, taller than it."""
    return block(16, 16, 30)


MODELS: dict[str, Callable[[], Manifold]] = {
    "hidden_cavity": hidden_cavity,
    "through_hole": through_hole,
    "bushing": bushing,
    "hollow_box": hollow_box,
    "cup": cup,
    "dome": dome,
    "sphere": sphere,
    "cone_up": cone_up,
    "cone_down": cone_down,
    "stairs": stairs,
    "raised_text": raised_text,
    "engraved_text": engraved_text,
    "bottom_text": bottom_text,
    "side_text": side_text,
    "bridge": bridge,
    "arch": arch,
    "pillars_fins": pillars_fins,
    "perforated_plate": perforated_plate,
    "lofted_hull": lofted_hull,
    "lobed_vase": lobed_vase,
    "low_disc": low_disc,
    "post": post,
    "modifier_box": modifier_box,
}

_BUILT: dict[str, Manifold] = {}


def build(name: str) -> Manifold:
    """The model `name` of :data:`MODELS` (built once per process)."""
    if name not in _BUILT:
        solid = MODELS[name]()
        if solid.is_empty():
            raise ValueError(f"model {name!r} is empty")
        _BUILT[name] = solid
    return _BUILT[name]


# --------------------------------------------------------------------------- meshes and sections


def mesh_triangles(solid: Manifold) -> np.ndarray:
    """The triangles of `solid`.

    Returns
    -------
    (n, 3, 3) float64 array
        Vertices in mm, counter-clockwise seen from outside (as ``models.write_stl`` expects).
    """
    mesh = solid.to_mesh64() if hasattr(solid, "to_mesh64") else solid.to_mesh()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    return vertices[np.asarray(mesh.tri_verts, dtype=np.int64)]


def write_model_stl(path: str | os.PathLike, solid: Manifold, name: str) -> int:
    """Write `solid` as a binary STL; returns the triangle count."""
    from DelaunayInfill.models import write_stl

    return write_stl(path, mesh_triangles(solid), name=name)


def _ring_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def cross_section_polygons(cross_section: CrossSection) -> MultiPolygon:
    """A manifold3d cross-section as shapely polygons (each outline with its holes), mm."""
    polygons = []
    for component in cross_section.decompose():
        rings = [np.asarray(r, dtype=np.float64) for r in component.to_polygons() if len(r) >= 3]
        if not rings:
            continue
        areas = [abs(_ring_area(r)) for r in rings]
        outer = int(np.argmax(areas))
        holes = [r for i, r in enumerate(rings) if i != outer]
        polygon = Polygon(rings[outer], holes)
        if not polygon.is_valid:
            polygon = polygon.buffer(0)
        polygons.extend(polygon.geoms if hasattr(polygon, "geoms") else [polygon])
    return MultiPolygon([p for p in polygons if not p.is_empty])


def section(solid: Manifold, z: float) -> MultiPolygon:
    """Where `solid` has material at height z (model coordinates, mm), from manifold3d's own slicer."""
    return cross_section_polygons(solid.slice(z))


# --------------------------------------------------------------------------- the corpus cases


@dataclass(frozen=True)
class EverydayCase:
    """One (models, settings) combination of the corpus; sliced at every density of :data:`DENSITIES`.

    Attributes
    ----------
    name : str
    models : tuple of (model name, (dx, dy))
        Models of :data:`MODELS`, each placed at an X/Y offset (mm), sliced together.
    settings : dict
        Cura settings over ``curaengine.DEFAULT_SETTINGS`` (``infill_sparse_density`` is set per density).
    exercises : str
        What the case is there for.
    mesh_settings : tuple of dict
        Per-mesh Cura settings, one per model (none: every model has none), e.g. ``{"extruder_nr": 1}``
        with ``machine_extruder_count`` 2 in `settings`.
    """

    name: str
    models: tuple
    settings: dict = field(default_factory=dict, hash=False)
    exercises: str = ""
    mesh_settings: tuple = field(default=(), hash=False)

    def mesh_names(self) -> list[str]:
        """STL file names, as ``;MESH:`` shows them (``<model>.stl``, numbered when repeated)."""
        names = []
        for index, (model, _) in enumerate(self.models):
            name = f"{model}.stl"
            names.append(name if name not in names else f"{model}_{index}.stl")
        return names

    def key(self, density: float, version: str) -> str:
        """Cache key: case, density and engine version."""
        what = [self.name, [list(m) for m in self.models], self.settings, density, version]
        if self.mesh_settings:
            what.append(list(self.mesh_settings))
        blob = json.dumps(what, sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _one(model: str, settings: dict | None = None, exercises: str = "") -> EverydayCase:
    return EverydayCase(model, ((model, (0.0, 0.0)),), settings or {}, exercises)


CASES: list[EverydayCase] = [
    _one("hidden_cavity", {"wall_line_count": 2},
         "a hole that opens at z=5 and closes at z=12: roof skin over the hole, infill beside it"),
    _one("through_hole", {"infill_pattern": "triangles", "wall_line_count": 3},
         "round and square through holes with 3 walls; triangles"),
    _one("bushing", {"infill_pattern": "gyroid", "skin_outline_count": 0},
         "ring sections of two sizes (flange, tube): infill in thin annuli; gyroid; no skin wall"),
    _one("hollow_box", {"top_bottom_pattern": "concentric", "infill_before_walls": False},
         "a closed cavity: floor, four 3 mm walls, a roof bridging it; concentric skin; walls first"),
    _one("cup", {"infill_pattern": "cubic", "wall_line_count": 4},
         "floor, open top: a 4 mm ring wall with 4 lines; cubic"),
    _one("dome", {"top_bottom_pattern": "zigzag", "skin_overlap": 25},
         "a hemisphere: top skin grows layer by layer beside infill; zigzag skin, 25 % skin overlap"),
    _one("sphere", {"gradual_infill_steps": 2},
         "a sphere on a flat cut: overhang below, dome above; gradual infill (2 steps)"),
    _one("cone_up", {"bridge_settings_enabled": True, "wall_line_count": 1},
         "a cone growing upwards on a small foot: bottom skin on every overhanging ring; 1 wall; "
         "bridge settings"),
    _one("cone_down", {"infill_pattern": "lightning"},
         "a cone shrinking to a tip: infill shrinks under the skin; lightning"),
    _one("stairs", {"skin_overlap": 25, "infill_multiplier": 2},
         "steps: skin beside infill in one layer; infill line multiplier 2"),
    _one("raised_text", {"infill_pattern": "grid"},
         "raised lettering (counters in A, R) on a 4 mm plate: top skin round the letters' feet"),
    _one("engraved_text", {"skin_outline_count": 0, "top_bottom_pattern": "concentric"},
         "lettering engraved into the top face: skin at the engraving's floor; concentric, no skin wall"),
    _one("bottom_text", {"infill_pattern": "triangles", "top_bottom_pattern": "zigzag"},
         "mirrored lettering engraved into the bottom face: bottom skin above the letters"),
    _one("side_text", {"infill_pattern": "cubic", "wall_line_count": 3},
         "lettering engraved into a vertical face: walls follow the letters inside the infill"),
    _one("bridge", {"bridge_settings_enabled": True, "infill_before_walls": False},
         "a 20 mm bridge between two pillars: bridge skin, infill in the deck; bridge settings"),
    _one("arch", {"bridge_settings_enabled": True, "infill_pattern": "gyroid", "skin_overlap": 25},
         "a half-round tunnel: overhanging skin over the arch, infill in the shoulders"),
    _one("pillars_fins", {"wall_line_count": 1, "infill_multiplier": 2},
         "3, 4, 6 mm pillars and 2, 3 mm fins on a base plate: tiny infill areas; 1 wall; multiplier 2"),
    _one("perforated_plate", {"top_bottom_pattern": "concentric", "skin_outline_count": 1},
         "a 5 mm plate with 36 round holes of 3-5 mm: infill between the holes"),
    _one("lofted_hull", {"gradual_infill_steps": 2, "infill_pattern": "cubic"},
         "a convex hull of rotated ellipses: many facets, sections change every layer; gradual cubic"),
    _one("lobed_vase", {"infill_pattern": "gyroid", "wall_line_count": 3, "infill_before_walls": False},
         "a twisted lobed vase: non-convex faceted sections; gyroid, 3 walls"),
    EverydayCase("plate_of_heights",
                 (("low_disc", (-28.0, 0.0)), ("post", (0.0, 0.0)), ("dome", (32.0, 0.0))),
                 {"infill_pattern": "triangles", "skin_outline_count": 0},
                 "three parts of 4, 20 and 20 mm on one plate: parts end at different layers"),
    EverydayCase("plate_mixed",
                 (("cup", (-26.0, 0.0)), ("cone_down", (26.0, 0.0))),
                 {"infill_pattern": "lightning", "top_bottom_pattern": "zigzag", "wall_line_count": 2},
                 "a cup and a cone side by side: lightning across two meshes"),
]

CASES_BY_NAME: dict[str, EverydayCase] = {case.name: case for case in CASES}


def placed_model(name: str, offset: tuple[float, float]) -> Manifold:
    """Model `name` moved by `offset` (mm) in X/Y."""
    return build(name).translate((offset[0], offset[1], 0.0))


#: per-mesh settings that make a mesh a modifier: no material of its own outside the models
MODIFIER_KEYS = ("infill_mesh", "cutting_mesh", "anti_overhang_mesh", "support_mesh")


def is_modifier(mesh_values: Mapping) -> bool:
    """Whether a mesh with these per-mesh settings is a modifier of other meshes."""
    return any(mesh_values.get(key) for key in MODIFIER_KEYS)


def case_solid(case: EverydayCase) -> Manifold:
    """All the models of `case` in place (modifiers left out), in model coordinates."""
    values = case.mesh_settings or [{}] * len(case.models)
    return Manifold.compose([placed_model(name, offset) for (name, offset), v in zip(case.models, values)
                             if not is_modifier(v)])


# --------------------------------------------------------------------------- slicing


def reference_settings(settings: Mapping, infill_line_width: float) -> dict:
    """The reference slice's settings: `settings` with dense ``lines`` infill.

    ``infill_line_distance`` = `infill_line_width` (mm), no gradual infill, no multiplier; the
    density is left as it is (top/bottom layer counts and infill overlap depend on it), so walls and
    skin are those of the sparse slice and the FILL lines cover Cura's sparse-infill area.

    Measured (both engines, 16 cases): Cura's sparse FILL lies within the reference lines buffered by
    one line width for >= 99.999 % of its length, >= 99.95 % in every layer.  With a buffer of half a line width + 0.05 mm
    up to 4 % of a layer's sparse length falls outside, by at most 0.38 mm: where the border of the
    area is oblique to the reference lines it is a saw-tooth of line ends, and sparse lines that run
    along the border (cubic or gyroid in a thin ring, the cup's 0.8 mm annulus) pass between the teeth.
    ``zig_zaggify_infill`` would join the teeth but shrinks the reference by half a line width.
    """
    return {**settings, "infill_pattern": "lines", "infill_line_distance": float(infill_line_width),
            "gradual_infill_steps": 0, "infill_multiplier": 1}


@dataclass
class EverydaySlice:
    """A case sliced at one density: the sparse G-code, the dense reference and the model's truth.

    Attributes
    ----------
    case : EverydayCase
    density : float
        ``infill_sparse_density``, %.
    version : str
        CuraEngine version ("4.13", "5.0").
    cura_gcode, reference_gcode : str
        Paths of the sparse slice and of the reference slice.
    stl : dict
        Mesh name (as ``;MESH:`` shows it) -> STL path.
    settings : dict
        Resolved global settings of the sparse slice.
    reference_settings_used : dict
        The user settings the reference was sliced with.
    line_width : float
        ``infill_line_width``, mm.
    infill_line_distance : dict
        Mesh name -> Cura's sparse infill line distance, mm.
    bed_offset : (float, float)
        Model (0, 0) in G-code coordinates, mm.
    seconds : float
        Wall time of the two slices (they run at the same time), s.
    """

    case: EverydayCase
    density: float
    version: str
    cura_gcode: str
    reference_gcode: str
    stl: dict
    settings: dict
    reference_settings_used: dict
    line_width: float
    infill_line_distance: dict
    bed_offset: tuple
    seconds: float
    folder: str
    _sections: dict = field(default_factory=dict, repr=False)
    _solid: Manifold | None = field(default=None, repr=False)

    @property
    def spacing(self) -> float:
        """The local line spacing coverage is judged by: a grid's line distance at the case's density, mm.

        Pattern-independent (Cura's own ``infill_line_distance`` is a line width / density for lines,
        gyroid and concentric, twice that for grid, three times for triangles and cubic): every place of
        a Delaunay pattern of density d lies within about a line width / d of one of its lines, and
        within twice that almost everywhere.
        """
        return 2.0 * self.line_width / (self.density / 100.0)

    def section_at(self, z: float) -> MultiPolygon:
        """Where the models have material at G-code height `z` (mm), in G-code X/Y coordinates (mm).

        The models rest on z = 0 in G-code as in model coordinates (no raft); X/Y are shifted by
        :attr:`bed_offset`.
        """
        key = round(float(z), 4)
        if key not in self._sections:
            from shapely.affinity import translate

            if self._solid is None:
                self._solid = case_solid(self.case)
            self._sections[key] = translate(section(self._solid, key), *self.bed_offset)
        return self._sections[key]


def cura_footer(settings: Mapping) -> str:
    """The ``;SETTING_3`` footer Cura's G-code writer appends: the changed settings as JSON, 80 columns.

    Cura writes a JSON object of serialized settings containers (``global_quality``, one
    ``extruder_quality`` per extruder; here every changed setting goes into each extruder's, where
    Cura keeps per-extruder settings), escapes backslashes and newlines for a comment, and cuts the
    text into lines of ``;SETTING_3 `` + 69 characters.
    """
    values = "".join(f"{key} = {str(value).lower() if isinstance(value, bool) else value}\n"
                     for key, value in sorted(settings.items()))
    extruders = [("[general]\nversion = 4\nname = Everyday\ndefinition = fdmprinter\n\n[metadata]\n"
                  f"type = quality_changes\nquality_type = normal\nposition = {number}\n\n[values]\n" + values)
                 for number in range(max(1, int(settings.get("machine_extruder_count", 1))))]
    glob = ("[general]\nversion = 4\nname = Everyday\ndefinition = fdmprinter\n\n[metadata]\n"
            "type = quality_changes\nquality_type = normal\n\n[values]\n")
    text = json.dumps({"global_quality": glob, "extruder_quality": extruders})
    escaped = text.replace("\\", "\\\\").replace("\n", "\\n").replace("\r", "\\r")
    return "".join(f";SETTING_3 {escaped[i:i + 69]}\n" for i in range(0, len(escaped), 69))


def slice_everyday(case: EverydayCase, density: float, version: str,
                   folder: str | os.PathLike) -> EverydaySlice:
    """Slice `case` at `density` (%) with CuraEngine `version`: the sparse slice and its reference.

    The STLs are written into ``folder/<case>-<density>-<key>/`` and both slices run at the same
    time.  Raises ``CuraEngineError`` when the engine cannot run.
    """
    from DelaunayInfill import curaengine

    from .engines import engine

    chosen = engine(version)
    target = os.path.join(os.fspath(folder), f"{case.name}-{density:g}-{case.key(density, version)}")
    os.makedirs(target, exist_ok=True)
    stl = {}
    for mesh_name, (model, offset) in zip(case.mesh_names(), case.models):
        path = os.path.join(target, mesh_name)
        write_model_stl(path, placed_model(model, offset), mesh_name)
        stl[mesh_name] = path
    meshes = [(name, dict(values)) for name, values in zip(stl, case.mesh_settings or [{}] * len(stl))]
    settings = {**case.settings, "infill_sparse_density": density}
    resolved = curaengine.resolve_settings(settings, meshes, resources=chosen.resources)
    line_width = float({**resolved.global_values, **resolved.extruder_values}["infill_line_width"])
    reference = reference_settings(settings, line_width)
    # an infill or cutting mesh's infill is dense lines in the reference too; a 0 % one's stays none (its
    # own line distance 0: the reference's global one would reach it)
    reference_meshes = [(name, (reference_settings(values, line_width) if values.get("infill_sparse_density", 1) != 0
                                else {**values, "infill_line_distance": 0.0})
                         if values.get("infill_mesh") or values.get("cutting_mesh") else values)
                        for name, values in meshes]

    def run(user: dict, out_name: str, with_meshes: list):
        return curaengine.slice_models(with_meshes, user, os.path.join(target, out_name),
                                       engine=chosen.executable, resources=chosen.resources, cwd=target)

    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=2) as pool:
        sparse_job = pool.submit(run, settings, "cura.gcode", meshes)
        reference_job = pool.submit(run, reference, "reference.gcode", reference_meshes)
        sparse, dense = sparse_job.result(), reference_job.result()
    seconds = time.perf_counter() - start
    # Saved as Cura's GUI saves G-code: with the print's changed settings in a ;SETTING_3 footer
    with open(sparse.path, "a", encoding="utf-8") as f:
        f.write(cura_footer(settings))
    values = sparse.settings.global_values
    extruder = sparse.settings.extruder_values
    distances = {name: float({**values, **extruder, **mesh_values}["infill_line_distance"])
                 for (name, _), (_, mesh_values) in zip(meshes, sparse.settings.meshes)}
    offset = (0.0, 0.0) if values.get("machine_center_is_zero") else \
        (float(values["machine_width"]) / 2, float(values["machine_depth"]) / 2)
    return EverydaySlice(case, density, version, sparse.path, dense.path, stl, dict(values), reference,
                         line_width, distances, offset, seconds, target)


class EverydaySliceCache:
    """Slices each (case, density, engine version) once per session into `folder`."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = os.fspath(folder)
        self._done: dict[str, EverydaySlice] = {}

    def get(self, case: EverydayCase, density: float, version: str) -> EverydaySlice:
        key = case.key(density, version)
        if key not in self._done:
            self._done[key] = slice_everyday(case, density, version, self.folder)
        return self._done[key]


# --------------------------------------------------------------------------- command line


def render(out_dir: str, columns: int = 6, names: Sequence[str] | None = None,
           file_name: str = "everyday-models.png") -> str:
    """Draw the models `names` (default: the corpus's, the modifier box left out) of :data:`MODELS`
    (matplotlib 3-D) into ``out_dir/file_name``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if names is None:
        names = [name for name in MODELS if name != "modifier_box" and not name.startswith("random_")]
    rows = math.ceil(len(names) / columns)
    figure = plt.figure(figsize=(3.0 * columns, 3.0 * rows))
    elevation, azimuth = np.radians(28.0), np.radians(-60.0)
    camera = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                       np.sin(elevation)])
    light = np.array([0.4, -0.5, 0.75]) / np.linalg.norm([0.4, -0.5, 0.75])
    for index, name in enumerate(names):
        # small triangles (matplotlib sorts whole triangles by depth) and no faces turned away
        triangles = mesh_triangles(build(name).refine_to_length(1.5))
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        facing = normals @ camera > 0.0
        triangles, normals = triangles[facing], normals[facing]
        shade = 0.35 + 0.65 * np.clip(normals @ light, 0.0, 1.0)
        axes = figure.add_subplot(rows, columns, index + 1, projection="3d")
        colours = np.column_stack([0.25 * shade, 0.55 * shade, 0.85 * shade, np.ones_like(shade)])
        faces = Poly3DCollection(triangles, facecolors=colours, edgecolors=colours, linewidths=0.3)
        axes.add_collection3d(faces)
        axes.set_xlim(-30, 30)
        axes.set_ylim(-30, 30)
        axes.set_zlim(0, 20)
        axes.set_box_aspect((60, 60, 20))
        axes.view_init(elev=np.degrees(elevation), azim=np.degrees(azimuth))
        axes.set_axis_off()
        axes.set_title(name, fontsize=10)
    figure.tight_layout()
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, file_name)
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


def slice_all(out_dir: str, version: str = "4.13") -> float:
    """Slice every case at every density (sparse + reference); print timings; returns the wall time, s."""
    cache = EverydaySliceCache(out_dir)
    start = time.perf_counter()
    for case in CASES:
        for density in DENSITIES:
            done = cache.get(case, density, version)
            print(f"{case.name:18s} {density:3d} %  {done.seconds:5.1f} s", flush=True)
    total = time.perf_counter() - start
    print(f"total {total:.1f} s for {len(CASES) * len(DENSITIES)} (sparse + reference) slices")
    return total


def process_and_check(done: EverydaySlice):
    """The sparse slice through the plugin's API, checked by `everyday_check`: (processed text, report, result)."""
    from DelaunayInfill import process_gcode
    from DelaunayInfill.gcode.read import as_cura_list

    from .everyday_check import check_everyday

    with open(done.cura_gcode, encoding="utf-8") as f:
        original = f.read()
    with open(done.reference_gcode, encoding="utf-8") as f:
        reference = f.read()
    layers, report = process_gcode(as_cura_list(original))
    processed = "".join(layers)
    with open(os.path.join(done.folder, "processed.gcode"), "w", encoding="utf-8") as f:
        f.write(processed)
    result = check_everyday(original, processed, reference, done.section_at, spacing=done.spacing,
                            line_width=done.line_width)
    add_failed_layers(result, report)
    return processed, report, result


def add_failed_layers(result, report) -> None:
    """A layer the pass failed keeps Cura's infill, which the checker passes: a problem all the same."""
    if report.failed_layers:
        result.add_problem(f"{len(report.failed_layers)} layer(s) failed and kept Cura's infill: "
                           + "; ".join(report.failure_messages[:3]))


def report_row(done: EverydaySlice, report, result) -> str:
    """One line of the corpus table: containment, material, skin, coverage, islands, Cura's lines kept."""
    f = result.figures
    worst_layer, worst_fraction = f["worst_outside_layer"] or ("-", 0.0)
    return (f"{done.case.name:18s} {done.density:4g} {done.version:>5s}  {100 * f['outside_fraction']:7.3f}"
            f" {100 * worst_fraction:6.2f} ({worst_layer:>3s}) {f['material_mm']:7.2f} {f['on_skin_mm']:7.2f}"
            f" {100 * f['coverage']:7.2f} {f['lost_islands']:4d} {report.cura_infill_kept_mm:8.0f}"
            f"  {'ok' if result.ok else 'FAILED'}")


REPORT_HEADER = (f"{'case':18s} {'dens':>4s} {'eng':>5s}  {'out %':>7s} {'worst layer %':>13s} {'mat mm':>7s}"
                 f" {'skin mm':>7s} {'cover %':>7s} {'lost':>4s} {'kept mm':>8s}")


def report(out_dir: str, versions: Sequence[str]) -> int:
    """Slice, process and check every case at every density with each engine; print the table.

    Columns: new infill outside Cura's infill area (+ half a line width) in the file and in its worst
    layer, new infill where the model has no material (mm), on Cura's skin (mm), coverage of Cura's
    infill places (within a grid's line spacing at the density), islands that lost their infill, and
    the length of Cura's own lines the pass kept.  Returns the number of failed cases.
    """
    cache = EverydaySliceCache(out_dir)
    print(REPORT_HEADER, flush=True)
    failed = 0
    for version in versions:
        for case in CASES:
            for density in DENSITIES:
                done = cache.get(case, density, version)
                _, processed_report, result = process_and_check(done)
                failed += not result.ok
                print(report_row(done, processed_report, result), flush=True)
    return failed


#: (case, z in mm) of the README's picture: one layer of each, Cura's and the pass's
PICTURE_LAYERS = (("hidden_cavity", 8.0), ("engraved_text", 4.5), ("perforated_plate", 2.5),
                  ("pillars_fins", 8.0), ("bushing", 8.0), ("stairs", 6.0))


def pictures(out_dir: str, version: str = "4.13", density: float = 20) -> str:
    """One layer of several corpus models, Cura's G-code above and the processed one below: a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from DelaunayInfill.gcode.preview import layer_segments

    from .everyday_check import extract_layers

    cache = EverydaySliceCache(out_dir)
    colours = {"WALL-OUTER": "#d62728", "WALL-INNER": "#2ca02c", "SKIN": "#e6c619", "FILL": "#ff7f0e"}
    figure, axes = plt.subplots(2, len(PICTURE_LAYERS), figsize=(3.2 * len(PICTURE_LAYERS), 6.8), squeeze=False)
    for column, (name, z) in enumerate(PICTURE_LAYERS):
        done = cache.get(CASES_BY_NAME[name], density, version)
        process_and_check(done)
        layers = extract_layers(open(done.cura_gcode, encoding="utf-8").read())
        layer = min((abs(moves.z - z), number) for (number, occurrence), moves in layers.items()
                    if occurrence == 0 and len(moves.fill))[1]
        for row, path in enumerate((done.cura_gcode, os.path.join(done.folder, "processed.gcode"))):
            groups = layer_segments(path, layer)
            ax = axes[row][column]
            for kind, colour in colours.items():
                segments = groups.get(kind)
                if segments is not None and len(segments):
                    ax.add_collection(LineCollection(segments, colors=colour, linewidths=0.6))
            ax.set_aspect("equal")
            ax.autoscale_view()
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{name}, layer {layer}: {'Cura' if row == 0 else 'Delaunay'}", fontsize=8)
    figure.tight_layout()
    path = os.path.join(out_dir, "everyday-layers.png")
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m tests.engine.everyday",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--render", metavar="OUT_DIR", help="write OUT_DIR/everyday-models.png")
    parser.add_argument("--slice-all", metavar="OUT_DIR", help="slice the whole corpus into OUT_DIR")
    parser.add_argument("--report", metavar="OUT_DIR",
                        help="slice, process and check the whole corpus into OUT_DIR; print the table")
    parser.add_argument("--pictures", metavar="OUT_DIR", help="write OUT_DIR/everyday-layers.png")
    parser.add_argument("--engine", action="append", help="CuraEngine version (4.13, 5.0); --report: "
                        "each one given (default both), others: the first (default 4.13)")
    args = parser.parse_args(argv)
    if not (args.render or args.slice_all or args.report or args.pictures):
        parser.error("give --render, --slice-all, --report and/or --pictures OUT_DIR")
    engines = args.engine or []
    if args.render:
        print(render(args.render))
    if args.slice_all:
        slice_all(args.slice_all, engines[0] if engines else "4.13")
    if args.pictures:
        print(pictures(args.pictures, engines[0] if engines else "4.13"))
    if args.report:
        from .engines import ENGINES

        return 1 if report(args.report, engines or list(ENGINES)) else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
