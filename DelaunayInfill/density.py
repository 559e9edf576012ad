"""Density maps and the sampling radius of a density.

A density map is a base density plus regions ``(polygon, density)`` that
override it where they lie (later regions win), optionally blended across a
border of `feather` mm.  The sampler needs a radius field; for a maximal
Poisson-disk set triangulated by Delaunay the printed density is close to
``KAPPA * line_width / r`` (edge length per area times line width), so the
first guess is ``r = KAPPA * w / density`` (`sampling_radius`) and measured
calibration corrects it per zone until the printed density matches the
target (the pattern build, with `metering` and `calibration`).

The paper's calibration is its Formula (6), rho = 2 / r at a 1.2 mm line
width; scaled for the line width that is ``r = 2 * (w / 1.2) / rho``.

`DensityMap.raster` labels the zones on a grid of square cells (a scanline
fill, run by run): with several sharp-border zones the pattern build
measures its zones on it (`metering.RasterMeter`) instead of cutting lines
with the zones' polygons.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .geometry import as_area, boundary_segments, contains_xy, to_multipolygon, unary_union

__all__ = ["DensityMap", "KAPPA", "LATTICE_SIDE", "ZoneRaster", "coverage_runs", "paper_radius", "sampling_radius",
           "shortest_edges", "check_density", "check_line_width"]

KAPPA = 2.70  # printed density * r / w for maximal Poisson-disk Delaunay edges (measured)
LATTICE_SIDE = 2.0 * math.sqrt(3.0)  # a triangular lattice of density d has side LATTICE_SIDE * w / d
_BITS = 52  # polygons per coverage raster: one bit each in a float64 cell sum (exact up to 2^53)


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


def sampling_radius(density: np.ndarray | float, line_width: float, calibration: str = "measured") -> np.ndarray | float:
    """Poisson-disk radius (mm) first taken for a density (fraction) at a line width (mm).

    ``measured``: ``KAPPA * line_width / density``; ``paper``: Formula (6) (`paper_radius`).
    """
    return paper_radius(density, line_width) if calibration == "paper" else KAPPA * line_width / density


def shortest_edges(segments: np.ndarray, dmap: DensityMap, width: float) -> np.ndarray:
    """A quarter of the local spacing (the lattice side at the wanted density) per segment (k, 2, 2), mm.

    Across a border the denser side's spacing (the densest of the two ends and the middle).
    """
    if len(segments) == 0:
        return np.zeros(0)
    at = np.concatenate((segments[:, 0], segments[:, 1], segments.mean(axis=1)))
    densest = dmap.at(at).reshape(3, -1).max(axis=0)
    return 0.25 * LATTICE_SIDE * width / densest


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

    def raster(self, area, cell: float) -> ZoneRaster | None:
        """Sharp-border zones of `area` on a grid of square cells (see `zones`).

        Parameters
        ----------
        area : shapely (Multi)Polygon
            The area the zones tile, mm.
        cell : float
            Cell side, mm; a cell takes the zone at its centre.

        Returns
        -------
        ZoneRaster or None
            Label 0 the base zone, k region k (later regions win), -1 outside
            `area`; None with more than `_BITS` - 1 regions.
        """
        if len(self.regions) >= _BITS:
            return None
        grid = ZoneRaster.grid_over(area.bounds, cell)
        # Region k adds 2^(k - 1), `area` the highest bit: inside `area` the sum's highest
        # other bit is the last region covering the cell (frexp(2^(k - 1)) = (0.5, k); 0: none).
        polygons = [poly for poly, _ in self.regions]
        start, covered = coverage_runs([*polygons, area], grid)
        whole = 2.0 ** len(polygons)
        label = np.where(covered >= whole, np.frexp(covered - whole)[1], -1)
        return _runs_to_raster(grid, start, label, len(polygons) + 1)


def _runs_to_raster(grid: ZoneRaster, start: np.ndarray, label: np.ndarray, zones: int) -> ZoneRaster:
    """The grid's cells labelled run by run: `coverage_runs`' run starts (q,), a label per run (q,).

    The cell past each row's end (covered by no polygon) must be labelled -1:
    the zones' cell counts are then taken from the runs.
    """
    ny, nx = grid.labels.shape
    label = label.astype(np.int8)
    run = np.diff(np.append(start, ny * (nx + 1)))
    cells = np.repeat(label, run).reshape(ny, nx + 1)[:, :nx]
    counts = np.bincount(label.astype(np.intp) + 1, run, zones + 1)[1:].astype(np.intp)
    return ZoneRaster(cells, grid.x0, grid.y0, grid.cell, [counts])


@dataclass
class ZoneRaster:
    """Zone labels on a grid of square cells.

    Attributes
    ----------
    labels : ndarray of int, shape (ny, nx)
        Zone index per cell (row j, column i: centre ``(x0 + (i + 0.5) cell, y0 + (j + 0.5) cell)``),
        -1 where no zone.
    x0, y0 : float
        Lower left corner of the grid, mm.
    cell : float
        Cell side, mm.
    """

    labels: np.ndarray
    x0: float
    y0: float
    cell: float
    _counts: list = field(default_factory=list, compare=False, repr=False)  # [cells per label 0, 1, ...]
    _padded: list = field(default_factory=list, compare=False, repr=False)

    @classmethod
    def grid_over(cls, bounds, cell: float) -> ZoneRaster:
        """An empty grid (labels -1) of cells of side `cell` (mm) covering `bounds` (x0, y0, x1, y1)."""
        x0, y0, x1, y1 = bounds
        shape = (max(1, math.ceil((y1 - y0) / cell)), max(1, math.ceil((x1 - x0) / cell)))
        return cls(np.full(shape, -1, dtype=np.int8), float(x0), float(y0), float(cell))

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Label (m,) of the cells holding the points (m, 2) (mm); -1 off the grid."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        ny, nx = self.labels.shape
        if not self._padded:  # a frame of -1 round the grid: points off it are clipped onto the frame
            padded = np.full((ny + 2, nx + 2), -1, dtype=self.labels.dtype)
            padded[1:-1, 1:-1] = self.labels
            self._padded.append(padded.ravel())
        # NaN coordinates: clip keeps NaN, taken as off the grid (index 0, on the frame) below.
        i = np.clip(np.floor((xy[:, 0] - self.x0) / self.cell) + 1, 0, nx + 1)
        j = np.clip(np.floor((xy[:, 1] - self.y0) / self.cell) + 1, 0, ny + 1)
        flat = np.nan_to_num(j * (nx + 2) + i, nan=0.0).astype(np.intp)
        return self._padded[0][flat].astype(np.intp)

    def counts(self, zones: int) -> np.ndarray:
        """Cells per zone label 0 .. zones - 1, shape (zones,)."""
        if not self._counts:
            self._counts.append(np.bincount(self.labels.ravel().astype(np.intp) + 1)[1:])
        counts = self._counts[0][:zones]
        return np.pad(counts, (0, zones - counts.size)) if counts.size < zones else counts


def coverage_runs(polygons, grid: ZoneRaster) -> tuple[np.ndarray, np.ndarray]:
    """Which polygons cover the cell centres of `grid`, run by run: the sum of 2^k over the polygons k.

    Scanline fill: every ring edge is crossed with the rows of cell centres it
    spans; along a row, a polygon's crossings (sorted) pair up into the spans
    inside it.  Each polygon adds its own bit over its spans; the sum changes
    only where a span starts or ends, so it is kept per run of cells (exact
    in float64 for up to `_BITS` polygons).

    Parameters
    ----------
    polygons : sequence of shapely (Multi)Polygon
        mm, holes allowed; at most `_BITS`.
    grid : ZoneRaster
        The cells (its labels are not read), ny rows of nx.

    Returns
    -------
    start : ndarray of int, shape (q,)
        First cell of each run, ascending from 0, as flat indices into the
        rows of nx + 1 cells (each row has one more cell, past its end, that no
        polygon covers: every run that covers ends in its own row).
    covered : ndarray of float, shape (q,)
        The sum over each run.
    """
    if len(polygons) > _BITS:
        raise ValueError(f"at most {_BITS} polygons per coverage, got {len(polygons)}")
    ny, nx = grid.labels.shape
    edges = [boundary_segments(poly) for poly in polygons]
    owner = np.repeat(np.arange(len(polygons)), [len(e) for e in edges])
    if owner.size == 0:
        return np.zeros(1, np.intp), np.zeros(1)
    edges = np.concatenate(edges)
    # In cell units, cell centres at integers.
    xa, xb = ((edges[:, :, 0] - grid.x0) / grid.cell - 0.5).T
    ya, yb = ((edges[:, :, 1] - grid.y0) / grid.cell - 0.5).T
    # Rows whose centre lies in [min y, max y) of the edge (a vertex on a row counts once).
    lo = np.clip(np.ceil(np.minimum(ya, yb)), 0, ny).astype(np.intp)
    hi = np.clip(np.ceil(np.maximum(ya, yb)), 0, ny).astype(np.intp)
    spans = hi - lo
    edge = np.repeat(np.arange(len(edges)), spans)
    row = np.arange(edge.size) - np.repeat(np.cumsum(spans) - spans, spans) + lo[edge]
    t = (row - ya[edge]) / (yb[edge] - ya[edge])  # spans > 0: yb != ya
    column = np.clip(np.ceil(xa[edge] + t * (xb[edge] - xa[edge])), 0, nx).astype(np.intp)
    order = np.lexsort((column, row, owner[edge]))
    key = row[order] * (nx + 1) + column[order]
    bit = np.ldexp(1.0, owner[edge][order][0::2])
    # The sum's steps, in cell order; steps at one cell merge (their sum is exact).
    key = np.concatenate((key[0::2], key[1::2]))
    step = np.concatenate((bit, -bit))
    order = np.argsort(key, kind="stable")
    key, step = key[order], step[order]
    last = np.append(key[1:] != key[:-1], True)
    start = key[last]
    covered = np.cumsum(step)[last]
    if start.size == 0 or start[0] != 0:  # the cells before the first step: covered by none
        start, covered = np.append(0, start), np.append(0.0, covered)
    return start, covered
