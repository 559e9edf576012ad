"""Poisson-disk sampling of planar regions with a constant or variable radius.

Three samplers:

``fast`` (default)
    Vectorized.  Candidates come from jittered grids anchored at the origin;
    their jitter and their priorities are hashes of (cell, seed), so the
    pattern is a fixed function of the plane: a different region, or a
    slightly different radius, changes it only locally.  The accepted set is
    the greedy maximal independent set of the candidates' conflict graph in
    priority order, computed in parallel rounds (a candidate wins when it has
    the lowest priority among its remaining conflicts; with a constant radius
    the first round runs on the grid arrays themselves).  Then the gaps left
    between the disks are filled until none is left, so the set is maximal
    (see `uncovered_fraction`) and interior triangle angles are at least
    30 deg.  With a constant radius a gap is found exactly, without a
    triangulation, at a crossing of two circles that no third disk covers,
    and filled at the Delaunay circumcentre reached from there; with a
    variable radius the circumcentres of a Delaunay triangulation whose
    circles are wider than the radius there are inserted.

``lattice``
    ``fast`` seeded with a triangular lattice (side ``LATTICE_SPACING`` r,
    orientation and offset hashed from the seed, anchored at the origin)
    wherever the radius is constant: with a constant radius the lattice is
    the whole sampling; with a variable one each radius keeps its lattice a
    radius short of where the radius changes (a region inside the part only a
    few lattice sides across: a quarter radius short of a denser zone, whose
    samples then keep their distance), and ``fast``'s candidates (after the lattice points in
    priority) fill the bands between.  The
    lattice is a Poisson-disk set (side > r) and maximal (circumradius
    0.72 r < r); its Delaunay triangles are equilateral.

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

from .geometry import as_area, cell_centres, contains_xy

__all__ = ["sample_poisson_disk", "uncovered_fraction", "radius_function", "hash_uniform", "lattice_points",
           "sample_lattice", "LATTICE_SPACING", "LATTICE_AREA", "lattice_basis", "lattice_coordinates",
           "lattice_nodes_over", "lattice_xy"]

RadiusLike = float | Callable[[np.ndarray], np.ndarray]

_CANDIDATE_SPACING = 0.5  # fast sampler: first grid spacing, in units of the smallest radius
_ALL_PAIRS = 16384  # close_pairs: up to this many point pairs, test them all (no k-d trees)
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
def close_pairs(p: np.ndarray, rp: np.ndarray, q: np.ndarray | None = None, rq: np.ndarray | None = None,
                reaching=None):
    """Index pairs of points closer than the larger of their two radii.

    Parameters
    ----------
    p : ndarray, shape (n, 2)
    rp : ndarray, shape (n,)
        Radius at each point of `p`, mm.
    q, rq : ndarray, shape (m, 2) and (m,), optional
        A second set; when omitted, pairs within `p` are returned in both
        each once (i != j).
    reaching : ndarray, optional
        Radii whose samples may lie closer to denser ones (see `_apart`).

    Returns
    -------
    i, j : ndarray of int
        ``|p[i] - q[j]| < max(rp[i], rq[j])`` (`_apart` with `reaching`).
    """
    same = q is None
    if same:
        q, rq = p, rp
    if len(p) == 0 or len(q) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    if len(p) * len(q) <= _ALL_PAIRS:
        # Few points (gap filling's later passes): every distance at once beats building trees.
        hit = np.hypot(p[:, None, 0] - q[None, :, 0], p[:, None, 1] - q[None, :, 1]) < _apart(rp[:, None], rq, reaching)
        if same:
            hit &= np.arange(len(p))[:, None] < np.arange(len(p))
        i, j = np.nonzero(hit)
        return i.astype(np.intp), j.astype(np.intp)
    lo = float(min(rp.min(), rq.min()))
    # Radius classes (factor 2) keep each query bound tight: a pair is found
    # from the class holding its larger radius.
    cls_p = np.floor(np.log2(rp / lo)).astype(np.int64)
    cls_q = cls_p if same else np.floor(np.log2(rq / lo)).astype(np.int64)
    found_i, found_j = [], []

    def keep(ia, jb, d):
        ok = d < _apart(rp[ia], rq[jb], reaching)
        found_i.append(ia[ok])
        found_j.append(jb[ok])

    classes = np.unique(np.r_[cls_p, cls_q])
    members_p = {c: np.flatnonzero(cls_p == c) for c in classes}
    members_q = members_p if same else {c: np.flatnonzero(cls_q == c) for c in classes}
    for c in classes:
        mp, mq = members_p[c], members_q[c]
        bound = float(max(rp[mp].max() if mp.size else 0.0, rq[mq].max() if mq.size else 0.0))
        if same:
            tree = _tree(p[mp]) if mp.size else None
            if mp.size > 1:
                pairs = tree.query_pairs(bound, output_type="ndarray")
                ia, jb = mp[pairs[:, 0]], mp[pairs[:, 1]]
                keep(ia, jb, np.hypot(*(p[ia] - p[jb]).T))
            lower = np.flatnonzero(cls_p < c)
            if mp.size and lower.size:
                sdm = tree.sparse_distance_matrix(_tree(p[lower]), bound, output_type="ndarray")
                keep(mp[sdm["i"]], lower[sdm["j"]], sdm["v"])
            continue
        lower_q = np.flatnonzero(cls_q <= c)
        if mp.size and lower_q.size:  # p in class c against q in classes <= c
            sdm = _tree(p[mp]).sparse_distance_matrix(_tree(q[lower_q]), bound, output_type="ndarray")
            keep(mp[sdm["i"]], lower_q[sdm["j"]], sdm["v"])
        lower_p = np.flatnonzero(cls_p < c)
        if mq.size and lower_p.size:  # q in class c against p in classes < c
            sdm = _tree(q[mq]).sparse_distance_matrix(_tree(p[lower_p]), bound, output_type="ndarray")
            keep(lower_p[sdm["j"]], mq[sdm["i"]], sdm["v"])
    if not found_i:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return np.concatenate(found_i).astype(np.intp), np.concatenate(found_j).astype(np.intp)


def _apart(ra, rb, reaching):
    """How far apart two samples of radii `ra`, `rb` (mm, broadcast) must be: the larger radius.

    A sample of one of the `reaching` radii (a lattice reaching a denser zone, `_lattice_cores`) and
    one of a smaller radius need only be max(smaller, `_CROSS` x larger) apart.
    """
    if reaching is None:
        return np.maximum(ra, rb)
    hi, lo = np.maximum(ra, rb), np.minimum(ra, rb)
    near = (hi > lo * (1 + 1e-9)) & np.isin(hi, reaching)
    return np.where(near, np.maximum(lo, _CROSS * hi), hi)


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
        Priorities; lower wins (ties go to the lower node index).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    a = np.asarray(a, dtype=np.intp)
    b = np.asarray(b, dtype=np.intp)
    pa, pb = priority[a], priority[b]
    a_first = (pa < pb) | ((pa == pb) & (a < b))
    first, second = np.where(a_first, a, b), np.where(a_first, b, a)
    return _oriented_independent_set(np.ones(n, dtype=bool), np.zeros(n, dtype=bool), first, second)


def _oriented_independent_set(active, chosen, first, second) -> np.ndarray:
    """Finish the greedy rounds on edges oriented `first` -> `second`.

    `active` (nodes still undecided) and `chosen` (bool, shape (n,)) are
    updated in place; the orientation (priority order) is acyclic, so every
    round keeps at least the earliest active node.
    """
    while active.any():
        live = active[first] & active[second]
        first, second = first[live], second[live]
        beaten = np.zeros(len(active), dtype=bool)
        beaten[second] = True
        win = active & ~beaten
        chosen |= win
        active &= ~win
        active[second[win[first]]] = False
    return chosen


# --------------------------------------------------------------------------- fast sampler
def _jitter(ii: np.ndarray, jj: np.ndarray, spacing: float, salt: int, seed: int) -> np.ndarray:
    """One hashed point per grid cell (i, j) of the given spacing; shape (n, 2)."""
    return np.c_[
        (ii + hash_uniform(ii, jj, salt, seed)) * spacing,
        (jj + hash_uniform(ii, jj, salt + 1, seed)) * spacing,
    ]


def _grid_cells(area, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell indices (i, j), each shape (nx, ny), of the grid anchored at the origin over `area`."""
    x0, y0, x1, y1 = area.bounds
    i = np.arange(math.floor(x0 / spacing), math.floor(x1 / spacing) + 1)
    j = np.arange(math.floor(y0 / spacing), math.floor(y1 / spacing) + 1)
    return np.meshgrid(i, j, indexing="ij")


