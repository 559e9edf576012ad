"""Concave-to-convex decomposition (the paper's layout, Section 2).

A vertex p_i of a counter-clockwise ring is concave (reflex) when the cross
product of P_{i-1}P_i and P_iP_{i+1} (the paper's Formula (3)) is negative.
A polygon is split along diagonals at its reflex vertices until every piece
is convex: diagonals between two reflex vertices first (each removes two),
then diagonals that resolve the reflex angle, shortest first.  Holes are
opened first by cutting along a line through each hole.  Every split makes
both pieces smaller, so the process ends.
"""

from __future__ import annotations

import numpy as np
from shapely.geometry import LineString, Polygon
from shapely.geometry.polygon import orient
from shapely.ops import split

from .geometry import as_area, polygons_of

__all__ = ["cross_turn", "reflex_vertices", "is_convex", "decompose_convex"]

_TOL = 1e-9
_SLIVER_MM2 = 0.01  # a piece this small that cannot be split further is left out ...
_SLIVER_WIDTH_MM = 0.02  # ... and one this thin on average (twice its area over its perimeter), however long


def cross_turn(ring: np.ndarray) -> np.ndarray:
    """The paper's Formula (3) at every vertex of a ring.

    Parameters
    ----------
    ring : ndarray, shape (m, 2)
        Vertices, not repeating the first at the end.

    Returns
    -------
    ndarray, shape (m,)
        (x_i - x_{i-1}) (y_{i+1} - y_i) - (x_{i+1} - x_i) (y_i - y_{i-1});
        > 0 convex, = 0 collinear, < 0 concave for a counter-clockwise ring.
    """
    prev = np.roll(ring, 1, axis=0)
    nxt = np.roll(ring, -1, axis=0)
    return (ring[:, 0] - prev[:, 0]) * (nxt[:, 1] - ring[:, 1]) - (nxt[:, 0] - ring[:, 0]) * (ring[:, 1] - prev[:, 1])


def _open_ring(polygon: Polygon) -> np.ndarray:
    return np.asarray(polygon.exterior.coords, dtype=float)[:-1, :2]


def reflex_vertices(polygon: Polygon) -> np.ndarray:
    """The concave vertices of a polygon's exterior ring.

    Returns
    -------
    ndarray, shape (k, 2)
        Coordinates of the vertices where Formula (3) is negative once the
        ring is counter-clockwise.
    """
    ring = _open_ring(orient(polygon, 1.0))
    scale = max(1.0, float(np.ptp(ring, axis=0).max())) ** 2
    return ring[cross_turn(ring) < -_TOL * scale]


def is_convex(polygon: Polygon) -> bool:
    """True for a polygon without holes and without concave vertices."""
    return len(polygon.interiors) == 0 and len(reflex_vertices(polygon)) == 0


def _split_pieces(polygon: Polygon, line: LineString) -> list[Polygon]:
    pieces = [p for p in polygons_of(split(polygon, line)) if p.area > _TOL * max(polygon.area, 1.0)]
    return pieces if len(pieces) >= 2 else []


def _open_holes(polygon: Polygon) -> list[Polygon]:
    """Cut a polygon with holes along a horizontal line through its first hole (else a vertical one).

    A hole that neither line opens (a sliver where two borders almost meet, so close to the outline
    that a cut leaves only a crumb beside it) is filled when it is at most 0.01 mm².
    """
    hole = Polygon(polygon.interiors[0])
    x, y = hole.representative_point().coords[0]
    x0, y0, x1, y1 = polygon.bounds
    pieces = (_split_pieces(polygon, LineString([(x0 - 1.0, y), (x1 + 1.0, y)]))
              or _split_pieces(polygon, LineString([(x, y0 - 1.0), (x, y1 + 1.0)])))
    if not pieces and hole.area <= _SLIVER_MM2:
        return [Polygon(polygon.exterior, polygon.interiors[1:])]
    if not pieces:
        raise ValueError("could not open a hole of the region for convex decomposition")
    return pieces


