"""Travel that stays inside the part: shortest paths around concave corners and holes.

Cura "combs" its travels: a move between two places of the same part follows the inside of the part
instead of crossing the outside, so it needs no retraction and strings nothing across the gap. The
infill emitter asks this module for such a path whenever a straight travel would leave the part.

The shortest path inside a polygon bends only at its reflex vertices. The path's bends are taken on
the part shrunk by a margin (the nozzle keeps clear of the outer wall); every leg of the path is tested
against the part itself, exactly, by clipping.
"""

from __future__ import annotations

import numpy as np
from shapely.geometry.polygon import orient

from .decomposition import cross_turn
from .geometry import SHAPELY2, contains_xy, covers_segments, polygons_of, rings_of, to_multipolygon
from .routing import clip_segments

__all__ = ["CombingArea", "segments_inside"]


def segments_inside(starts: np.ndarray, ends: np.ndarray, area) -> np.ndarray:
    """Whether each straight segment lies inside `area` (its clipped length equals its length).

    Parameters
    ----------
    starts, ends : (k, 2) float arrays
        End points, mm. Rows with a non-finite coordinate are never inside.
    area : shapely Polygon or MultiPolygon, or None

    Returns
    -------
    (k,) bool array. A zero-length segment is inside when its point is.
    """
    starts = np.asarray(starts, dtype=float).reshape(-1, 2)
    ends = np.asarray(ends, dtype=float).reshape(-1, 2)
    if area is None or len(starts) == 0 or area.is_empty:
        return np.zeros(len(starts), dtype=bool)
    known = np.isfinite(starts).all(axis=1) & np.isfinite(ends).all(axis=1)
    everyone = bool(known.all())
    if not everyone:
        if not known.any():
            return known
        starts, ends = starts[known], ends[known]
    # (the emitter asks a few travels at a time, many times a layer: no step more than needed)
    segments = np.concatenate([starts, ends], axis=1).reshape(-1, 2, 2)
    delta = ends - starts
    length = np.hypot(delta[:, 0], delta[:, 1])
    point = length <= 1e-9
    has_points = bool(point.any())
    lines = segments[~point] if has_points else segments
    inside = covers_segments(area, lines) if SHAPELY2 else None
    if inside is None:  # shapely 1.8: clip them, and compare the lengths
        pieces, source = clip_segments(segments, area, return_index=True)
        clipped = np.bincount(source, np.hypot(*(pieces[:, 1] - pieces[:, 0]).T), minlength=len(segments))
        inside = (clipped >= length - 1e-6)[~point]
    if has_points:
        found = np.zeros(len(segments), dtype=bool)
        found[~point] = inside
        found[point] = contains_xy(area, segments[point, 0, 0], segments[point, 0, 1])
    else:
        found = inside
    if everyone:
        return found
    result = np.zeros(len(known), dtype=bool)
    result[known] = found
    return result


def reflex_vertices(area) -> np.ndarray:
    """The vertices of `area` where its inside turns by more than 180 degrees.

    Parameters
    ----------
    area : shapely Polygon or MultiPolygon

    Returns
    -------
    (n, 2) float array, mm: concave corners of the outlines and convex corners of the holes.
    """
    found = []
    for polygon in polygons_of(area):
        # exterior counter-clockwise, holes clockwise: the inside is on the left of every ring,
        # so a right turn (negative cross product) is a reflex corner
        for ring in rings_of(orient(polygon, 1.0)):
            points = ring[:-1] if len(ring) > 1 and np.array_equal(ring[0], ring[-1]) else ring
            if len(points) >= 3:
                found.append(points[cross_turn(points) < 0])
    return np.concatenate(found) if found else np.zeros((0, 2))


