"""Rebuilding a layer's sparse-infill area from the G-code's walls, skin and FILL.

The G-code carries no infill polygons.  Per mesh and layer:

* the part interior is the even-odd union of the WALL-OUTER loops, a loop
  joined from the pieces Cura prints it in (`wall_rings`);
* the walls' footprint is every wall line buffered by half a line width;
* infill area = (interior - walls) grown by the infill overlap, minus the
  skin: its lines and the space between them (`skin_region`);
* a mesh without walls (an infill-only mesh) has a closed hull of its FILL
  lines as its area;
* what other meshes print in the layer is not infill area of this one
  (`without_foreign`): their walls and skin, and the whole part of a mesh
  with walls inside this one (an infill mesh, which Cura cuts out of it).

Nothing here trusts Cura's FILL lines to widen an area: where they fall
outside it, `witness.py` keeps Cura's own lines there.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon
from shapely.validation import make_valid

from ..geometry import (
    boxes_meet,
    contains_xy,
    empty_area,
    multilinestring_of,
    polygons_of,
    to_multipolygon,
    unary_union,
)
from .read import FILL, SKIN, WALL_INNER, WALL_OUTER, LayerParse

__all__ = [
    "MeshLayer",
    "mesh_layer",
    "without_foreign",
    "CarvedArea",
    "carved_as_cura4",
    "cura4_infill_areas",
    "runs_of",
    "fill_hull",
    "fraction_inside",
    "piece_centres",
    "sample_segments",
    "segments_of",
    "direction_peaks",
    "median_of",
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
    starts = np.flatnonzero(~joined)
    stops = np.r_[starts[1:], idx.size]
    # every run's start points followed by its last end point, all runs in one array; a run is a slice of it
    points = np.insert(np.column_stack([x0, y0]), stops, np.column_stack([x1[stops - 1], y1[stops - 1]]), axis=0)
    first = starts + np.arange(len(starts))
    last = stops + np.arange(1, len(stops) + 1)
    return [points[a:b] for a, b in zip(first.tolist(), last.tolist())]


def wall_rings(runs: list[np.ndarray], tolerance: float) -> list[np.ndarray]:
    """Closed loops from wall runs, a loop joined from the pieces it was printed in.

    Cura prints some wall loops in pieces with short travels between them (a
    hole's wall in three pieces, a loop broken where another part's wall
    meets it).  Runs are chained end to start, nearest end first, while the
    gap is at most `tolerance`; a chain is a loop when its ends meet within
    `tolerance`.  Pieces that close no loop are left out.

    Parameters
    ----------
    runs : list of ndarray, each shape (m, 2)
        Polylines of wall moves, mm.
    tolerance : float
        Largest gap bridged, mm.

    Returns
    -------
    list of ndarray, each shape (m, 2)
    """
    rings, pieces = [], []
    for run in runs:
        if len(run) < 2:
            continue
        if len(run) >= 3 and np.hypot(*(run[-1] - run[0])) <= tolerance:
            rings.append(run)
        else:
            pieces.append(run)
    if not pieces:
        return rings
    heads = np.array([p[0] for p in pieces])
    tails = np.array([p[-1] for p in pieces])
    free = np.ones(len(pieces), dtype=bool)
    for first in range(len(pieces)):
        if not free[first]:
            continue
        free[first] = False
        chain = [pieces[first]]
        head, tail = heads[first], tails[first]
        while free.any():
            # the nearest free end to the chain's tail: a piece's head (as printed) or its tail (reversed)
            to_heads = np.where(free, np.hypot(*(heads - tail).T), np.inf)
            to_tails = np.where(free, np.hypot(*(tails - tail).T), np.inf)
            k_head, k_tail = int(np.argmin(to_heads)), int(np.argmin(to_tails))
            if min(to_heads[k_head], to_tails[k_tail]) > tolerance:
                break
            if to_heads[k_head] <= to_tails[k_tail]:
                chain.append(pieces[k_head])
                tail = tails[k_head]
                free[k_head] = False
            else:
                chain.append(pieces[k_tail][::-1])
                tail = heads[k_tail]
                free[k_tail] = False
            if np.hypot(*(tail - head)) <= tolerance:
                break
        joined = np.concatenate(chain)
        if len(joined) >= 3 and np.hypot(*(tail - head)) <= tolerance:
            rings.append(joined)
    return rings


def _even_odd(rings: list[np.ndarray]):
    """Even-odd union of closed rings (holes where rings nest)."""
    result = None
    for ring in rings:
        poly = Polygon(ring)
        if not poly.is_valid:
            poly = make_valid(poly)
        poly = to_multipolygon(poly)
        if poly.is_empty:
            continue
        # (the first ring is the result so far: an overlay with nothing costs as much as one with it)
        result = poly if result is None else to_multipolygon(result.symmetric_difference(poly))
    return empty_area() if result is None else result


def _buffer_runs(runs: list[np.ndarray], radius: float):
    lines = [r for r in runs if len(r) >= 2]
    if not lines:
        return empty_area()
    return to_multipolygon(multilinestring_of(lines).buffer(radius, 4))


def _opened(area, line_width: float):
    """`area` without the strips narrower than 0.9 line widths that walls and skin leave between them.

    Cura's skin lines run up to the inner wall; the space between the wall's and the skin's
    buffers is a sliver that no infill line of Cura's goes in (a line along it would lie on both).
    A mitred opening keeps the area's corners.
    """
    r = 0.45 * line_width
    return _grown_back(area, area.buffer(-r, join_style=2, mitre_limit=4.0), r)


def _opened_as_cura4(area, line_width: float):
    """`area` opened as CuraEngine 4.13 opens every infill area: shrunk and grown back by half a line width.

    (``generateInfill``: ``offset(-w / 2).offset(w / 2)``, Clipper's mitre joins with a limit of 1.2,
    which cut corners almost as round ones do.)  Strips narrower than a line width go, and sharp tips
    lose what no line-wide disc reaches: CuraEngine 4.13 prints no infill there.  CuraEngine 5 does
    not open the area.
    """
    r = line_width / 2
    return _grown_back(area, area.buffer(-r, join_style=2, mitre_limit=1.2), r, mitre_limit=1.2)


def _grown_back(area, shrunk, radius: float, mitre_limit: float = 4.0):
    """`shrunk` (`area` shrunk by `radius`, mitred) grown back inside `area`: the opening's second half."""
    if shrunk.is_empty:
        return empty_area()
    grown = to_multipolygon(_mitred_grown(shrunk, radius, mitre_limit).intersection(area))
    cores = polygons_of(shrunk)
    if len(cores) < 2:
        return grown
    # Two cores may grow back into one piece: the mitred spikes of their sharp tips meet in the neck
    # between them (random shape 111: a pocket between two holes' walls).  Then the neck goes.
    inside = np.array([c.representative_point().coords[0] for c in cores])
    owner = np.full(len(cores), -1)
    for k, piece in enumerate(polygons_of(grown)):
        owner[contains_xy(piece, inside[:, 0], inside[:, 1])] = k
    if len(np.unique(owner)) == len(cores):
        return grown
    backs = [_mitred_grown(c, radius, mitre_limit) for c in cores]
    lo_x, lo_y, hi_x, hi_y = np.array([b.bounds for b in backs]).T
    pair = ((owner[:, None] == owner[None]) & (lo_x[:, None] <= hi_x[None]) & (lo_x[None] <= hi_x[:, None])
            & (lo_y[:, None] <= hi_y[None]) & (lo_y[None] <= hi_y[:, None]))
    meets = [backs[i].intersection(backs[j]) for i, j in zip(*np.nonzero(np.triu(pair, 1)), strict=True)
             if backs[i].intersects(backs[j])]
    if not meets:
        return grown
    return to_multipolygon(grown.difference(unary_union(meets).buffer(_EPS, 4)))