def _grid_candidates(area, spacing: float, salt: int, seed: int):
    """Jittered-grid candidates inside `area`; returns points and their cell ids."""
    ii, jj = (a.ravel() for a in _grid_cells(area, spacing))
    pts = _jitter(ii, jj, spacing, salt, seed)
    inside = contains_xy(area, pts[:, 0], pts[:, 1])
    return pts[inside], ii[inside], jj[inside]


def _grid_offsets(shape: tuple[int, int], reach: int):
    """Half of the (2 reach + 1)^2 cell window, as pairs of array slices.

    Yields ``(sa, sb, step)``: ``x[sa]`` and ``x[sb]`` pair every cell with
    its neighbour at one offset, ``step`` is that offset in flat (row-major)
    indices; each unordered pair of cells comes once.
    """
    nx, ny = shape
    for di in range(reach + 1):
        for dj in range(-reach, reach + 1):
            if (di == 0 and dj <= 0) or di >= nx or abs(dj) >= ny:
                continue
            sa = (slice(0, nx - di), slice(max(0, -dj), ny - max(0, dj)))
            sb = (slice(di, nx), slice(max(0, dj), ny - max(0, -dj)))
            yield sa, sb, di * ny + dj


def _grid_independent_set(x, y, inside, priority, radius: float, reach: int) -> np.ndarray:
    """Greedy independent set of a jittered grid, one candidate per cell.

    The first round, which decides most cells, works on the cell arrays
    directly (the grid is the spatial index: no tree, no edge list); only the
    conflicts between cells it leaves open become an edge list.

    Parameters
    ----------
    x, y : ndarray, shape (nx, ny)
        Candidate coordinates per cell, mm.
    inside : ndarray of bool, shape (nx, ny)
        Cells whose candidate takes part.
    priority : ndarray, shape (nx, ny)
        Lower wins; ties go to the lower flat index.
    radius : float
        Candidates closer than this conflict, mm.
    reach : int
        Largest cell offset at which two candidates can conflict.

    Returns
    -------
    ndarray of bool, shape (nx, ny)
        Equal to `greedy_independent_set` on the candidates' conflict graph.
    """
    r2 = radius * radius
    x = np.where(inside, x, np.nan)  # NaN distances: cells outside conflict with none
    beaten = np.zeros(x.shape, dtype=bool)
    conflicts = []
    for sa, sb, step in _grid_offsets(x.shape, reach):
        dx = x[sa] - x[sb]
        dx *= dx
        dy = y[sa] - y[sb]
        dy *= dy
        dx += dy
        hit = dx < r2
        a_first = priority[sa] <= priority[sb]
        a_beats = hit & a_first
        b_beats = hit > a_first
        beaten[sb] |= a_beats
        beaten[sa] |= b_beats
        conflicts.append((sa, sb, step, a_beats, b_beats))
    win = inside & ~beaten
    decided = win | ~inside
    for sa, sb, _, a_beats, b_beats in conflicts:
        decided[sb] |= a_beats & win[sa]
        decided[sa] |= b_beats & win[sb]
    open_ = ~decided
    flat = np.arange(x.size).reshape(x.shape)
    first, second = [], []
    for sa, sb, step, a_beats, b_beats in conflicts:
        both = open_[sa] & open_[sb]
        for beats, forward in ((a_beats, True), (b_beats, False)):
            left = flat[sa][beats & both]
            if left.size:
                first.append(left if forward else left + step)
                second.append(left + step if forward else left)
    chosen = win.ravel()
    if first:
        _oriented_independent_set(open_.ravel(), chosen, np.concatenate(first), np.concatenate(second))
    else:
        chosen |= open_.ravel()
    return chosen.reshape(x.shape)