class CombingArea:
    """Shortest inside-the-part travels for one layer's part.

    Built once per part (the visibility between its corners is the costly step) and asked for many
    travels. A travel has no combed path when its ends lie in different islands, when an end sees no
    corner, or when the part has more corners than `max_corners` (then the caller retracts).

    Parameters
    ----------
    part : shapely Polygon or MultiPolygon
        Where a travel may go (the area inside the outer wall), mm.
    margin : float
        How far inside the part the path's bends stay, mm (about a line width).
    tolerance : float
        How far outside `part` a leg may pass, mm: the travel's own ends may lie on the part's
        outline (Cura's next move starts on its outer wall), a little outside its reconstruction.
    max_corners : int
        Above this many reflex corners the part is not combed (the visibility test grows as n^2).
    """

    def __init__(self, part, margin: float, *, tolerance: float = 0.0, max_corners: int = 400):
        self.source = part  # the object it was built from (callers key caches by it)
        self.outline = to_multipolygon(part)
        self.tolerance = float(tolerance)
        self._part = None if tolerance > 0 else self.outline  # grown on the first travel asked for
        self.margin = float(margin)
        self.max_corners = int(max_corners)
        self.corners: np.ndarray | None = None  # built on the first travel that needs them
        self._memo: dict[tuple, np.ndarray | None] = {}

    @property
    def part(self):
        """Where a leg may go: the part grown by `tolerance` (built when first asked: most layers'
        travels all stay inside the part, and the emitter asks for no combed path then)."""
        if self._part is None:
            self._part = to_multipolygon(self.outline.buffer(self.tolerance, 4))
        return self._part

    def _build(self) -> None:
        shrunk = self.outline.buffer(-self.margin, 2)
        if not shrunk.is_empty:
            shrunk = shrunk.simplify(self.margin / 4.0, preserve_topology=True)
        corners = reflex_vertices(shrunk) if not shrunk.is_empty else np.zeros((0, 2))
        self.usable = len(corners) <= self.max_corners
        self.corners = corners if self.usable else np.zeros((0, 2))
        n = len(self.corners)
        if n >= 2:
            i, j = np.triu_indices(n, 1)
            seen = segments_inside(self.corners[i], self.corners[j], self.part)
            i, j = i[seen], j[seen]
            self._i = np.concatenate([i, j])
            self._j = np.concatenate([j, i])
        else:
            self._i = self._j = np.zeros(0, dtype=int)
        self._w = np.hypot(*(self.corners[self._i] - self.corners[self._j]).T) if len(self._i) else np.zeros(0)

    def path(self, start, end) -> np.ndarray | None:
        """The bends of the shortest inside travel from `start` to `end`.

        Parameters
        ----------
        start, end : (2,) float, mm

        Returns
        -------
        (k, 2) float array of the points between `start` and `end` (k = 0 when the straight travel
        stays inside), or None when no inside path is known.
        """
        key = (float(start[0]), float(start[1]), float(end[0]), float(end[1]))
        if key not in self._memo:  # the same travels come back layer after layer on a prism
            if len(self._memo) >= 1024:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = self._shortest(np.array(key[:2]), np.array(key[2:]))
        return self._memo[key]

    def _shortest(self, start: np.ndarray, end: np.ndarray) -> np.ndarray | None:
        if segments_inside(start[None], end[None], self.part)[0]:
            return np.zeros((0, 2))
        if self.corners is None:
            self._build()
        n = len(self.corners)
        if not self.usable or n == 0:
            return None
        ends = np.array([start, end])
        seen = segments_inside(np.repeat(ends, n, axis=0), np.tile(self.corners, (2, 1)), self.part).reshape(2, n)
        if not seen[0].any() or not seen[1].any():
            return None
        s, t = n, n + 1  # graph ids of the travel's ends
        from_s = np.flatnonzero(seen[0])
        to_t = np.flatnonzero(seen[1])
        rows = np.concatenate([self._i, np.full(len(from_s), s), to_t])
        cols = np.concatenate([self._j, from_s, np.full(len(to_t), t)])
        weights = np.concatenate([
            self._w,
            np.hypot(*(self.corners[from_s] - start).T),
            np.hypot(*(self.corners[to_t] - end).T),
        ])
        # (imported here: most runs comb no travel, and the graph module adds to every start-up)
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        graph = coo_matrix((np.maximum(weights, 1e-9), (rows, cols)), shape=(n + 2, n + 2)).tocsr()
        dist, previous = dijkstra(graph, directed=True, indices=s, return_predecessors=True)
        if not np.isfinite(dist[t]):
            return None
        bends = []
        node = previous[t]
        while node != s and node >= 0:
            bends.append(node)
            node = previous[node]
        return self.corners[bends[::-1]]
