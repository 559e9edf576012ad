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


def _support(p: np.ndarray, a: np.ndarray, depth: float, phi: np.ndarray) -> np.ndarray:
    """Support function of the sections of ``T + ball(depth)``, one direction per row.

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
    ndarray, shape (k,)
        ``max u·q`` over the section, ``u = (cos phi, sin phi)``, mm.
    """
    dots = p[:, :, 0] * np.cos(phi)[:, None] + p[:, :, 1] * np.sin(phi)[:, None]  # (k, 3)
    c = -a / depth  # stationary point of each corner's piece: t / sqrt(1 + t^2) = c
    i, j = np.array([0, 1, 2]), np.array([1, 2, 0])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        stationary = np.where(np.abs(c) < 1.0, c / np.sqrt(np.maximum(1.0 - c * c, 1e-300)), np.nan)
        kinks = (dots[:, j] - dots[:, i]) / (a[:, i] - a[:, j])  # where two corners' pieces cross
        t = np.concatenate([stationary, kinks], axis=1)  # (k, 6)
        t = np.where(np.isfinite(t), t, np.nan)
        g = (dots[:, None, :] + t[:, :, None] * a[:, None, :]).max(axis=2) + depth * np.sqrt(1.0 + t * t)
    return np.where(np.isnan(g), np.inf, g).min(axis=1)


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


def neighbourhood_corners(triangles: np.ndarray, depth: float, z: float, *,
                          tolerance: float = DEFAULT_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's ``T + ball(depth)`` cut at height `z`, as the corners of a convex polygon.

    The polygon is the intersection of the section's supporting half-planes in a set of
    directions: 32 uniform ones, the normals of the section's straight parts, and more where a
    corner may lie farther than `tolerance` outside the true section (a corner lies within the
    triangle it makes with its neighbours, so its distance to the line through them bounds its
    error); up to 8 rounds of refinement.  Only triangles whose neighbourhood reaches strictly past
    the plane (``min z - depth < z < max z + depth``) are kept: a plane that only touches one
    has no area there.

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
    h = _support(p[owner], a[owner], depth, phi)
    for round_ in range(_ROUNDS + 1):
        order = np.lexsort((phi, owner))
        owner, phi, h = owner[order], phi[order], h[order]
        # (nearly) equal directions: keep one (their corner is undefined, their edge empty)
        nxt, _ = _group_neighbours(owner)
        gap = (phi[nxt] - phi) % (2.0 * math.pi)
        dup = gap < _SAME_ANGLE
        if dup.any():
            keep = ~dup
            owner, phi, h = owner[keep], phi[keep], h[keep]
            nxt, _ = _group_neighbours(owner)
            gap = (phi[nxt] - phi) % (2.0 * math.pi)
        q = _corners(phi, h, nxt)
        if round_ == _ROUNDS:
            break
        # a corner's error is at most its distance to the line through its neighbours
        _, prv = _group_neighbours(owner)
        base = q[nxt] - q[prv]
        span = np.hypot(base[:, 0], base[:, 1])
        cross = np.abs(base[:, 0] * (q[:, 1] - q[prv, 1]) - base[:, 1] * (q[:, 0] - q[prv, 0]))
        err = np.where(span > 1e-12, cross / np.maximum(span, 1e-300),
                       np.hypot(*(q - q[prv]).T))
        bad = np.flatnonzero(err > tolerance)
        if len(bad) == 0:
            break
        new_phi = (phi[bad] + 0.5 * gap[bad]) % (2.0 * math.pi)
        new_owner = owner[bad]
        new_h = _support(p[new_owner], a[new_owner], depth, new_phi)
        owner, phi, h = np.r_[owner, new_owner], np.r_[phi, new_phi], np.r_[h, new_h]
    return q + centre[owner], kept[owner]


def _polygons(corners: np.ndarray, owner: np.ndarray) -> list:
    """One convex Polygon per owner from its corners in order (its hull where rounding made it invalid)."""
    cuts = np.flatnonzero(owner[1:] != owner[:-1]) + 1
    if SHAPELY2:
        import shapely

        _, ids = np.unique(owner, return_inverse=True)
        closed = np.insert(corners, np.r_[cuts, len(corners)], corners[np.r_[0, cuts]], axis=0)
        closed_ids = np.insert(ids, np.r_[cuts, len(corners)], ids[np.r_[0, cuts]])
        polys = shapely.polygons(shapely.linearrings(closed, indices=closed_ids))
        bad = ~shapely.is_valid(polys)
        if bad.any():
            hull = shapely.convex_hull(shapely.multipoints(corners, indices=ids))
            polys[bad] = hull[bad]
        polys = polys[(shapely.get_type_id(polys) == 3) & (shapely.area(polys) > 0.0)]
        return list(polys)
    from shapely.geometry import MultiPoint, Polygon  # pragma: no cover - shapely 1.8

    out = []  # pragma: no cover
    for c in np.split(corners, cuts):  # pragma: no cover
        p = Polygon(c.tolist())
        if not p.is_valid:
            p = MultiPoint(c.tolist()).convex_hull
        if p.geom_type == "Polygon" and p.area > 0.0:
            out.append(p)
    return out  # pragma: no cover


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
    if len(corners) == 0:
        return empty_area()
    polygons = _polygons(corners, owner)
    if not polygons:
        return empty_area()
    union = to_multipolygon(polygons[0] if len(polygons) == 1 else unary_union(polygons))
    holes = [(k, h) for k, p in enumerate(union.geoms) for h in range(len(p.interiors))]
    if not holes:
        return union
    from shapely.geometry import Polygon

    parts = [Polygon(union.geoms[k].interiors[h]) for k, h in holes]
    reps = np.array([p.representative_point().coords[0] for p in parts], dtype=float)
    inside = point_distances(np.c_[reps, np.full(len(reps), float(z))], tri[near]) <= depth
    if not inside.any():
        return union
    return to_multipolygon(unary_union([union, *[p for p, fill in zip(parts, inside) if fill]]))


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
