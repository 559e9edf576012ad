"""Routes through a layer's paths, built from scratch: where `routing.order_paths` starts.

A route prints every path once, either way round, from a start point to an end point (both
optional); its cost is the straight travel between consecutive paths, from the start and to the
end.  Path ends are given as ``ends``, shape (2 n,): row k < n the head of path k, row n + k its tail.
Every function returns ``(order, flipped)``: ``order`` (n,) int, the paths in print order, and
``flipped`` (n,) bool, whether each is printed tail first.

* `shortest_route`: the exact shortest route (Held-Karp over subsets of paths), for few paths.
* `nearest_end_route`: from where the nozzle is, the nearest free path end, each time.
* `shortest_links_route`: the shortest links between path ends first, skipping those that would
  give an end two links or close a loop (the greedy-edge construction of travelling-salesman
  routes).  Nearest end first strands short paths that the route then comes back for; shortest
  links first joins them to their neighbours.  Neither is better everywhere (see `order_paths`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["shortest_route", "nearest_end_route", "shortest_links_route", "route_ends", "route_travel"]


def distance_or_zero(a, b) -> np.ndarray:
    """|a - b| of complex points, 0 where either is NaN (no start, no end to reach)."""
    return np.fmax(np.abs(a - b), 0.0)  # (fmax takes the number where the other is NaN)


def route_ends(ends: np.ndarray, order: np.ndarray, flipped: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each position of a route enters its path and where it leaves it, each shape (n,) complex."""
    n = len(order)
    entry = np.where(flipped, ends[order + n], ends[order])
    leave = np.where(flipped, ends[order], ends[order + n])
    return entry, leave


def route_travel(entry: np.ndarray, leave: np.ndarray, origin: complex, terminus: complex) -> float:
    """The straight travel of a route (`route_ends`): from `origin`, between its paths, to `terminus`, mm."""
    return float(distance_or_zero(entry[1:], leave[:-1]).sum() + distance_or_zero(entry[0], origin)
                 + distance_or_zero(terminus, leave[-1]))


@lru_cache(maxsize=16)
def _subsets_by_size(n: int) -> tuple[np.ndarray, ...]:
    """Bit masks of the subsets of n paths with 2, 3, ..., n members, one array per size."""
    masks = np.arange(1 << n, dtype=np.int64)
    members = sum((masks >> k) & 1 for k in range(n))
    return tuple(masks[members == size] for size in range(2, n + 1))


def shortest_route(ends: np.ndarray, origin: complex, terminus: complex) -> tuple[np.ndarray, np.ndarray]:
    """The shortest route through all paths, each printed either way: Held-Karp dynamic programming.

    ``cost[S, k]`` is the least travel that prints the set S of paths and ends having entered its
    last path at end k (so the nozzle is at that path's other end); a set of s paths is reached
    from the sets of s - 1, all of one size at once.  Time and memory grow as 2^n (2 n)^2 and
    2^n 2 n: about 1 ms at n = 9, 8 ms at 12, 0.4 s at 16.

    Parameters
    ----------
    ends : ndarray of complex, shape (2 n,)
        Heads then tails, mm.
    origin, terminus : complex
        Where the nozzle starts and where it must go after the last path; NaN: nowhere given.

    Returns
    -------
    (order, flipped) : ndarray of int (n,), ndarray of bool (n,)
    """
    count = len(ends)
    n = count // 2
    leave = np.r_[ends[n:], ends[:n]]  # entered at end k, the path is left at its other end
    hop = np.abs(ends[None, :] - leave[:, None])  # (2n, 2n): left after entering at a -> entering at b
    into = hop.T[None]  # (1, b, a)
    bit = np.int64(1) << (np.arange(count, dtype=np.int64) % n)
    cost = np.full((1 << n, count), np.inf)
    cost[bit, np.arange(count)] = distance_or_zero(ends, origin)
    came_from = np.full((1 << n, count), -1, dtype=np.int64)
    for masks in _subsets_by_size(n):
        before = masks[:, None] ^ bit[None, :]  # (m, 2n): the set without end b's path
        via = cost[before] + into  # (m, b, a): the route to `before`, ending at a, then to b
        best = via.argmin(axis=2)
        value = np.take_along_axis(via, best[..., None], axis=2)[..., 0]
        value[(masks[:, None] & bit[None, :]) == 0] = np.inf  # b's path is not in the set
        cost[masks] = value
        came_from[masks] = best
    total = cost[-1] + distance_or_zero(terminus, leave)
    k = int(total.argmin())
    entered = []
    mask = (1 << n) - 1
    while k >= 0:  # n steps back
        entered.append(k)
        k, mask = int(came_from[mask, k]), mask ^ int(bit[k])
    entered = np.array(entered[::-1], dtype=np.int64)
    return entered % n, entered >= n


