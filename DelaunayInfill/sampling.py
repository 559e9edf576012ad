"""Poisson-disk sampling of planar regions with a constant or variable radius.

Two samplers:

``fast`` (default)
    Vectorized.  Candidates come from jittered grids anchored at the origin;
    their jitter and their priorities are hashes of (cell, seed), so the
    pattern is a fixed function of the plane: a different region, or a
    slightly different radius, changes it only locally.  The accepted set is
    the greedy maximal independent set of the candidates' conflict graph in
    priority order, computed in parallel rounds (a candidate wins when it has
    the lowest priority among its remaining conflicts).  Then every Delaunay
    triangle whose empty circumcircle is wider than the radius gets its
    circumcentre inserted, until none is left: the set is maximal (see
    `uncovered_fraction`) and interior triangle angles are at least 30 deg.

``bridson``
    The paper's algorithm (Bridson 2007 as described by Qiao et al. 2022):
    background grid with cell diagonal r, active list, k = 30 candidates in
    the annulus r..2r, 5 x 5 neighbourhood check (wider where the radius
    varies).  It restarts from an uncovered point when the active list runs
    dry, so disconnected regions are filled too.

Two samples p, q conflict when |p - q| < max(r(p), r(q)): every sample keeps
its own radius free of others, whatever the radius is at its neighbour.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree

from .geometry import as_area, contains_xy

__all__ = ["sample_poisson_disk", "uncovered_fraction", "radius_function", "hash_uniform"]

RadiusLike = float | Callable[[np.ndarray], np.ndarray]

_CANDIDATE_SPACING = 0.5  # fast sampler: first grid spacing, in units of the smallest radius
_BRIDSON_K = 30


# --------------------------------------------------------------------------- hashing
_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xC2B2AE3D27D4EB4F)
_M3 = np.uint64(0xBF58476D1CE4E5B9)
_M4 = np.uint64(0x94D049BB133111EB)


def hash_uniform(i: np.ndarray, j: np.ndarray, salt: int, seed: int) -> np.ndarray:
    """Deterministic uniform numbers in [0, 1) from integer cell indices.

    Parameters
    ----------
    i, j : ndarray of int, shape (n,)
        Grid cell indices (may be negative).
    salt, seed : int
        Stream selectors.

    Returns
    -------
    ndarray of float, shape (n,)
    """
    with np.errstate(over="ignore"):
        key = np.uint64((seed * 1_000_003 + salt * 7919 + 0x5851F42D) % (1 << 63))
        x = np.asarray(i).astype(np.int64).astype(np.uint64) * _M1
        x ^= np.asarray(j).astype(np.int64).astype(np.uint64) * _M2
        x ^= key
        x ^= x >> np.uint64(30)
        x *= _M3
        x ^= x >> np.uint64(27)
        x *= _M4
        x ^= x >> np.uint64(31)
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


# --------------------------------------------------------------------------- radius
def radius_function(radius: RadiusLike) -> Callable[[np.ndarray], np.ndarray]:
    """Normalize a radius (float mm, or callable on (m, 2) points) to a callable.

    The callable returns an (m,) float array; non-finite or non-positive values
    raise ValueError when they are used.
    """
    if callable(radius):

        def fn(xy: np.ndarray) -> np.ndarray:
            r = np.asarray(radius(xy), dtype=float)
            r = np.broadcast_to(r, (len(xy),)).astype(float)
            if r.size and not (np.isfinite(r).all() and (r > 0).all()):
                raise ValueError("radius function must return finite values > 0 mm")
            return r

        return fn
    try:
        value = float(radius)
    except (TypeError, ValueError):
        raise ValueError(f"radius must be a number in mm or a callable, got {radius!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"radius must be a finite number > 0 mm, got {radius!r}")
    return lambda xy: np.full(len(xy), value)


def _radius_range(area, radius_fn) -> tuple[float, float]:
    """Smallest and largest radius over the area (probed on a grid + vertices)."""
    x0, y0, x1, y1 = area.bounds
    gx, gy = np.meshgrid(np.linspace(x0, x1, 41), np.linspace(y0, y1, 41))
    probe = np.c_[gx.ravel(), gy.ravel()]
    r = radius_fn(probe)
    return float(r.min()), float(r.max())


# --------------------------------------------------------------------------- conflicts
def close_pairs(p: np.ndarray, rp: np.ndarray, q: np.ndarray | None = None, rq: np.ndarray | None = None):
    """Index pairs of points closer than the larger of their two radii.

    Parameters
    ----------
    p : ndarray, shape (n, 2)
    rp : ndarray, shape (n,)
        Radius at each point of `p`, mm.
    q, rq : ndarray, shape (m, 2) and (m,), optional
        A second set; when omitted, pairs within `p` are returned in both
        each once (i != j).

    Returns
    -------
    i, j : ndarray of int
        ``|p[i] - q[j]| < max(rp[i], rq[j])``.
    """
    same = q is None
    if same:
        q, rq = p, rp
    if len(p) == 0 or len(q) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    lo = float(min(rp.min(), rq.min()))
    # Radius classes (factor 2) keep each query bound tight: a pair is found
    # from the class holding its larger radius.
    cls_p = np.floor(np.log2(rp / lo)).astype(np.int64)
    cls_q = cls_p if same else np.floor(np.log2(rq / lo)).astype(np.int64)
    found_i, found_j = [], []

    def keep(ia, jb, d):
        ok = d < np.maximum(rp[ia], rq[jb])
        found_i.append(ia[ok])
        found_j.append(jb[ok])

    classes = np.unique(np.r_[cls_p, cls_q])
    members_p = {c: np.flatnonzero(cls_p == c) for c in classes}
    members_q = members_p if same else {c: np.flatnonzero(cls_q == c) for c in classes}
    for c in classes:
        mp, mq = members_p[c], members_q[c]
        bound = float(max(rp[mp].max() if mp.size else 0.0, rq[mq].max() if mq.size else 0.0))
        lower_q = np.flatnonzero(cls_q <= c)
        if same:
            if mp.size > 1:
                pairs = cKDTree(p[mp]).query_pairs(bound, output_type="ndarray")
                ia, jb = mp[pairs[:, 0]], mp[pairs[:, 1]]
                keep(ia, jb, np.hypot(*(p[ia] - p[jb]).T))
            lower = np.flatnonzero(cls_p < c)
            if mp.size and lower.size:
                sdm = cKDTree(p[mp]).sparse_distance_matrix(cKDTree(p[lower]), bound, output_type="ndarray")
                keep(mp[sdm["i"]], lower[sdm["j"]], sdm["v"])
            continue
        if mp.size and lower_q.size:  # p in class c against q in classes <= c
            sdm = cKDTree(p[mp]).sparse_distance_matrix(cKDTree(q[lower_q]), bound, output_type="ndarray")
            keep(mp[sdm["i"]], lower_q[sdm["j"]], sdm["v"])
        lower_p = np.flatnonzero(cls_p < c)
        if mq.size and lower_p.size:  # q in class c against p in classes < c
            sdm = cKDTree(q[mq]).sparse_distance_matrix(cKDTree(p[lower_p]), bound, output_type="ndarray")
            keep(lower_p[sdm["j"]], mq[sdm["i"]], sdm["v"])
    if not found_i:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return np.concatenate(found_i).astype(np.intp), np.concatenate(found_j).astype(np.intp)


def greedy_independent_set(n: int, a: np.ndarray, b: np.ndarray, priority: np.ndarray) -> np.ndarray:
    """Greedy maximal independent set in priority order, in parallel rounds.

    Equal to taking the nodes one by one in increasing `priority` and keeping
    each that has no kept neighbour; each round keeps every node that has the
    lowest priority among its remaining neighbours.

    Parameters
    ----------
    n : int
        Number of nodes.
    a, b : ndarray of int, shape (e,)
        Undirected edges (each once, either direction).
    priority : ndarray, shape (n,)
        Distinct priorities; lower wins.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    active = np.ones(n, dtype=bool)
    chosen = np.zeros(n, dtype=bool)
    while active.any():
        live = active[a] & active[b]
        a, b = a[live], b[live]
        beaten = np.zeros(n, dtype=bool)
        beaten[np.where(priority[a] < priority[b], b, a)] = True
        win = active & ~beaten
        chosen |= win
        active &= ~win
        active[b[win[a]]] = False
        active[a[win[b]]] = False
    return chosen


