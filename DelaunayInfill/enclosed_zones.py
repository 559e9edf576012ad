"""Zones enclosed by others of one kind: sampled round as holes, each filled with its own lattice.

A region sparser than everything round it (a 10 % region painted into a 40 % part) is joined to its
surroundings by Delaunay triangles that fan from its few samples to the denser zone's border row: those
lines lie in the region, make it print above its density unless its own lattice is thinned, and carry
less per gram than a lattice (a 36 mm region at 10 % in 40 %: 0.72 of a uniform 10 % pattern's C_min / rho,
`bench/bench_regions.py`).  Here the denser zones are sampled and triangulated as if the region were a
hole in the part, and the region gets its own lattice's lines clipped to what their triangles leave
open, each joined at the denser zone's nearest node (`hole_lines`).  The region is then its lattice right
up to its border; the change of density lies outside it, on the denser side, within about one of the
denser zone's spacings.

A region denser than everything round it is its own lattice too, in whole triangles (`lattice_patch`):
cut at the border, its lines end in the sparser zone's long triangles, and even two exact lattices
meeting there carry 0.89-0.93 of a uniform pattern over the region (`bench/bench_regions.py --ideal`).
The sparser zones are sampled round the patch, and their triangles end on some of its outline's nodes
(`LatticePatch.joins`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree
from shapely.ops import unary_union

from .geometry import contains_xy, polygons_from, polygons_of, to_multipolygon
from .metering import ZoneMeter
from .routing import clip_segments
from .sampling import (LATTICE_AREA, LATTICE_SPACING, lattice_basis, lattice_coordinates, lattice_nodes_over,
                       lattice_points, lattice_xy)
from .triangulation import unique_edges

__all__ = ["BORDER_GAP", "LatticePatch", "border_samples", "enclosed_zones", "hole_lines", "lattice_edges",
           "lattice_patch"]

_RING_POINTS = 64  # probes round a zone for its neighbours' densities
BORDER_GAP = 0.6  # radii: a border sample keeps this far from every other sample
_SNAP = 1.5  # a clipped line end joins the denser zone's nearest node within this many of its radii


def enclosed_zones(dmap, zones: list, area, radii: np.ndarray, settled: np.ndarray, denser: bool) -> np.ndarray:
    """Which zones are sparser (`denser`: denser) than every zone round them and lie inside `area` with a
    ring to spare.

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
        if ((densities[labels] < densities[k]) if denser else (densities[labels] > densities[k])).all():
            surround[k] = int(np.bincount(labels, minlength=len(zones)).argmax())
    return surround


def border_samples(zone, points: np.ndarray, radius: float) -> np.ndarray:
    """Samples on the enclosed zone's outline (k, 2) mm, about a radius apart and at least `BORDER_GAP`
    radii from `points` (n, 2) and from each other: the denser zone's triangles then reach the border.

    `radius`: the surrounding zone's sampling radius, mm.
    """
    out = []
    taken = cKDTree(points) if len(points) else None
    for ring in (r for p in polygons_of(zone) for r in (p.exterior, *p.interiors)):
        count = max(3, int(np.ceil(ring.length / radius)))
        along = np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.arange(count) / count])
        free = np.ones(len(along), bool) if taken is None else (
            taken.query(along, distance_upper_bound=BORDER_GAP * radius)[0] == np.inf)
        out.append(along[free])
    border = np.concatenate(out) if out else np.zeros((0, 2))
    # neighbours on the outline are a radius apart; a ring's last and first may be closer: keep one
    if len(border) > 1:
        keep = np.ones(len(border), bool)
        for i, j in cKDTree(border).query_pairs(BORDER_GAP * radius, output_type="ndarray"):
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
    keep = (length > 1e-6) & ~(cut_ends.all(axis=1) & (length < 0.25 * side))
    # a piece whose ends both joined the nodes of one denser edge, or of another piece, is printed once
    dense = points[unique_edges(triangles[near])] if covered is not None else np.zeros((0, 2, 2))
    keep &= ~_repeats(lines, dense)
    return lines[keep]


def _repeats(lines: np.ndarray, others: np.ndarray) -> np.ndarray:
    """(k,) bool: which of `lines` (k, 2, 2) mm run between the same two points (to a micrometre) as one of
    `others` (m, 2, 2) or as an earlier one of `lines`."""
    both = np.concatenate((others, lines))
    ends = np.round(both * 1e6).astype(np.int64).reshape(-1, 2, 2)
    first = (ends[:, 0, 0] < ends[:, 1, 0]) | ((ends[:, 0, 0] == ends[:, 1, 0]) & (ends[:, 0, 1] <= ends[:, 1, 1]))
    keys = np.where(first[:, None], ends.reshape(-1, 4), ends[:, ::-1].reshape(-1, 4))
    _, index = np.unique(keys, axis=0, return_index=True)
    once = np.zeros(len(both), bool)
    once[index] = True  # (the first of each: the others come first)
    return ~once[len(others):]


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
    ij = lattice_coordinates(ends, side, seed)
    on_node = (np.abs(ij - np.round(ij)) < 1e-6).all(axis=1)
    distance, nearest = cKDTree(points).query(ends, distance_upper_bound=reach)
    moved = np.isfinite(distance) & (~on_node | (distance <= 0.25 * LATTICE_SPACING * reach))
    ends[moved] = points[nearest[moved]]
    return ends.reshape(-1, 2, 2), (~on_node & ~moved).reshape(-1, 2)


