"""Infill patterns: built once per footprint and density map, clipped per layer.

`InfillPattern.build` samples, triangulates and calibrates a pattern over a
footprint (an area that covers every layer it will serve).  `clip` cuts it
to one layer's infill area and routes it.  Layers clipped from the same
pattern print the same edges, so infill walls stack layer on layer.

`build` checks its inputs and hands them to the layout's own module
(`seamless_layout`, `paper_layout`).  Both re-sample with corrected radii
while that brings the zones closer to their targets; what the radius alone
cannot reach is calibrated on the best sampling (`calibration`: scaling one
zone, balancing several, the paper layout's choice of samplings).  The zones
are measured with the meters of `metering`.

Layouts
-------
``seamless`` (default)
    One variable-radius Poisson-disk sampling of the footprint grown by the
    largest radius, one Delaunay triangulation, edges clipped to the layer:
    no doubled lines along region borders, the density changes within about
    2 r of a border, and lines end cleanly at the infill boundary.  Where
    the density is uniform the samples are a triangular lattice (sampler
    ``lattice``, the default): its Delaunay triangles are equilateral, as
    stiff per gram as a line network gets and the same in every direction;
    Poisson-disk samples fill the bands between zones.  A zone's band along
    a denser zone (one of its own lattice sides wide) prints the zone's own
    density: the build tries other samplings of those Poisson-disk samples
    until it does (`calibration.settled_bands`), so the change lies on the denser side.
``paper``
    The paper's pipeline: every density zone is decomposed into convex parts,
    each sampled and triangulated on its own (Bridson sampling by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .density import DensityMap, check_line_width
from .geometry import as_area, contains_xy, to_multipolygon
from .metering import measured_density, segment_length
from .paper_layout import build_paper
from .routing import chain_segments, clip_segments, odd_vertex_count, order_paths
from .seamless_layout import build_seamless
from .triangulation import edge_length_stats, lop_violations, triangle_angles, unique_edges

# (`segment_length` and `measured_density` live in `metering`; they stay importable from here.)
__all__ = ["InfillPattern", "InfillResult", "generate_infill", "segment_length"]

LAYOUTS = ("seamless", "paper")
CALIBRATIONS = ("measured", "paper")


@dataclass
class InfillResult:
    """Infill for one area.

    Attributes
    ----------
    paths : list of ndarray, each (m, 2)
        Polylines in print order, mm.
    segments : ndarray, shape (k, 2, 2)
        The same lines as segments.
    travel_mm : float
        Straight travel between consecutive paths (from the start point and to the end point when given).
    area : MultiPolygon
        The area the infill fills.
    line_width : float
    density_map : DensityMap
    """

    paths: list
    segments: np.ndarray
    travel_mm: float
    area: object
    line_width: float
    density_map: DensityMap
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def extrude_mm(self) -> float:
        """Total extruded path length, mm."""
        return segment_length(self.segments)

    @property
    def density(self) -> float:
        """Measured fill fraction: path length x line width / area."""
        return self.extrude_mm * self.line_width / self.area.area if self.area.area > 0 else float("nan")

    @property
    def region_densities(self) -> list[float]:
        """Measured density per zone: index 0 the base area, then each region (NaN: no area)."""
        if "zones" not in self._cache:
            zones = self.density_map.zones(self.area)
            self._cache["zones"] = [measured_density(self.segments, z, self.line_width) for z in zones]
        return self._cache["zones"]

    @property
    def odd_vertices(self) -> int:
        """Vertices of odd degree; half of them is the lower bound on the path count."""
        return odd_vertex_count(self.segments)


@dataclass
class InfillPattern:
    """A Delaunay infill pattern over a footprint, reusable for every layer inside it.

    Build it with `InfillPattern.build`; call `clip` per layer.

    Attributes
    ----------
    segments : ndarray, shape (k, 2, 2)
        Every triangle edge of the pattern, mm.
    points : ndarray, shape (n, 2)
        The samples.
    triangles : ndarray of int, shape (t, 3)
        Triangles kept (hull slivers dropped).
    footprint : MultiPolygon
    density_map : DensityMap
        Target densities.
    line_width : float
    layout, calibration : str
    calibrated_densities : list of float
        Measured density per zone after calibration: each zone whole, the
        bands along other zones included, inside the infill area (`build`'s
        `infill_area`); with a feather, the zone cores (`metering.zone_interiors`).
    """

    segments: np.ndarray
    points: np.ndarray
    triangles: np.ndarray
    footprint: object
    density_map: DensityMap
    line_width: float
    layout: str
    calibration: str
    calibrated_densities: list
    iterations: int = 1

    # ------------------------------------------------------------------ build
    @classmethod
    def build(
        cls,
        footprint,
        density: float,
        line_width: float,
        *,
        regions=(),
        seed: int = 0,
        layout: str = "seamless",
        calibration: str = "measured",
        relax: int = 0,
        feather: float = 0.0,
        sampler: str | None = None,
        infill_area=None,
    ) -> InfillPattern:
        """Sample, triangulate and calibrate a pattern for `footprint`.

        Parameters
        ----------
        footprint : shapely (Multi)Polygon
            Covers every area the pattern will be clipped to.
        density : float
            Base density, a fraction in (0, 1].
        line_width : float
            Infill line width, mm.
        regions : sequence of (Polygon, float)
            Regions with their own density; later ones win.
        seed : int
        layout : {"seamless", "paper"}
        calibration : {"measured", "paper"}
            ``measured``: one zone is sampled at the radius of
            ``KAPPA * line_width / density`` (Newton steps if far off), then
            the pattern is scaled to within about 0.04 points of the target;
            several zones are re-sampled until each (whole, its border bands
            included) is within 0.3 points of its target or two
            samplings bring nothing better, then the zones still off by more
            than 0.15 points are balanced by single edges;
            ``paper``: Formula (6).
        relax : int
            Lloyd relaxation steps (more regular triangles); with the
            ``lattice`` sampler only the samples between lattices move.
        feather : float
            Blend width across region borders, mm (seamless layout).
        sampler : {"lattice", "fast", "bridson"}, optional
            Default: ``lattice`` for seamless (``fast`` with a feather),
            ``bridson`` for paper.  ``lattice``: where the
            density is uniform the samples are a triangular lattice
            (equilateral triangles: the stiffest line network per density,
            the same in every direction), Poisson-disk samples elsewhere;
            ``fast``: Poisson-disk samples everywhere.
        infill_area : shapely (Multi)Polygon, optional
            Where the lines will be printed (a layer's infill area, inside the
            footprint; the G-code pass builds on it grown by a line width, and
            over a growing mesh's whole extent): calibration measures the lines
            there, each zone whole, the paper layout each convex part against
            its part of it.  Default: the footprint.

        Raises
        ------
        ValueError
            Bad region, density, line width, layout or calibration.
        """
        area = as_area(footprint, what="footprint")
        width = check_line_width(line_width)
        dmap = DensityMap.create(density, regions, feather, footprint=area)
        if layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
        if calibration not in CALIBRATIONS:
            raise ValueError(f"calibration must be one of {CALIBRATIONS}, got {calibration!r}")
        relax = int(relax)
        if relax < 0:
            raise ValueError(f"relax steps must be >= 0, got {relax}")
        sampler = sampler or ("bridson" if layout == "paper" else "lattice")
        printed = area if infill_area is None else to_multipolygon(as_area(infill_area, what="infill area").intersection(area))
        printed = printed if printed.area > 0 else area
        if layout == "seamless":
            done = build_seamless(area, dmap, width, int(seed), calibration, relax, sampler, printed)
            return cls(done.segments, done.points, done.triangles, area, dmap, width, layout, calibration,
                       list(done.measured), done.iteration)
        segments, points, triangles, measured = build_paper(area, dmap, width, int(seed), calibration, relax,
                                                            sampler, printed)
        return cls(segments, points, triangles, area, dmap, width, layout, calibration, measured)

    # ------------------------------------------------------------------ use
    def clip(self, area, *, start=None, end=None) -> InfillResult:
        """The pattern inside one area, chained and ordered.

        Parameters
        ----------
        area : shapely (Multi)Polygon
            A layer's infill area (inside the footprint).
        start : (x, y), optional
            Nozzle position before the infill; the first path starts near it.
        end : (x, y), optional
            Where the nozzle goes after the infill (the next feature's start); the route ends near it.

        Returns
        -------
        InfillResult
        """
        area = as_area(area, what="infill area")
        segments = clip_segments(self.segments, area)
        paths, travel = order_paths(chain_segments(segments), start, end=end)
        return InfillResult(paths, segments, travel, area, self.line_width, self.density_map)

    def quality(self) -> dict:
        """Triangle quality inside the footprint.

        Returns
        -------
        dict
            ``lop_violations`` (the paper's criterion, expected 0),
            ``min_angle_deg`` (smallest angle), ``mean_min_angle_deg`` (mean of
            each triangle's smallest angle), ``sharp_triangle_share``
            (triangles with an angle under 40 degrees), ``short_edge_share``
            (edges shorter than half the mean) and ``mean_edge_mm``, over the
            triangles whose centroid is in the footprint (clipped stubs at the
            boundary excluded).
        """
        tri = self.triangles
        centroid = self.points[tri].mean(axis=1) if len(tri) else np.zeros((0, 2))
        inside = tri[contains_xy(self.footprint, centroid[:, 0], centroid[:, 1])] if len(tri) else tri
        stats = edge_length_stats(self.points[unique_edges(inside)])
        smallest = triangle_angles(self.points, inside).min(axis=1) if len(inside) else np.full(1, np.nan)
        return {
            "lop_violations": lop_violations(self.points, tri),
            "min_angle_deg": float(smallest.min()),
            "mean_min_angle_deg": float(smallest.mean()),
            "sharp_triangle_share": float(np.mean(smallest < 40.0)),
            "short_edge_share": stats["short_share"],
            "mean_edge_mm": stats["mean_mm"],
        }


def generate_infill(
    region,
    density: float,
    line_width: float,
    *,
    regions=(),
    seed: int = 0,
    layout: str = "seamless",
    calibration: str = "measured",
    relax: int = 0,
    feather: float = 0.0,
    sampler: str | None = None,
    start=None,
) -> InfillResult:
    """Delaunay infill for one region.

    Parameters
    ----------
    region : shapely Polygon or MultiPolygon
        The infill area, mm; holes allowed.
    density : float
        Target fill fraction in (0, 1].
    line_width : float
        mm.
    regions : sequence of (Polygon, float)
        Override the base density where they lie; later ones win.
    seed, layout, calibration, relax, feather, sampler
        See `InfillPattern.build`.
    start : (x, y), optional
        Nozzle position; the first path starts near it.

    Returns
    -------
    InfillResult
        ``.paths`` in print order, ``.segments``, ``.density`` (measured),
        ``.region_densities`` (index 0 base area, then one per region).
    """
    pattern = InfillPattern.build(
        region,
        density,
        line_width,
        regions=regions,
        seed=seed,
        layout=layout,
        calibration=calibration,
        relax=relax,
        feather=feather,
        sampler=sampler,
    )
    return pattern.clip(pattern.footprint, start=start)
