"""Test regions used across the core-engine tests (mm)."""

import math

from shapely.geometry import Point, Polygon, box


def star_points(outer=30.0, inner_ratio=0.45, points=5):
    """Outer tips and inner (concave) vertices of the paper's five-point star."""
    tips, inner = [], []
    for i in range(points * 2):
        r = outer if i % 2 == 0 else outer * inner_ratio
        a = math.pi / 2 + i * math.pi / points
        (tips if i % 2 == 0 else inner).append((r * math.cos(a), r * math.sin(a)))
    return tips, inner


def star():
    tips, inner = star_points()
    ring = [p for pair in zip(tips, inner) for p in pair]
    return Polygon(ring)


def star_regions(densities=(0.3, 0.3, 0.2, 0.5, 0.5, 0.1)):
    """Figure 10: five tip triangles and the central pentagon with their densities."""
    tips, inner = star_points()
    triangles = [Polygon([inner[i - 1], tips[i], inner[i]]) for i in range(5)]
    return [(t, d) for t, d in zip(triangles, densities[:5])] + [(Polygon(inner), densities[5])]


def square(size=50.0):
    return box(0, 0, size, size)


def annulus(outer=30.0, inner=12.0):
    return Point(0, 0).buffer(outer, 32).difference(Point(0, 0).buffer(inner, 32))


SHAPES = {"square": square, "star": star, "annulus": annulus}
