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
  rebuilt), with no new line near them (an island too small for the
  pattern), or in a strip of a small piece narrower than two line widths
  that no new line runs along (a finger beside a hole).  They are printed
  as Cura printed them.
* `isolated_cura_lines` finds a mesh's groups of lines that lie apart from
  the rest of its lines and far, for that mesh's own density, from any new
  line (a corner of a dense modifier cut off by skin, inside a sparse
  host's piece).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
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
from .area import run_bounds, sample_segments, segment_samples

__all__ = ["witnessed", "kept_cura_pieces", "isolated_cura_lines", "new_line_places", "segment_polylines",
           "witness_radius"]


def witness_radius(spacing: float | None, line_width: float) -> float:
    """How far from a Cura line its infill area can reach, mm: one line spacing, at least two line widths."""
    if spacing is None or not np.isfinite(spacing):
        spacing = 10.0 * line_width
    return float(min(25.0, max(2.0 * line_width, spacing)))


def witnessed(area, runs, line_width: float, radius: float):
    """The part of `area` that Cura's FILL lines confirm.

    Parameters
    ----------
    area : (Multi)Polygon
        Rebuilt sparse-infill area, mm.
    runs : list of ndarray, each shape (m, 2), or ndarray, shape (k, 2, 2)
        Cura's FILL extrusion (the mesh's and its modifiers'), as polylines or as segments in the
        order printed, mm.
    line_width : float
        mm.
    radius : float
        Reach of a Cura line into its area (`witness_radius`), mm.

    Returns
    -------
    MultiPolygon
        The pieces of `area` that hold a Cura line, cut to within `radius` of the lines.
    """
    if isinstance(runs, np.ndarray):
        segments = runs.reshape(-1, 2, 2)
    else:
        runs = [r for r in runs if len(r) >= 2]
        segments = np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in runs]) if runs else np.zeros((0, 2, 2))
    if area.is_empty or not len(segments):
        return empty_area()
    points = sample_segments(segments, line_width)
    pieces = polygons_of(area)
    held = [p for p in pieces if contains_xy(p, points[:, 0], points[:, 1]).any()]
    if not held:
        return empty_area()
    confirmed = to_multipolygon(area if len(held) == len(pieces) else unary_union(held))
    if _within_reach(confirmed, points, radius):
        return confirmed  # (the usual case: no need to build the lines' reach)
    reach = multilinestring_of(segment_polylines(segments)).buffer(radius, 2)
    return to_multipolygon(confirmed.intersection(reach))