def _uniform_level(area, spacing: float, radius: float, seed: int) -> np.ndarray:
    """Greedy independent set of one hashed candidate per grid cell (constant radius); (n, 2)."""
    ii, jj = _grid_cells(area, spacing)
    x = (ii + hash_uniform(ii, jj, 0, seed)) * spacing
    y = (jj + hash_uniform(ii, jj, 1, seed)) * spacing
    inside = contains_xy(area, x.ravel(), y.ravel()).reshape(x.shape)
    reach = max(1, math.ceil(radius / spacing - 1e-9))
    chosen = _grid_independent_set(x, y, inside, hash_uniform(ii, jj, 3, seed), radius, reach)
    return np.stack((x[chosen], y[chosen]), axis=1)


def _variable_level(area, spacing: float, r_lo: float, radius_fn, seed: int, first=None, info=None,
                    reaching=None):
    """Greedy independent set of hashed grid candidates, thinned where the radius is larger.

    Thinning by (r_min / r)^2 keeps the number of candidates per disk
    constant.  `first`: points (m, 2) that take part ahead of every candidate
    (lattice cores: they are kept wherever they conflict with no earlier one;
    those kept come first among the samples, and `info` gets their number as
    ``"lattice"``).  Returns the samples (n, 2) and their radii (n,).
    """
    pts, ii, jj = _grid_candidates(area, spacing, 0, seed)
    r = radius_fn(pts)
    keep = hash_uniform(ii, jj, 2, seed) < (r_lo / r) ** 2
    pts, ii, jj, r = pts[keep], ii[keep], jj[keep], r[keep]
    priority = hash_uniform(ii, jj, 3, seed)
    if first is not None and len(first):
        pts = np.concatenate((first, pts))
        r = np.concatenate((radius_fn(first), r))
        priority = np.concatenate((np.arange(len(first)) - float(len(first)), priority))
    pi, pj = close_pairs(pts, r, reaching=reaching)
    chosen = greedy_independent_set(len(pts), pi, pj, priority)
    if info is not None:
        info["lattice"] = 0 if first is None else int(np.count_nonzero(chosen[: len(first)]))
    return pts[chosen], r[chosen]


