"""Sparse zones enclosed by denser ones: cut out of the sampling, filled with their own lattice.

A region sparser than everything round it (a 10 % region painted into a 40 % part) is joined to its
surroundings by Delaunay triangles that fan from its few samples to the denser zone's border row: those
lines lie in the region, make it print above its density unless its own lattice is thinned, and carry
less per gram than a lattice (a 36 mm region at 10 % in 40 %: 0.72 of a uniform 10 % pattern's C_min / rho,
`bench/bench_regions.py`).  Here the denser zones are sampled and triangulated as if the region were a
hole in the part, and the region gets its own lattice's lines clipped to what their triangles leave
open, each joined at the denser zone's nearest node.  The region is then its lattice right up to its
border; the change of density lies outside it, on the denser side, within about one of the denser
zone's spacings.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from shapely.ops import unary_union

from .geometry import polygons_from, polygons_of, to_multipolygon
from .routing import clip_segments
from .sampling import LATTICE_AREA, LATTICE_SPACING, lattice_basis, lattice_frame, lattice_points

__all__ = ["border_samples", "enclosed_sparse_zones", "hole_lines", "lattice_edges"]

_RING_POINTS = 64  # probes round a zone for its neighbours' densities
_BORDER_GAP = 0.6  # radii: a border sample keeps this far from every other sample
_SNAP = 1.5  # a clipped line end joins the denser zone's nearest node within this many of its radii


def enclosed_sparse_zones(dmap, zones: list, area, radii: np.ndarray, settled: np.ndarray) -> np.ndarray:
    """Which zones are sparser than every zone round them and lie inside `area` with a ring to spare.

    Parameters
    ----------
    dmap : DensityMap
        Sharp borders (no feather).
    zones : list of MultiPolygon
        `DensityMap.zones` (index 0 the base, which is never enclosed).
    area : shapely MultiPolygon
        Where the pattern is built.
    radii : ndarray, shape (zones,)
        Each zone's sampling radius, mm.
    settled : ndarray of bool, shape (zones,)
        Zones with area where the lines are printed.

    Returns
    -------
    ndarray of int, shape (zones,)
        For an enclosed zone the index of the zone that holds most of its surroundings (whose density it
        is sampled at), else -1.
    """
    densities = np.asarray(dmap.densities, dtype=float)
    surround = np.full(len(zones), -1, dtype=np.intp)
    for k in range(1, len(zones)):
        zone, r = zones[k], float(radii[k])
        if not settled[k] or zone.is_empty or zone.area < LATTICE_AREA * r * r:  # (too small for its lattice)
            continue
        if not area.buffer(-r, 4).covers(zone):  # a part's edge: not enclosed
            continue
        ring = zone.buffer(0.25 * r, 4).boundary
        probes = np.array([ring.interpolate(t, normalized=True).coords[0]
                           for t in np.linspace(0.0, 1.0, _RING_POINTS, endpoint=False)])
        labels = dmap.labels(probes)
        if (densities[labels] > densities[k]).all():
            surround[k] = int(np.bincount(labels, minlength=len(zones)).argmax())
    return surround


def border_samples(zone, points: np.ndarray, radius: float) -> np.ndarray:
    """Samples on the enclosed zone's outline (k, 2) mm, about a radius apart and at least `_BORDER_GAP`
    radii from `points` (n, 2) and from each other: the denser zone's triangles then reach the border.

    `radius`: the surrounding zone's sampling radius, mm.
    """
    out = []
    taken = cKDTree(points) if len(points) else None
    for ring in (r for p in polygons_of(zone) for r in (p.exterior, *p.interiors)):
        count = max(3, int(np.ceil(ring.length / radius)))
        along = np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.arange(count) / count])
        free = np.ones(len(along), bool) if taken is None else (
            taken.query(along, distance_upper_bound=_BORDER_GAP * radius)[0] == np.inf)
        out.append(along[free])
    border = np.concatenate(out) if out else np.zeros((0, 2))
    # neighbours on the outline are a radius apart; a ring's last and first may be closer: keep one
    if len(border) > 1:
        keep = np.ones(len(border), bool)
        for i, j in cKDTree(border).query_pairs(_BORDER_GAP * radius, output_type="ndarray"):
            if keep[i] and keep[j]:
                keep[j] = False
        border = border[keep]
    return border


def lattice_edges(area, side: float, seed: int) -> np.ndarray:
    """Every edge of a seed's triangular lattice of the given side that meets `area`.

    The lattice is `sampling.lattice_points`'s (the same plane-fixed frame per seed).

    Returns
    -------
    ndarray, shape (k, 2, 2)
        mm, each edge once.
    """
    nodes = lattice_points(area.buffer(side, 4), side, seed)
    v1, v2 = lattice_basis(side, seed)
    steps = np.stack((v1, v2, v2 - v1))  # each edge leaves exactly one of its ends along one of these
    starts = np.repeat(nodes, 3, axis=0)
    return np.stack((starts, starts + np.tile(steps, (len(nodes), 1))), axis=1)


def hole_lines(zone, points: np.ndarray, triangles: np.ndarray, side: float, seed: int,
               reach: float) -> np.ndarray:
    """The enclosed zone's lattice lines where the denser zones' triangles leave it open, joined to them.

    Parameters
    ----------
    zone : shapely MultiPolygon
        The enclosed zone, mm.
    points : ndarray, shape (n, 2)
        The denser zones' samples, mm.
    triangles : ndarray of int, shape (t, 3)
        Their triangles (none across the zone).
    side : float
        The zone's lattice side, mm.
    seed : int
    reach : float
        The surrounding zone's radius, mm: how far outside the zone the open space is looked for and
        how far a clipped end moves to the nearest node.

    Returns
    -------
    ndarray, shape (k, 2, 2)
        mm.
    """
    around = zone.buffer(2.0 * reach, 4)
    if len(triangles):
        corners = points[triangles]
        x0, y0, x1, y1 = around.bounds
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        near = (lo[:, 0] <= x1) & (hi[:, 0] >= x0) & (lo[:, 1] <= y1) & (hi[:, 1] >= y0)
        covered = unary_union(polygons_from(corners[near])) if near.any() else None
    else:
        covered = None
    open_space = to_multipolygon(around if covered is None else around.difference(covered))
    # only the open pieces that hold part of the zone (not gaps left between triangles elsewhere)
    inside = [p for p in polygons_of(open_space) if p.intersects(zone) and p.intersection(zone).area > 1e-9]
    if not inside:
        return np.zeros((0, 2, 2))
    open_space = to_multipolygon(unary_union(inside))
    lines = clip_segments(lattice_edges(zone, side, seed), open_space)
    if len(lines) == 0 or len(points) == 0:
        return lines
    lines, cut_ends = _joined(lines, points, side, seed, _SNAP * reach)
    length = np.hypot(*(lines[:, 1] - lines[:, 0]).T)
    # a piece cut at both ends that no node took (a corner of a triangle over the zone): a stub
    return lines[(length > 1e-6) & ~(cut_ends.all(axis=1) & (length < 0.25 * side))]


def _joined(lines: np.ndarray, points: np.ndarray, side: float, seed: int,
            reach: float) -> tuple[np.ndarray, np.ndarray]:
    """`lines` (k, 2, 2) joined to the denser zones' samples `points` (n, 2): each end that clipping made
    (not a lattice node) moves to the nearest sample within `reach` mm, so that a line ends on a node and
    not in the middle of an edge, and so does a lattice node within ``0.25 * LATTICE_SPACING * reach`` of
    a sample, so that no piece is that short (`reach` is `_SNAP` of the denser zone's radii: that is 3/8
    of the denser lattice's side).

    Returns
    -------
    (ndarray, shape (k, 2, 2); ndarray of bool, shape (k, 2))
        The lines, and which of their ends are cut ends that stayed where they were.
    """
    ends = lines.reshape(-1, 2).copy()
    v1, v2 = lattice_basis(side, seed)
    basis = np.stack((v1, v2), axis=1)
    ij = np.linalg.solve(basis, (ends - basis @ lattice_frame(seed)[1]).T).T
    on_node = (np.abs(ij - np.round(ij)) < 1e-6).all(axis=1)
    distance, nearest = cKDTree(points).query(ends, distance_upper_bound=reach)
    moved = np.isfinite(distance) & (~on_node | (distance <= 0.25 * LATTICE_SPACING * reach))
    ends[moved] = points[nearest[moved]]
    return ends.reshape(-1, 2, 2), (~on_node & ~moved).reshape(-1, 2)
