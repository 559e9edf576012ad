"""Shapely 1.8 / 2.x compatibility and small geometry helpers.

The engine runs on whatever shapely the host Cura bundles: 1.8.x (Cura 4.13 on
Debian, Cura 5.1-5.4) or 2.0.x (Cura 5.5 and later).  Everything version
specific lives here; the rest of the engine calls these functions only.
shapely 2's vectorized functions are used when present.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import (
    GeometryCollection,
    LineString,
    MultiLineString,
    MultiPoint,
    MultiPolygon,
    Point,
    Polygon,
    box,
)
from shapely.geometry.base import BaseGeometry
from shapely.ops import polygonize, unary_union
from shapely.validation import make_valid

SHAPELY2 = int(shapely.__version__.split(".")[0]) >= 2

if not SHAPELY2:  # pragma: no cover - exercised on the shapely 1.8 CI leg
    from shapely import vectorized as _vectorized

__all__ = [
    "SHAPELY2",
    "as_area",
    "boxes_meet",
    "cell_centres",
    "contains_xy",
    "covers_segments",
    "distances",
    "empty_area",
    "points_of",
    "polygons_from",
    "polygons_of",
    "rings_of",
    "to_multipolygon",
    "unary_union",
    "box",
    "convex_hull_of",
    "covers",
    "multilinestring_of",
    "points_on_surface",
    "polygonize_segments",
]


def contains_xy(geometry: BaseGeometry, x, y) -> np.ndarray:
    """Vectorized point-in-area test.

    Parameters
    ----------
    geometry : shapely geometry
        A (Multi)Polygon.
    x, y : array_like, shape (n,)
        Coordinates in mm.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the point lies in the interior of `geometry`.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size == 0 or geometry.is_empty:
        return np.zeros(x.shape, dtype=bool)
    if SHAPELY2:
        return np.asarray(shapely.contains_xy(geometry, x, y), dtype=bool)
    return np.asarray(_vectorized.contains(geometry, x, y), dtype=bool)  # pragma: no cover


def distances(geometries, other: BaseGeometry) -> np.ndarray:
    """Distance (mm) from each geometry to `other`, shape (n,) (vectorized on shapely 2)."""
    if len(geometries) == 0:
        return np.zeros(0)
    if SHAPELY2:
        return np.asarray(shapely.distance(np.asarray(geometries, dtype=object), other), dtype=float)
    return np.array([g.distance(other) for g in geometries], dtype=float)  # pragma: no cover


def points_of(xy) -> list[Point]:
    """Point geometries of coordinates, shape (k, 2) mm (vectorized on shapely 2)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if SHAPELY2:
        return list(shapely.points(xy))
    return [Point(p) for p in xy.tolist()]  # pragma: no cover


def polygons_from(rings) -> list[Polygon]:
    """Polygons without holes from rings of as many corners, shape (k, m, 2) mm (vectorized on shapely 2)."""
    rings = np.asarray(rings, dtype=float)
    if len(rings) == 0:
        return []
    if SHAPELY2:
        return list(shapely.polygons(rings))
    return [Polygon(r) for r in rings.tolist()]  # pragma: no cover


def polygons_of(geometry: BaseGeometry | None) -> list[Polygon]:
    """The non-empty polygons of any geometry (collections flattened)."""
    if geometry is None or geometry.is_empty:
        return []
    if isinstance(geometry, Polygon):
        return [geometry]
    if isinstance(geometry, (MultiPolygon, GeometryCollection)):
        out: list[Polygon] = []
        for part in geometry.geoms:
            out.extend(polygons_of(part))
        return out
    return []


def to_multipolygon(geometry: BaseGeometry | None) -> MultiPolygon:
    """The polygonal part of `geometry` as a MultiPolygon (possibly empty).

    A MultiPolygon of non-empty parts comes back as it is (geometries are immutable; building a
    copy of a detailed area costs more than the step that made it).
    """
    if isinstance(geometry, MultiPolygon) and not geometry.is_empty:
        if SHAPELY2:
            if not shapely.is_empty(shapely.get_parts(geometry)).any():
                return geometry
        elif not any(part.is_empty for part in geometry.geoms):  # pragma: no cover - shapely 1.8
            return geometry
    return MultiPolygon(polygons_of(geometry))


def boxes_meet(a: tuple, b: tuple) -> bool:
    """Whether two bounding boxes (minx, miny, maxx, maxy) overlap or touch."""
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def cell_centres(bounds, step: float) -> np.ndarray:
    """Centres of the square cells of side `step` (mm) that tile the rectangle `bounds` (x0, y0, x1, y1) from its
    lower left corner, x fastest, shape (n, 2) mm; n = 0 where the rectangle is under half a step across."""
    x0, y0, x1, y1 = bounds
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    return np.column_stack((gx.ravel(), gy.ravel()))


def empty_area() -> MultiPolygon:
    """An empty MultiPolygon."""
    return MultiPolygon()


def as_area(region, *, what: str = "region") -> MultiPolygon:
    """Validate a user-supplied region and return it as a valid MultiPolygon.

    Self-intersecting input is repaired with ``make_valid``; only the
    polygonal part is kept.

    Raises
    ------
    ValueError
        If `region` is not polygonal, has NaN/inf coordinates, or has no area.
    """
    if not isinstance(region, BaseGeometry):
        raise ValueError(f"{what} must be a shapely Polygon or MultiPolygon, got {type(region).__name__}")
    if region.is_empty:
        raise ValueError(f"{what} is empty")
    if not isinstance(region, (Polygon, MultiPolygon, GeometryCollection)):
        raise ValueError(f"{what} must be a Polygon or MultiPolygon, got {region.geom_type}")
    coords = np.concatenate([r for p in polygons_of(region) for r in rings_of(p)] or [np.zeros((0, 2))])
    if coords.size and not np.isfinite(coords).all():
        raise ValueError(f"{what} has NaN or infinite coordinates")
    if not region.is_valid:
        region = make_valid(region)
    area = to_multipolygon(region)
    if area.is_empty or not (area.area > 1e-9):
        raise ValueError(f"{what} has no area (degenerate polygon)")
    return area


def rings_of(polygon: Polygon) -> list[np.ndarray]:
    """Exterior and interior rings of a polygon as (m, 2) arrays (closed)."""
    rings = [np.asarray(polygon.exterior.coords, dtype=float)[:, :2]]
    rings.extend(np.asarray(r.coords, dtype=float)[:, :2] for r in polygon.interiors)
    return rings


def boundary_segments(area: BaseGeometry) -> np.ndarray:
    """All boundary edges of a (Multi)Polygon.

    Returns
    -------
    ndarray, shape (k, 2, 2)
        Segment start and end points in mm.
    """
    polygons = polygons_of(area)
    if SHAPELY2:
        if not polygons:
            return np.zeros((0, 2, 2))
        # every ring's corners at once (exterior first, then the holes, polygon by polygon), each
        # corner to the next of the same ring
        xy, ring = shapely.get_coordinates(shapely.get_rings(np.array(polygons, dtype=object)), return_index=True)
        same = ring[1:] == ring[:-1]
        return np.stack([xy[:-1][same], xy[1:][same]], axis=1)
    segs = []  # pragma: no cover - shapely 1.8
    for polygon in polygons:
        for ring in rings_of(polygon):
            if len(ring) >= 2:
                segs.append(np.stack([ring[:-1], ring[1:]], axis=1))
    if not segs:
        return np.zeros((0, 2, 2))
    return np.concatenate(segs)


def linestrings(paths) -> list[LineString]:
    """LineStrings from a sequence of (m, 2) arrays (vectorized on shapely 2)."""
    if SHAPELY2:
        return list(shapely.linestrings([np.asarray(p, dtype=float) for p in paths])) if len(paths) else []
    return [LineString(p) for p in paths]  # pragma: no cover


def polygon_area_signed(ring: np.ndarray) -> float:
    """Signed area of a closed or open ring (shoelace); positive when CCW."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def regular_polygon(center, radius: float, sides: int, start_angle: float = math.pi / 2) -> Polygon:
    """A regular polygon (used for round density regions and test shapes)."""
    a = start_angle + np.arange(sides) * 2 * math.pi / sides
    return Polygon(np.c_[center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)])


