"""Cura's own FILL lines as the witness of where infill may go.

Cura does not say where its infill area is; its FILL lines show it.  Every
place of Cura's sparse-infill area lies within about one line spacing of one
of its lines, and no line runs where there is no infill area.  So:

* `witnessed` keeps of a rebuilt area only what the lines confirm: the pieces
  that hold Cura lines, within `radius` (about Cura's line spacing) of them.
  What is narrower than that spacing (a small hole, a letter's skin) the walls
  and the skin must have cut out already (`area.py`).
* `kept_cura_pieces` finds the stretches of Cura's lines that the new infill
  does not take over: outside the final area (a part that could not be
  rebuilt) or with no new line near them (an island too small for the
  pattern).  They are printed as Cura printed them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..geometry import (
    boundary_segments,
    contains_xy,
    distances,
    empty_area,
    multilinestring_of,
    points_of,
    polygons_of,
    to_multipolygon,
    unary_union,
)
from .area import sample_segments

__all__ = ["witnessed", "kept_cura_pieces", "witness_radius"]


def witness_radius(spacing: float | None, line_width: float) -> float:
    """How far from a Cura line its infill area can reach, mm: one line spacing, at least two line widths."""
    if spacing is None or not np.isfinite(spacing):
        spacing = 10.0 * line_width
    return float(min(25.0, max(2.0 * line_width, spacing)))


def witnessed(area, runs: list[np.ndarray], line_width: float, radius: float):
    """The part of `area` that Cura's FILL lines confirm.

    Parameters
    ----------
    area : (Multi)Polygon
        Rebuilt sparse-infill area, mm.
    runs : list of ndarray, each shape (m, 2)
        Cura's FILL extrusion as polylines (the mesh's and its modifiers'), mm.
    line_width : float
        mm.
    radius : float
        Reach of a Cura line into its area (`witness_radius`), mm.

    Returns
    -------
    MultiPolygon
        The pieces of `area` that hold a Cura line, cut to within `radius` of the lines.
    """
    runs = [r for r in runs if len(r) >= 2]
    if area.is_empty or not runs:
        return empty_area()
    segments = np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in runs])
    points = sample_segments(segments, line_width)
    pieces = polygons_of(area)
    held = [p for p in pieces if contains_xy(p, points[:, 0], points[:, 1]).any()]
    if not held:
        return empty_area()
    confirmed = to_multipolygon(area if len(held) == len(pieces) else unary_union(held))
    if _within_reach(confirmed, points, radius):
        return confirmed  # (the usual case: no need to build the lines' reach)
    reach = multilinestring_of(runs).buffer(radius, 2)
    return to_multipolygon(confirmed.intersection(reach))


def _within_reach(area, points: np.ndarray, radius: float) -> bool:
    """Whether every place of `area` lies within `radius` of `points`, judged on a lattice.

    A place's nearest node of a lattice of step h lies within h / sqrt(2) of
    it.  When that node is inside `area` it is tested against
    ``radius - h / sqrt(2)``; when it is outside, the place lies within
    h / sqrt(2) of the border, so within h / sqrt(2) + b / 2 of one of the
    border's samples (b apart), which are tested against that much less.
    (h = radius / 4, b = h / 4: Cura's lines stop short of the border, so its
    places are the farthest from them.)
    False may be said of an area that is within reach: then the exact test
    decides.

    Parameters
    ----------
    area : MultiPolygon
    points : ndarray, shape (k, 2)
        Samples on the lines, mm.
    radius : float
        mm.
    """
    step = radius / 4.0
    border_step = step / 4.0
    minx, miny, maxx, maxy = area.bounds
    xs = np.arange(minx, maxx + step, step)
    ys = np.arange(miny, maxy + step, step)
    if len(xs) * len(ys) > 200_000:
        return False
    gx, gy = np.meshgrid(xs, ys)
    nodes = np.column_stack([gx.ravel(), gy.ravel()])
    nodes = nodes[contains_xy(area, nodes[:, 0], nodes[:, 1])]
    border = sample_segments(boundary_segments(area), border_step)
    tree = cKDTree(points)
    # (a sample is on a line: within reach of a sample is within reach of the lines)
    inner = tree.query(nodes, distance_upper_bound=radius)[0] if len(nodes) else np.zeros(0)
    edge = tree.query(border, distance_upper_bound=radius)[0] if len(border) else np.zeros(0)
    half_diagonal = step / np.sqrt(2.0)
    return bool((inner <= radius - half_diagonal).all() and (edge <= radius - half_diagonal - border_step / 2).all())


def kept_cura_pieces(
    cura: np.ndarray,
    area,
    new_paths: list[np.ndarray],
    line_width: float,
    reach: float,
    no_infill=None,
    min_length: float | None = None,
) -> list[np.ndarray]:
    """Stretches of Cura's FILL lines that the new infill does not take over.

    A place of a Cura line is kept when it lies outside `area` (grown by a line
    width: Cura's lines end at its border), or has no new line (of two line
    widths or more: a clip's stub takes nothing over) within `reach`
    inside the same piece of `area`, or its piece is small (at most `reach`
    squared) and holds less than half as much new infill as Cura's, or less
    than two line widths of it (an island the pattern barely reaches); places in
    `no_infill` (0 % regions) are never kept.  Neighbouring kept places form
    one piece.

    Parameters
    ----------
    cura : ndarray, shape (k, 2, 2)
        Cura's FILL extrusion segments, mm.
    area : (Multi)Polygon
        The area the new infill fills, mm.
    new_paths : list of ndarray, each shape (m, 2)
        The new infill, mm.
    line_width : float
        mm; Cura's lines are looked at in steps of half of it.
    reach : float
        mm.
    no_infill : (Multi)Polygon, optional
    min_length : float, optional
        Pieces shorter than this are dropped (one line width by default), mm.

    Returns
    -------
    list of ndarray, each shape (m, 2)
        Polylines along Cura's lines, mm.
    """
    if len(cura) == 0:
        return []
    step = line_width / 2
    if min_length is None:
        min_length = line_width
    d = cura[:, 1] - cura[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(1, np.ceil(length / step).astype(np.int64))
    # places: the midpoints of n equal steps of each segment
    seg = np.repeat(np.arange(len(cura)), n)
    first = np.cumsum(n) - n
    k = np.arange(seg.size) - first[seg]
    t0, t1 = k / n[seg], (k + 1) / n[seg]
    mid = cura[seg, 0] + d[seg] * ((t0 + t1) / 2)[:, None]
    keep = _uncovered(mid, area, new_paths, line_width, reach)
    if no_infill is not None and not no_infill.is_empty and keep.any():
        keep &= ~contains_xy(no_infill, mid[:, 0], mid[:, 1])
    if not keep.any():
        return []
    # runs of kept steps within one segment, joined across consecutive segments that meet
    idx = np.flatnonzero(keep)
    joined = np.zeros(idx.size, dtype=bool)
    same_seg = seg[idx[1:]] == seg[idx[:-1]]
    next_seg = (seg[idx[1:]] == seg[idx[:-1]] + 1) & (k[idx[1:]] == 0) & (k[idx[:-1]] == n[seg[idx[:-1]]] - 1)
    meets = np.zeros(idx.size - 1, dtype=bool)
    if next_seg.any():
        a, b = seg[idx[:-1]][next_seg], seg[idx[1:]][next_seg]
        meets[next_seg] = np.hypot(*(cura[a, 1] - cura[b, 0]).T) < 1e-6
    joined[1:] = (same_seg & (k[idx[1:]] == k[idx[:-1]] + 1)) | meets
    starts = np.flatnonzero(~joined)
    stops = np.r_[starts[1:], idx.size]
    pieces = []
    p0 = cura[seg, 0] + d[seg] * t0[:, None]
    p1 = cura[seg, 0] + d[seg] * t1[:, None]
    for a, b in zip(starts, stops, strict=True):
        rows = idx[a:b]
        line = np.vstack([p0[rows], p1[rows[-1:]]])
        # drop the inner points of straight stretches (the steps of one segment)
        if len(line) > 2:
            turn = np.ones(len(line), dtype=bool)
            s = seg[rows]
            turn[1:-1] = s[1:] != s[:-1]
            line = line[turn]
        if float(np.hypot(*np.diff(line, axis=0).T).sum()) >= min_length:
            pieces.append(line)
    return pieces


def _uncovered(points: np.ndarray, area, new_paths: list[np.ndarray], line_width: float, reach: float) -> np.ndarray:
    """Whether each point is outside `area` (grown by a line width) or not taken over in its piece (see above)."""
    out = np.ones(len(points), dtype=bool)
    if area is None or area.is_empty:
        return out
    # a stub a clip leaves (shorter than two line widths) takes nothing over
    new = _samples([p for p in new_paths if len(p) >= 2 and np.hypot(*np.diff(p, axis=0).T).sum() >= 2 * line_width],
                   line_width / 2)
    # the points of the area: inside it, or within a line width of it (Cura's lines end at its border)
    inside = contains_xy(area, points[:, 0], points[:, 1])
    member = inside.copy()
    rest = np.flatnonzero(~member)
    if len(rest):
        member[rest[distances(points_of(points[rest]), area) <= line_width]] = True
    decided = np.zeros(len(points), dtype=bool)
    for piece in polygons_of(area):
        if piece.area > reach * reach:
            continue
        # a small piece with far less new infill than Cura's (an island the pattern barely reaches):
        # Cura's lines stay (points every half line width on both: their counts compare lengths)
        grown = piece.buffer(line_width, 2)
        # its own points, and those at its border that lie in no piece
        mine = member & ~decided & (contains_xy(piece, points[:, 0], points[:, 1])
                                    | (~inside & contains_xy(grown, points[:, 0], points[:, 1])))
        if not mine.any():
            continue
        decided |= mine
        theirs = new[contains_xy(grown, new[:, 0], new[:, 1])] if len(new) else new
        if len(theirs) < max(0.5 * np.count_nonzero(mine), 4):  # (4 points: two line widths of new line)
            continue
        rows = np.flatnonzero(mine)
        out[rows[cKDTree(theirs).query(points[rows], distance_upper_bound=reach)[0] <= reach]] = False
    rows = np.flatnonzero(member & ~decided)
    if len(rows) and len(new):
        out[rows[cKDTree(new).query(points[rows], distance_upper_bound=reach)[0] <= reach]] = False
    return out


def _samples(paths: list[np.ndarray], step: float) -> np.ndarray:
    """Points along polylines at most `step` apart, shape (p, 2) mm."""
    paths = [p for p in paths if len(p) >= 2]
    if not paths:
        return np.zeros((0, 2))
    return sample_segments(np.concatenate([np.stack([p[:-1], p[1:]], axis=1) for p in paths]), step)
