"""Rebuilding a layer's sparse-infill area from the G-code's walls, skin and FILL.

The G-code carries no infill polygons.  Per mesh and layer:

* the part interior is the even-odd union of the closed WALL-OUTER loops;
* the walls' footprint is every wall line buffered by half a line width;
* infill area = (interior - walls) grown by the infill overlap, minus the
  skin lines buffered by half a line width;
* it is checked against Cura's own FILL lines: where they fall outside it
  (walls missing, odd geometry) a closed hull of the FILL lines is added.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from shapely.geometry import LineString, MultiLineString, Polygon
from shapely.validation import make_valid

from ..geometry import contains_xy, empty_area, polygons_of, to_multipolygon, unary_union
from .read import FILL, SKIN, WALL_INNER, WALL_OUTER, LayerParse

__all__ = [
    "MeshLayer",
    "mesh_layer",
    "runs_of",
    "fill_hull",
    "fraction_inside",
    "sample_segments",
    "segments_of",
    "split_by_lines",
]

_EPS = 0.02  # mm: closes numerical slivers between adjacent buffered lines


@dataclass
class MeshLayer:
    """One mesh's geometry in one layer.

    ``fill`` (k, 2, 2) Cura's FILL extrusion segments (mm); ``fill_block``
    (k,) the FILL block index of each; ``part`` the part interior (None when
    the mesh has no closed outer wall here); ``area`` the sparse-infill area;
    ``has_walls`` whether the mesh printed walls in this layer.
    """

    mesh: str
    fill: np.ndarray
    fill_block: np.ndarray
    fill_de: np.ndarray
    part: object
    area: object
    has_walls: bool
    used_hull: bool = False


def segments_of(moves: dict, mask: np.ndarray) -> np.ndarray:
    """The masked moves as segments, shape (k, 2, 2) (start, end; x, y), mm."""
    return np.stack([moves["x0"][mask], moves["y0"][mask], moves["x1"][mask], moves["y1"][mask]], axis=1).reshape(-1, 2, 2)


def _segments(parse: LayerParse, mask: np.ndarray) -> np.ndarray:
    return segments_of(parse.moves, mask)


def runs_of(parse: LayerParse, mask: np.ndarray) -> list[np.ndarray]:
    """Contiguous chains of the masked moves as polylines.

    Returns
    -------
    list of ndarray, each shape (m, 2)
        Consecutive masked moves whose ends meet form one polyline (mm).
    """
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    m = parse.moves
    x0, y0, x1, y1 = m["x0"][idx], m["y0"][idx], m["x1"][idx], m["y1"][idx]
    joined = np.zeros(idx.size, dtype=bool)
    joined[1:] = (idx[1:] == idx[:-1] + 1) & (np.abs(x0[1:] - x1[:-1]) < 1e-6) & (np.abs(y0[1:] - y1[:-1]) < 1e-6)
    run_id = np.cumsum(~joined) - 1
    starts = np.flatnonzero(~joined)
    stops = np.r_[starts[1:], idx.size]
    pts_start = np.column_stack([x0, y0])
    pts_end = np.column_stack([x1, y1])
    del run_id
    return [np.vstack([pts_start[a:b], pts_end[b - 1 : b]]) for a, b in zip(starts, stops, strict=True)]


def _closed_rings(runs: list[np.ndarray], tolerance: float) -> list[np.ndarray]:
    rings = []
    for run in runs:
        if len(run) >= 3 and np.hypot(*(run[-1] - run[0])) <= tolerance:
            rings.append(run)
    return rings


def _even_odd(rings: list[np.ndarray]):
    """Even-odd union of closed rings (holes where rings nest)."""
    result = empty_area()
    for ring in rings:
        poly = Polygon(ring)
        if not poly.is_valid:
            poly = make_valid(poly)
        poly = to_multipolygon(poly)
        if poly.is_empty:
            continue
        result = to_multipolygon(result.symmetric_difference(poly))
    return result


def _buffer_runs(runs: list[np.ndarray], radius: float):
    lines = [r for r in runs if len(r) >= 2]
    if not lines:
        return empty_area()
    return to_multipolygon(MultiLineString([LineString(r) for r in lines]).buffer(radius, 4))


def sample_segments(segments: np.ndarray, step: float) -> np.ndarray:
    """Points along segments at most `step` apart, ends included.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
    step : float
        mm.

    Returns
    -------
    ndarray, shape (p, 2)
    """
    if len(segments) == 0:
        return np.zeros((0, 2))
    d = segments[:, 1] - segments[:, 0]
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n + 1)
    offsets = np.arange(seg.size) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
    t = offsets / np.repeat(n, n + 1)
    return segments[seg, 0] + d[seg] * t[:, None]


def fraction_inside(segments: np.ndarray, area, step: float) -> float:
    """Length fraction of `segments` inside `area` (sampled every `step` mm)."""
    if len(segments) == 0:
        return 1.0
    if area is None or area.is_empty:
        return 0.0
    pts = sample_segments(segments, step)
    return float(contains_xy(area, pts[:, 0], pts[:, 1]).mean())


def fill_hull(runs: list[np.ndarray], line_width: float, reach: float, convex_fill: float = 0.8):
    """A closed area around FILL lines.

    The lines are buffered by `reach` and shrunk back to half a line width
    beyond them (a morphological closing).  A piece that fills at least
    `convex_fill` of its convex hull is taken as that hull: sparse lines cut
    the corners of a closing, while their ends lie on the real border (a box
    modifier comes back as its box).
    """
    if not runs:
        return empty_area()
    grown = _buffer_runs(runs, reach)
    closed = to_multipolygon(grown.buffer(-(reach - line_width / 2), 4))
    pieces = []
    for piece in polygons_of(closed):
        hull = piece.convex_hull
        pieces.append(hull if piece.area >= convex_fill * hull.area else piece)
    return to_multipolygon(unary_union(pieces))


def split_by_lines(area, fills: list[np.ndarray], spacings: list[float], step: float = 0.5) -> list:
    """Split `area` among meshes by whose FILL lines are nearest, in units of each one's line spacing.

    Cura cuts infill-mesh modifiers out of their host's infill, so the lines of
    neighbouring meshes end on their common border; comparing distances in
    units of line spacing puts the border between them.  Evaluated on a grid of
    `step` mm (coarser for large areas: at most ~60k probes).

    Parameters
    ----------
    area : (Multi)Polygon
        The host's infill area (includes the modifiers' parts).
    fills : list of ndarray, each shape (k, 2, 2)
        Cura's FILL segments per mesh, mm (may be empty).
    spacings : list of float
        Line spacing per mesh (line width / Cura's density), mm.

    Returns
    -------
    list of MultiPolygon
        One per mesh, in the order given.
    """
    out = [empty_area() for _ in fills]
    if area.is_empty or not any(len(f) for f in fills):
        return out
    minx, miny, maxx, maxy = area.bounds
    step = max(step, np.sqrt((maxx - minx) * (maxy - miny) / 60000.0))
    gx, gy = np.meshgrid(np.arange(minx + step / 2, maxx, step), np.arange(miny + step / 2, maxy, step))
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    inside = contains_xy(area, pts[:, 0], pts[:, 1])
    pts = pts[inside]
    if len(pts) == 0:
        return out
    dist = np.full((len(fills), len(pts)), np.inf)
    for k, (fill, spacing) in enumerate(zip(fills, spacings, strict=True)):
        if len(fill):
            dist[k] = cKDTree(sample_segments(fill, step / 2)).query(pts)[0] / spacing
    owner = np.argmin(dist, axis=0)
    # Each mesh's grid cells as rectangles, one per run of cells along a grid row: far fewer
    # shapes to merge than one square per cell.
    grid = np.full(gx.shape, -1, dtype=np.int64)
    grid.ravel()[inside] = owner
    for k in range(len(fills)):
        runs = np.diff(np.pad(grid == k, ((0, 0), (1, 1))).astype(np.int8), axis=1)
        rows, first = np.nonzero(runs == 1)
        _, stop = np.nonzero(runs == -1)  # row-major order: the i-th stop ends the i-th run
        if len(rows) == 0:
            continue
        x0, x1 = minx + first * step, minx + stop * step
        y0, y1 = miny + rows * step, miny + (rows + 1) * step
        cells = unary_union([Polygon([(a, c), (b, c), (b, d), (a, d)])
                             for a, b, c, d in zip(x0.tolist(), x1.tolist(), y0.tolist(), y1.tolist(), strict=True)])
        out[k] = to_multipolygon(cells.intersection(area))
    return out


class AreaCache:
    """Areas keyed by the bytes of a mesh's wall, skin and FILL geometry (prisms repeat layer after layer)."""

    def __init__(self, size: int = 16):
        self.size = size
        self._items: dict[bytes, tuple] = {}

    def get(self, key: bytes):
        return self._items.get(key)

    def put(self, key: bytes, value: tuple) -> None:
        if len(self._items) >= self.size:
            self._items.pop(next(iter(self._items)))
        self._items[key] = value


def mesh_layer(
    parse: LayerParse,
    mesh: str,
    line_width: float,
    overlap: float,
    fill_reach: float,
    cache: AreaCache | None = None,
) -> MeshLayer:
    """Rebuild one mesh's sparse-infill area in one parsed layer.

    Parameters
    ----------
    parse : LayerParse
    mesh : str
        ``;MESH:`` name.
    line_width : float
        Wall/infill line width, mm.
    overlap : float
        Infill overlap into the innermost wall, mm.
    fill_reach : float
        Closing radius for the FILL hull fallback, mm (about Cura's line spacing).
    cache : AreaCache, optional
    """
    m = parse.moves
    in_mesh = parse.mesh_mask(mesh)
    moved = (m["x1"] != m["x0"]) | (m["y1"] != m["y0"])
    extr = in_mesh & moved & (m["de"] > 0)
    kind = m["kind"]
    fill_mask = extr & (kind == FILL)
    fill = _segments(parse, fill_mask)
    fill_block = m["block"][fill_mask]
    fill_de = m["de"][fill_mask]
    wall_mask = extr & ((kind == WALL_OUTER) | (kind == WALL_INNER))
    has_walls = bool(wall_mask.any())
    skin_mask = extr & (kind == SKIN)

    key = None
    if cache is not None:
        h = hashlib.blake2b(digest_size=16)
        for mask in (wall_mask, skin_mask, fill_mask):
            h.update(np.round(_segments(parse, mask), 3).tobytes())
            h.update(b"|")
        h.update(np.array([line_width, overlap, fill_reach]).tobytes())
        key = h.digest()
        hit = cache.get(key)
        if hit is not None:
            part, area, used_hull = hit
            return MeshLayer(mesh, fill, fill_block, fill_de, part, area, has_walls, used_hull)

    part = None
    area = empty_area()
    if has_walls:
        outer_runs = runs_of(parse, extr & (kind == WALL_OUTER))
        rings = _closed_rings(outer_runs, 2.0 * line_width)
        if rings:
            part = _even_odd(rings)
            walls = _buffer_runs(runs_of(parse, wall_mask), line_width / 2 + _EPS)
            inner = part.difference(walls)
            area = to_multipolygon(inner.buffer(overlap, 4)) if overlap > 0 else to_multipolygon(inner)
    if skin_mask.any() and not area.is_empty:
        skin = _buffer_runs(runs_of(parse, skin_mask), line_width / 2 + _EPS)
        area = to_multipolygon(area.difference(skin))
    area = to_multipolygon(unary_union([p for p in polygons_of(area) if p.area > line_width * line_width]))

    used_hull = False
    if len(fill) and fraction_inside(fill, area, line_width) < 0.95:
        hull = fill_hull(runs_of(parse, fill_mask), line_width, fill_reach)
        if part is not None:
            hull = to_multipolygon(hull.intersection(part.buffer(line_width / 2)))
        area = to_multipolygon(unary_union([area, hull]))
        used_hull = True
    if cache is not None and key is not None:
        cache.put(key, (part, area, used_hull))
    return MeshLayer(mesh, fill, fill_block, fill_de, part, area, has_walls, used_hull)