# --------------------------------------------------------------------------- fast sampler
def _jitter(ii: np.ndarray, jj: np.ndarray, spacing: float, salt: int, seed: int) -> np.ndarray:
    """One hashed point per grid cell (i, j) of the given spacing; shape (n, 2)."""
    return np.c_[
        (ii + hash_uniform(ii, jj, salt, seed)) * spacing,
        (jj + hash_uniform(ii, jj, salt + 1, seed)) * spacing,
    ]


def _grid_candidates(area, spacing: float, salt: int, seed: int):
    """Jittered-grid candidates inside `area`; returns points and their cell ids."""
    x0, y0, x1, y1 = area.bounds
    i = np.arange(math.floor(x0 / spacing), math.floor(x1 / spacing) + 1)
    j = np.arange(math.floor(y0 / spacing), math.floor(y1 / spacing) + 1)
    ii, jj = np.meshgrid(i, j, indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    pts = _jitter(ii, jj, spacing, salt, seed)
    inside = contains_xy(area, pts[:, 0], pts[:, 1])
    return pts[inside], ii[inside], jj[inside]


def _conflicts_with(samples, samples_r, pts, r, uniform: bool) -> np.ndarray:
    """Bool mask (len(pts),): candidate conflicts with an existing sample."""
    if len(samples) == 0 or len(pts) == 0:
        return np.zeros(len(pts), dtype=bool)
    if uniform:
        d, _ = cKDTree(samples).query(pts, k=1, distance_upper_bound=r[0])
        return d < r[0]
    ci, _ = close_pairs(pts, r, samples, samples_r)
    mask = np.zeros(len(pts), dtype=bool)
    mask[ci] = True
    return mask


def _independent_candidates(pts, r, priority, uniform: bool) -> np.ndarray:
    """Greedy maximal independent subset of candidates (bool mask)."""
    if uniform:
        pairs = cKDTree(pts).query_pairs(r[0], output_type="ndarray")
        pi, pj = pairs[:, 0], pairs[:, 1]
    else:
        pi, pj = close_pairs(pts, r)
    return greedy_independent_set(len(pts), pi, pj, priority)


def _sample_fast(area, radius_fn, seed: int) -> np.ndarray:
    r_lo, r_hi = _radius_range(area, radius_fn)
    uniform = r_hi <= r_lo * (1 + 1e-12)
    spacing = _CANDIDATE_SPACING * r_lo
    expected = area.area / (spacing * spacing)
    if expected > 2e7:
        raise ValueError(
            f"radius {r_lo:.4g} mm is too small for a region of {area.area:.4g} mm^2 "
            f"(about {expected:.3g} candidates)"
        )
    # Level 0: one candidate per cell of a grid of spacing r/2 everywhere.
    pts, ii, jj = _grid_candidates(area, spacing, 0, seed)
    r = radius_fn(pts)
    if not uniform:
        # Thin where the radius is larger, so candidates per disk stay constant.
        keep = hash_uniform(ii, jj, 2, seed) < (r_lo / r) ** 2
        pts, ii, jj, r = pts[keep], ii[keep], jj[keep], r[keep]
    chosen = _independent_candidates(pts, r, hash_uniform(ii, jj, 3, seed), uniform)
    samples, samples_r = pts[chosen], r[chosen]
    return _fill_gaps(area, samples, samples_r, radius_fn, uniform)


def _fill_gaps(area, samples, samples_r, radius_fn, uniform: bool, passes: int = 6):
    """Insert circumcentres of empty circles wider than the radius.

    A Delaunay triangle whose circumradius exceeds the radius at its
    circumcentre leaves that centre uncovered; inserting such centres (an
    independent subset per pass) makes the set maximal, which also bounds
    every interior triangle angle below by 30 degrees.
    """
    from scipy.spatial import Delaunay, QhullError

    if len(samples) < 3:
        return samples
    try:
        triangulation = Delaunay(samples, incremental=True)
    except (QhullError, ValueError):
        return samples
    for _ in range(passes):
        tri = triangulation.simplices
        a, b, c = (samples[tri[:, k]] for k in range(3))
        d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
        ok = np.abs(d) > 1e-12
        d = np.where(ok, d, 1.0)
        sa, sb, sc = (np.einsum("ij,ij->i", p, p) for p in (a, b, c))
        center = np.c_[
            (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d,
            (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d,
        ]
        radius = np.hypot(*(center - a).T)
        # Only circles wider than the smallest radius can be gaps.
        wide = ok & (radius > samples_r.min() * (1 + 1e-9))
        center, radius = center[wide], radius[wide]
        inside = contains_xy(area, center[:, 0], center[:, 1])
        center, radius = center[inside], radius[inside]
        if len(center) == 0:
            break
        rc = radius_fn(center)
        gap = radius > rc * (1 + 1e-9)
        center, rc = center[gap], rc[gap]
        free = ~_conflicts_with(samples, samples_r, center, rc, uniform)
        center, rc = center[free], rc[free]
        if len(center) == 0:
            break
        won = _independent_candidates(center, rc, np.arange(len(center), dtype=float), uniform)
        samples = np.r_[samples, center[won]]
        samples_r = np.r_[samples_r, rc[won]]
        triangulation.add_points(center[won])
    triangulation.close()
    return samples


# --------------------------------------------------------------------------- Bridson (paper)
def _sample_bridson(area, radius_fn, seed: int, k: int = _BRIDSON_K) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r_lo, r_hi = _radius_range(area, radius_fn)
    cell = r_lo / math.sqrt(2.0)  # cell diagonal = r: at most one sample per cell
    reach = max(2, math.ceil(r_hi / cell))  # 2 -> the paper's 5 x 5 window
    x0, y0, x1, y1 = area.bounds
    nx = math.floor((x1 - x0) / cell) + 1
    ny = math.floor((y1 - y0) / cell) + 1
    if nx * ny > 5e7:
        raise ValueError(f"radius {r_lo:.4g} mm is too small for the region (grid of {nx}x{ny} cells)")
    grid = np.full((nx + 2 * reach, ny + 2 * reach), -1, dtype=np.int64)
    points = np.zeros((nx * ny + 1, 2))
    radii = np.zeros(nx * ny + 1)
    count = 0
    offs = np.arange(-reach, reach + 1)
    win_i, win_j = (a.ravel() for a in np.meshgrid(offs, offs, indexing="ij"))

    def cell_of(p):
        return (
            np.floor((p[..., 0] - x0) / cell).astype(np.int64) + reach,
            np.floor((p[..., 1] - y0) / cell).astype(np.int64) + reach,
        )

    def add(p, r) -> int:
        nonlocal count
        ci, cj = cell_of(p)
        grid[ci, cj] = count
        points[count], radii[count] = p, r
        count += 1
        return count - 1

    def free_mask(cands, rc):
        """Bool mask: candidate has no sample closer than max(r, r_sample)."""
        ci, cj = cell_of(cands)
        nb = grid[ci[:, None] + win_i[None, :], cj[:, None] + win_j[None, :]]  # (c, window)
        has = nb >= 0
        safe = np.where(has, nb, 0)
        d = np.hypot(points[safe, 0] - cands[:, None, 0], points[safe, 1] - cands[:, None, 1])
        return ~(has & (d < np.maximum(radii[safe], rc[:, None]))).any(axis=1)

    # The paper's loop, restarted from still-uncovered probe points until the
    # region is covered (the first start is a random probe point).
    probe = _coverage_probe(area, r_lo, seed)
    probe_r = radius_fn(probe)
    uncovered = np.ones(len(probe), dtype=bool)
    active: list[int] = []
    for _round in range(100):
        if count:
            idx = np.flatnonzero(uncovered)
            ci, _ = close_pairs(probe[idx], probe_r[idx], points[:count], radii[:count])
            uncovered[idx[np.unique(ci)]] = False
        todo = np.flatnonzero(uncovered)
        if todo.size == 0:
            break
        for t in rng.permutation(todo) if count else todo[rng.integers(todo.size)][None]:
            if free_mask(probe[t][None], probe_r[t][None])[0]:
                active.append(add(probe[t], probe_r[t]))
        while active:
            a = int(rng.integers(len(active)))
            p, rp = points[active[a]], radii[active[a]]
            ang = rng.uniform(0, 2 * math.pi, k)
            dist = rp * np.sqrt(rng.uniform(1.0, 4.0, k))  # uniform in the annulus r..2r
            cands = p + np.c_[dist * np.cos(ang), dist * np.sin(ang)]
            cands = cands[contains_xy(area, cands[:, 0], cands[:, 1])]
            hits = np.zeros(0, dtype=np.intp)
            if len(cands):
                rc = radius_fn(cands)
                hits = np.flatnonzero(free_mask(cands, rc))
            if hits.size:
                active.append(add(cands[hits[0]], rc[hits[0]]))
            else:
                active[a] = active[-1]
                active.pop()
    return points[:count].copy()


def _coverage_probe(area, r_lo: float, seed: int) -> np.ndarray:
    """Probe points on a jittered grid of spacing r/4 inside `area`."""
    pts, _, _ = _grid_candidates(area, r_lo / 4.0, 977, seed)
    return pts


def _uncovered_mask(probe, samples, sample_r, radius_fn) -> np.ndarray:
    if len(samples) == 0:
        return np.ones(len(probe), dtype=bool)
    rp = radius_fn(probe)
    ci, _ = close_pairs(probe, rp, samples, sample_r)
    mask = np.ones(len(probe), dtype=bool)
    mask[ci] = False
    return mask


# --------------------------------------------------------------------------- public
def sample_poisson_disk(region, radius: RadiusLike, *, seed: int = 0, method: str = "fast") -> np.ndarray:
    """Poisson-disk samples of a region.

    Parameters
    ----------
    region : shapely Polygon or MultiPolygon
        Holes allowed; invalid (self-intersecting) input is repaired.
    radius : float or callable
        Minimum distance between samples in mm, or ``radius(xy) -> r`` taking
        an (m, 2) array and returning (m,) radii for a variable radius.
    seed : int
        Same region, radius and seed give identical samples.
    method : {"fast", "bridson"}
        ``fast``: vectorized; ``bridson``: the paper's algorithm.

    Returns
    -------
    ndarray, shape (n, 2)
        Sample coordinates in mm, inside `region`; no two closer than the
        larger of their radii.

    Raises
    ------
    ValueError
        Empty/degenerate region, NaN coordinates, radius <= 0 or not finite,
        unknown method.
    """
    area = as_area(region)
    radius_fn = radius_function(radius)
    if method == "fast":
        return _sample_fast(area, radius_fn, int(seed))
    if method == "bridson":
        return _sample_bridson(area, radius_fn, int(seed))
    raise ValueError(f"method must be 'fast' or 'bridson', got {method!r}")


def uncovered_fraction(region, samples: np.ndarray, radius: RadiusLike, *, spacing: float | None = None) -> float:
    """Share of the region's area farther than r(x) from every sample.

    Measured on a regular grid (default spacing r_min / 10): a point x is
    covered when some sample s has |x - s| < max(r(x), r(s)).

    Returns
    -------
    float
        Fraction in [0, 1]; 0 for a maximal sampling.
    """
    area = as_area(region)
    radius_fn = radius_function(radius)
    r_lo, _ = _radius_range(area, radius_fn)
    h = spacing or r_lo / 10.0
    x0, y0, x1, y1 = area.bounds
    gx, gy = np.meshgrid(np.arange(x0 + h / 2, x1, h), np.arange(y0 + h / 2, y1, h))
    grid = np.c_[gx.ravel(), gy.ravel()]
    grid = grid[contains_xy(area, grid[:, 0], grid[:, 1])]
    if len(grid) == 0:
        return 0.0
    samples = np.asarray(samples, dtype=float).reshape(-1, 2)
    return float(_uncovered_mask(grid, samples, radius_fn(samples), radius_fn).mean())