def _mitred_grown(shape, radius: float, mitre_limit: float):
    """`shape` grown by `radius` with mitred joins, valid: GEOS can return a mitred buffer that crosses
    itself where two sharp corners' spikes meet, and an overlay with it then fails (random regions 35,
    CuraEngine 5.0: "TopologyException: found non-noded intersection", a failed layer)."""
    return valid_area(shape.buffer(radius, join_style=2, mitre_limit=mitre_limit))


def _without_necks(area, line_width: float):
    """`area` cut where a strip narrower than 0.9 line widths joins two of its parts, or is all of a piece.

    Walls of two loops (a hole's and the outline's) that run within two line widths of each other
    leave such a strip between their buffers, where Cura has no infill area: through it a pocket
    beyond would count as part of the rest (`witness`: the new infill there "takes over" Cura's
    line in the pocket).  The opening of `_opened` is done only where it changes the pieces: a
    piece whose core (shrunk by 0.45 line widths) is one piece keeps its outline (a finger that
    ends in it is the witness's to judge).
    """
    r = 0.45 * line_width
    shrunk = area.buffer(-r, join_style=2, mitre_limit=4.0)
    pieces, cores = polygons_of(area), polygons_of(shrunk)
    if len(cores) == len(pieces):
        inside = np.array([c.representative_point().coords[0] for c in cores]).reshape(-1, 2)
        owners = [np.flatnonzero(contains_xy(p, inside[:, 0], inside[:, 1])) for p in pieces]
        if all(len(o) == 1 for o in owners) and len({int(o[0]) for o in owners}) == len(pieces):
            return area
    return _grown_back(area, shrunk, r)


