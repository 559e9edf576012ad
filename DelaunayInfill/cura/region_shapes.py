"""Density-region geometry for the Cura tool, in pure numpy (no Cura import).

The region tool (``region_tool.py``) builds its modifier meshes and hands
scene regions to the G-code pipeline through these functions, so they can be
tested without Cura.

Coordinate systems
------------------
Cura scene: millimetres, Y up, the build plate centre at X = Z = 0.
G-code (what CuraEngine prints and the pipeline works in)::

    gcode X = scene x + machine_width / 2
    gcode Y = -scene z + machine_depth / 2
    gcode Z = scene y

The half-width/depth shift is skipped when ``machine_center_is_zero``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

SHAPES = ("sphere", "cube", "cylinder")
"""Shapes the tool can place; ``"mesh"`` marks a region we did not build (Per Model Settings)."""

REGION_NAME_PREFIX = "DelaunayRegion_"
_REGION_NAME = re.compile(r"^" + REGION_NAME_PREFIX + r"(\d+)$")

MIN_SIZE_MM = 0.5
MAX_SIZE_MM = 2000.0


def region_name(number: int) -> str:
    """The scene-node (and ``;MESH:``) name of region `number`, e.g. ``DelaunayRegion_3``."""
    return f"{REGION_NAME_PREFIX}{int(number)}"


def region_number(name: str) -> int | None:
    """The number in a ``DelaunayRegion_<n>`` name, or None for any other name."""
    match = _REGION_NAME.match(name or "")
    return int(match.group(1)) if match else None


def next_region_number(names) -> int:
    """The smallest number above every ``DelaunayRegion_<n>`` among `names` (1 when none)."""
    numbers = [n for n in (region_number(name) for name in names) if n is not None]
    return max(numbers, default=0) + 1


def clamp_density_percent(value) -> float:
    """A density in percent, validated and clamped to [0, 100].

    Raises
    ------
    ValueError
        If `value` is not a finite number.
    """
    density = float(value)
    if not math.isfinite(density):
        raise ValueError(f"density must be a number, got {value!r}")
    return min(100.0, max(0.0, density))


def clamp_size_mm(value) -> float:
    """A region size in mm, validated and clamped to [MIN_SIZE_MM, MAX_SIZE_MM]."""
    size = float(value)
    if not math.isfinite(size):
        raise ValueError(f"size must be a number, got {value!r}")
    return min(MAX_SIZE_MM, max(MIN_SIZE_MM, size))


def shape_triangles(shape: str, size: float, *, segments: int = 32) -> np.ndarray:
    """A closed triangle mesh of a region shape centred on the origin, in scene axes.

    Parameters
    ----------
    shape : {"sphere", "cube", "cylinder"}
        Sphere of diameter `size`; cube of edge `size`; cylinder of diameter
        `size` and height `size` with its axis along scene Y (vertical).
    size : float
        mm.
    segments : int
        Facets around a circle (sphere and cylinder).

    Returns
    -------
    ndarray, float32, shape (k, 3, 3)
        Triangles (corner, xyz) wound counter-clockwise seen from outside.
    """
    size = clamp_size_mm(size)
    half = size / 2.0
    if shape == "cube":
        tris = _cube_triangles(half)
    elif shape == "cylinder":
        tris = _cylinder_triangles(half, half, segments)
    elif shape == "sphere":
        tris = _sphere_triangles(half, segments)
    else:
        raise ValueError(f"unknown region shape {shape!r}; use one of {', '.join(SHAPES)}")
    return tris.astype(np.float32)


def _cube_triangles(half: float) -> np.ndarray:
    corners = np.array(
        [[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)], dtype=float
    )
    # corner index = 4*ix + 2*iy + iz; two triangles per face, outward winding
    faces = np.array(
        [
            [0, 1, 3], [0, 3, 2],  # -x
            [4, 6, 7], [4, 7, 5],  # +x
            [0, 4, 5], [0, 5, 1],  # -y
            [2, 3, 7], [2, 7, 6],  # +y
            [0, 2, 6], [0, 6, 4],  # -z
            [1, 5, 7], [1, 7, 3],  # +z
        ]
    )
    return corners[faces]


def _cylinder_triangles(radius: float, half_height: float, segments: int) -> np.ndarray:
    segments = max(3, int(segments))
    angle = np.arange(segments) * 2 * math.pi / segments
    ring_x, ring_z = radius * np.cos(angle), -radius * np.sin(angle)
    nxt = np.roll(np.arange(segments), -1)
    bottom = np.c_[ring_x, np.full(segments, -half_height), ring_z]
    top = np.c_[ring_x, np.full(segments, half_height), ring_z]
    centre_bottom = np.broadcast_to([0.0, -half_height, 0.0], bottom.shape)
    centre_top = np.broadcast_to([0.0, half_height, 0.0], top.shape)
    side_a = np.stack([bottom, bottom[nxt], top[nxt]], axis=1)
    side_b = np.stack([bottom, top[nxt], top], axis=1)
    cap_top = np.stack([centre_top, top, top[nxt]], axis=1)
    cap_bottom = np.stack([centre_bottom, bottom[nxt], bottom], axis=1)
    return np.concatenate([side_a, side_b, cap_top, cap_bottom])


def _sphere_triangles(radius: float, segments: int) -> np.ndarray:
    segments = max(6, int(segments))
    rings = max(3, segments // 2)
    polar = np.linspace(0.0, math.pi, rings + 1)
    azimuth = np.arange(segments) * 2 * math.pi / segments
    p, a = np.meshgrid(polar, azimuth, indexing="ij")
    grid = np.stack(
        [radius * np.sin(p) * np.cos(a), radius * np.cos(p), -radius * np.sin(p) * np.sin(a)], axis=-1
    )  # (rings + 1, segments, 3), row 0 the north pole (+y)
    nxt = np.roll(np.arange(segments), -1)
    upper_left, upper_right = grid[:-1], grid[:-1][:, nxt]
    lower_left, lower_right = grid[1:], grid[1:][:, nxt]
    # drop the zero-area triangles at the poles: a's in the last band, b's in the first
    tri_a = np.stack([upper_left, lower_left, lower_right], axis=2)[:-1]
    tri_b = np.stack([upper_left, lower_right, upper_right], axis=2)[1:]
    return np.concatenate([tri_a.reshape(-1, 3, 3), tri_b.reshape(-1, 3, 3)])


def infer_shape(triangle_count: int, *, segments: int = 32) -> str:
    """The shape :func:`shape_triangles` made a mesh of `triangle_count` triangles with, else "mesh".

    Used for regions restored from a project file, where only the mesh survives.
    """
    for shape in SHAPES:
        if len(shape_triangles(shape, 10.0, segments=segments)) == int(triangle_count):
            return shape
    return "mesh"


def mesh_volume(triangles: np.ndarray) -> float:
    """Enclosed volume (mm³) of a closed, outward-wound triangle mesh (divergence theorem)."""
    tri = np.asarray(triangles, dtype=float)
    if tri.size == 0:
        return 0.0
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def scene_to_gcode(points, machine_width: float, machine_depth: float, center_is_zero: bool = False) -> np.ndarray:
    """Scene coordinates (Y up) to G-code coordinates (Z up), as CuraEngine places meshes.

    Parameters
    ----------
    points : array_like, shape (..., 3)
        Scene x, y, z in mm.

    Returns
    -------
    ndarray, float, shape (..., 3)
        G-code X, Y, Z in mm.
    """
    pts = np.asarray(points, dtype=float)
    out = np.empty_like(pts)
    out[..., 0] = pts[..., 0]
    out[..., 1] = -pts[..., 2]
    out[..., 2] = pts[..., 1]
    if not center_is_zero:
        out[..., 0] += machine_width / 2.0
        out[..., 1] += machine_depth / 2.0
    return out


def gcode_to_scene(points, machine_width: float, machine_depth: float, center_is_zero: bool = False) -> np.ndarray:
    """Inverse of :func:`scene_to_gcode`."""
    pts = np.asarray(points, dtype=float).copy()
    if not center_is_zero:
        pts[..., 0] -= machine_width / 2.0
        pts[..., 1] -= machine_depth / 2.0
    out = np.empty_like(pts)
    out[..., 0] = pts[..., 0]
    out[..., 1] = pts[..., 2]
    out[..., 2] = -pts[..., 1]
    return out


def transform_points(matrix, points) -> np.ndarray:
    """Apply a 4×4 homogeneous transform (column-vector convention) to (..., 3) points."""
    m = np.asarray(matrix, dtype=float)
    pts = np.asarray(points, dtype=float)
    return pts @ m[:3, :3].T + m[:3, 3]


@dataclass
class SceneRegion:
    """One density region as the G-code pipeline receives it.

    Attributes
    ----------
    name : str
        Scene-node name; also the ``;MESH:`` name of its FILL blocks.
    density : float
        Target fill fraction in [0, 1].
    triangles : ndarray, shape (k, 3, 3)
        The region's closed surface in G-code coordinates (mm).
    number : int or None
        n of ``DelaunayRegion_<n>``; None for regions made with Per Model Settings.
    shape : str
        "sphere", "cube", "cylinder" or "mesh".
    size : float
        mm (largest bounding-box extent for "mesh").
    parent : str
        Name of the model the region belongs to ("" when free-standing).
    mesh_order : int
        Cura's ``infill_mesh_order``: a higher order wins where modifiers overlap
        (the tool gives region n the order 1 + n; Cura's default is 1).
    """

    name: str
    density: float
    triangles: np.ndarray = field(repr=False)
    number: int | None = None
    shape: str = "mesh"
    size: float = 0.0
    parent: str = ""
    mesh_order: int = 1

    def bounds(self) -> np.ndarray:
        """(2, 3) array: min and max G-code corner of the region's triangles."""
        pts = np.asarray(self.triangles, dtype=float).reshape(-1, 3)
        return np.stack([pts.min(axis=0), pts.max(axis=0)])


def order_regions(regions):
    """Regions in the order the pipeline applies them (later ones win where they overlap).

    As CuraEngine does with overlapping infill meshes, a higher
    ``infill_mesh_order`` wins; at equal order, Per Model Settings modifiers
    (no number, in scene order) come before the tool's regions, and those
    follow their numbers, i.e. their creation, so the newest wins.
    """
    indexed = list(enumerate(regions))
    indexed.sort(key=lambda item: (item[1].mesh_order, item[1].number is not None, item[1].number or 0, item[0]))
    return [region for _index, region in indexed]


def pipeline_regions(regions):
    """``(triangles, density)`` pairs in application order, the form ``process_gcode`` takes."""
    return [(np.asarray(r.triangles, dtype=float), float(r.density)) for r in order_regions(regions)]