# --------------------------------------------------------------------------- lattice seeding
# Lattice seeding: triangle side / radius.  A triangular lattice of side a prints 2 sqrt(3) w / a;
# the `fast` sampler's maximal sets print 2.766 w / r (Delaunay edges, measured on a 200 mm square):
# at this side the lattice prints what the Poisson-disk samples around it print at the same radius.
LATTICE_SPACING = 2.0 * math.sqrt(3.0) / 2.766
_LATTICE_RING = 12  # a lattice point is kept where the radius is its own at this many points ...
_RING_RADII = 1.0  # ... on a ring of this many radii around it
# A radius holding less area than this many squared radii keeps Poisson-disk samples (a few
# samples).  Larger ones keep their lattice where it fits, however few cells: a 30 mm region at
# 20 % in a 60 % part (about 4 sides across) measured 0.80 of a uniform pattern's C_min / rho with
# its lattice against 0.74 with Poisson-disk samples (`bench/bench_regions.py`, 3 seeds).
LATTICE_AREA = 4.0
# A zone of 16 to 36 squared radii (a few lattice sides across: most of it lies within a radius of
# its border) keeps its lattice up to _NEAR_RING radii from a denser zone, not one radius: kept a
# radius off, its border band held no point of its own, only long edges fanning from its few inner
# points to the denser zone's border row (a 30 mm region at 20 % in a 60 % part: 9-12 points against
# about 21 in its lattice, 63-71 % of its lines in pieces reaching its border; C_min / rho 0.81 of a
# uniform pattern's, 0.87 so, `bench/bench_regions.py --seeds 5`).  Those lattice points are placed
# first and keep a denser zone's samples only _CROSS of their radius away, so the change of density
# lies on the denser side.  Larger zones keep the band (a large region's is a small part of it; done
# for every zone, the dense regions lost: 60 % in 20 % 0.90 -> 0.88-0.90, 40 % in 10 % 0.85 -> 0.80-0.84),
# and so does a zone that reaches the area's outline, a part's base: in a narrow part of a small one,
# its lattice reaching the regions put lines across the strip CuraEngine 4.13 leaves empty between an
# infill mesh and its host (random regions 1: 0.4-0.6 mm of a layer's 20 mm outside Cura's area).
_NEAR_AREA = 36.0
_NEAR_MIN = 16.0
_NEAR_RING = 0.25
_CROSS = 0.85
_BETWEEN_SALT = 1_000_003  # another sampling between the lattices: seeds apart from every seed's own


def lattice_frame(seed: int) -> tuple[float, np.ndarray]:
    """Orientation (radians, within the lattice's 60 degree period) and offset (in sides) of a seed's lattice."""
    key = np.array([int(seed)])
    angle = (math.pi / 3.0) * float(hash_uniform(key, key, 11, 0)[0])
    offset = np.array([float(hash_uniform(key, key, 12, 0)[0]), float(hash_uniform(key, key, 13, 0)[0])])
    return angle, offset