def nearest_end_route(ends: np.ndarray, start) -> tuple[np.ndarray, np.ndarray]:
    """Nearest free path end first, from `start` (or from path 0's head); ties to the lower row.

    Parameters
    ----------
    ends : ndarray, shape (2 n, 2)
        Heads then tails, mm (real coordinates, not complex).
    start : (x, y) or None

    Returns
    -------
    (order, flipped) : ndarray of int (n,), ndarray of bool (n,)
    """
    n = len(ends) // 2
    x, y = ends[:, 0].copy(), ends[:, 1].copy()
    points = ends.tolist()
    hx, hy = (float(v) for v in start) if start is not None else points[0]
    order = np.zeros(n, dtype=np.int64)
    flipped = np.zeros(n, dtype=bool)
    d2, dy = np.empty(2 * n), np.empty(2 * n)
    for k in range(n):
        # squared distance to every free end, written in place (the loop is short; its calls add up)
        np.subtract(x, hx, out=d2)
        np.multiply(d2, d2, out=d2)
        np.subtract(y, hy, out=dy)
        np.multiply(dy, dy, out=dy)
        d2 += dy
        j = int(d2.argmin())
        i = j % n
        x[i] = x[i + n] = np.inf  # a printed path's ends move to infinity
        order[k], flipped[k] = i, j >= n
        hx, hy = points[i] if j >= n else points[i + n]
    return order, flipped


def shortest_links_route(ends: np.ndarray, origin: complex,
                         terminus: complex) -> tuple[np.ndarray, np.ndarray]:
    """Join path ends by the shortest links first, each end one link, no loop; read the route off.

    The start and the end to reach are ends of their own with one link each.  Links are costed
    all at once and sorted; the loop that takes them stops at the n - 1 (+ start, + end) links a
    route has, and is meant for tens of paths (it sees every pair of ends).

    Parameters
    ----------
    ends : ndarray of complex, shape (2 n,)
        Heads then tails, mm.
    origin, terminus : complex
        NaN: not given.

    Returns
    -------
    (order, flipped) : ndarray of int (n,), ndarray of bool (n,)
    """
    count = len(ends)
    n = count // 2
    anchors = [p for p in (origin, terminus) if not np.isnan(p)]
    points = np.r_[ends, np.array(anchors, dtype=complex)]
    # owner of each point: its path, or n for the start and n + 1 (or n) for the end
    owner = np.r_[np.arange(count) % n, n + np.arange(len(anchors))]
    first, second = np.triu_indices(len(points), 1)
    keep = owner[first] != owner[second]
    first, second = first[keep], second[keep]
    by_length = np.argsort(np.abs(points[first] - points[second]), kind="stable")
    start_id = n if not np.isnan(origin) else -1
    end_id = n + len(anchors) - 1 if not np.isnan(terminus) else -1
    group = list(range(n + len(anchors)))  # union-find over paths and anchors

    def root(a: int) -> int:
        while group[a] != a:
            group[a] = group[group[a]]
            a = group[a]
        return a

    linked = [-1] * len(points)
    wanted = n - 1 + len(anchors)
    made = 0
    for a, b in zip(first[by_length].tolist(), second[by_length].tolist()):
        if linked[a] >= 0 or linked[b] >= 0:
            continue
        ra, rb = root(int(owner[a])), root(int(owner[b]))
        if ra == rb:
            continue
        # the start's and the end's chains meet only with the last link (else paths are left out)
        if start_id >= 0 and end_id >= 0 and made < wanted - 1 and {ra, rb} == {root(start_id), root(end_id)}:
            continue
        linked[a], linked[b] = b, a
        group[ra] = rb
        made += 1
        if made == wanted:
            break
    # Walk from the start's link, or from the free path end the route begins at.
    at = linked[count] if start_id >= 0 else next(k for k in range(count) if linked[k] < 0)
    order = np.zeros(n, dtype=np.int64)
    flipped = np.zeros(n, dtype=bool)
    for step in range(n):
        path = at % n
        order[step], flipped[step] = path, at >= n
        at = linked[path + n if at < n else path]  # from the path's other end
    return order, flipped
