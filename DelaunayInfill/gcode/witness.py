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

from ..geometry import contains_xy, empty_area, multilinestring_of, polygons_of, to_multipolygon, unary_union
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
    held = [p for p in polygons_of(area) if contains_xy(p, points[:, 0], points[:, 1]).any()]
    if not held:
        return empty_area()
    reach = multilinestring_of(runs).buffer(radius, 2)
    return to_multipolygon(unary_union(held).intersection(reach))


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
    width: Cura's lines end at its border) or has no new line within `reach`
    inside the same piece of `area`; places in `no_infill` (0 % regions) are
    never kept.  Neighbouring kept places form one piece.

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
        Pieces shorter than this are dropped (two line widths by default), mm.

    Returns
    -------
    list of ndarray, each shape (m, 2)
        Polylines along Cura's lines, mm.
    """
    if len(cura) == 0:
        return []
    step = line_width / 2
    if min_length is None:
        min_length = 2.0 * line_width
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
    """Whether each point is outside `area` (grown by a line width) or has no new line within `reach` in its piece."""
    out = np.ones(len(points), dtype=bool)
    if area is None or area.is_empty:
        return out
    new = (np.concatenate([sample_segments(np.stack([p[:-1], p[1:]], axis=1), line_width / 2) for p in new_paths
                           if len(p) >= 2]) if new_paths else np.zeros((0, 2)))
    for piece in polygons_of(area):
        grown = piece.buffer(line_width, 2)
        mine = contains_xy(grown, points[:, 0], points[:, 1])
        if not mine.any():
            continue
        if len(new):
            theirs = new[contains_xy(grown, new[:, 0], new[:, 1])]
        else:
            theirs = new
        if len(theirs) == 0:
            continue  # nothing new in this piece: Cura's lines stay
        near = cKDTree(theirs).query(points[mine], distance_upper_bound=reach)[0] <= reach
        rows = np.flatnonzero(mine)
        out[rows[near]] = False
    return out