def multilinestring_of(paths) -> MultiLineString:
    """One MultiLineString of polylines, each an (m, 2) array, m >= 2, mm (vectorized on shapely 2)."""
    if SHAPELY2:
        coords = np.concatenate([np.asarray(p, dtype=float) for p in paths])
        part = np.repeat(np.arange(len(paths)), [len(p) for p in paths])
        return shapely.multilinestrings(shapely.linestrings(coords, indices=part))
    return MultiLineString([LineString(p) for p in paths])  # pragma: no cover


def polygonize_segments(segments) -> list[Polygon]:
    """The faces enclosed by segments that meet only at their ends, shape (k, 2, 2) mm (vectorized on shapely 2).

    Every bounded face comes back, a hole's face too (as its own polygon).
    """
    segments = np.asarray(segments, dtype=float)
    if len(segments) == 0:
        return []
    if SHAPELY2:
        return list(shapely.get_parts(shapely.polygonize(shapely.linestrings(segments))))
    return list(polygonize([LineString(s) for s in segments.tolist()]))  # pragma: no cover


def points_on_surface(polygons) -> np.ndarray:
    """A point inside each polygon, shape (n, 2) mm (vectorized on shapely 2)."""
    if len(polygons) == 0:
        return np.zeros((0, 2))
    if SHAPELY2:
        return shapely.get_coordinates(shapely.point_on_surface(np.asarray(polygons, dtype=object)))
    return np.array([p.representative_point().coords[0] for p in polygons], dtype=float)  # pragma: no cover


def convex_hull_of(points) -> BaseGeometry:
    """Convex hull of points, shape (n, 2) mm: a Polygon (a LineString or Point when degenerate)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if SHAPELY2:
        return shapely.multipoints(points).convex_hull
    return MultiPoint(points.tolist()).convex_hull  # pragma: no cover


def covers(container: BaseGeometry, geometry: BaseGeometry) -> bool:
    """Whether `container` covers `geometry` (no point of it outside), `container` prepared on shapely 2.

    A predicate: far cheaper than the overlay ``geometry.difference(container)`` that says the same,
    and the container (a pattern's footprint) is asked again layer after layer.
    """
    if SHAPELY2:
        shapely.prepare(container)  # (in place, once)
    return bool(container.covers(geometry))


def covers_segments(area, segments: np.ndarray) -> np.ndarray | None:
    """Whether `area` covers each straight segment (no point of it outside), or None on shapely 1.8.

    Parameters
    ----------
    area : (Multi)Polygon
    segments : ndarray, shape (k, 2, 2)
        Start and end points, mm; none of zero length.

    Returns
    -------
    ndarray of bool, shape (k,), or None
        None where shapely has no vectorized predicates (1.8): the caller clips instead.
    """
    if not SHAPELY2:  # pragma: no cover - exercised on the shapely 1.8 CI leg
        return None
    if len(segments) == 0:
        return np.zeros(0, dtype=bool)
    shapely.prepare(area)  # (in place, once: the same part is asked again and again)
    return np.asarray(shapely.covers(area, shapely.linestrings(np.asarray(segments, dtype=float))), dtype=bool)
