"""Density maps and density calibration.

A density map is a base density plus regions ``(polygon, density)`` that
override it where they lie (later regions win), optionally blended across a
border of `feather` mm.  The sampler needs a radius field; for a maximal
Poisson-disk set triangulated by Delaunay the printed density is close to
``KAPPA * line_width / r`` (edge length per area times line width), so the
first guess is ``r = KAPPA * w / density`` and measured calibration corrects
it per zone until the printed density matches the target.

The paper's calibration is its Formula (6), rho = 2 / r at a 1.2 mm line
width; scaled for the line width that is ``r = 2 * (w / 1.2) / rho``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .geometry import as_area, boundary_segments, contains_xy, to_multipolygon, unary_union

__all__ = ["DensityMap", "KAPPA", "paper_radius", "check_density", "check_line_width"]

KAPPA = 2.70  # printed density * r / w for maximal Poisson-disk Delaunay edges (measured)


def check_density(value, what: str = "density") -> float:
    """Validate a density fraction in (0, 1]; returns it as float."""
    try:
        d = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number in (0, 1], got {value!r}") from None
    if not (math.isfinite(d) and 0.0 < d <= 1.0):
        raise ValueError(f"{what} must be a fraction in (0, 1] (e.g. 0.2 for 20 %), got {value!r}")
    return d


def check_line_width(value) -> float:
    """Validate a line width in mm (> 0, finite)."""
    try:
        w = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"line width must be a number in mm, got {value!r}") from None
    if not (math.isfinite(w) and w > 0):
        raise ValueError(f"line width must be > 0 mm, got {value!r}")
    return w


def paper_radius(density: np.ndarray | float, line_width: float) -> np.ndarray | float:
    """Poisson-disk radius from the paper's Formula (6), scaled for the line width (mm)."""
    return 2.0 * (line_width / 1.2) / density


@dataclass(frozen=True)
class DensityMap:
    """Base density plus overriding regions.

    Parameters
    ----------
    base : float
        Density fraction in (0, 1] outside every region.
    regions : tuple of (Polygon, float)
        Later regions win where they overlap.
    feather : float
        Width (mm) over which the density blends across a region border;
        0 for a sharp border.
    """

    base: float
    regions: tuple = ()
    feather: float = 0.0
    footprint: object = None
    _trees: list = field(default_factory=list, compare=False, repr=False)

    @classmethod
    def create(cls, base, regions=(), feather: float = 0.0, footprint=None) -> DensityMap:
        """Validated map; regions given as ``(polygon, density)`` pairs.

        `footprint` (optional) limits feathering to borders between zones:
        a region edge on or outside the footprint's boundary does not blend.
        """
        base = check_density(base)
        checked = []
        for k, item in enumerate(regions):
            try:
                poly, dens = item
            except (TypeError, ValueError):
                raise ValueError(f"region {k + 1} must be a (polygon, density) pair") from None
            checked.append((as_area(poly, what=f"region {k + 1}"), check_density(dens, f"region {k + 1} density")))
        feather = float(feather)
        if not (math.isfinite(feather) and feather >= 0):
            raise ValueError(f"feather width must be >= 0 mm, got {feather!r}")
        return cls(base, tuple(checked), feather, footprint)

    def with_densities(self, densities) -> DensityMap:
        """The same geometry with new densities (index 0 base, then regions)."""
        regions = tuple((poly, float(d)) for (poly, _), d in zip(self.regions, densities[1:]))
        return DensityMap(float(densities[0]), regions, self.feather, self.footprint, self._trees)

    @property
    def densities(self) -> list[float]:
        """Index 0 the base density, then one per region."""
        return [self.base] + [d for _, d in self.regions]

    def zones(self, area) -> list:
        """Where each density applies inside `area`.

        Returns
        -------
        list of MultiPolygon
            Index 0 the base zone, then the visible part of each region
            (minus later regions), all clipped to `area`.
        """
        polys = [poly for poly, _ in self.regions]
        boxes = np.array([poly.bounds for poly in polys], dtype=float).reshape(-1, 4)
        out = []
        for k, poly in enumerate(polys):
            part = poly if area.covers(poly) else poly.intersection(area)
            # Only later regions whose inside meets this one's take anything from it (regions
            # that merely touch, as modifier meshes split along a border do, take nothing).
            x0, y0, x1, y1 = boxes[k]
            later = [polys[j] for j in range(k + 1, len(polys))
                     if boxes[j, 0] <= x1 and boxes[j, 2] >= x0 and boxes[j, 1] <= y1 and boxes[j, 3] >= y0
                     and poly.relate_pattern(polys[j], "T********")]
            if later:
                part = part.difference(later[0] if len(later) == 1 else unary_union(later))
            out.append(to_multipolygon(part))
        base = area.difference(unary_union(polys)) if polys else area
        return [to_multipolygon(base), *out]

    def _weights(self, k: int, xy: np.ndarray) -> np.ndarray:
        poly = self.regions[k][0]
        inside = contains_xy(poly, xy[:, 0], xy[:, 1])
        if self.feather <= 0:
            return inside.astype(float)
        while len(self._trees) <= k:  # boundary samples for distances, spacing feather / 8
            edges = boundary_segments(self.regions[len(self._trees)][0])
            step = self.feather / 8.0
            length = np.hypot(*(edges[:, 1] - edges[:, 0]).T)
            n = np.maximum(1, np.ceil(length / step)).astype(int)
            seg = np.repeat(np.arange(len(edges)), n)
            t = (np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)) / n[seg]
            pts = edges[seg, 0] + (edges[seg, 1] - edges[seg, 0]) * t[:, None]
            if self.footprint is not None:  # only borders between zones blend
                inner = self.footprint.buffer(-0.5 * step)
                pts = pts[contains_xy(inner, pts[:, 0], pts[:, 1])]
            self._trees.append(cKDTree(pts) if len(pts) else None)
        if self._trees[k] is None:
            return inside.astype(float)
        d, _ = self._trees[k].query(xy, k=1)
        signed = np.where(inside, d, -d)
        return np.clip(0.5 + signed / self.feather, 0.0, 1.0)

    def labels(self, xy: np.ndarray) -> np.ndarray:
        """Whose density holds at each point, sharp borders: 0 the base, k region k (later regions win).

        Parameters
        ----------
        xy : ndarray, shape (m, 2)

        Returns
        -------
        ndarray of int, shape (m,)
            Indices into `densities`.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        x, y = xy[:, 0], xy[:, 1]
        out = np.zeros(len(xy), dtype=np.intp)
        free = np.ones(len(xy), dtype=bool)
        # Last region first: a point it holds is not tested against earlier ones (they lose there).
        # Only points inside a region's bounding box are tested (the rest cannot be inside).
        for k in range(len(self.regions), 0, -1):
            poly = self.regions[k - 1][0]
            x0, y0, x1, y1 = poly.bounds
            near = (free & (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).nonzero()[0]
            hit = near[contains_xy(poly, x[near], y[near])]
            out[hit] = k
            free[hit] = False
        return out

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Density at points.

        Parameters
        ----------
        xy : ndarray, shape (m, 2)

        Returns
        -------
        ndarray, shape (m,)
            Density fraction at each point.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self.feather <= 0:
            return np.asarray(self.densities, dtype=float)[self.labels(xy)]
        rho = np.full(len(xy), self.base)
        for k, (_, dens) in enumerate(self.regions):
            w = self._weights(k, xy)
            rho = rho * (1.0 - w) + dens * w
        return rho
