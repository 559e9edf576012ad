"""Painted density regions: the part of a model within a depth of faces painted on its surface.

A painted set is (model mesh, painted triangle indices, density, depth).  Its region is the part
of the model within `depth` (mm, 3-D distance) of the painted faces.  At a layer's height z it is

    section(union over painted triangles T of T + ball(depth), z)  ∩  section(model, z)

where ``T + ball(depth)`` (the Minkowski sum: every point within `depth` of T) is convex, so its
section at z is a convex polygon.  That polygon is computed exactly through its support function:
for a direction u in the plane,

    h(u) = min over t of  max_i (u·p_i + t (z_i - z)) + depth * sqrt(1 + t²)

(p_i, z_i the triangle's corners; duality of the section of a convex set with its support
function ``h(w) = max_i w·P_i + depth |w|``).  The function of t is convex and piecewise smooth, so
its minimum lies at one of six candidates: where the piece of corner i is stationary
(``t = c / sqrt(1 - c²)``, ``c = (z - z_i) / depth``), or where two pieces cross.  The polygon is
the intersection of the half-planes ``u·q <= h(u)`` over uniformly spaced directions plus the
normals of the section's straight parts (the triangle's own plane and its horizontal edges), so it
lies outside the true section by at most the tolerance on round parts and not at all along straight
ones.  Everything is vectorized over triangles x directions; triangles are culled by z first.

``PaintedRegion`` plugs into the G-code pass exactly as a mesh :class:`~DelaunayInfill.gcode.Region`
does (it is one: ``density``, ``name``, ``at(z)``).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from .gcode.settings import Region
from .geometry import SHAPELY2, empty_area, to_multipolygon, unary_union

__all__ = [
    "DEFAULT_TOLERANCE",
    "PaintedRegion",
        "load_faces",
    "cone_angles",
    "neighbourhood_corners",
    "neighbourhood_section",
    "painted_section",
    "point_distances",
]

#: largest distance (mm) by which a round part of a section's polygon may lie outside the true one
DEFAULT_TOLERANCE = 0.02
#: extra directions per triangle: ± its plane's horizontal normal, ± the normal of each edge's plan view
_EXTRA = 8
_START = 32  # uniform directions per triangle before refinement
_ROUNDS = 8  # refinement rounds (each halves the angle between two directions where needed)
_SAME_ANGLE = 1e-7  # radians under which two directions count as one


def load_faces(path: str | os.PathLike, n_triangles: int, *, model_name: str | None = None) -> np.ndarray:
    """Read a FACES.json file: the painted triangles of a model.

    The file holds ``{"faces": [i, j, ...]}``: 0-based indices into the model's triangles in
    its STL's order.  Repeated indices count once.

    Parameters
    ----------
    path : str or path-like
        The JSON file.
    n_triangles : int
        How many triangles the model has (the STL's count).
    model_name : str, optional
        The model's name for messages (default "the model").

    Returns
    -------
    ndarray of int64, shape (k,)
        The painted indices, sorted, unique, each in ``[0, n_triangles)``; k >= 1.

    Raises
    ------
    ValueError
        The file is not JSON, not an object with a "faces" list of whole numbers, the list is
        empty, or an index is negative or not below `n_triangles`.
    OSError
        The file cannot be read.
    """
    name = os.path.basename(os.fspath(path))
    model = model_name or "the model"
    with open(path, "rb") as f:
        data = f.read()
    try:
        doc = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"{name} is not valid JSON ({exc})") from None
    if not isinstance(doc, dict) or "faces" not in doc:
        raise ValueError(f'{name} must be a JSON object {{"faces": [i, j, ...]}} (0-based triangle indices)')
    faces = doc["faces"]
    if not isinstance(faces, list):
        raise ValueError(f'{name}: "faces" must be a list of triangle indices, got {type(faces).__name__}')
    if not faces:
        raise ValueError(f"{name} lists no faces: paint at least one triangle")
    bad = next((v for v in faces if isinstance(v, bool) or not isinstance(v, int)), None)
    if bad is not None:
        raise ValueError(f"{name}: face indices must be whole numbers, got {bad!r}")
    idx = np.asarray(faces, dtype=object)
    low, high = min(faces), max(faces)
    if low < 0:
        raise ValueError(f"{name} lists face {low}: indices start at 0")
    if high >= n_triangles:
        raise ValueError(f"{name} lists face {high} but {model} has {n_triangles} triangles")
    return np.unique(idx.astype(np.int64))


def _extra_directions(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normals of the straight parts a triangle's sections can have, as angles.

    ± the horizontal part of the triangle's normal (where the plane cuts its two offset copies)
    and ± the plan-view normal of each edge (where the plane cuts an edge's cylinder along a
    horizontal edge).

    Parameters
    ----------
    tri : ndarray, shape (n, 3, 3)
        mm.

    Returns
    -------
    angles : ndarray, shape (n, 8)
        Radians in [0, 2 pi).
    defined : ndarray of bool, shape (n, 8)
        False where the normal has no horizontal part (a horizontal triangle, a vertical edge).
    """
    n = len(tri)
    vec = np.empty((n, _EXTRA, 2))
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vec[:, 0] = normal[:, :2]
    vec[:, 1] = -normal[:, :2]
    edges = np.roll(tri, -1, axis=1) - tri  # (n, 3, 3)
    perp = np.stack([edges[:, :, 1], -edges[:, :, 0]], axis=-1)  # (n, 3, 2)
    vec[:, 2:5] = perp
    vec[:, 5:8] = -perp
    length = np.hypot(vec[..., 0], vec[..., 1])
    full = np.concatenate([np.repeat(np.linalg.norm(normal, axis=1)[:, None], 2, axis=1),
                           np.tile(np.linalg.norm(edges, axis=2), (1, 2))], axis=1)  # (n, 8): 3-D lengths
    defined = length > 1e-9 * full
    return np.arctan2(vec[..., 1], vec[..., 0]) % (2.0 * math.pi), defined


def _support(p: np.ndarray, a: np.ndarray, depth: float, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Support function of the sections of ``T + ball(depth)``, one direction per row, and a touching point.

    Parameters
    ----------
    p : ndarray, shape (k, 3, 2)
        Each row's triangle corners in plan view, mm (relative to any origin per row).
    a : ndarray, shape (k, 3)
        The corners' heights above the cutting plane, mm.
    depth : float
        mm, > 0.
    phi : ndarray, shape (k,)
        The direction of each row, radians.

    Returns
    -------
    h : ndarray, shape (k,)
        ``max u·q`` over the section, ``u = (cos phi, sin phi)``, mm.
    touch : ndarray, shape (k, 2)
        A point of the section on its support line ``u·q = h`` (same origin as `p`), mm.
    touched : ndarray of bool, shape (k,)
        Where `touch` is known to be such a point (else it is not to be used).

    Notes
    -----
    At the minimising slope t the solid's touching point in direction ``w = (u, t)`` is
    ``P_i + depth w / |w|`` for the corner i that attains the maximum, or a point of the edge
    between the two that tie; its height is 0 where the minimum is stationary (checked).
    """
    c_phi, s_phi = np.cos(phi), np.sin(phi)
    dots = p[:, :, 0] * c_phi[:, None] + p[:, :, 1] * s_phi[:, None]  # (k, 3)
    c = -a / depth  # stationary point of each corner's piece: t / sqrt(1 + t^2) = c
    i, j = np.array([0, 1, 2]), np.array([1, 2, 0])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        stationary = np.where(np.abs(c) < 1.0, c / np.sqrt(np.maximum(1.0 - c * c, 1e-300)), np.nan)
        kinks = (dots[:, j] - dots[:, i]) / (a[:, i] - a[:, j])  # where two corners' pieces cross
        t = np.concatenate([stationary, kinks], axis=1)  # (k, 6)
        t = np.where(np.isfinite(t), t, np.nan)
        g = (dots[:, None, :] + t[:, :, None] * a[:, None, :]).max(axis=2) + depth * np.sqrt(1.0 + t * t)
    g = np.where(np.isnan(g), np.inf, g)
    best = np.argmin(g, axis=1)
    rows = np.arange(len(g))
    h = g[rows, best]
    slope = np.nan_to_num(t[rows, best])
    norm = np.sqrt(1.0 + slope * slope)
    lift, reach = depth * slope / norm, depth / norm  # the offset's height and plan-view length
    values = dots + slope[:, None] * a  # (k, 3): each corner's piece at the slope
    order = np.argsort(-values, axis=1)
    first, second = order[:, 0], order[:, 1]
    a1, a2 = a[rows, first], a[rows, second]
    scale = 1.0 + np.abs(values).max(axis=1)
    tie = values[rows, first] - values[rows, second] <= 1e-9 * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(tie & (np.abs(a1 - a2) > 1e-12), (a1 + lift) / (a1 - a2), 0.0)
    share = np.where(np.abs(a1 + lift) <= 1e-7 * (1.0 + depth), 0.0, share)  # the corner alone is at height 0
    height = a1 + share * (a2 - a1) + lift
    touched = np.isfinite(h) & (share >= -1e-9) & (share <= 1.0 + 1e-9) & (np.abs(height) <= 1e-6 * (1.0 + depth))
    p1, p2 = p[rows, first], p[rows, second]
    touch = p1 + share[:, None] * (p2 - p1) + reach[:, None] * np.stack([c_phi, s_phi], axis=1)
    return h, touch, touched


def _group_neighbours(owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Next and previous index within each run of equal `owner` values, cyclically, shape (N,) each."""
    n = len(owner)
    idx = np.arange(n)
    first = np.r_[True, owner[1:] != owner[:-1]]
    last = np.r_[owner[1:] != owner[:-1], True]
    start = np.maximum.accumulate(np.where(first, idx, 0))
    end = np.minimum.accumulate(np.where(last, idx, n - 1)[::-1])[::-1]
    return np.where(last, start, idx + 1), np.where(first, end, idx - 1)


def _corners(phi: np.ndarray, h: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """Where each support line meets the next one of its triangle, shape (N, 2) mm (relative origins)."""
    c, s = np.cos(phi), np.sin(phi)
    c1, s1, h1 = c[nxt], s[nxt], h[nxt]
    det = c * s1 - s * c1
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([(h * s1 - h1 * s) / det, (c * h1 - c1 * h) / det], axis=1)


def _segment_distances(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each point q to the segment [a, b], all shape (N, 2), mm."""
    ab = b - a
    s = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return np.hypot(*(q - (a + s[:, None] * ab)).T)


def _corner_errors(q: np.ndarray, touch: np.ndarray, touched: np.ndarray, nxt: np.ndarray,
                   prv: np.ndarray) -> np.ndarray:
    """How far each corner may lie outside the true section (an upper bound), shape (N,) mm.

    Corner i lies on support lines i and next(i).  Where both lines' touching points are known,
    the true section's border between them lies in the triangle they make with the corner
    (convexity), and the section holds the chord between them: the corner is at most its
    distance to that chord outside.  Elsewhere the bound is the corner's distance to the line
    through its neighbouring corners (the polygon's own triangle round it).
    """
    chord = _segment_distances(q, touch, touch[nxt])
    base = q[nxt] - q[prv]
    span = np.hypot(base[:, 0], base[:, 1])
    cross = np.abs(base[:, 0] * (q[:, 1] - q[prv, 1]) - base[:, 1] * (q[:, 0] - q[prv, 0]))
    loose = np.where(span > 1e-12, cross / np.maximum(span, 1e-300), np.hypot(*(q - q[prv]).T))
    known = touched & touched[nxt] & np.isfinite(chord)
    return np.where(known, np.minimum(chord, loose), loose)


def neighbourhood_corners(triangles: np.ndarray, depth: float, z: float, *,
                          tolerance: float = DEFAULT_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's ``T + ball(depth)`` cut at height `z`, as the corners of a convex polygon.

    The polygon is the intersection of the section's supporting half-planes in a set of
    directions: 32 uniform ones, the normals of the section's straight parts, and more where a
    corner may lie farther than `tolerance` outside the true section (:func:`_corner_errors`);
    up to 8 rounds of refinement, each new direction inserted in place (the rows stay in
    angular order per triangle, so nothing is sorted again).  Only triangles whose
    neighbourhood reaches strictly past the plane (``min z - depth < z < max z + depth``) are
    kept: a plane that only touches one has no area there.

    Parameters
    ----------
    triangles : ndarray, shape (n, 3, 3)
        mm.
    depth : float
        mm, > 0.
    z : float
        mm.
    tolerance : float
        mm: how far the polygon may reach outside the true section.

    Returns
    -------
    corners : ndarray, shape (N, 2)
        mm; counter-clockwise per triangle.
    owner : ndarray of int64, shape (N,)
        Index into `triangles` of each corner's triangle, non-decreasing.
    """
    tri = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    depth = float(depth)
    if not (math.isfinite(depth) and depth > 0.0):
        raise ValueError(f"depth must be a positive number of mm, got {depth}")
    zs = tri[:, :, 2]
    kept = np.flatnonzero((zs.min(axis=1) - depth < z) & (z < zs.max(axis=1) + depth))
    if len(kept) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    tri = tri[kept]
    k = len(tri)
    centre = tri[:, :, :2].mean(axis=1)  # (k, 2): better conditioned sums
    p = tri[:, :, :2] - centre[:, None, :]
    a = tri[:, :, 2] - z
    extra, defined = _extra_directions(tri)
    uniform = np.arange(_START) * (2.0 * math.pi / _START)
    owner = np.concatenate([np.repeat(np.arange(k), _START), np.repeat(np.arange(k), _EXTRA)[defined.ravel()]])
    phi = np.concatenate([np.tile(uniform, k), extra[defined]])
    order = np.lexsort((phi, owner))  # once: later directions are inserted in place
    owner, phi = owner[order], phi[order]
    h, touch, touched = _support(p[owner], a[owner], depth, phi)
    for round_ in range(_ROUNDS + 1):
        # (nearly) equal directions: keep one (their corner is undefined, their edge empty)
        nxt, prv = _group_neighbours(owner)
        gap = (phi[nxt] - phi) % (2.0 * math.pi)
        dup = gap < _SAME_ANGLE
        if dup.any():
            keep = ~dup
            owner, phi, h, touch, touched = owner[keep], phi[keep], h[keep], touch[keep], touched[keep]
            nxt, prv = _group_neighbours(owner)
            gap = (phi[nxt] - phi) % (2.0 * math.pi)
        q = _corners(phi, h, nxt)
        if round_ == _ROUNDS:
            break
        bad = np.flatnonzero(_corner_errors(q, touch, touched, nxt, prv) > tolerance)
        if len(bad) == 0:
            break
        new_phi = (phi[bad] + 0.5 * gap[bad]) % (2.0 * math.pi)
        new_owner = owner[bad]
        new_h, new_touch, new_touched = _support(p[new_owner], a[new_owner], depth, new_phi)
        at = bad + 1  # between line i and the next one of its triangle: after row i
        owner, phi, h = np.insert(owner, at, new_owner), np.insert(phi, at, new_phi), np.insert(h, at, new_h)
        touch, touched = np.insert(touch, at, new_touch, axis=0), np.insert(touched, at, new_touched)
    return q + centre[owner], kept[owner]


def _convex_rings(corners: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Which owners' corners make a convex counter-clockwise ring of some area, shape (N,) bool per corner.

    Rounding can make a corner of nearly parallel support lines fall a little the wrong way; such
    a ring is not a valid polygon (its convex hull is used instead).
    """
    nxt, prv = _group_neighbours(owner)
    e1, e2 = corners - corners[prv], corners[nxt] - corners
    turn = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    size = np.maximum(np.hypot(*e1.T) * np.hypot(*e2.T), 1e-300)
    ok_corner = np.isfinite(turn) & (turn >= -1e-9 * size)
    _, ids = np.unique(owner, return_inverse=True)
    ok = np.ones(ids.max() + 1 if len(ids) else 0, dtype=bool)
    np.logical_and.at(ok, ids, ok_corner)
    area = np.zeros(len(ok))  # twice the signed area (shoelace): a flat ring is no polygon
    np.add.at(area, ids, np.where(np.isfinite(turn), corners[prv, 0] * corners[:, 1] - corners[:, 0] * corners[prv, 1], 0.0))
    return (ok & (area > 0.0))[ids]


def _multipolygon_wkb(corners: np.ndarray, owner: np.ndarray) -> bytes:
    """WKB of a MultiPolygon with one ring per owner (its corners, closed), built in numpy (no Python loop)."""
    cuts = np.flatnonzero(owner[1:] != owner[:-1]) + 1
    starts = np.r_[0, cuts]
    counts = np.diff(np.r_[starts, len(corners)]) + 1  # closed rings
    closed = np.insert(corners, np.r_[cuts, len(corners)], corners[starts], axis=0).astype("<f8")
    header = np.zeros(len(starts), dtype=np.dtype([("order", "u1"), ("kind", "<u4"), ("rings", "<u4"), ("points", "<u4")]))
    header["order"], header["kind"], header["rings"], header["points"] = 1, 3, 1, counts
    sizes = header.dtype.itemsize + 16 * counts
    offsets = 9 + np.r_[0, np.cumsum(sizes)[:-1]]
    out = np.empty(9 + int(sizes.sum()), dtype=np.uint8)
    top = np.array([(1, 6, len(starts))], dtype=[("order", "u1"), ("kind", "<u4"), ("parts", "<u4")])
    out[:9] = np.frombuffer(top.tobytes(), dtype=np.uint8)
    width = header.dtype.itemsize
    out[(offsets[:, None] + np.arange(width)).ravel()] = np.frombuffer(header.tobytes(), dtype=np.uint8)
    coord_bytes = np.frombuffer(closed.tobytes(), dtype=np.uint8)
    first = np.repeat(offsets + width, 16 * counts)
    local = np.arange(len(coord_bytes)) - np.repeat(np.r_[0, np.cumsum(16 * counts)[:-1]], 16 * counts)
    out[first + local] = coord_bytes
    return out.tobytes()


def _union_of_convex(corners: np.ndarray, owner: np.ndarray):
    """The union of the convex polygons of corners grouped by owner (MultiPolygon, possibly empty).

    Rings that rounding made non-convex are replaced by their corners' convex hull.  On
    shapely 2 the polygons are made and united with its array functions; on shapely 1.8 as one
    MultiPolygon built as WKB and united by GEOS directly (neither loops in Python over them).
    """
    if len(corners) == 0:
        return empty_area()
    convex = _convex_rings(corners, owner)
    parts = []
    if SHAPELY2:
        import shapely

        if convex.any():
            parts.append(shapely.from_wkb(_multipolygon_wkb(corners[convex], owner[convex])))
        if not convex.all():
            _, ids = np.unique(owner[~convex], return_inverse=True)
            hulls = shapely.convex_hull(shapely.multipoints(corners[~convex], indices=ids))
            parts.extend(hulls[(shapely.get_type_id(hulls) == 3) & (shapely.area(hulls) > 0.0)])
        return to_multipolygon(shapely.union_all(parts)) if parts else empty_area()
    from shapely import wkb  # pragma: no cover - shapely 1.8
    from shapely.geometry import MultiPoint  # pragma: no cover
    from shapely.geometry.base import geom_factory  # pragma: no cover
    from shapely.geos import lgeos  # pragma: no cover

    if convex.any():  # pragma: no cover
        many = wkb.loads(_multipolygon_wkb(corners[convex], owner[convex]))
        parts.append(geom_factory(lgeos.methods["unary_union"](many._geom)))
    if not convex.all():  # pragma: no cover - rare: a few rings only
        bad_owner, bad_corners = owner[~convex], corners[~convex]
        cuts = np.flatnonzero(bad_owner[1:] != bad_owner[:-1]) + 1
        hulls = (MultiPoint(c.tolist()).convex_hull for c in np.split(bad_corners, cuts))
        parts.extend(h for h in hulls if h.geom_type == "Polygon" and h.area > 0.0)
    if not parts:  # pragma: no cover
        return empty_area()
    return to_multipolygon(parts[0] if len(parts) == 1 else unary_union(parts))  # pragma: no cover


def point_distances(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """3-D distance from each point to the nearest of the triangles.

    Parameters
    ----------
    points : ndarray, shape (m, 3)
        mm.
    triangles : ndarray, shape (n, 3, 3)
        mm, n >= 1.

    Returns
    -------
    ndarray, shape (m,)
        mm.
    """
    x = np.asarray(points, dtype=float).reshape(-1, 1, 3)
    t = np.asarray(triangles, dtype=float).reshape(1, -1, 3, 3)
    a, b, c = t[:, :, 0], t[:, :, 1], t[:, :, 2]

    def segment(p, q):
        pq = q - p
        s = np.clip(np.einsum("mnk,mnk->mn", x - p, pq) / np.maximum(np.einsum("mnk,mnk->mn", pq, pq), 1e-300), 0.0, 1.0)
        return np.linalg.norm(x - (p + s[..., None] * pq), axis=-1)

    best = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=-1)
    n = normal / np.maximum(length, 1e-300)[..., None]
    height = np.einsum("mnk,mnk->mn", x - a, n)
    foot = x - height[..., None] * n
    inside = np.ones(best.shape, dtype=bool)
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("mnk,mnk->mn", np.cross(q - p, foot - p), n) >= 0.0
    inside &= length > 0.0
    return np.where(inside, np.minimum(np.abs(height), best), best).min(axis=1)


def cone_angles(triangles: np.ndarray) -> np.ndarray:
    """How far the normal directions at each triangle's corners may turn from its own normal.

    A point at distance `depth` from a surface of triangles, whose nearest point lies on
    triangle T, is ``y + depth * v`` with y in T and v within this angle of T's normal (or of
    its opposite).  The angle is twice the largest angle between a corner's triangles'
    normals and their mean, plus a little; pi (any direction) where a corner lies on the
    surface's border (an edge of one triangle only, or of more than two).

    Parameters
    ----------
    triangles : ndarray, shape (n, 3, 3)
        mm; corners shared by triangles must be bit-identical (as in an STL of a closed mesh).

    Returns
    -------
    ndarray, shape (n,)
        Radians in [0, pi].
    """
    tri = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    n = len(tri)
    if n == 0:
        return np.zeros(0)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    unit = normal / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    _, vid = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    vid = vid.reshape(n, 3)
    nv = int(vid.max()) + 1
    owner = np.repeat(np.arange(n), 3)
    mean = np.zeros((nv, 3))
    np.add.at(mean, vid.ravel(), unit[owner])
    mean /= np.maximum(np.linalg.norm(mean, axis=1), 1e-300)[:, None]
    cosine = np.full(nv, 1.0)
    np.minimum.at(cosine, vid.ravel(), np.einsum("ij,ij->i", unit[owner], mean[vid.ravel()]))
    turn = np.minimum(math.pi, 2.0 * np.arccos(np.clip(cosine, -1.0, 1.0)) + 0.02)
    # border corners: an edge of one triangle (or of more than two)
    edges = np.sort(np.stack([vid, np.roll(vid, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    _, edge_id, count = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    border_edges = edges[count[edge_id.ravel()] != 2]
    turn[border_edges.ravel()] = math.pi
    return turn[vid].max(axis=1)


def _may_bound(tri: np.ndarray, depth: float, z: float, cone: np.ndarray) -> np.ndarray:
    """Which triangles may hold the nearest point of a point of the section's border, shape (n,) bool.

    Such a point is ``y + depth * v`` (y in T, v within `cone` of ±T's normal), so the plane
    must cross ``T + depth * v`` for some of those v.
    """
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nz = np.abs(normal[:, 2]) / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    tilt = np.arccos(np.clip(nz, 0.0, 1.0))  # of the normal (or its opposite) from the vertical, <= pi/2
    top = np.cos(np.maximum(tilt - cone, 0.0))  # the largest upward part of such a v
    low = np.cos(np.minimum(tilt + cone, math.pi))  # the smallest (of the side facing up)
    zs = tri[:, :, 2]
    zlo, zhi = zs.min(axis=1), zs.max(axis=1)
    # side facing up: heights [zlo + depth*low, zhi + depth*top]; facing down: [zlo - depth*top, zhi - depth*low]
    up = (zlo + depth * low <= z) & (z <= zhi + depth * top)
    down = (zlo - depth * top <= z) & (z <= zhi - depth * low)
    return up | down


def neighbourhood_section(triangles: np.ndarray, depth: float, z: float, *,
                          tolerance: float = DEFAULT_TOLERANCE, cone: np.ndarray | None = None):
    """Where the plane at height `z` meets the points within `depth` of the triangles.

    Only the triangles that may hold the nearest point of a point of the section's border
    (see :func:`cone_angles`) are cut: their sections' union has the true section's border,
    and any hole of it that the other triangles fill (a point of it within `depth` of a
    triangle) is filled.

    Parameters
    ----------
    triangles : ndarray, shape (n, 3, 3)
        mm.
    depth, z, tolerance : float
        mm (see :func:`neighbourhood_corners`).
    cone : ndarray, shape (n,), optional
        :func:`cone_angles` of `triangles` (computed here when not given).

    Returns
    -------
    shapely MultiPolygon
        Possibly empty, mm.
    """
    tri = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    zs = tri[:, :, 2]
    near = (zs.min(axis=1) - depth < z) & (z < zs.max(axis=1) + depth)
    if not near.any():
        return empty_area()
    if cone is None:
        cone = cone_angles(tri)
    cone = np.asarray(cone, dtype=float)
    bounding = near & _may_bound(tri, float(depth), z, cone)
    corners, owner = neighbourhood_corners(tri[bounding], depth, z, tolerance=tolerance)
    union = _union_of_convex(corners, owner)
    if union.is_empty:
        return empty_area()
    return _fill_gaps(union, tri[near], depth, z)


def _fill_gaps(union, triangles: np.ndarray, depth: float, z: float):
    """`union` with the bounded gaps of it that lie within `depth` of the triangles filled in.

    A gap is a connected piece of the holes of `union`'s parts less `union` itself (a hole of one
    part may hold another part, as the outer border's ring holds the inner one on a dome).  The
    union has the true border, so no gap holds a point of it: a gap is wholly inside the region
    or wholly outside, and one point of it says which (its exact distance to the triangles).
    """
    from shapely.geometry import Polygon

    holes = [Polygon(ring) for part in union.geoms for ring in part.interiors]
    if not holes:
        return union
    gaps = to_multipolygon(unary_union(holes).difference(union))
    gaps = [g for g in gaps.geoms if g.area > 0.0]
    if not gaps:
        return union
    reps = np.array([g.representative_point().coords[0] for g in gaps], dtype=float)
    inside = point_distances(np.c_[reps, np.full(len(reps), float(z))], triangles) <= depth
    if not inside.any():
        return union
    return to_multipolygon(unary_union([union, *[g for g, fill in zip(gaps, inside) if fill]]))


def painted_section(model_triangles: np.ndarray, painted_triangles: np.ndarray, depth: float, z: float, *,
                    tolerance: float = DEFAULT_TOLERANCE, model_section=None, cone: np.ndarray | None = None,
                    margin: float = 0.0):
    """A painted region at height `z`: the part of the model's section within `depth` of the painted faces.

    Parameters
    ----------
    model_triangles : ndarray, shape (n, 3, 3)
        The closed model mesh, mm.
    painted_triangles : ndarray, shape (k, 3, 3)
        The painted faces (usually ``model_triangles[faces]``), mm.
    depth, z, tolerance : float
        mm.
    model_section : shapely geometry, optional
        The model's section at `z` when already known (else sliced here).
    cone : ndarray, shape (k,), optional
        :func:`cone_angles` of `painted_triangles` (computed here when not given).
    margin : float
        mm: cut with the model's section grown by this much (0: the section itself).  Inside the
        model the result is the same; see :class:`PaintedRegion` for why the pass uses 1 mm.

    Returns
    -------
    shapely MultiPolygon
        Possibly empty, mm.
    """
    near = neighbourhood_section(painted_triangles, depth, z, tolerance=tolerance, cone=cone)
    if near.is_empty:
        return empty_area()
    if model_section is None:
        from .meshslice import slice_mesh

        model_section = slice_mesh(model_triangles, z)
    if model_section.is_empty:
        return empty_area()
    if margin > 0.0:
        model_section = model_section.buffer(margin, 8)
    return to_multipolygon(near.intersection(model_section))


class PaintedRegion(Region):
    """A density region painted on a model: its part within `depth` of the painted faces.

    Used by the G-code pass exactly like a mesh :class:`~DelaunayInfill.gcode.Region` (it is
    one): ``density``, ``name``, ``at(z)``.

    ``at(z)`` is the painted faces' depth-neighbourhood cut with the model's section grown by
    `margin` (default 1 mm): inside the model exactly the painted region, and it reaches a little
    past the model's surface, as a modifier mesh does.  Cut at the surface itself, the region's
    border would lie on the part's own border, and the seamless pattern blends a region's density
    into what lies beyond its border (the base density, outside the part) over about two sample
    radii: measured on a bushing whose bore is painted 6 mm deep at 60 % (a 3.4 mm wide ring of
    infill), 54 % with no margin, 60 % with 0.5 mm or more.  Nothing is printed outside the part.

    Parameters
    ----------
    model : ndarray, shape (n, 3, 3)
        The closed model mesh in G-code coordinates, mm.
    faces : array_like of int, shape (k,)
        Painted triangle indices into `model`, 0-based.
    density : float
        Fraction 0-1.
    depth : float
        mm, > 0.
    name : str
    tolerance : float
        mm, see :func:`neighbourhood_corners`.
    margin : float
        mm, how far past the model's surface the region reaches (see above).
    """

    def __init__(self, model, faces, density: float, depth: float, name: str = "", *,
                 tolerance: float = DEFAULT_TOLERANCE, margin: float = 1.0):
        super().__init__(density=density, triangles=model, name=name)
        faces = np.unique(np.asarray(faces, dtype=np.int64).reshape(-1))
        if len(faces) == 0:
            raise ValueError(f"painted region {name}: no faces painted")
        if faces[0] < 0 or faces[-1] >= len(self.triangles):
            bad = faces[0] if faces[0] < 0 else faces[-1]
            raise ValueError(f"painted region {name}: face {bad} is not one of the model's {len(self.triangles)} triangles")
        depth = float(depth)
        if not (math.isfinite(depth) and depth > 0.0):
            raise ValueError(f"painted region {name}: depth must be a positive number of mm, got {depth:g}")
        self.faces = faces
        self.depth = depth
        self.tolerance = float(tolerance)
        self.margin = float(margin)
        self.painted = self.triangles[faces]
        self.cone = cone_angles(self.painted)
        pz = self.painted[:, :, 2]
        self.z_min = max(self.z_min, float(pz.min()) - depth)
        self.z_max = min(self.z_max, float(pz.max()) + depth)

    @classmethod
    def from_files(cls, stl_path, faces_path, density: float, depth: float, offset=(0.0, 0.0, 0.0),
                   name: str | None = None) -> PaintedRegion:
        """A painted region from MODEL.stl and FACES.json, the model shifted by `offset` (mm).

        Raises
        ------
        ValueError
            A bad STL or FACES.json (see :func:`load_faces`), or a bad depth or density.
        """
        from .meshslice import read_stl

        tri = read_stl(stl_path) + np.asarray(list(offset) + [0.0] * (3 - len(offset)), dtype=float)[:3]
        model_name = os.path.basename(os.fspath(stl_path))
        faces = load_faces(faces_path, len(tri), model_name=model_name)
        return cls(tri, faces, density, depth,
                   name=name or f"painted {model_name}:{os.path.basename(os.fspath(faces_path))}")

    def at(self, z: float):
        """The region's area at height `z` (MultiPolygon, possibly empty), mm."""
        if not (self.z_min <= z <= self.z_max):
            return empty_area()
        key = round(float(z), 4)
        hit = self._cache.get(key)
        if hit is None:
            hit = painted_section(self.triangles, self.painted, self.depth, key, tolerance=self.tolerance,
                                    cone=self.cone, margin=self.margin)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def bounds_xy(self):
        pts = self.painted.reshape(-1, 3)
        lo, hi = pts[:, :2].min(axis=0) - self.depth, pts[:, :2].max(axis=0) + self.depth
        return (*lo, *hi)
