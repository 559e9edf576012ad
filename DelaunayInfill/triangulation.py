"""Delaunay triangulation, the paper's LOP criterion, angle statistics, relaxation.

The triangulation is qhull's (``scipy.spatial.Delaunay``).  The paper's
Local Optimization Procedure (Lawson) flips an interior edge when the two
angles opposite it sum to more than 180 degrees; `lop_violations` counts such
edges, so a triangulation that satisfies the criterion has none.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from .geometry import contains_xy

__all__ = [
    "delaunay_triangles",
    "GrowingDelaunay",
    "growing_delaunay",
    "canonical_triangles",
    "unique_edges",
    "lop_violations",
    "triangle_angles",
    "edge_length_stats",
    "relax_points",
    "node_edge_counts",
    "uncrowded_edges",
]


def delaunay_triangles(points: np.ndarray) -> np.ndarray:
    """Delaunay triangles of a point set.

    Parameters
    ----------
    points : ndarray, shape (n, 2)

    Returns
    -------
    ndarray of int, shape (t, 3)
        Vertex indices, counter-clockwise; empty when fewer than 3
        non-collinear points.
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 3:
        return np.zeros((0, 3), dtype=np.intp)
    try:
        tri = Delaunay(points)
    except (QhullError, ValueError):  # all points collinear or coincident
        return np.zeros((0, 3), dtype=np.intp)
    return _counter_clockwise(points, tri.simplices)