@dataclass(frozen=True, eq=False)
class LatticePatch:
    """A dense zone's own lattice in whole triangles (`lattice_patch`)."""

    area: object  # shapely MultiPolygon: the triangles together, mm
    lines: np.ndarray  # (k, 2, 2) mm: their edges, each once
    outline: np.ndarray  # (b, 2) mm: their corners on the patch's outline
    side: float  # the lattice's side, mm

    @cached_property
    def _near(self):
        return self.area.buffer(0.5 * self.side, 4)

    @cached_property
    def _outline_tree(self):
        return cKDTree(self.outline)

    @cached_property
    def _meter(self):
        # the patch shrunk and grown by a thousandth of a side: lines through it, lines along its outline
        return ZoneMeter([self.area.buffer(-1e-3 * self.side, 4), self.area.buffer(1e-3 * self.side, 4)])

    def over(self, segments: np.ndarray) -> np.ndarray:
        """(k,) bool: which other lines (`segments` (k, 2, 2) mm) lie on the patch, where its own lines
        are: those that run through it (a junction edge across one of its outline's corners) or along its
        outline for a quarter side (one of its outline's edges printed twice), and chords between two of
        its outline's nodes with their middle inside it or within half a side of it."""
        if not len(segments) or not len(self.outline):
            return np.zeros(len(segments), bool)
        gap = self._outline_tree.query(segments.reshape(-1, 2), distance_upper_bound=1e-6 * self.side)[0]
        on = np.isfinite(gap).reshape(-1, 2).all(axis=1)
        middle = segments[on].mean(axis=1)
        on[on] = contains_xy(self._near, middle[:, 0], middle[:, 1])
        through, along = self._meter.inside_all(segments)
        return on | (through > 1e-3 * self.side) | (along > 0.25 * self.side)

    def joins(self, zone, points: np.ndarray, radius: float) -> np.ndarray:
        """The outline's nodes (b, 2) mm nearest to points a sampling `radius` apart along `zone`'s outline
        (`border_samples`), none within `BORDER_GAP` radii of `points` (n, 2) mm: where the sparser zone's
        triangles join the patch."""
        targets = border_samples(zone, np.zeros((0, 2)), radius)
        if not len(targets) or not len(self.outline):
            return np.zeros((0, 2))
        chosen = np.unique(self.outline[self._outline_tree.query(targets)[1]], axis=0)
        if len(points):
            chosen = chosen[cKDTree(points).query(chosen, distance_upper_bound=BORDER_GAP * radius)[0] == np.inf]
        return chosen


def lattice_patch(zone, side: float, seed: int, room=None) -> LatticePatch | None:
    """A dense zone's own lattice, whole triangles: those with at least two corners in `zone` and the
    others in `room` (optional, a shapely geometry: where the patch may reach past the zone).

    The lattice is `sampling.lattice_points`'s.  A triangle with two corners in the zone reaches past its
    border by at most its height (0.87 `side`); cut at the border instead, the lines there would end in
    the sparser zone's long triangles and the zone would lose what its border band carries.

    Returns
    -------
    LatticePatch or None
        None when no triangle has two corners in the zone.
    """
    cell = lattice_nodes_over(zone.buffer(side, 4).bounds, side, seed)
    # each lattice cell (i, j) holds two triangles: (i, j) (i+1, j) (i, j+1) and (i+1, j) (i+1, j+1) (i, j+1)
    corners = np.concatenate((np.stack((cell, cell + [1, 0], cell + [0, 1]), axis=1),
                              np.stack((cell + [1, 0], cell + [1, 1], cell + [0, 1]), axis=1)))
    nodes, index = np.unique(corners.reshape(-1, 2), axis=0, return_inverse=True)
    index = index.reshape(-1, 3)
    xy = lattice_xy(nodes, side, seed)
    inside = contains_xy(zone, xy[:, 0], xy[:, 1])
    if room is None:
        allowed = np.ones(len(xy), bool)
    else:
        allowed = inside if room.is_empty else inside | contains_xy(room, xy[:, 0], xy[:, 1])
    index = index[(inside[index].sum(axis=1) >= 2) & allowed[index].all(axis=1)]
    if not len(index):
        return None
    edges = np.unique(np.sort(np.concatenate((index[:, [0, 1]], index[:, [1, 2]], index[:, [2, 0]])), axis=1),
                      axis=0)
    patch = to_multipolygon(unary_union(polygons_from(xy[index])))
    used = np.unique(edges)
    core = patch.buffer(-1e-3 * side, 4)
    outline = used[~contains_xy(core, xy[used, 0], xy[used, 1])]
    return LatticePatch(patch, xy[edges], xy[outline], side)
