"""Triangle meshes as density regions: STL reading and slicing at a height.

``slice_mesh(triangles, z)`` cuts a closed triangle mesh with the plane at
height z and returns the cross-section as polygons (even-odd nesting, so
hollow parts keep their holes).  Fully vectorized over triangles.
"""

from __future__ import annotations

import os
import re

import numpy as np
from shapely.geometry import LineString
from shapely.ops import polygonize

from .geometry import empty_area, polygons_of, to_multipolygon, unary_union

__all__ = ["read_stl", "slice_mesh", "mesh_bounds"]

_BINARY_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
_ASCII_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


def read_stl(path: str | os.PathLike) -> np.ndarray:
    """Read a binary or ASCII STL file.

    Returns
    -------
    ndarray, shape (n, 3, 3), float64
        Triangle vertices, file units (mm).

    Raises
    ------
    ValueError
        The file is not a complete STL, or has no triangles.
    """
    name = os.fspath(path)
    with open(path, "rb") as f:
        data = f.read()
    if len(data) >= 84:
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) == 84 + count * _BINARY_RECORD.itemsize and count > 0:
            rec = np.frombuffer(data, dtype=_BINARY_RECORD, count=count, offset=84)
            tris = rec["vertices"].astype(np.float64)
            if not np.isfinite(tris).all():
                raise ValueError(f"{name}: STL has NaN or infinite coordinates")
            return tris
    head = data[:1024].lstrip().lower()
    if head.startswith(b"solid") and b"facet" in data[:4096].lower() or head.startswith(b"solid") and b"endsolid" in data:
        values = _ASCII_VERTEX.findall(data)
        if not values or len(values) % 3:
            raise ValueError(f"{name}: ASCII STL without complete triangles")
        try:
            tris = np.array(values, dtype=np.float64).reshape(-1, 3, 3)
        except ValueError as exc:
            raise ValueError(f"{name}: ASCII STL has a malformed vertex line") from exc
        if not np.isfinite(tris).all():
            raise ValueError(f"{name}: STL has NaN or infinite coordinates")
        return tris
    raise ValueError(f"{name}: not an STL file (neither a complete binary STL nor ASCII 'solid ... facet')")


def mesh_bounds(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of the mesh, each shape (3,)."""
    pts = np.asarray(triangles, dtype=float).reshape(-1, 3)
    return pts.min(axis=0), pts.max(axis=0)


def slice_segments(triangles: np.ndarray, z: float) -> np.ndarray:
    """Where the plane at height `z` cuts the mesh.

    Vertices exactly at `z` count as above it, so every crossing triangle
    gives one segment, and triangles sharing an edge give bit-identical
    endpoints (each edge is interpolated from its lexicographically smaller
    vertex).

    Returns
    -------
    ndarray, shape (k, 2, 2)
        Segment endpoints (x, y), mm.
    """
    tri = np.asarray(triangles, dtype=float)
    if tri.ndim != 3 or tri.shape[1:] != (3, 3):
        raise ValueError(f"triangles must have shape (n, 3, 3), got {tri.shape}")
    above = tri[:, :, 2] >= z
    n_above = above.sum(axis=1)
    cross = (n_above == 1) | (n_above == 2)
    tri = tri[cross]
    above = above[cross]
    if len(tri) == 0:
        return np.zeros((0, 2, 2))
    # The lonely vertex is the one alone on its side of the plane.
    lonely_is_above = above.sum(axis=1) == 1
    lonely = np.where(lonely_is_above, np.argmax(above, axis=1), np.argmin(above, axis=1))
    rows = np.arange(len(tri))
    a = tri[rows, lonely]
    b = tri[rows, (lonely + 1) % 3]
    c = tri[rows, (lonely + 2) % 3]

    def cut(p, q):
        # Canonical edge direction: the same edge in two triangles gives the same float result.
        swap = (p[:, 0] > q[:, 0]) | ((p[:, 0] == q[:, 0]) & ((p[:, 1] > q[:, 1]) | ((p[:, 1] == q[:, 1]) & (p[:, 2] > q[:, 2]))))
        lo = np.where(swap[:, None], q, p)
        hi = np.where(swap[:, None], p, q)
        t = (z - lo[:, 2]) / (hi[:, 2] - lo[:, 2])
        return lo[:, :2] + t[:, None] * (hi[:, :2] - lo[:, :2])

    return np.stack([cut(a, b), cut(a, c)], axis=1)


def _parity_inside(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Even-odd test of points against an unordered set of boundary segments."""
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    px, py = points[:, 0:1], points[:, 1:2]
    ax, ay = segments[None, :, 0, 0], segments[None, :, 0, 1]
    bx, by = segments[None, :, 1, 0], segments[None, :, 1, 1]
    straddle = (ay > py) != (by > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = ax + (py - ay) * (bx - ax) / (by - ay)
    hits = straddle & (px < x_cross)
    return (hits.sum(axis=1) % 2) == 1


_COLLINEAR_MM = 1e-7  # a vertex this close to the line through its neighbours is dropped


def slice_mesh(triangles: np.ndarray, z: float, *, min_area: float = 1e-6):
    """Cross-section of a closed triangle mesh at height `z`.

    Parameters
    ----------
    triangles : ndarray, shape (n, 3, 3)
        mm, the coordinates the result should be in (G-code coordinates for the pipeline).
    z : float
        mm.

    Returns
    -------
    shapely MultiPolygon
        Possibly empty; holes where the section nests (even-odd).
    """
    segs = slice_segments(triangles, z)
    keep = np.hypot(*(segs[:, 1] - segs[:, 0]).T) > 1e-9 if len(segs) else np.zeros(0, dtype=bool)
    segs = segs[keep]
    if len(segs) < 3:
        return empty_area()
    faces = list(polygonize([LineString(s) for s in segs]))
    if not faces:
        # Not watertight: fall back to polygonizing the noded linework.
        faces = list(polygonize(unary_union([LineString(s) for s in segs])))
    faces = [f for f in faces if f.area > min_area]
    if not faces:
        return empty_area()
    reps = np.array([f.representative_point().coords[0] for f in faces])
    inside = _parity_inside(reps, segs)
    kept = [f for f, ok in zip(faces, inside, strict=True) if ok]
    if not kept:
        return empty_area()
    # Collinear vertices (where a flat side's triangles meet the plane) go: a prism's sections are
    # then the same polygon at every height, so layers that repeat are seen to repeat.
    return to_multipolygon(unary_union(kept).simplify(_COLLINEAR_MM))


def polygons_at(triangles: np.ndarray, z: float) -> list:
    """The section at `z` as a list of Polygons."""
    return polygons_of(slice_mesh(triangles, z))
