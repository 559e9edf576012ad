"""Infill routing: clip segments to an area, chain them, order the chains.

* `clip_segments` keeps the parts of segments inside an area (exact:
  intersections with the boundary split segments, piece midpoints decide).
* `chain_segments` joins segments into polylines through shared vertices.
  At every vertex the incident segment ends are paired, opposite directions
  first, so chains run as straight as the triangulation allows; a vertex of
  odd degree leaves one end unpaired, where a chain must start or stop.  The
  number of open chains therefore equals the lower bound (odd vertices / 2);
  closed loops come on top.  Chains are read off by pointer jumping (list
  ranking), without a Python loop over segments.
* `order_paths` orders (and flips) chains to keep travel short: the
  shortest route for a few, else routes from `first_routes` improved by
  2-opt and or-opt, counting the travel to a given end.
* `plan_runs` shares one ordered route among blocks that must start and end
  at given points (Cura's FILL blocks of a layer), cutting it where the least
  travel is added (`route_cuts`, dynamic programming); `TravelCost` prices a
  travel that leaves the part like a retraction.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .first_routes import (distance_or_zero, nearest_end_route, route_ends, route_travel, shortest_links_route,
                           shortest_route)
from .geometry import boundary_segments, contains_xy

__all__ = ["clip_segments", "chain_segments", "order_paths", "travel_length", "odd_vertex_count", "TravelCost",
           "plan_runs", "route_cuts"]

_EPS = 1e-9
_QUANTUM = 1e-5  # mm: endpoints closer than this are one vertex
_OR_OPT_MOST = 5000  # order_paths: or-opt on routes of at most this many paths
_EXACT_MOST = 9  # order_paths: routes of at most this many paths are the shortest (`shortest_route`, ~1 ms)
_TWO_STARTS_MOST = 32  # ... of at most this many also start from the shortest links (the shorter is kept)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def split_segments(segments: np.ndarray, longest: float) -> tuple[np.ndarray, np.ndarray]:
    """Segments (m, 2, 2) cut into equal pieces at most `longest` mm long.

    Returns
    -------
    (ndarray, shape (k, 2, 2), ndarray of int, shape (k,))
        The pieces, in order, and the index of the segment each comes from.
    """
    d = segments[:, 1] - segments[:, 0]
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / longest).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n)
    k = np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)
    t0, t1 = (k / n[seg])[:, None], ((k + 1) / n[seg])[:, None]
    return np.stack([segments[seg, 0] + d[seg] * t0, segments[seg, 0] + d[seg] * t1], axis=1), seg


_BOUNDARIES: dict[int, tuple] = {}  # id(area) -> (area, its boundary segments): areas are clipped against repeatedly
_BRUTE_FORCE_PAIRS = 1024  # up to this many segment x boundary pairs, test them all (no sweep)
_MAX_CANDIDATES = 4_000_000  # pairs the box sweep compares at most (beyond: pairs by distance)
_BROADCAST_PAIRS = 250_000  # up to this many, every box against every box at once (no sweep)


def _boundary_of(area) -> np.ndarray:
    """`boundary_segments(area)`, remembered for the last few areas (held, so their ids stay theirs)."""
    hit = _BOUNDARIES.get(id(area))
    if hit is not None and hit[0] is area:
        return hit[1]
    boundary = boundary_segments(area)
    if len(_BOUNDARIES) >= 8:
        _BOUNDARIES.clear()  # (clear, not evict one: safe if another thread clips at the same time)
    _BOUNDARIES[id(area)] = (area, boundary)
    return boundary


def _meeting_pairs(segments: np.ndarray, length: np.ndarray, pieces: np.ndarray):
    """The (segment, piece) pairs whose bounding boxes meet: index arrays (p,), (p,), by segment.

    A superset of the crossing pairs, found by a sweep along the axis where the
    pieces are narrowest: sorted by their lower end, the pieces that can meet a
    segment's extent on that axis are one run of the order; only those are
    compared box to box.  None when more than `_MAX_CANDIDATES` would be.
    """
    margin = 1e-6 * max(1.0, float(length.max()))
    s_lo, s_hi = segments.min(axis=1) - margin, segments.max(axis=1) + margin
    p_lo, p_hi = pieces.min(axis=1), pieces.max(axis=1)
    widest = (p_hi - p_lo).max(axis=0)
    axis = int(widest[1] < widest[0])
    order = np.argsort(p_lo[:, axis], kind="stable")
    sorted_lo = p_lo[order, axis]
    first = np.searchsorted(sorted_lo, s_lo[:, axis] - widest[axis], side="left")
    count = np.searchsorted(sorted_lo, s_hi[:, axis], side="right") - first
    if int(count.sum()) > _MAX_CANDIDATES:
        return None
    ia = np.repeat(np.arange(len(segments), dtype=np.intp), count)
    ib = order[np.arange(ia.size) - np.repeat(np.cumsum(count) - count - first, count)]
    meet = (s_lo[ia, 0] <= p_hi[ib, 0]) & (s_hi[ia, 0] >= p_lo[ib, 0])
    meet &= (s_lo[ia, 1] <= p_hi[ib, 1]) & (s_hi[ia, 1] >= p_lo[ib, 1])
    return ia[meet], ib[meet].astype(np.intp)


def clip_segments(segments: np.ndarray, area, *, return_index: bool = False):
    """The parts of `segments` that lie inside `area`.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        Start and end points, mm.
    area : shapely (Multi)Polygon
    return_index : bool
        Also return, for every piece, the index of the segment it came from.

    Returns
    -------
    ndarray, shape (k', 2, 2)
        Inside pieces, in input order; a segment crossing the boundary is cut
        at the crossing points.
    ndarray of int, shape (k',)
        Only with `return_index`.
    """
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if len(segments) == 0 or area.is_empty:
        empty = np.zeros((0, 2, 2))
        return (empty, np.zeros(0, np.intp)) if return_index else empty
    boundary = _boundary_of(area)
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    longest = float(length.max()) if len(length) else 0.0
    # Only the segments whose boxes meet the area's can have a piece inside it (the rest are left
    # out before any work; the boundary is still split by the longest segment of all, as before).
    s_lo, s_hi = np.minimum(segments[:, 0], segments[:, 1]), np.maximum(segments[:, 0], segments[:, 1])
    x0, y0, x1, y1 = area.bounds
    near = np.flatnonzero((s_lo[:, 0] <= x1) & (s_hi[:, 0] >= x0) & (s_lo[:, 1] <= y1) & (s_hi[:, 1] >= y0))
    segments, length, s_lo, s_hi = segments[near], length[near], s_lo[near], s_hi[near]
    ia = np.zeros(0, np.intp)
    ta = np.zeros(0)
    if len(boundary) and longest > 0 and len(segments):
        boundary, _ = split_segments(boundary, max(longest, 1e-3))
        pairs = None
        n_pairs = len(segments) * len(boundary)
        if n_pairs <= _BRUTE_FORCE_PAIRS:
            # Few pairs: test them all.  Pairs the box sweep or the k-d trees would skip cannot
            # intersect, so the crossings (and the result) are the same.
            ia = np.repeat(np.arange(len(segments), dtype=np.intp), len(boundary))
            ib = np.tile(np.arange(len(boundary), dtype=np.intp), len(segments))
        elif n_pairs <= _BROADCAST_PAIRS:
            # Every segment's box against every piece's at once (the pairs the sweep finds, fewer calls)
            margin = 1e-6 * max(1.0, longest)
            a_lo, a_hi = s_lo - margin, s_hi + margin
            b_lo = np.minimum(boundary[:, 0], boundary[:, 1])
            b_hi = np.maximum(boundary[:, 0], boundary[:, 1])
            meet = (a_lo[:, None, 0] <= b_hi[None, :, 0]) & (a_hi[:, None, 0] >= b_lo[None, :, 0])
            meet &= (a_lo[:, None, 1] <= b_hi[None, :, 1]) & (a_hi[:, None, 1] >= b_lo[None, :, 1])
            ia, ib = np.nonzero(meet)
        elif (pairs := _meeting_pairs(segments, length, boundary)) is not None:
            ia, ib = pairs
        else:  # a degenerate layout (pieces wide on both axes everywhere): pairs by distance
            blen = np.hypot(*(boundary[:, 1] - boundary[:, 0]).T)
            reach = 0.5 * (longest + float(blen.max())) + 1e-6
            sdm = cKDTree(segments.mean(axis=1)).sparse_distance_matrix(
                cKDTree(boundary.mean(axis=1)), reach, output_type="ndarray"
            )
            ia, ib = sdm["i"].astype(np.intp), sdm["j"].astype(np.intp)
        p, r = segments[ia, 0], segments[ia, 1] - segments[ia, 0]
        q, s = boundary[ib, 0], boundary[ib, 1] - boundary[ib, 0]
        denom = _cross(r, s)
        ok = np.abs(denom) > 1e-15
        safe = np.where(ok, denom, 1.0)
        t = _cross(q - p, s) / safe
        u = _cross(q - p, r) / safe
        hit = ok & (t > _EPS) & (t < 1 - _EPS) & (u >= -_EPS) & (u <= 1 + _EPS)
        ia, ta = ia[hit], t[hit]
    k = len(segments)
    seg_id = np.concatenate((np.arange(k), np.arange(k), ia))
    param = np.concatenate((np.zeros(k), np.ones(k), ta))
    order = np.lexsort((param, seg_id))
    seg_id, param = seg_id[order], param[order]
    same = seg_id[1:] == seg_id[:-1]
    sid = seg_id[:-1][same]
    t0, t1 = param[:-1][same], param[1:][same]
    keep = (t1 - t0) * length[sid] > 1e-7
    sid, t0, t1 = sid[keep], t0[keep], t1[keep]
    a, b = segments[sid, 0], segments[sid, 1]
    start = a + (b - a) * t0[:, None]
    end = a + (b - a) * t1[:, None]
    mid = 0.5 * (start + end)
    inside = contains_xy(area, mid[:, 0], mid[:, 1])
    pieces = np.stack([start[inside], end[inside]], axis=1)
    return (pieces, near[sid[inside]]) if return_index else pieces


def _vertex_ids(points: np.ndarray) -> tuple[np.ndarray, int]:
    """Ids of coincident points (within _QUANTUM); returns (ids, count)."""
    q = np.round(points / _QUANTUM).astype(np.int64)
    key = q[:, 0] * (1 << 32) + (q[:, 1] + (1 << 31))
    _, ids = np.unique(key, return_inverse=True)
    ids = ids.ravel()
    return ids, int(ids.max()) + 1 if ids.size else 0


def odd_vertex_count(segments: np.ndarray) -> int:
    """Number of vertices of odd degree in the segment graph."""
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if len(segments) == 0:
        return 0
    ids, n = _vertex_ids(segments.reshape(-1, 2))
    return int(np.count_nonzero(np.bincount(ids, minlength=n) % 2))


def _rank(nxt: np.ndarray):
    """Pointer jumping: for each node, the last node of its chain and the steps to it."""
    n = len(nxt)
    idx = np.arange(n)
    ptr = np.where(nxt >= 0, nxt, idx)
    dist = (nxt >= 0).astype(np.int64)
    for _ in range(max(1, math.ceil(math.log2(max(n, 2)))) + 1):
        dist = dist + dist[ptr]
        ptr = ptr[ptr]
    return ptr, dist


def chain_segments(segments: np.ndarray) -> list[np.ndarray]:
    """Join segments into polylines through shared vertices.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)

    Returns
    -------
    list of ndarray, each shape (m, 2)
        Polylines using every segment exactly once; a closed loop repeats its
        first point at the end.
    """
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    k = len(segments)
    if k == 0:
        return []
    ends = segments.reshape(-1, 2)  # end e = 2*segment + side
    vid, _ = _vertex_ids(ends)
    other = ends[np.arange(2 * k) ^ 1]
    angle = np.arctan2(other[:, 1] - ends[:, 1], other[:, 0] - ends[:, 0])
    # Pair the ends at each vertex: sorted by direction, end p with end p + d/2
    # (the most opposite direction); an odd vertex leaves its last end free.
    order = np.lexsort((angle, vid))
    svid = vid[order]
    start = np.flatnonzero(np.r_[True, svid[1:] != svid[:-1]])
    size = np.diff(np.r_[start, 2 * k])
    group = np.repeat(np.arange(len(start)), size)
    pos = np.arange(2 * k) - start[group]
    half = (size // 2)[group]
    a = np.flatnonzero(pos < half)
    b = a + half[a]
    partner = np.full(2 * k, -1, dtype=np.int64)
    partner[order[a]] = order[b]
    partner[order[b]] = order[a]

    # Walking a chain: enter segment at end e, leave at e ^ 1, continue into
    # the end paired with e ^ 1.
    nxt = partner[np.arange(2 * k) ^ 1]
    ptr, _ = _rank(nxt)
    in_loop = nxt[ptr] >= 0
    starts = []
    if in_loop.any():
        # A loop is seen in both directions; keep the one holding the smaller
        # end index and open it there.
        label = np.where(in_loop, np.arange(2 * k), 2 * k)
        jump = np.where(in_loop, nxt, np.arange(2 * k))
        for _ in range(max(1, math.ceil(math.log2(2 * k))) + 1):
            label = np.minimum(label, label[jump])
            jump = jump[jump]
        mirror = label[np.arange(2 * k) ^ 1]
        kept = in_loop & (label < mirror)
        closing = np.flatnonzero(kept & (nxt == label))  # the end that leads back to the start
        nxt = nxt.copy()
        nxt[closing] = -1
        starts.append(np.flatnonzero(kept & (label == np.arange(2 * k))))
    free = np.flatnonzero(partner < 0)
    ptr, dist = _rank(nxt)
    # An open chain has a free end at each side; keep one direction.
    free = free[free < (ptr[free] ^ 1)]
    starts.insert(0, free)
    starts = np.concatenate(starts)
    terminal = ptr[starts]
    chain_of = np.full(2 * k, -1, dtype=np.int64)
    chain_of[terminal] = np.arange(len(starts))
    member = np.flatnonzero(chain_of[ptr] >= 0)
    chain = chain_of[ptr[member]]
    member = member[np.lexsort((-dist[member], chain))]
    chain = chain_of[ptr[member]]
    # Polyline of a chain: the entry point of its first segment, then the exit
    # point of every segment.
    cuts = np.flatnonzero(np.r_[True, chain[1:] != chain[:-1]])
    exits = ends[member ^ 1]
    first_entry = ends[member[cuts]]
    counts = np.diff(np.r_[cuts, len(member)])
    points = np.insert(exits, cuts, first_entry, axis=0)
    bounds = np.cumsum(counts + 1)[:-1]
    return np.split(points, bounds)


def order_paths(
    paths: list[np.ndarray], start=None, *, end=None, rounds: int = 8, window: int = 64
) -> tuple[list[np.ndarray], float]:
    """Order and orient paths to keep travel between them short.

    Up to `_EXACT_MOST` paths the route is the shortest (`first_routes.shortest_route`).
    Beyond, greedy nearest end first, then rounds of 2-opt: reversing a run of
    paths (each flipped) changes only the two travels at its ends, so every
    move (run start x run length up to `window`) is scored at once, and the
    best non-touching moves are applied together.  Greedy order leaves mostly
    local detours; the window keeps a round linear in the number of paths.
    Then or-opt (`_or_opt`: single paths moved into better gaps) and 2-opt
    once more.  Up to `_TWO_STARTS_MOST` paths the same improvement also runs
    from the shortest links first (`first_routes.shortest_links_route`), and
    the shorter route is kept: nearest end first strands short paths that a
    route must come back for, and local moves rarely undo that (on the
    everyday models' routes of 10-32 paths the two starts travel about 5 %
    less than one: `bench/bench_routes.py`).

    Parameters
    ----------
    paths : list of ndarray, each shape (m, 2)
    start : (x, y), optional
        Where the nozzle is before the first path.
    end : (x, y), optional
        Where the nozzle goes after the last path (the next feature's start): the travel there
        counts too.
    rounds : int
        2-opt rounds at most (0: nearest end first only, whatever the count);
        they stop early when a round saves less than 0.2 % of the travel.
    window : int
        Longest run of paths a 2-opt move reverses.

    Returns
    -------
    (paths, travel_mm)
        Reordered (and possibly reversed) paths, and the straight-line travel
        between consecutive paths (from `start` and to `end` when given).
    """
    n = len(paths)
    if n == 0:
        return [], 0.0
    # Row j < n is the head of path j, row n + j its tail.
    ends = np.concatenate([[p[0] for p in paths], [p[-1] for p in paths]])
    # Path ends as complex numbers: gathers on 1-D arrays and abs() (numpy's hypot) keep a round cheap.
    ends_c = ends[:, 0] + 1j * ends[:, 1]
    origin = complex(*np.asarray(start, dtype=float)) if start is not None else complex(np.nan, np.nan)
    terminus = complex(*np.asarray(end, dtype=float)) if end is not None else complex(np.nan, np.nan)
    if rounds > 0 and n <= _EXACT_MOST:
        firsts = [shortest_route(ends_c, origin, terminus)]
    else:
        firsts = [nearest_end_route(ends, start)]
        if rounds > 0 and n <= _TWO_STARTS_MOST:
            firsts.append(shortest_links_route(ends_c, origin, terminus))
    improve = rounds > 0 and n > _EXACT_MOST  # (a shortest route needs no improving)
    near = near_paths(ends, n) if improve and n <= _OR_OPT_MOST else None
    best = None
    for order, flipped in firsts:
        entry, exit_ = route_ends(ends_c, order, flipped)
        if improve:
            _improve(entry, exit_, order, flipped, origin, terminus, near, rounds, window)
        travel = route_travel(entry, exit_, origin, terminus)
        if best is None or travel < best[0] - 1e-9:
            best = (travel, order, flipped)
    travel, order, flipped = best
    return [paths[i][::-1] if f else paths[i] for i, f in zip(order.tolist(), flipped.tolist())], travel


def _improve(entry: np.ndarray, exit_: np.ndarray, order: np.ndarray, flipped: np.ndarray, origin: complex,
             terminus: complex, near: np.ndarray | None, rounds: int, window: int) -> None:
    """2-opt, then or-opt and 2-opt again when or-opt moved a path (it opens new reversals), in place.

    Arrays as in `_two_opt`; `origin` / `terminus` complex, NaN: none; `near` the paths near each
    (`near_paths`; None: no or-opt).
    """
    n = len(order)
    if n < 2:
        return
    with_start = not np.isnan(origin)
    moves = _moves(n, window, with_start)
    _two_opt(entry, exit_, order, flipped, origin if with_start else entry[0], moves, rounds, terminus)
    if near is not None and _or_opt(entry, exit_, order, flipped, origin, terminus, rounds, near):
        _two_opt(entry, exit_, order, flipped, origin if with_start else entry[0], moves, rounds, terminus)


_MOVES: dict[tuple, tuple] = {}  # (paths, window, with a start) -> the 2-opt moves (`_moves`)


def _moves(n: int, window: int, with_start: bool) -> tuple:
    """The 2-opt moves of `order_paths` for n paths, remembered (order_paths runs often on few paths).

    Row i, column c: reverse positions i..j with j = i + c + 1 (clipped to n - 1).  Returns
    ``(i, j, valid, nxt, last, prev, after_first, rows)``: ``i`` (n, 1) and ``after_first``
    (n, 1, i > 0), the others (n, w) with w = min(window, n - 1) (longer runs are never valid
    moves), ``rows`` (n,).  Shared: never written to.
    """
    key = (n, window, with_start)
    hit = _MOVES.get(key)
    if hit is None:
        offsets = np.arange(1, max(1, min(window, n - 1)) + 1)
        i = np.arange(n)[:, None]
        j = np.minimum(i + offsets[None, :], n - 1)
        valid = (i + offsets[None, :] <= n - 1) & ((i > 0) | with_start)
        nxt = np.minimum(j + 1, n - 1)
        last = j == n - 1  # reversing up to the end: no travel after it
        prev = np.maximum(i - 1, 0)
        hit = (i, j, valid, nxt, last, prev, i > 0, np.arange(n))
        if len(_MOVES) >= 256:
            _MOVES.clear()
        _MOVES[key] = hit
    return hit


def _two_opt(entry: np.ndarray, exit_: np.ndarray, order: np.ndarray, flipped: np.ndarray, origin, moves: tuple,
             rounds: int, terminus: complex = complex(np.nan, np.nan)) -> None:
    """Rounds of 2-opt on a route, in place: `entry`/`exit_` (n,) complex ends of each position's path,
    `order` (n,) its path, `flipped` (n,) whether it runs backwards; `origin` the start, `terminus` the
    end to reach after the last path (complex; NaN: none)."""
    i, j, valid, nxt, last, prev, after_first, rows = moves
    n = len(order)
    for _ in range(rounds):
        # Reversing positions i..j turns the travels (exit[i-1] -> entry[i]) and
        # (exit[j] -> entry[j+1]) into (exit[i-1] -> exit[j]) and (entry[i] -> entry[j+1]).
        before = np.where(after_first, exit_[prev], origin)
        following = np.where(last, terminus, entry[nxt])
        old = np.abs(entry[i] - before) + distance_or_zero(following, exit_[j])
        new = np.abs(exit_[j] - before) + distance_or_zero(following, entry[i])
        gain = np.where(valid, old - new, -np.inf)
        best = gain.argmax(axis=1)
        best_gain = gain[rows, best]
        movers = np.flatnonzero(best_gain > 1e-9)
        if movers.size == 0:
            break
        # Apply the best moves whose runs (with one path of margin) do not touch.
        busy = [False] * (n + 2)
        saved = 0.0
        gains, ends_at = best_gain.tolist(), best.tolist()
        for a in movers[np.argsort(-best_gain[movers])].tolist():
            b = a + ends_at[a] + 1  # a valid move's j
            if any(busy[a : b + 3]):
                continue
            busy[a : b + 3] = [True] * (b + 3 - a)  # (b + 3 <= n + 2)
            saved += gains[a]
            run = slice(a, b + 1)
            entry[run], exit_[run] = exit_[run][::-1].copy(), entry[run][::-1].copy()
            order[run] = order[run][::-1].copy()
            flipped[run] = ~flipped[run][::-1]
        if saved < 2e-3 * float(np.abs(entry[1:] - exit_[:-1]).sum()):
            break


_NEAR_PATHS = 6  # or-opt: each path tries the gaps beside the paths with an end among this many nearest to its ends


def near_paths(ends: np.ndarray, n: int) -> np.ndarray:
    """Per path, the paths with an end among the `_NEAR_PATHS` nearest to either of its ends.

    Parameters
    ----------
    ends : ndarray, shape (2 n, 2)
        Row j < n the head of path j, row n + j its tail, mm.
    n : int

    Returns
    -------
    ndarray of int, shape (n, 2 k)
        Path indices (a path may list itself; or-opt leaves such a move out).
    """
    k = min(_NEAR_PATHS + 1, 2 * n)
    _, idx = cKDTree(ends).query(ends, k=k)
    idx = np.asarray(idx).reshape(2 * n, k) % n
    return np.concatenate([idx[:n], idx[n:]], axis=1)


def _near_gaps(order: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Per position, the gaps beside the positions of its path's `near` paths, and the route's two
    ends (gap g lies between positions g - 1 and g), shape (n, 4 k + 2)."""
    n = len(order)
    position = np.empty(n, dtype=np.int64)
    position[order] = np.arange(n)
    beside = position[near[order]]  # (n, 2 k)
    return np.concatenate([beside, beside + 1, np.zeros((n, 1), np.int64), np.full((n, 1), n)], axis=1)


def _or_opt(entry: np.ndarray, exit_: np.ndarray, order: np.ndarray, flipped: np.ndarray, origin: complex,
            terminus: complex, rounds: int, near: np.ndarray) -> bool:
    """Rounds of or-opt on a route, in place (arrays as in `_two_opt`; `origin` / `terminus` the start
    and the end to reach, complex, NaN: none): each path may move, either way round, into another gap.

    2-opt only reverses runs; a short path the greedy order left behind (a stub at the far end of a
    part, printed on a detour) needs moving.  Taking path p
    out of its place saves ``|a - p.entry| + |p.exit - b| - |a - b|`` (a, b its neighbours' ends), putting
    it into gap (c, d) costs ``min(|c - p.entry| + |p.exit - d|, |c - p.exit| + |p.entry - d|) - |c - d|``,
    scored at once for every path and the gaps beside its `near` paths (`near_paths`, by path; a move
    far from both of a path's ends only adds travel) and at the route's two ends; per round the best moves that touch none of the same positions are applied; the rounds stop when
    one saves under 0.2 % of the travel.  Returns whether any path moved.
    """
    n = len(order)
    if n < 3:
        return False
    rows = np.arange(n)
    at_origin, at_terminus = np.array([origin]), np.array([terminus])
    moved_any = False
    for _ in range(rounds):
        left = np.concatenate((at_origin, exit_))  # (n + 1,) gap g lies between position g - 1 and g
        right = np.concatenate((entry, at_terminus))
        before, after = left[:-1], right[1:]  # (n,) the end each position is reached from, and goes to
        taken_out = (distance_or_zero(before, entry) + distance_or_zero(exit_, after)
                     - distance_or_zero(before, after))
        gaps = _near_gaps(order, near)  # (n, c) candidate gaps of each position's path
        lg, rg = left[gaps], right[gaps]
        open_gap = distance_or_zero(lg, rg)
        forward = distance_or_zero(lg, entry[:, None]) + distance_or_zero(exit_[:, None], rg)
        backward = distance_or_zero(lg, exit_[:, None]) + distance_or_zero(entry[:, None], rg)
        gain = taken_out[:, None] - (np.minimum(forward, backward) - open_gap)
        gain[(gaps == rows[:, None]) | (gaps == rows[:, None] + 1)] = -np.inf  # next to the path itself: no move
        pick = gain.argmax(axis=1)
        best_gain = gain[rows, pick]
        best = gaps[rows, pick]
        flip_best = backward[rows, pick] < forward[rows, pick]
        movers = np.flatnonzero(best_gain > 1e-6)
        if movers.size == 0:
            break
        busy = np.zeros(n + 2, dtype=bool)
        moves, saved = [], 0.0
        for p in movers[np.argsort(-best_gain[movers])].tolist():
            g = int(best[p])
            touched = [p - 1, p, p + 1, g - 1, g]
            if busy[np.clip(touched, 0, n)].any():
                continue
            busy[np.clip(touched, 0, n)] = True
            moves.append((p, g, bool(flip_best[p])))
            saved += float(best_gain[p])
        # The new order: a moved path leaves its position and enters gap g, just before position g
        # (at most one path enters a gap: its neighbours are busy then).
        key = np.arange(n, dtype=float)
        turn_of = np.zeros(n, dtype=bool)
        for p, g, flip in moves:
            key[p] = g - 0.5
            turn_of[p] = flip
        at = np.argsort(key, kind="stable")
        turn = turn_of[at]
        new_entry = np.where(turn, exit_[at], entry[at])
        new_exit = np.where(turn, entry[at], exit_[at])
        entry[:], exit_[:] = new_entry, new_exit
        order[:] = order[at]
        flipped[:] = flipped[at] ^ turn
        moved_any = True
        if saved < 2e-3 * route_travel(entry, exit_, origin, terminus):
            break
    return moved_any


def travel_length(paths: list[np.ndarray], start=None) -> float:
    """Straight-line travel between consecutive paths (from `start` if given), mm."""
    if not paths:
        return 0.0
    heads = np.array([p[0] for p in paths])
    tails = np.array([p[-1] for p in paths])
    total = float(np.hypot(*(heads[1:] - tails[:-1]).T).sum())
    if start is not None:
        total += float(np.hypot(*(heads[0] - np.asarray(start, dtype=float))))
    return total


# ----------------------------------------------------------------------------- a route shared among blocks
class TravelCost:
    """Cost of straight travels: their length, plus `penalty` mm for each that leaves `part`."""

    def __init__(self, part, penalty: float):
        self.part = part
        self.penalty = penalty

    def __call__(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Cost (mm) of the travels starts[i] -> ends[i], each (k, 2); unknown (NaN) points cost 0."""
        starts = np.broadcast_to(np.asarray(starts, dtype=float).reshape(-1, 2), np.shape(ends)).reshape(-1, 2)
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        d = np.hypot(*(ends - starts).T)
        known = np.isfinite(d)
        cost = np.where(known, d, 0.0)
        if self.penalty <= 0 or self.part is None or not known.any():
            return cost
        from .combing import segments_inside  # (combing clips with this module: imported when used)

        idx = np.flatnonzero(known & (d > 1e-9))
        cost[idx] += np.where(segments_inside(starts[idx], ends[idx], self.part), 0.0, self.penalty)
        return cost


def plan_runs(paths: list[np.ndarray], ends: np.ndarray, cost_of, rounds: int = 3) -> list[list[np.ndarray]]:
    """Share an ordered route among blocks that start and end at given points, with little travel.

    The blocks keep Cura's order, and each must start and end where Cura's
    did.  Each round cuts the route where the added travel is least
    (`route_cuts`; a block may get no path: it is then one travel), then
    re-routes each run from its block's start (or back from its end) when
    that is shorter; the runs joined are the next round's route.

    Parameters
    ----------
    paths : list of ndarray, each (m, 2)
        The layer's paths in print order, mm.
    ends : ndarray, shape (b, 4)
        Per block in print order: start x, y and end x, y (NaN: unknown).
    cost_of : callable(starts (k, 2), ends (k, 2)) -> ndarray (k,)
        Cost of straight travels, mm (`TravelCost`).

    Returns
    -------
    list of list of ndarray
        One run of paths per block.
    """
    best_runs, best_cost = None, math.inf
    order = paths
    routed: dict[tuple, list] = {}  # (block, its run's paths): its routes; a block's run often stays the same
    for _ in range(rounds):
        cuts = route_cuts(order, ends, cost_of)
        # Per block: its run as cut, routed forward from its start, and routed back from its end.
        options = []
        for i in range(len(ends)):
            run = order[cuts[i] : cuts[i + 1]]
            b = ends[i]
            options.append([run])
            if len(run) >= 2:
                key = (i, *map(id, run))
                if key not in routed:
                    head = (b[0], b[1]) if math.isfinite(b[0]) else None
                    tail = (b[2], b[3]) if math.isfinite(b[2]) else None
                    forward, _ = order_paths(run, head, end=tail)
                    backward, _ = order_paths(run, tail, end=head)
                    routed[key] = [forward, [p[::-1] for p in backward[::-1]]]
                options[-1] += routed[key]
        flat = [(run, ends[i]) for i, opts in enumerate(options) for run in opts]
        costs = runs_travel([r for r, _ in flat], [b for _, b in flat], cost_of)
        runs, total, at = [], 0.0, 0
        for opts in options:
            pick = int(np.argmin(costs[at : at + len(opts)] - 1e-6 * (np.arange(len(opts)) == 0)))
            runs.append(list(opts[pick]))
            total += float(costs[at + pick])
            at += len(opts)
        if total >= best_cost - 1e-6:
            break
        best_runs, best_cost = runs, total
        joined = [p for r in runs for p in r]
        if len(joined) == len(order) and all(a is b for a, b in zip(joined, order)):
            break  # the same route again: the next round would cut and cost it the same way
        order = joined
    return best_runs


def route_cuts(paths: list[np.ndarray], ends: np.ndarray, cost_of) -> np.ndarray:
    """Where to cut an ordered route into runs for blocks that must start and end at given points.

    Block i (in print order) starts at ``ends[i, :2]`` and must end at
    ``ends[i, 2:]``; it prints paths ``cuts[i]:cuts[i + 1]`` (possibly none:
    then it is one travel from its start to its end).  Dynamic programming
    over the cut positions minimizes the total travel (straight lines), each
    block's run costing the travel in, the travel between its paths and the
    travel out; with prefix minima it is O(blocks x paths).

    Parameters
    ----------
    paths : list of ndarray, each (m, 2)
        The route, in order, mm.
    ends : ndarray, shape (b, 4)
        Per block: start x, y and end x, y (NaN: unknown, costs nothing).
    cost_of : callable
        Cost of straight travels (`TravelCost`).

    Returns
    -------
    ndarray of int, shape (b + 1,)
        ``cuts[0] = 0``, ``cuts[-1] = len(paths)``, non-decreasing.
    """
    n, nb = len(paths), len(ends)
    heads = np.array([p[0] for p in paths], dtype=float).reshape(-1, 2)
    tails = np.array([p[-1] for p in paths], dtype=float).reshape(-1, 2)
    # Every travel the programme may choose, costed at once: between paths, into each path from
    # each block's start, out of each path to each block's end, and each block's own hop.
    starts = np.concatenate([tails[:-1], np.repeat(ends[:, :2], n, axis=0), np.tile(tails, (nb, 1)), ends[:, :2]])
    stops = np.concatenate([heads[1:], np.tile(heads, (nb, 1)), np.repeat(ends[:, 2:], n, axis=0), ends[:, 2:]])
    every = cost_of(starts, stops)
    gaps, rest = every[: max(n - 1, 0)], every[max(n - 1, 0) :]
    enter_cost = rest[: nb * n].reshape(nb, n)
    exit_cost = rest[nb * n : 2 * nb * n].reshape(nb, n)
    hops = rest[2 * nb * n :]
    inner = np.r_[0.0, np.cumsum(gaps)]  # inner[k]: travel between paths 0..k

    # f[k]: least travel of the blocks so far when the next block's run starts at path k.
    f = np.full(n + 1, np.inf)
    f[0] = 0.0
    choice = np.zeros((nb, n + 1), dtype=np.int64)
    stay = np.arange(n + 1)  # choice "no run ends here": the cut stays where it is
    through = np.full(n + 1, np.inf)  # (through[0] stays inf: a run has a path)
    run_from = np.zeros(n + 1, dtype=np.int64)
    for i in range(nb):
        hop = float(hops[i])
        # Run k'..k-1: f[k'] + |start -> head k'| - inner[k'] + inner[k-1] + |tail k-1 -> stop|.
        enter = f[:n] + enter_cost[i] - inner
        best = np.minimum.accumulate(enter)
        run_from[1:] = running_argmin(enter, best)
        through[1:] = best + inner + exit_cost[i]
        empty = f + hop
        use_run = through < empty
        choice[i] = np.where(use_run, run_from, stay)
        f = np.where(use_run, through, empty)
    if not np.isfinite(f[n]):
        return np.r_[0, np.full(nb, n)]
    cuts = np.zeros(nb + 1, dtype=np.int64)
    cuts[nb] = n
    k = n
    for i in range(nb - 1, -1, -1):
        k = int(choice[i, k])
        cuts[i] = k
    cuts[0] = 0
    return cuts


def runs_travel(runs: list, ends: list, cost_of) -> np.ndarray:
    """`run_travel` of many (run, ends) pairs with one call of `cost_of`."""
    # Every run's points in travel order: its start, head and tail of each path, its end; the
    # travels are the consecutive pairs (each run adds an even count, so pairs never straddle runs).
    points: list = []
    travels = np.empty(len(runs), dtype=np.int64)
    for k, (run, b) in enumerate(zip(runs, ends, strict=True)):
        points.append(b[:2])
        for p in run:
            points.append(p[0])
            points.append(p[-1])
        points.append(b[2:])
        travels[k] = len(run) + 1
    pts = np.array(points, dtype=float).reshape(-1, 2)
    costs = cost_of(pts[0::2], pts[1::2])
    return np.bincount(np.repeat(np.arange(len(runs)), travels), costs, len(runs))


def run_travel(run: list[np.ndarray], ends, cost_of) -> float:
    """Travel cost of a block printing `run`: in from ends[:2], between the paths, out to ends[2:] (mm).

    With no path it is the travel from ends[:2] to ends[2:]; unknown (NaN) ends cost nothing.
    """
    pts = [np.asarray(ends[:2], dtype=float)]
    for p in run:
        pts += [p[0], p[-1]]
    pts.append(np.asarray(ends[2:], dtype=float))
    pts = np.array(pts).reshape(-1, 2, 2)
    return float(cost_of(pts[:, 0], pts[:, 1]).sum())


def running_argmin(values: np.ndarray, best: np.ndarray | None = None) -> np.ndarray:
    """Index of the minimum of values[:k + 1] for every k (`best`: their running minimum, if known)."""
    if best is None:
        best = np.minimum.accumulate(values)
    is_new = np.empty(len(values), dtype=bool)
    is_new[:1] = True
    np.less(values[1:], best[:-1], out=is_new[1:])
    idx = np.where(is_new, np.arange(len(values)), 0)
    return np.maximum.accumulate(idx)