def _best_diagonal(polygon: Polygon) -> LineString | None:
    """The diagonal from a reflex vertex to split along, None if none lies inside.

    Candidates ranked by (to another reflex vertex 0, resolving the reflex angle
    1, else 2; length), ties in ring order; the best whose line lies inside the
    polygon is taken.  All candidates are ranked at once: on a curved outline
    (hundreds of vertices, half of them reflex) the containment test runs only
    until the first that holds.
    """
    ring = _open_ring(polygon)
    m = len(ring)
    turn = cross_turn(ring)
    scale = max(1.0, float(np.ptp(ring, axis=0).max())) ** 2
    reflex = turn < -_TOL * scale
    vs = np.flatnonzero(reflex)
    if not vs.size:
        return None
    v = np.repeat(vs, m)  # (k m,): every reflex vertex against every vertex, in ring order
    u = np.tile(np.arange(m), vs.size)
    ok = (u != v) & (u != (v - 1) % m) & (u != (v + 1) % m)
    v, u = v[ok], u[ok]
    d = ring[u] - ring[v]
    to_next = ring[(v + 1) % m] - ring[v]
    to_prev = ring[(v - 1) % m] - ring[v]
    resolves = (to_next[:, 0] * d[:, 1] - to_next[:, 1] * d[:, 0] >= 0) & (d[:, 0] * to_prev[:, 1] - d[:, 1] * to_prev[:, 0] >= 0)
    rank = np.where(reflex[u], 0, np.where(resolves, 1, 2))
    order = np.lexsort((np.hypot(d[:, 0], d[:, 1]), rank))  # stable: ties keep ring order
    for k in order.tolist():
        line = LineString([ring[v[k]], ring[u[k]]])
        if polygon.contains(line):
            return line
    return None


def decompose_convex(region) -> list[Polygon]:
    """Split a region into convex polygons.

    Parameters
    ----------
    region : shapely Polygon or MultiPolygon
        Holes allowed.

    Returns
    -------
    list of Polygon
        Convex pieces covering the region exactly (no overlaps), but for slivers
        of at most 0.01 mm² or 0.02 mm wide on average (units mm) that no
        diagonal, edge extension or triangulation splits.
    """
    stack = [orient(p, 1.0) for p in polygons_of(as_area(region))]
    out: list[Polygon] = []
    while stack:
        poly = stack.pop()
        if poly.interiors:
            stack.extend(orient(p, 1.0) for p in _open_holes(poly))
            continue
        if is_convex(poly):
            out.append(poly)
            continue
        line = _best_diagonal(poly)
        pieces = _split_pieces(poly, line) if line is not None else []
        if len(pieces) < 2:
            # No diagonal between vertices lies inside (one would touch the border): cut along an
            # edge of a reflex vertex carried on into the polygon, else into ear-clipped triangles.
            pieces = _extension_pieces(poly) or _triangles(poly)
        if len(pieces) < 2:
            if poly.area <= _SLIVER_MM2 or 2.0 * poly.area <= _SLIVER_WIDTH_MM * poly.length:
                continue  # a sliver (where two borders almost meet) that nothing fits in: left out
            raise ValueError("convex decomposition failed: no valid diagonal at a concave vertex")
        stack.extend(orient(p, 1.0) for p in pieces)
    return out


def _extension_pieces(polygon: Polygon) -> list[Polygon]:
    """The polygon cut along the extension of an edge beyond one of its reflex vertices ([] if none cuts it).

    The cut ends where it meets the border, so it resolves that vertex's reflex angle.
    """
    ring = _open_ring(polygon)
    m = len(ring)
    turn = cross_turn(ring)
    scale = max(1.0, float(np.ptp(ring, axis=0).max()))
    for v in np.flatnonzero(turn < -_TOL * scale * scale):
        for before in (ring[(v - 1) % m], ring[(v + 1) % m]):
            direction = ring[v] - before
            norm = float(np.hypot(*direction))
            if norm <= 0:
                continue
            ray = LineString([ring[v], ring[v] + direction / norm * 4.0 * scale])
            pieces = [p for p in _split_pieces(polygon, ray) if p.area > _TOL * scale * scale]
            if len(pieces) >= 2:
                return pieces
    return []


def _triangles(polygon: Polygon) -> list[Polygon]:
    """Ear-clipped triangles of a simple polygon (each convex); [] when it cannot be triangulated."""
    from .models import triangulate_polygon

    ring = _open_ring(polygon)
    try:
        triangles = triangulate_polygon(ring)
    except ValueError:
        return []
    return [Polygon(ring[t]) for t in triangles if Polygon(ring[t]).area > 0]