def lattice_basis(side: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The two side vectors (2,) mm of a seed's lattice, 60 degrees apart (`lattice_frame`'s orientation)."""
    angle = lattice_frame(seed)[0]
    return (side * np.array([math.cos(angle), math.sin(angle)]),
            side * np.array([math.cos(angle + math.pi / 3), math.sin(angle + math.pi / 3)]))


def lattice_coordinates(points: np.ndarray, side: float, seed: int = 0) -> np.ndarray:
    """Where `points` (k, 2) mm lie on a seed's lattice of the given side: (k, 2) multiples of its two
    side vectors (`lattice_basis`) from its origin, whole numbers at its nodes."""
    v1, v2 = lattice_basis(side, seed)
    basis = np.stack((v1, v2), axis=1)  # columns
    origin = basis @ lattice_frame(seed)[1]
    return np.linalg.solve(basis, (np.asarray(points, dtype=float).reshape(-1, 2) - origin).T).T


def lattice_nodes_over(bounds: tuple, side: float, seed: int = 0) -> np.ndarray:
    """The lattice coordinates (m, 2) (whole numbers, `lattice_coordinates`) of every node of a seed's
    lattice in a band of lattice cells round `bounds` (x0, y0, x1, y1) mm, at least one cell wider
    than it on every side."""
    x0, y0, x1, y1 = bounds
    ij = lattice_coordinates(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]), side, seed)
    lo, hi = np.floor(ij.min(axis=0)) - 1, np.ceil(ij.max(axis=0)) + 1
    if (hi - lo).prod() > 2e7:
        raise ValueError(f"lattice side {side:.4g} mm is too small for the region")
    i, j = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    return np.stack((i.ravel(), j.ravel()), axis=1)


def lattice_xy(nodes: np.ndarray, side: float, seed: int = 0) -> np.ndarray:
    """The points (m, 2) mm of lattice coordinates `nodes` (m, 2) (`lattice_coordinates`)."""
    v1, v2 = lattice_basis(side, seed)
    origin = np.stack((v1, v2), axis=1) @ lattice_frame(seed)[1]
    return origin + nodes[:, :1] * v1 + nodes[:, 1:] * v2


def lattice_points(area, side: float, seed: int = 0) -> np.ndarray:
    """The points (n, 2) of a triangular lattice of the given side inside `area`.

    The lattice is a fixed function of the plane for each seed (orientation
    and offset from `lattice_frame`, anchored at the origin): another area
    cuts the same lattice.
    """
    x0, y0, x1, y1 = area.bounds
    pts = lattice_xy(lattice_nodes_over(area.bounds, side, seed), side, seed)
    box_ok = (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
    pts = pts[box_ok]
    return pts[contains_xy(area, pts[:, 0], pts[:, 1])]


def _lattice_cores(area, radius_fn, r_lo: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice points in the parts of `area` where the radius is constant (variable radius).

    Each radius that holds at least `LATTICE_AREA` squared radii gets its lattice (side
    ``LATTICE_SPACING * r``), kept where the radius is that value at the point
    and on a ring of one radius around it: the lattices of two radii end a
    radius short of the border between them each, so they never conflict, and
    Poisson-disk samples fill the band between them.  A radius that varies
    continuously (a feathered border) holds no lattice.  A radius holding
    `_NEAR_MIN` to `_NEAR_AREA` squared radii, all of them a radius inside the
    area (a region inside the part), keeps its lattice up to `_NEAR_RING` radii
    from a denser radius (a smaller one); its points come first.

    Returns
    -------
    points : ndarray, shape (n, 2)
        mm.
    reaching : ndarray, shape (m,)
        The radii whose lattices reach a denser radius's border (mm), for `_apart`.
    """
    step = r_lo
    probe = cell_centres(area.bounds, step)
    if len(probe) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    probe_radius = radius_fn(probe)
    values, counts = np.unique(probe_radius, return_counts=True)
    held = counts * step * step / (values * values)  # squared radii of area
    values, held = values[held >= LATTICE_AREA], held[held >= LATTICE_AREA]  # a continuous radius: none
    reaches = (held >= _NEAR_MIN) & (held < _NEAR_AREA)
    for k in np.flatnonzero(reaches):  # only a zone enclosed in the area: a region, not a part's base
        inside = probe[probe_radius == values[k]]
        reaches[k] = bool(contains_xy(area.buffer(-values[k], 4), inside[:, 0], inside[:, 1]).all())
    ring = np.exp(2j * np.pi * np.arange(_LATTICE_RING) / _LATTICE_RING)
    ring = np.stack((ring.real, ring.imag), axis=1)
    first, rest = [], []
    for value, reaching in zip(values.tolist(), reaches.tolist(), strict=True):
        pts = lattice_points(area, LATTICE_SPACING * value, seed)
        if len(pts) == 0:
            continue
        pts = pts[radius_fn(pts) == value]
        if len(pts) == 0:  # (a radius that only the probes hit exactly)
            continue
        around = radius_fn((pts[:, None, :] + _RING_RADII * value * ring[None]).reshape(-1, 2)).reshape(len(pts), -1)
        if reaching:
            close = radius_fn((pts[:, None, :] + _NEAR_RING * value * ring[None]).reshape(-1, 2))
            first.append(pts[(around <= value).all(axis=1) & (close == value).reshape(len(pts), -1).all(axis=1)])
        else:
            rest.append(pts[(around == value).all(axis=1)])
    points = np.concatenate(first + rest) if first or rest else np.zeros((0, 2))
    return points, values[reaches]


def _sample_fast(area, radius_fn, seed: int, keep: list | None = None, lattice: bool = False,
                 info: dict | None = None, between_seed: int | None = None) -> np.ndarray:
    """`fast` (or `lattice`) sampling; `info` gets ``"lattice"``: how many of the first samples are lattice points.

    `between_seed` (variable radius only): the seed of the Poisson-disk samples alone, the lattices
    staying those of `seed` (another sampling of the bands between them).
    """
    info = {} if info is None else info
    info["lattice"] = 0
    r_lo, r_hi = _radius_range(area, radius_fn)
    spacing = _CANDIDATE_SPACING * r_lo
    expected = area.area / (spacing * spacing)
    if expected > 2e7:
        raise ValueError(
            f"radius {r_lo:.4g} mm is too small for a region of {area.area:.4g} mm^2 "
            f"(about {expected:.3g} candidates)"
        )
    if r_hi <= r_lo * (1 + 1e-12):
        if lattice:
            seeds = lattice_points(area, LATTICE_SPACING * r_lo, seed)
            info["lattice"] = len(seeds)  # gap filling appends after them
            return _fill_gaps_constant(area, seeds, r_lo)
        return _fill_gaps_constant(area, _uniform_level(area, spacing, r_lo, seed), r_lo)
    first, reaching = _lattice_cores(area, radius_fn, r_lo, seed) if lattice else (None, np.zeros(0))
    poisson_seed = seed if between_seed is None else _BETWEEN_SALT * (seed + 1) + between_seed
    reaching = reaching if len(reaching) else None
    samples, samples_r = _variable_level(area, spacing, r_lo, radius_fn, poisson_seed, first, info, reaching)
    return _fill_gaps_variable(area, samples, samples_r, radius_fn, keep=keep, reaching=reaching)