def without_necks(area, line_width: float, cura4_opening: bool = False):
    """`area` without the strips under a line width that join two of its parts (`_without_necks`),
    or opened as CuraEngine 4.13 opens every infill area (`cura4_opening`, `_opened_as_cura4`)."""
    return _opened_as_cura4(area, line_width) if cura4_opening else _without_necks(area, line_width)


def skin_region(runs: list[np.ndarray], line_width: float):
    """The area skin covers: its lines grown by half a line width, the gaps between them closed.

    Skin lines lie about a line width apart (bridges and some top/bottom
    patterns a little more), so the space between neighbouring lines is skin
    too: a closing of one line width joins lines up to two line widths apart.

    Parameters
    ----------
    runs : list of ndarray, each shape (m, 2)
        Polylines of skin moves, mm.
    line_width : float
        mm.
    """
    reach = line_width
    # Grown in two steps, which is the same area (discs add: r1 + r2): first each line by its half
    # width and a hair more, so neighbours a line width apart just overlap, then that area by the
    # rest.  GEOS unions a line buffer's offset curves: at the full radius every line overlaps two
    # or three neighbours, and that union costs twice the two steps on a top skin.
    strips = _buffer_runs(runs, line_width / 2 + _EPS)
    if strips.is_empty:
        return strips
    grown = strips.buffer(reach - _EPS, 4)
    return to_multipolygon(grown.buffer(-reach, 4))