def _counter_clockwise(points: np.ndarray, simplices: np.ndarray) -> np.ndarray:
    """Triangles (t, 3) of vertex indices into `points` (n, 2), each turned counter-clockwise (a copy)."""
    simplices = simplices.astype(np.intp)
    a, b, c = (points[simplices[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = cross < 0
    simplices[flip] = simplices[flip][:, [0, 2, 1]]
    return simplices


class GrowingDelaunay:
    """Delaunay triangles of a point set that only grows (points appended, indices kept).

    Adding a few points to qhull's incremental triangulation costs a fraction
    of triangulating them all again.  The triangles are those of
    `delaunay_triangles` of all the points, in another order (and each may
    start at another corner).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
        At least 3 points, not all collinear (else qhull's error is raised:
        ``scipy.spatial.QhullError`` or ValueError).
    qhull : scipy.spatial.Delaunay, optional
        An incremental triangulation of `points` (not closed) to take over
        instead of triangulating them again.
    """

    def __init__(self, points: np.ndarray, qhull=None):
        self.points = np.asarray(points, dtype=float)
        # `qhull`: an open incremental ``scipy.spatial.Delaunay`` of exactly these points, to go on from.
        self._qhull = Delaunay(self.points, incremental=True) if qhull is None else qhull

    def add(self, points: np.ndarray) -> np.ndarray:
        """Append points (m, 2); returns the triangles (t, 3) of all points, counter-clockwise."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(points):
            self._qhull.add_points(points)
            self.points = np.concatenate((self.points, points))
        return _counter_clockwise(self.points, self._qhull.simplices)


def growing_delaunay(points: np.ndarray) -> GrowingDelaunay | None:
    """A `GrowingDelaunay` of the points (n, 2), or None where qhull refuses them (degenerate)."""
    try:
        return GrowingDelaunay(points)
    except (QhullError, ValueError):
        return None


def canonical_triangles(triangles: np.ndarray) -> np.ndarray:
    """Triangles (t, 3) each started at its smallest vertex index (turn kept), rows sorted.

    Two triangulations with the same triangles give the same array, so what
    is computed from it does not depend on the order qhull listed them in.
    """
    triangles = np.asarray(triangles, dtype=np.intp).reshape(-1, 3)
    start = np.argmin(triangles, axis=1)
    turned = np.take_along_axis(triangles, (start[:, None] + np.arange(3)) % 3, axis=1)
    return turned[np.lexsort(turned.T[::-1])]


def unique_edges(triangles: np.ndarray) -> np.ndarray:
    """Edges of a triangle mesh, each once.

    Parameters
    ----------
    triangles : ndarray of int, shape (t, 3)

    Returns
    -------
    ndarray of int, shape (e, 2)
        Vertex index pairs with ``e[:, 0] < e[:, 1]``.
    """
    if len(triangles) == 0:
        return np.zeros((0, 2), dtype=np.intp)
    t = np.asarray(triangles, dtype=np.int64)
    a = np.concatenate((t[:, 0], t[:, 1], t[:, 2]))
    b = np.concatenate((t[:, 1], t[:, 2], t[:, 0]))
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    # One int64 key per edge sorts as the (lo, hi) rows do: np.unique on it
    # is much cheaper than np.unique(axis=0) on rows.
    span = int(hi.max()) + 1
    key = np.unique(lo * span + hi)
    return np.stack((key // span, key % span), axis=1).astype(np.intp)


def _interior_edge_opposites(triangles: np.ndarray):
    """For each interior edge: its two opposite vertices and its endpoints.

    Returns
    -------
    (p, q, u, v) : ndarrays of int, shape (m,)
        Edge (u, v) is shared by triangles (u, v, p) and (v, u, q).
    """
    t = len(triangles)
    # Half-edges k -> k+1 with the opposite vertex k+2.
    u = triangles.ravel()
    v = np.roll(triangles, -1, axis=1).ravel()
    w = np.roll(triangles, -2, axis=1).ravel()
    lo, hi = np.minimum(u, v), np.maximum(u, v)
    key = lo.astype(np.int64) * (triangles.max() + 1 if t else 1) + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    pair = np.flatnonzero(ks[1:] == ks[:-1])
    first, second = order[pair], order[pair + 1]
    return w[first], w[second], lo[first], hi[first]


def lop_violations(points: np.ndarray, triangles: np.ndarray, tol_deg: float = 1e-7) -> int:
    """Number of interior edges that break the paper's LOP criterion.

    An interior edge shared by triangles ABC and ABD satisfies the criterion
    when the opposite angles C and D sum to at most 180 degrees
    (sin(C + D) >= 0 in the paper's notation, i.e. D not inside the
    circumcircle of ABC).

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    triangles : ndarray of int, shape (t, 3)
    tol_deg : float
        Slack for cocircular points, degrees.

    Returns
    -------
    int
    """
    if len(triangles) < 2:
        return 0
    p, q, u, v = _interior_edge_opposites(np.asarray(triangles))
    pts = np.asarray(points, dtype=float)

    def angle_at(c):
        a, b = pts[u] - pts[c], pts[v] - pts[c]
        cos = (a * b).sum(1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    return int(np.count_nonzero(angle_at(p) + angle_at(q) > 180.0 + tol_deg))


def triangle_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Interior angles of each triangle.

    Returns
    -------
    ndarray, shape (t, 3)
        Degrees, the angle at each vertex of each triangle.
    """
    pts = np.asarray(points, dtype=float)
    a, b, c = (pts[triangles[:, k]] for k in range(3))

    def ang(o, x, y):
        d1, d2 = x - o, y - o
        cos = (d1 * d2).sum(1) / (np.linalg.norm(d1, axis=1) * np.linalg.norm(d2, axis=1))
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    return np.stack([ang(a, b, c), ang(b, c, a), ang(c, a, b)], axis=1)


def edge_length_stats(segments: np.ndarray) -> dict:
    """Mean edge length and the share of edges shorter than half the mean.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)

    Returns
    -------
    dict with ``mean_mm`` and ``short_share`` (fraction of edges < mean / 2).
    """
    if len(segments) == 0:
        return {"mean_mm": float("nan"), "short_share": float("nan")}
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    mean = float(length.mean())
    return {"mean_mm": mean, "short_share": float(np.mean(length < 0.5 * mean))}


def node_edge_counts(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nodes of a segment network and how many segments meet at each.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        Segments whose shared ends are the same floats (as edges taken from one point array are).

    Returns
    -------
    (nodes, ends, counts)
        `nodes` (n, 2) the distinct end points, `ends` (k, 2) each segment's node indices,
        `counts` (n,) segments per node.
    """
    flat = np.ascontiguousarray(np.asarray(segments, dtype=float).reshape(-1, 2))
    if len(flat) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2), np.intp), np.zeros(0, np.intp)
    nodes, inverse = np.unique(flat, axis=0, return_inverse=True)
    ends = inverse.reshape(-1, 2)
    return nodes, ends, np.bincount(ends.ravel(), minlength=len(nodes))


def uncrowded_edges(segments: np.ndarray, shortest: np.ndarray | float = 0.0, *, max_edges: int = 8,
                    min_edges: int = 3, fixed: np.ndarray | None = None) -> np.ndarray:
    """Which segments to keep so that no node has more than `max_edges` and none is too short.

    Where a point ends up among closer neighbours than the sampling radius
    (a refinement centre, a sample in the band between two lattices) it
    gathers up to a dozen edges: a lump of plastic and short, weak pieces.
    At such a node an edge is left out, one at a time, until it has
    `max_edges`: the shortest of those whose leaving out opens a gap (the
    two angles beside it added) of at most a quarter turn, else the one that
    opens the smallest gap; then every edge shorter than `shortest` is left
    out.  An
    edge is left out only while both its nodes keep `min_edges` (the cells
    beside it merge into one polygon; the network stays connected).

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        The network, mm; shared ends are the same floats.
    shortest : float or ndarray, shape (k,)
        Shortest length kept per segment, mm (0: no length limit).
    max_edges, min_edges : int
    fixed : ndarray of bool, shape (k,), optional
        Segments that count at their nodes but are never left out.

    Returns
    -------
    ndarray of bool, shape (k,)
    """
    segments = np.asarray(segments, dtype=float)
    keep = np.ones(len(segments), dtype=bool)
    if len(segments) == 0:
        return keep
    nodes, ends, counts = node_edge_counts(segments)
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    fixed = np.zeros(len(segments), bool) if fixed is None else np.asarray(fixed, bool)
    too_short = np.flatnonzero((length < np.broadcast_to(np.asarray(shortest, dtype=float), length.shape)) & ~fixed)
    crowded = np.flatnonzero(counts > max_edges)
    if crowded.size == 0 and too_short.size == 0:
        return keep
    counts = counts.copy()
    # (a few nodes and edges per pattern: plain loops over them)
    for node in crowded.tolist():
        while counts[node] > max_edges:
            mine = np.flatnonzero(keep & ((ends[:, 0] == node) | (ends[:, 1] == node)))
            other = np.where(ends[mine, 0] == node, ends[mine, 1], ends[mine, 0])
            d = nodes[other] - nodes[node]
            order = np.argsort(np.arctan2(d[:, 1], d[:, 0]))
            mine, other = mine[order], other[order]
            angle = np.arctan2(d[order, 1], d[order, 0])
            gap = np.diff(np.append(angle, angle[0] + 2 * np.pi))  # gap after each edge
            closed = gap + np.roll(gap, 1)  # the gap that leaving an edge out opens
            closed[(counts[other] <= min_edges) | fixed[mine]] = np.inf
            if not np.isfinite(closed).any():
                break
            # The shortest of the edges whose leaving out opens no gap wider than a quarter turn (it
            # prints the least: on a node between two densities, an edge into the denser side); else
            # the edge that opens the smallest gap.
            length_here = np.hypot(*d[order].T)
            fine = np.flatnonzero(closed <= 0.5 * np.pi)
            pick = int(fine[np.argmin(length_here[fine])]) if fine.size else int(np.argmin(closed))
            keep[mine[pick]] = False
            counts[node] -= 1
            counts[other[pick]] -= 1
    for edge in too_short[np.argsort(length[too_short])].tolist():
        a, b = ends[edge]
        if keep[edge] and counts[a] > min_edges and counts[b] > min_edges:
            keep[edge] = False
            counts[a] -= 1
            counts[b] -= 1
    return keep


def relax_points(points: np.ndarray, area, radius_fn, steps: int, *, seed: int = 0, fixed: int = 0) -> np.ndarray:
    """Lloyd relaxation towards a centroidal Voronoi tessellation.

    Monte-Carlo Lloyd: each step assigns many random points of `area` to
    their nearest sample and moves every sample to the weighted centroid of
    its points.  The weight 1 / r(x)^4 keeps the local point density
    proportional to 1 / r(x)^2, so variable density survives relaxation.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    area : shapely (Multi)Polygon
        Samples stay inside it.
    radius_fn : callable (m, 2) -> (m,)
    steps : int
    seed : int
    fixed : int
        The first `fixed` points stay where they are (a lattice: only the
        samples between lattices move).

    Returns
    -------
    ndarray, shape (n, 2)
    """
    pts = np.asarray(points, dtype=float).copy()
    if steps <= 0 or len(pts) < 3:
        return pts
    rng = np.random.default_rng(seed + 7_777)
    x0, y0, x1, y1 = area.bounds
    per_point = 96  # probe points per sample: Monte-Carlo noise stays well below r
    for _ in range(steps):
        m = per_point * len(pts)
        probe = np.c_[rng.uniform(x0, x1, 2 * m), rng.uniform(y0, y1, 2 * m)]
        probe = probe[contains_xy(area, probe[:, 0], probe[:, 1])][:m]
        weight = radius_fn(probe) ** -4.0
        _, owner = cKDTree(pts).query(probe, k=1)
        mass = np.bincount(owner, weight, minlength=len(pts))
        cx = np.bincount(owner, weight * probe[:, 0], minlength=len(pts))
        cy = np.bincount(owner, weight * probe[:, 1], minlength=len(pts))
        moved = mass > 0
        moved[:fixed] = False
        pts[moved] = np.c_[cx[moved] / mass[moved], cy[moved] / mass[moved]]
    return pts