def sample_lattice(region, radius: RadiusLike, *, seed: int = 0,
                   between_seed: int | None = None) -> tuple[np.ndarray, int]:
    """`sample_poisson_disk` with ``method="lattice"``, and how many of the first samples are lattice points.

    `between_seed`: another sampling of the Poisson-disk samples between the lattices (the lattices
    are the seed's); None: the seed's own.

    Returns
    -------
    (ndarray, shape (n, 2); int)
        The samples; the first k of them lie on the lattices (the rest are
        Poisson-disk samples between them).
    """
    info = {}
    points = _sample_fast(as_area(region), radius_function(radius), int(seed), lattice=True, info=info,
                          between_seed=between_seed)
    return points, info["lattice"]


# --------------------------------------------------------------------------- gap filling
_SHRINK = 1e-9  # a crossing lies on two circles: a third covers it when its power is below -_SHRINK r^2
_NUDGE = 1e-6  # fallback insertion: this far (in radii) into the gap from its open crossing
_WALK_NEIGHBOURS = 6  # second try for a gap centre: the third sample among the nearest to the crossing


def _neighbour_table(rows: np.ndarray, cols: np.ndarray, n_rows: int, pad: int) -> np.ndarray:
    """Padded neighbour lists, shape (n_rows, most neighbours): ``cols`` grouped by ``rows``, then `pad`."""
    order = np.argsort(rows, kind="stable")
    rows, cols = rows[order], cols[order]
    count = np.bincount(rows, minlength=n_rows)
    table = np.full((n_rows, max(1, int(count.max(initial=0)))), pad, dtype=np.intp)
    table[rows, np.arange(len(rows)) - (np.cumsum(count) - count)[rows]] = cols
    return table


def _padded_coordinates(samples: np.ndarray):
    """x and y of the samples, shape (n + 1,): NaN at n, the padding of neighbour tables (compares false)."""
    xs = np.empty(len(samples) + 1)
    ys = np.empty(len(samples) + 1)
    xs[:-1], ys[:-1] = samples[:, 0], samples[:, 1]
    xs[-1] = ys[-1] = np.nan
    return xs, ys


def _open_crossings(samples: np.ndarray, radius: float, a, b, near):
    """Crossings of the circles around samples a and b that no third disk covers.

    Both crossings of each pair are tested against the samples closer than
    2 r to `a`, the only ones that can cover them.

    Parameters
    ----------
    samples : ndarray, shape (n, 2)
        mm.
    radius : float
        mm.
    a, b : ndarray of int, shape (m,)
        Sample pairs closer than 2 r, each once.
    near : ndarray of int, shape (m, k)
        Every sample closer than 2 r to each `a`, padded with n.

    Returns
    -------
    crossing, inward : ndarray, shape (q, 2)
        Open crossings (mm) and unit vectors from them into the gap (along
        the bisector of the pair, away from both).
    which : ndarray of int, shape (q,)
        Index of each one's pair in `a`, `b`.
    """
    xs, ys = _padded_coordinates(samples)
    r2 = radius * radius
    ax, ay = xs[a], ys[a]
    ex, ey = xs[b] - ax, ys[b] - ay
    length = np.sqrt(ex * ex + ey * ey)
    ux, uy = -ey / length, ex / length  # unit normal, left of a -> b
    half_chord = np.sqrt(np.maximum(r2 - 0.25 * length * length, 0.0))
    mx, my = ax + 0.5 * ex, ay + 0.5 * ey
    sides = [
        (mx + half_chord * ux, my + half_chord * uy, ux, uy),
        (mx - half_chord * ux, my - half_chord * uy, -ux, -uy),
    ]
    # Nearest distance^2 per crossing, a column of `near` at a time: short
    # 1-D temporaries instead of (m, k) ones.
    nearest = [np.full(len(a), np.inf) for _ in sides]
    for column in near.T:
        kx, ky = xs[column], ys[column]
        for (px, py, _, _), best in zip(sides, nearest):
            dx = px - kx
            dx *= dx
            dy = py - ky
            dy *= dy
            dx += dy
            np.fmin(best, dx, out=best)
    found = []
    for (px, py, wx, wy), best in zip(sides, nearest):
        gap = np.flatnonzero(best >= (1.0 - _SHRINK) * r2)
        found.append((np.stack((px[gap], py[gap]), axis=1), np.stack((wx[gap], wy[gap]), axis=1), gap))
    return tuple(np.concatenate(parts) for parts in zip(*found))