def run_bounds(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the runs of segments printed one after another start and stop (each starting where the
    last ended): (starts, stops) indices into `segments` (k, 2, 2), the run being ``segments[a:b]``."""
    joined = np.zeros(len(segments), dtype=bool)
    joined[1:] = (np.abs(segments[1:, 0] - segments[:-1, 1]) < 1e-6).all(axis=1)
    starts = np.flatnonzero(~joined)
    return starts, np.r_[starts[1:], len(segments)]


def closed_loops(segments: np.ndarray, tolerance: float = 0.05) -> tuple[list[np.ndarray], np.ndarray]:
    """The closed polylines among segments printed one after another (Cura's infill walls).

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        Extrusion segments in the order printed, mm.
    tolerance : float
        How close a run's last point comes back to its first, mm.

    Returns
    -------
    loops : list of ndarray, each shape (m, 2)
        The closed runs as polylines (last point = first, within `tolerance`).
    in_loops : ndarray of bool, shape (k,)
        Which segments belong to them.
    """
    in_loops = np.zeros(len(segments), dtype=bool)
    if len(segments) < 3:
        return [], in_loops
    starts, stops = run_bounds(segments)
    gap = segments[stops - 1, 1] - segments[starts, 0]
    closed = ((stops - starts) >= 3) & (np.hypot(gap[:, 0], gap[:, 1]) < tolerance)
    loops = []
    for a, b in zip(starts[closed].tolist(), stops[closed].tolist()):  # (a few loops a layer)
        loops.append(np.vstack([segments[a:b, 0], segments[b - 1 : b, 1]]))
        in_loops[a:b] = True
    return loops, in_loops


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
    return segment_samples(segments, step)[0]


def segment_samples(segments: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """`sample_segments`, and which segment each sample lies on.

    Returns
    -------
    points : ndarray, shape (p, 2)
        mm.
    owner : ndarray, shape (p,)
        Index into `segments`.
    """
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    d = segments[:, 1] - segments[:, 0]
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n + 1)
    offsets = np.arange(seg.size) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
    t = offsets / np.repeat(n, n + 1)
    return segments[seg, 0] + d[seg] * t[:, None], seg


def piece_centres(segments: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Each segment cut into equal pieces at most `step` long: the pieces' centres and lengths.

    A length measured by which centres lie in an area counts a segment that ends on the area's border
    (a clipped line) whole; samples on its ends would fall on the border, in or out by rounding.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        mm.
    step : float
        mm.

    Returns
    -------
    centres : ndarray, shape (p, 2)
        mm.
    lengths : ndarray, shape (p,)
        mm; they sum to the segments' length.
    """
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    d = segments[:, 1] - segments[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(1, np.ceil(length / step).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n)
    index = np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)
    t = (index + 0.5) / n[seg]
    return segments[seg, 0] + d[seg] * t[:, None], (length / n)[seg]


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


def direction_peaks(fill: np.ndarray, min_share: float = 0.12):
    """Main directions of segments, on a 2-degree histogram weighted by length.

    Parameters
    ----------
    fill : ndarray, shape (k, 2, 2)
        Segments, mm.
    min_share : float
        A peak holds at least this share of the total length.

    Returns
    -------
    length : ndarray, shape (k,)
        Segment lengths, mm.
    angle : ndarray, shape (k,)
        Directions in degrees, [0, 180).
    peaks : ndarray of int
        Histogram bins (bin b is 2 b degrees) that are local maxima.
    total : float
        Total length, mm.
    """
    d = fill[:, 1] - fill[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    angle = np.mod(np.degrees(np.arctan2(d[:, 1], d[:, 0])), 180.0)
    bins = np.round(angle / 2.0).astype(int) % 90
    weight = np.bincount(bins, weights=length, minlength=90)
    total = float(weight.sum())
    # A direction can straddle two 2-degree bins: smooth, then take local maxima as families
    # (neighbours round the circle of bins by padding; np.roll costs more on 90 bins).
    around = np.concatenate((weight[-1:], weight, weight[:1]))
    smooth = around[1:-1] + around[:-2] + around[2:]
    around = np.concatenate((smooth[-1:], smooth, smooth[:1]))
    peak = (smooth > min_share * total) & (smooth >= around[:-2]) & (smooth > around[2:])
    return length, angle, np.flatnonzero(peak), total


def median_of(values: np.ndarray) -> float:
    """Median of a 1-d array, as ``np.median`` gives it (a plain sort: far less overhead on a few values)."""
    ordered = np.sort(values)
    half = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[half])
    return float((ordered[half - 1] + ordered[half]) / 2.0)


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
    hull_without_walls: bool = True,
    cura4_opening: bool = False,
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
    hull_without_walls : bool
        Whether a mesh without walls here gets the FILL hull as its area.  An
        infill-mesh modifier needs none: its host's area holds its part (and
        the hull's closing is the costliest step); its area stays empty.
    cura4_opening : bool
        Open the area as CuraEngine 4.13 does (`_opened_as_cura4`) instead of cutting only the
        slivers beside skin and the necks between parts (CuraEngine 5 keeps every corner).
    """
    m = parse.moves
    extr = parse.mesh_mask(mesh) & parse.extruding()
    fill_mask = extr & parse.kind_mask(FILL)
    fill_block = m["block"][fill_mask]
    fill_de = m["de"][fill_mask]
    outer_mask = extr & parse.kind_mask(WALL_OUTER)
    wall_mask = outer_mask | (extr & parse.kind_mask(WALL_INNER))
    has_walls = bool(wall_mask.any())
    skin_mask = extr & parse.kind_mask(SKIN)
    # the wall, skin and FILL segments at once; each class is a selection of them
    used = wall_mask | skin_mask | fill_mask
    segments = parse.xy_segments()[used]
    fill = segments[fill_mask[used]]

    key = None
    if cache is not None:
        rounded = np.round(segments, 3)
        h = hashlib.blake2b(digest_size=16)
        for mask in (wall_mask, skin_mask, fill_mask):
            h.update(rounded[mask[used]].tobytes())
            h.update(b"|")
        h.update(np.array([line_width, overlap, fill_reach, hull_without_walls, cura4_opening]).tobytes())
        key = h.digest()
        hit = cache.get(key)
        if hit is not None:
            part, area, used_hull = hit
            return MeshLayer(mesh, fill, fill_block, fill_de, part, area, has_walls, used_hull)

    part = None
    area = empty_area()
    if has_walls:
        rings = wall_rings(runs_of(parse, outer_mask), 2.0 * line_width)
        if rings:
            part = _even_odd(rings)
            walls = _buffer_runs(runs_of(parse, wall_mask), line_width / 2 + _EPS)
            inner = part.difference(walls)
            area = to_multipolygon(inner.buffer(overlap, 4)) if overlap > 0 else to_multipolygon(inner)
    if skin_mask.any() and not area.is_empty:
        area = area.difference(skin_region(runs_of(parse, skin_mask), line_width))
        area = _opened_as_cura4(area, line_width) if cura4_opening else _opened(area, line_width)
    elif not area.is_empty:
        area = without_necks(area, line_width, cura4_opening)
    pieces = polygons_of(area)
    kept = [p for p in pieces if p.area > line_width * line_width]
    if len(kept) < len(pieces):  # (slivers left between walls and skin go; else the area stays as it is)
        area = to_multipolygon(unary_union(kept))

    used_hull = False
    if len(fill) and not has_walls and hull_without_walls:
        # An infill-only mesh: its FILL lines are all there is to go by.
        area = fill_hull(runs_of(parse, fill_mask), line_width, fill_reach)
        used_hull = True
    if cache is not None and key is not None:
        cache.put(key, (part, area, used_hull))
    return MeshLayer(mesh, fill, fill_block, fill_de, part, area, has_walls, used_hull)


def _foreign_key(segments: np.ndarray, kinds: np.ndarray, meshes: np.ndarray, line_width: float, area) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    for a in (np.round(segments, 3), kinds, meshes, np.array([line_width])):
        h.update(np.ascontiguousarray(a).tobytes() + b"|")
    coords = [np.round(np.asarray(r.coords), 3).tobytes() for p in polygons_of(area) for r in (p.exterior, *p.interiors)]
    h.update(b"|".join(coords))
    return h.digest()


def without_foreign(parse: LayerParse, geo: MeshLayer, line_width: float, cache: AreaCache | None = None) -> MeshLayer:
    """`geo` with what the layer's other meshes print cut out of its area.

    Cura gives each mesh its own walls and skin, and an infill mesh with walls
    (or a mesh nested in another with carving off) is cut out of the infill of
    the mesh around it: the host's walls do not go round it.  So the area
    rebuilt from the host's own walls holds the other mesh's walls, its skin
    (an infill mesh's bottom and top layers are skin) and its infill.  Cut out:
    the other meshes' wall lines grown by half a line width, their skin
    (`skin_region`), and the part inside the outer walls of each other mesh
    whose part lies (nine tenths or more) inside this mesh's part.

    Parameters
    ----------
    parse : LayerParse
    geo : MeshLayer
        The mesh's geometry in this layer (`mesh_layer`).
    line_width : float
        mm.
    cache : AreaCache, optional

    Returns
    -------
    MeshLayer
        `geo` itself when no other mesh prints walls or skin near its area,
        else a copy with the smaller area (the same area object for a layer
        that repeats the last one, from `cache`).
    """
    area = geo.area
    if area.is_empty:
        return geo
    m = parse.moves
    kinds = m["kind"]
    others = parse.extruding() & ~parse.mesh_mask(geo.mesh)
    others &= (kinds == WALL_OUTER) | (kinds == WALL_INNER) | (kinds == SKIN)
    if not others.any():
        return geo
    # only moves that reach the area's bounding box (grown by a line width) can touch it
    x_lo, y_lo, x_hi, y_hi = area.bounds
    reach = line_width
    x_lo, y_lo, x_hi, y_hi = x_lo - reach, y_lo - reach, x_hi + reach, y_hi + reach
    near = ((np.maximum(m["x0"], m["x1"]) >= x_lo) & (np.minimum(m["x0"], m["x1"]) <= x_hi)
            & (np.maximum(m["y0"], m["y1"]) >= y_lo) & (np.minimum(m["y0"], m["y1"]) <= y_hi))
    others &= near
    if not others.any():
        return geo
    key = None
    if cache is not None:
        key = b"foreign" + _foreign_key(parse.xy_segments()[others], kinds[others], m["mesh"][others], line_width, area)
        hit = cache.get(key)
        if hit is not None:
            return MeshLayer(geo.mesh, geo.fill, geo.fill_block, geo.fill_de, geo.part, hit[0], geo.has_walls, geo.used_hull)
    walls = others & ((kinds == WALL_OUTER) | (kinds == WALL_INNER))
    pieces = [_buffer_runs(runs_of(parse, walls), line_width / 2 + _EPS)]
    skin = others & (kinds == SKIN)
    if skin.any():
        pieces.append(skin_region(runs_of(parse, skin), line_width))
    host = geo.part if geo.part is not None else area
    host_grown = host.buffer(line_width, 4)
    outer = others & (kinds == WALL_OUTER)
    for index in np.unique(m["mesh"][outer]).tolist():
        rings = wall_rings(runs_of(parse, outer & (m["mesh"] == index)), 2.0 * line_width)
        nested = _even_odd(rings) if rings else empty_area()
        if not nested.is_empty and nested.difference(host_grown).area <= 0.1 * nested.area:
            pieces.append(to_multipolygon(nested.buffer(line_width / 2, 4)))
    pieces = [p for p in pieces if not p.is_empty]
    smaller = _opened(area.difference(unary_union(pieces)), line_width) if pieces else area
    kept = [p for p in polygons_of(smaller) if p.area > line_width * line_width]
    if len(kept) < len(polygons_of(smaller)):  # (slivers between the other mesh's walls and ours go)
        smaller = to_multipolygon(unary_union(kept))
    if cache is not None and key is not None:
        cache.put(key, (smaller,))
    return MeshLayer(geo.mesh, geo.fill, geo.fill_block, geo.fill_de, geo.part, smaller, geo.has_walls, geo.used_hull)


@dataclass(frozen=True)
class CarvedArea:
    """A host's infill area as CuraEngine 4.13 leaves it to its wall-less modifiers and itself."""

    area: object  # MultiPolygon: where the new infill may go, mm
    pieces: object  # MultiPolygon: the meshes' own areas, each an island of Cura's infill (None: as `area`'s)


def carved_as_cura4(area, modifiers: list, line_width: float, lines: np.ndarray | None = None) -> CarvedArea:
    """`area` less what wall-less infill meshes leave empty in CuraEngine 4.13: a rim along its border,
    and the pieces its carving insets and opens away.

    CuraEngine 4.13 gives an infill-mesh modifier the host's infill area inside its outline and insets
    that by half an inner wall's width even when the modifier has no walls (``generateInfill``'s
    inner-wall offset): its lines end half a line width short of where the host's would (CuraEngine 5
    does not inset).  A narrow part inside such a modifier printed to the host's border put 1-12 % of
    a layer's new infill where Cura prints none (random regions 1, 10, 15).  Pieces that carving leaves
    to no mesh (`cura4_infill_areas`) go too, but for a quarter line width round each mesh's own area
    (which closes the half line width Cura leaves between two meshes' areas, not the wider gap where
    an opening rounded their corners) and half a line width round Cura's lines.  The islands of Cura's
    infill (`CarvedArea.pieces`) are the meshes' own areas and Cura's lines a tenth of a line width wide.

    Parameters
    ----------
    area : MultiPolygon
        The host's infill area, mm.
    modifiers : list of (Multi)Polygon
        The modifiers' areas in the layer in CuraEngine's mesh order (any extent: only where they
        overlap `area` counts), mm.
    line_width : float
        mm.
    lines : ndarray, shape (k, 2, 2), optional
        Cura's FILL of the host and its modifiers, mm: where it runs stays.
    """
    modifiers = [m for m in modifiers if not m.is_empty and boxes_meet(m.bounds, area.bounds) and m.intersects(area)]
    if not modifiers or area.is_empty:
        return CarvedArea(area, None)
    rim = unary_union(modifiers).intersection(area).difference(area.buffer(-line_width / 2, 4))
    kept = area.difference(rim) if not rim.is_empty else area
    owned = [own for own in cura4_infill_areas(area, modifiers, line_width) if not own.is_empty]
    reach, islands = owned, owned
    if lines is not None and len(lines):  # (where Cura printed, its area is: the witness outranks the model)
        runs = list(lines)
        reach = [*owned, _buffer_runs(runs, line_width / 2).intersection(area)]
        # As islands, thin strips: half a line width wide, a mesh's line ending at its own area's edge and
        # another mesh's line beside it bridged the gap between their areas and made one island of two
        # (random regions 148: a 0.88 mm² tip lost Cura's line to the new lines of the region beyond)
        islands = [*owned, _buffer_runs(runs, 0.1 * line_width).intersection(area)]
    if not reach:
        return CarvedArea(empty_area(), empty_area())
    pieces = to_multipolygon(unary_union(islands))
    grown = to_multipolygon(unary_union(reach)).buffer(line_width / 4 + _EPS, 4)
    return CarvedArea(valid_area(kept.intersection(grown)), pieces)


def valid_area(shape):
    """`shape` as a valid MultiPolygon: GEOS can hand back an overlay whose holes nest, which the next
    overlay fails on (random regions 50: "TopologyException: found non-noded intersection", a failed layer)."""
    shape = to_multipolygon(shape)
    return shape if shape.is_valid else to_multipolygon(shape.buffer(0))


def cura4_infill_areas(area, modifiers: list, line_width: float) -> list:
    """Each mesh's own infill area as CuraEngine 4.13 carves wall-less infill meshes out of a host's.

    Each modifier in turn (a later one wins) takes its outline's share of every earlier mesh's own area,
    which loses it; each share is a part of the modifier, inset by half a line width (the inner-wall
    offset it gets without walls) and opened by half a line width (``processInfillMesh``, then
    ``generateInfill``).  A modifier inside another is inset twice over: a strip of it narrower than
    about three line widths along the host's walls is no mesh's (random regions 104: a 60 % sphere
    over an 80 % cube in a 5 x 2 mm part, a third of the part).

    Parameters
    ----------
    area : MultiPolygon
        The host's infill area, mm.
    modifiers : list of (Multi)Polygon
        The wall-less modifiers' sections in the layer, in CuraEngine's mesh order, mm.
    line_width : float
        mm.

    Returns
    -------
    list of MultiPolygon
        The host's own area, then each modifier's.
    """
    owns = [to_multipolygon(area)]
    for outline in modifiers:
        shares = []
        for k, own in enumerate(owns):
            if own.is_empty or not boxes_meet(own.bounds, outline.bounds):
                continue
            share = own.intersection(outline)
            if share.is_empty:
                continue
            shares.append(share)
            owns[k] = valid_area(own.difference(outline))
        parts = [_opened_as_cura4(to_multipolygon(s.buffer(-line_width / 2, join_style=2, mitre_limit=1.2)), line_width)
                 for s in shares]
        owns.append(valid_area(unary_union([p for p in parts if not p.is_empty])) if parts else empty_area())
    return owns