def segment_polylines(segments: np.ndarray) -> list[np.ndarray]:
    """Segments, shape (k, 2, 2) mm in the order printed, joined into polylines where one starts at the last's end."""
    starts, stops = run_bounds(segments)
    return [np.vstack([segments[a:b, 0], segments[b - 1 : b, 1]]) for a, b in zip(starts, stops, strict=True)]


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
    inside = contains_xy(area, nodes[:, 0], nodes[:, 1])
    # blocks of 3 x 3 lattice nodes (`_all_near` answers a block whose middle is near enough at once)
    row, col = np.divmod(np.arange(len(nodes)), len(xs))
    block = (row // 3) * ((len(xs) + 2) // 3) + col // 3
    by_block = np.argsort(block[inside], kind="stable")
    nodes, block = nodes[inside][by_block], block[inside][by_block]
    border = sample_segments(boundary_segments(area), border_step)
    tree = kd_tree(points)
    # (a sample is on a line: within reach of a sample is within reach of the lines)
    half_diagonal = step / np.sqrt(2.0)
    return (_all_near(tree, nodes, block, radius - half_diagonal)
            and _all_near(tree, border, np.arange(len(border)) // 8, radius - half_diagonal - border_step / 2))


def kd_tree(points: np.ndarray) -> cKDTree:
    """A KD-tree of `points`, shape (k, 2) mm, for one layer's queries.

    Built without balancing (sliding midpoint splits) and without shrinking its boxes to the
    points: about half the build time, and a query finds the same nearest points.
    """
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _all_near(tree: cKDTree, points: np.ndarray, group: np.ndarray, limit: float) -> bool:
    """Whether every point lies within `limit` of a point of `tree` (see `_near_in_groups`)."""
    return bool(_near_in_groups(tree, points, group, limit).all())


def _near_in_groups(tree: cKDTree, points: np.ndarray, group: np.ndarray, limit: float) -> np.ndarray:
    """Whether each point lies within `limit` of a point of `tree`, shape (p,): as querying each would say.

    `group` (shape (p,), int, each group's points consecutive) gathers neighbouring points: a group whose middle
    (of its bounding box) lies within `limit` less the group's radius of a tree point has all its
    points within `limit` of that point, so one query answers it; only the points of the other
    groups are queried one by one.
    """
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    first = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    lo = np.minimum.reduceat(points, first, axis=0)
    hi = np.maximum.reduceat(points, first, axis=0)
    middle = (lo + hi) / 2
    sizes = np.diff(np.r_[first, len(points)])
    spread = np.hypot(*(points - np.repeat(middle, sizes, axis=0)).T)
    reach = np.maximum.reduceat(spread, first)
    near = np.repeat(tree.query(middle, distance_upper_bound=limit)[0] + reach <= limit, sizes)
    todo = np.flatnonzero(~near)
    if len(todo):
        near[todo] = tree.query(points[todo], distance_upper_bound=limit)[0] <= limit
    return near


def kept_cura_pieces(
    cura: np.ndarray,
    area,
    new_paths: list[np.ndarray],
    line_width: float,
    reach: float,
    no_infill=None,
    min_length: float | None = None,
    pieces=None,
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
    pieces : MultiPolygon, optional
        The islands of Cura's infill inside `area`, judged as its pieces are (CuraEngine 4.13 leaves
        a gap between a host's and its wall-less modifiers' areas that the new infill crosses), mm;
        by default `area`'s pieces.

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
    keep = _uncovered(mid, area, new_paths, line_width, reach, groups=(seg, k, length / n), pieces=pieces)
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


def new_line_places(new_paths: list[np.ndarray], line_width: float) -> cKDTree | None:
    """A KD-tree of the places of the new infill that take Cura's lines over: every half line width along
    its paths of two line widths or more (a stub a clip leaves takes nothing over); None without any."""
    places = _samples(_long_paths(new_paths, 2 * line_width), line_width / 2)
    return kd_tree(places) if len(places) else None


def isolated_cura_lines(cura: np.ndarray, new_places: cKDTree | None, line_width: float, link: float,
                        reach: float) -> np.ndarray:
    """Which of one mesh's Cura segments lie in a group of its lines that no new line comes near.

    A group is the segments whose places lie within `link` of each other (chains of them: about
    that mesh's line spacing joins all the lines of one zone); it is isolated when no new line of
    two line widths or more (a stub takes nothing over) comes within `reach` of any of its places.
    `kept_cura_pieces` measures the new infill against the sparsest density of the whole host: a
    small corner of a dense modifier with Cura lines but too small for the new pattern's, cut off
    from the rest of its zone by skin, is then taken as covered by the host's new lines a few
    millimetres away, across the modifier's border (random regions 75: 0.5 mm of Cura's lines,
    no new infill, on a 1.5 mm² island at 60 %).

    Parameters
    ----------
    cura : ndarray, shape (k, 2, 2)
        One mesh's Cura FILL segments, mm.
    new_places : cKDTree or None
        The new infill's places (`new_line_places`), mm.
    line_width : float
        mm; places are taken every half of it.
    link : float
        Places of one group lie within this of another place of it, mm.
    reach : float
        A new line within this of a group's place takes the group over, mm.

    Returns
    -------
    ndarray, shape (k,), bool
    """
    if len(cura) == 0:
        return np.zeros(0, dtype=bool)
    # groups of segments: places a quarter of `link` apart are close enough to join them (a line spacing
    # holds some 25 of them within `link`: the pairs stay few)
    coarse, coarse_owner = segment_samples(cura, max(line_width / 2, link / 4))
    pairs = kd_tree(coarse).query_pairs(link, output_type="ndarray")
    n = len(cura)
    joins = coo_matrix((np.ones(len(pairs)), (coarse_owner[pairs[:, 0]], coarse_owner[pairs[:, 1]])), shape=(n, n))
    count, group = connected_components(joins, directed=False)
    # a group is taken over when a new line comes within `reach` of one of its places (every half line width)
    places, owner = segment_samples(cura, line_width / 2)
    taken = np.zeros(count, dtype=bool)
    if new_places is not None:
        near = new_places.query(places, distance_upper_bound=reach)[0] <= reach
        taken[group[owner[near]]] = True
    return ~taken[group]


def _uncovered(points: np.ndarray, area, new_paths: list[np.ndarray], line_width: float, reach: float,
               groups: tuple | None = None, pieces=None) -> np.ndarray:
    """Whether each point is outside `area` (grown by a line width) or not taken over in its piece (see above).

    `groups` (segment index (p,), step index (p,), step length per segment (k,) mm) says that the
    points are the midpoints of equal steps along Cura's segments: runs of them are then tested at
    once (`_near`).  `pieces`: the pieces judged (by default `area`'s).
    """
    out = np.ones(len(points), dtype=bool)
    if area is None or area.is_empty:
        return out
    # a stub a clip leaves (shorter than two line widths) takes nothing over
    new = _samples(_long_paths(new_paths, 2 * line_width), line_width / 2)
    # the points of the area: inside it, or within a line width of it (Cura's lines end at its border)
    inside = contains_xy(area, points[:, 0], points[:, 1])
    member = inside.copy()
    rest = np.flatnonzero(~member)
    if len(rest):
        member[rest[distances(points_of(points[rest]), area) <= line_width]] = True
    decided = np.zeros(len(points), dtype=bool)
    in_pieces = inside if pieces is None else contains_xy(pieces, points[:, 0], points[:, 1])
    for piece in polygons_of(area if pieces is None else pieces):
        if piece.area > reach * reach:
            continue
        # a small piece with far less new infill than Cura's (an island the pattern barely reaches):
        # Cura's lines stay (points every half line width on both: their counts compare lengths)
        grown = piece.buffer(line_width, 2)
        # its own points, and those at its border that lie in no piece
        mine = member & ~decided & (contains_xy(piece, points[:, 0], points[:, 1])
                                    | (~in_pieces & contains_xy(grown, points[:, 0], points[:, 1])))
        if not mine.any():
            continue
        decided |= mine
        theirs = new[contains_xy(grown, new[:, 0], new[:, 1])] if len(new) else new
        if len(theirs) < max(0.5 * np.count_nonzero(mine), 4):  # (4 points: two line widths of new line)
            continue
        rows = np.flatnonzero(mine)
        taken = kd_tree(theirs).query(points[rows], distance_upper_bound=reach)[0]
        # A place in a strip of the piece under two line widths (a finger beside a hole) with no new
        # line within a line width stays Cura's: the pattern crosses such a strip only as stubs.
        finger = taken > line_width
        if finger.any():
            core = piece.buffer(-line_width, join_style=2, mitre_limit=4.0)
            finger[finger] = ~_near_area(core, points[rows[finger]], 1.25 * line_width)
        out[rows[(taken <= reach) & ~finger]] = False
    rows = np.flatnonzero(member & ~decided)
    if len(rows) and len(new):
        out[rows[_near(kd_tree(new), points, rows, reach, groups)]] = False
    return out


def _near_area(area, points: np.ndarray, tolerance: float) -> np.ndarray:
    """Whether each point (p, 2) lies in `area` or within about `tolerance` (mm) of it, shape (p,)."""
    if area.is_empty:
        return np.zeros(len(points), dtype=bool)
    near = contains_xy(area, points[:, 0], points[:, 1])
    rest = np.flatnonzero(~near)
    if len(rest):
        # (the boundary sampled every quarter of the tolerance: a point is within an eighth of it of the line)
        edge = sample_segments(boundary_segments(area), tolerance / 4)
        near[rest] = kd_tree(edge).query(points[rest], distance_upper_bound=tolerance)[0] <= tolerance
    return near


def _near(tree, points: np.ndarray, rows: np.ndarray, reach: float, groups: tuple | None) -> np.ndarray:
    """Whether ``points[rows]`` lie within `reach` of a point of `tree`, shape (len(rows),).

    With `groups` (see `_uncovered`), consecutive rows along one segment are taken in runs of up to
    `reach` / 2 mm, each answered at once where it can be (`_near_in_groups`; the usual case: new
    infill a few millimetres away everywhere).  The answer is the same as querying every point.
    """
    if groups is None or len(rows) < 64:
        return tree.query(points[rows], distance_upper_bound=reach)[0] <= reach
    seg, step, step_len = groups
    s, k = seg[rows], step[rows]
    per_run = np.maximum(1, np.floor(0.5 * reach / np.maximum(step_len[s], 1e-9))).astype(np.int64)
    run_of = k // per_run
    # a run: consecutive rows of one segment in one window of `per_run` steps
    new_run = np.ones(len(rows), dtype=bool)
    new_run[1:] = (s[1:] != s[:-1]) | (run_of[1:] != run_of[:-1]) | (rows[1:] != rows[:-1] + 1)
    return _near_in_groups(tree, points[rows], np.cumsum(new_run), reach)


def _long_paths(paths: list[np.ndarray], min_length: float) -> list[np.ndarray]:
    """The polylines of `paths` at least `min_length` mm long (lengths summed in one pass)."""
    paths = [p for p in paths if len(p) >= 2]
    if not paths:
        return []
    points = np.concatenate(paths)
    step = np.hypot(*np.diff(points, axis=0).T)
    ends = np.cumsum([len(p) for p in paths])
    # a path's length: the steps from its first to its last point (the step into the next path left out)
    total = np.r_[0.0, np.cumsum(step)]
    lengths = total[ends - 1] - total[ends - np.array([len(p) for p in paths])]
    return [p for p, n in zip(paths, lengths, strict=True) if n >= min_length]


def _samples(paths: list[np.ndarray], step: float) -> np.ndarray:
    """Points along polylines at most `step` apart, shape (p, 2) mm."""
    paths = [p for p in paths if len(p) >= 2]
    if not paths:
        return np.zeros((0, 2))
    points = np.concatenate(paths)
    steps = np.ones(len(points) - 1, dtype=bool)  # point i to i + 1, but from one path to the next
    steps[np.cumsum([len(p) for p in paths[:-1]], dtype=np.int64) - 1] = False
    return sample_segments(np.stack([points[:-1][steps], points[1:][steps]], axis=1), step)