def _gap_centres(samples: np.ndarray, radius: float, crossing, inward, pair, near) -> np.ndarray:
    """Centre of the gap beyond each open crossing.

    Walking from crossing p of circles a and b along the bisector, into the
    gap, a and b stay the nearest samples until a third one is as near:
    there the walk ends, at the circumcentre of a Delaunay triangle whose
    circumradius exceeds r.  The third sample is sought in `near`.

    Parameters
    ----------
    crossing, inward : ndarray, shape (q, 2)
    pair : ndarray of int, shape (q, 2)
    near : ndarray of int, shape (q, k)
        Candidate third samples (n: padding).

    Returns
    -------
    ndarray, shape (q, 2)
        NaN where no sample in `near` closes the walk.
    """
    xs, ys = _padded_coordinates(samples)
    r2 = radius * radius
    px, py = crossing[:, 0], crossing[:, 1]
    wx, wy = inward[:, 0], inward[:, 1]
    gx, gy = xs[pair[:, 0]], ys[pair[:, 0]]
    # Power of x = p + t w against s: |p - s|^2 - r^2 + 2 t (p - s).w + t^2,
    # the same t^2 for every s: the walk meets s at t = power / (2 (s - a).w).
    # a and b have power 0 at p: only samples of positive power close it.
    half_t = np.full(len(px), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for column in near.T:
            kx, ky = xs[column], ys[column]
            dx = px - kx
            dy = py - ky
            power = dx * dx + dy * dy - r2
            rate = (kx - gx) * wx + (ky - gy) * wy
            step = power / rate
            step[~((rate > 1e-12 * radius) & (power > _SHRINK * r2))] = np.inf
            np.fmin(half_t, step, out=half_t)
    half_t[np.isinf(half_t)] = np.nan
    return crossing + (0.5 * half_t)[:, None] * inward


def _tree(points: np.ndarray) -> cKDTree:
    """A k-d tree built for a few queries: midpoint splits build faster than median ones."""
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _first_of_each(pts: np.ndarray, tolerance: float):
    """Groups of points (m, 2) equal after rounding to `tolerance`.

    Returns the index of one point of each group, and each point's group.
    """
    cell = np.round(pts / tolerance)
    _, first, group = np.unique(cell[:, 0] + 1j * cell[:, 1], return_index=True, return_inverse=True)
    return first, group.ravel()


def _free_inside(area, tree: cKDTree, pts: np.ndarray, radius: float) -> np.ndarray:
    """Bool mask (m,): finite point inside `area` with no sample closer than `radius`."""
    ok = np.isfinite(pts).all(axis=1)
    ok[ok] = contains_xy(area, pts[ok, 0], pts[ok, 1])
    if ok.any():
        d, _ = tree.query(pts[ok], k=1, distance_upper_bound=radius)
        ok[ok] = np.isinf(d)
    return ok


def _fill_gaps_constant(area, samples: np.ndarray, radius: float) -> np.ndarray:
    """Insert samples into the gaps between the disks until none is left (constant r).

    A gap (part of the area farther than r from every sample) is bounded by
    circle arcs and the area's border; where two arcs meet, at a crossing of
    two circles, no third disk covers it.  The first pass tests both
    crossings of every pair of samples closer than 2 r.  Each pass inserts,
    where it conflicts with no sample, each open crossing's gap centre (or,
    when that is unusable, a point just inside the gap at the crossing), an
    independent subset, deepest gap first.  A gap left after a pass touches a
    disk added in it, so later passes test only the crossings of added
    circles; they go on until nothing is added (a few passes after the first
    grid).  The result is maximal (see `uncovered_fraction`), so interior
    Delaunay angles are at least 30 deg, without triangulating.

    Parameters
    ----------
    area : shapely (Multi)Polygon
    samples : ndarray, shape (n, 2)
        Samples at least `radius` apart, mm.
    radius : float
        mm.

    Returns
    -------
    ndarray, shape (n + k, 2)
        `samples` followed by the inserted ones.
    """
    if len(samples) < 2:
        return samples
    tree = _tree(samples)
    pairs = tree.query_pairs(2.0 * radius, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    table = _neighbour_table(np.concatenate((a, b)), np.concatenate((b, a)), len(samples), len(samples))
    row, every_row = a, True  # table: rows of all samples at first, of the added ones later
    while True:  # each pass adds a sample at least, and r-separated samples in the area are finitely many
        p, u, which = _open_crossings(samples, radius, a, b, table[row])
        if len(p) == 0:
            break
        pair = np.stack((a[which], b[which]), axis=1)
        # The gap's third sample: near a (or b, when the table has its row).
        near = np.concatenate((table[pair[:, 0]], table[pair[:, 1]]), axis=1) if every_row else table[row[which]]
        cand = _gap_centres(samples, radius, p, u, pair, near)
        # The crossings around a gap reach the same centre: test each centre
        # once, keep one crossing per usable centre and every other crossing.
        found = np.flatnonzero(np.isfinite(cand[:, 0]))
        first, same = _first_of_each(cand[found], 1e-6 * radius)
        ok = np.zeros(len(cand), dtype=bool)
        ok[found] = _free_inside(area, tree, cand[found[first]], radius)[same]
        keep = np.sort(np.concatenate((np.flatnonzero(~ok), found[first][ok[found[first]]])))
        p, u, pair, cand, ok = p[keep], u[keep], pair[keep], cand[keep], ok[keep]
        # Farther from both: among the nearest to the crossing.
        rest = np.flatnonzero(~ok)
        if rest.size:
            nearest = tree.query(p[rest], k=min(_WALK_NEIGHBOURS, len(samples)))[1].reshape(rest.size, -1)
            cand[rest] = _gap_centres(samples, radius, p[rest], u[rest], pair[rest], nearest)
            ok[rest] = _free_inside(area, tree, cand[rest], radius)
        # Still nothing (centre outside the area): the open crossing itself,
        # nudged into the gap.
        rest = np.flatnonzero(~ok)
        cand[rest] = p[rest] + (_NUDGE * radius) * u[rest]
        ok[rest] = _free_inside(area, tree, cand[rest], radius)
        base = samples[pair[:, 0]]
        depth = np.einsum("ij,ij->i", cand - base, cand - base)
        cand, depth = cand[ok], depth[ok]
        if len(cand) == 0:
            break
        pairs = _tree(cand).query_pairs(radius, output_type="ndarray")
        won = greedy_independent_set(len(cand), pairs[:, 0], pairs[:, 1], -depth)
        fresh = np.arange(len(samples), len(samples) + np.count_nonzero(won))
        samples = np.concatenate((samples, cand[won]))
        tree = _tree(samples)
        # Every sample within 2 r of each added one: at most 18 (20 disks of
        # radius r / 2 do not fit in one of radius 2.5 r), after itself.
        table = tree.query(samples[fresh], k=min(19, len(samples)), distance_upper_bound=2.0 * radius)[1]
        table, every_row = table.reshape(len(fresh), -1)[:, 1:], False
        row, column = np.nonzero(table < len(samples))
        a, b = fresh[row], table[row, column]
        once = (b < fresh[0]) | (a < b)  # a pair of two added samples once
        row, a, b = row[once], a[once], b[once]
    return samples


def _fill_gaps_variable(area, samples, samples_r, radius_fn, passes: int = 6, keep: list | None = None,
                        reaching=None):
    """Insert circumcentres of empty circles wider than the radius (variable r).

    A Delaunay triangle whose circumradius exceeds the radius at its
    circumcentre leaves that centre uncovered; inserting such centres (an
    independent subset per pass) makes the set maximal.  (With a variable
    radius a sample may not go wherever no disk reaches: it must also keep its
    own radius free, so the gaps are sought among the circumcentres.)
    `keep`: a list that gets qhull's incremental triangulation of the samples
    returned (left open), when there is one.
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
        ci, _ = close_pairs(center, rc, samples, samples_r, reaching=reaching)
        free = np.ones(len(center), dtype=bool)
        free[ci] = False
        center, rc = center[free], rc[free]
        if len(center) == 0:
            break
        pi, pj = close_pairs(center, rc, reaching=reaching)
        won = greedy_independent_set(len(center), pi, pj, np.arange(len(center), dtype=float))
        samples = np.r_[samples, center[won]]
        samples_r = np.r_[samples_r, rc[won]]
        triangulation.add_points(center[won])
    if keep is None:
        triangulation.close()
    else:
        keep.append(triangulation)
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
    method : {"fast", "lattice", "bridson"}
        ``fast``: vectorized; ``lattice``: ``fast`` seeded with a triangular
        lattice of side ``LATTICE_SPACING * r`` where the radius is constant
        (a regular Poisson-disk set: every triangle equilateral there);
        ``bridson``: the paper's algorithm.

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
    if method in ("fast", "lattice"):
        return _sample_fast(area, radius_fn, int(seed), lattice=method == "lattice")
    if method == "bridson":
        return _sample_bridson(area, radius_fn, int(seed))
    raise ValueError(f"method must be 'fast', 'lattice' or 'bridson', got {method!r}")


def sample_triangulated(region, radius: RadiusLike, *, seed: int = 0, lattice: bool = False,
                        between_seed: int | None = None):
    """`sample_poisson_disk` (``fast``, or ``lattice``) and, where its gap filling triangulated them, the triangulation.

    `between_seed`: as in `sample_lattice`.

    Returns
    -------
    (ndarray, shape (n, 2); scipy.spatial.Delaunay or None; int)
        The samples, qhull's incremental triangulation of exactly them
        (left open for more points: see `triangulation.GrowingDelaunay`) or
        None (a constant radius, or too few samples), and how many of the
        first samples lie on the lattices.
    """
    keep, info = [], {}
    points = _sample_fast(as_area(region), radius_function(radius), int(seed), keep, lattice, info, between_seed)
    return points, (keep[0] if keep else None), info["lattice"]


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
    grid = cell_centres(area.bounds, h)
    grid = grid[contains_xy(area, grid[:, 0], grid[:, 1])]
    if len(grid) == 0:
        return 0.0
    samples = np.asarray(samples, dtype=float).reshape(-1, 2)
    return float(_uncovered_mask(grid, samples, radius_fn(samples), radius_fn).mean())
