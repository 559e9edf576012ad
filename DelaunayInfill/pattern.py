"""Infill patterns: built once per footprint and density map, clipped per layer.

`InfillPattern.build` samples, triangulates and calibrates a pattern over a
footprint (an area that covers every layer it will serve).  `clip` cuts it
to one layer's infill area and routes it.  Layers clipped from the same
pattern print the same edges, so infill walls stack layer on layer.

The build re-samples with corrected radii while that brings the zones closer
to their targets; what the radius alone cannot reach is calibrated on the
best sampling (`calibration`: scaling one zone, balancing several, the paper
layout's choice of samplings).  The zones are measured with the meters of
`metering`.

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

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .calibration import (
    TOLERANCE,
    balance_zones,
    edge_cache,
    fine_tune_scale,
    paper_choices,
    scale_limit,
    settled_bands,
)
from .decomposition import decompose_convex
from .density import DensityMap, check_line_width, sampling_radius
from .geometry import as_area, contains_xy, polygons_of, to_multipolygon
from .metering import measured_density, meter_for, segment_length
from .routing import chain_segments, clip_segments, odd_vertex_count, order_paths
from .sampling import sample_lattice, sample_poisson_disk, sample_triangulated
from .triangulation import (
    GrowingDelaunay,
    delaunay_triangles,
    edge_length_stats,
    growing_delaunay,
    lop_violations,
    relax_points,
    triangle_angles,
    uncrowded_edges,
    unique_edges,
)

# (`segment_length` and `measured_density` live in `metering`; they stay importable from here.)
__all__ = ["InfillPattern", "InfillResult", "generate_infill", "segment_length"]

LAYOUTS = ("seamless", "paper")
CALIBRATIONS = ("measured", "paper")
_PRINTED_TOLERANCE = 0.005  # paper layout calibrated on its clipped lines (`InfillPattern.build`'s infill_area)
_MAX_ITERATIONS = 8
_LOOP_TOLERANCE = 0.003  # several zones: the loop stops within 0.3 points (balancing does the rest)
_SLIVER = 1.5  # hull triangles with a circumradius above 1.5 r are not part of the pattern
_COARSE = 36.0  # several zones: a zone under this many squared radii is only balanced once off target
_LATTICE_SIDE = 2.0 * math.sqrt(3.0)  # triangular lattice of density d: side 2 sqrt(3) w / d


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
            return cls._build_seamless(area, dmap, width, int(seed), calibration, relax, sampler, printed)
        return cls._build_paper(area, dmap, width, int(seed), calibration, relax, sampler, printed)

    @classmethod
    def _build_seamless(cls, area, dmap, width, seed, calibration, relax, sampler, printed):
        if sampler == "lattice" and dmap.feather > 0:
            # A feathered border varies the radius over a band the lattices leave to the Poisson-disk
            # samples (measured there, `fast` keeps the blend closer to the map): `fast` throughout.
            sampler = "fast"
        # Measured where the lines are printed (a lattice a few sides across a small part prints a ring
        # round it that the infill area has not; a mesh's extent holds places it never prints).
        meter = meter_for(printed, dmap, width)
        zone_areas = meter.areas
        targets = np.array(dmap.densities)
        lowest = float(min(targets))
        reach = 1.3 * sampling_radius(lowest, width, calibration)
        # Simplified first: buffering a footprint with many short (rounded) edges by a large
        # reach is slow; the simplified outline is within `tol` of it, so grow by reach + tol.
        tol = 0.05 * reach
        sampling_area = to_multipolygon(area.simplify(tol).buffer(reach + tol, 8))

        def radius_of(d):
            return sampling_radius(d, width, calibration)

        settled = zone_areas > 0
        # Zones under about 4 x 4 of their own radii cannot be calibrated by the
        # radius alone; they are balanced by thinning or refinement at the end.
        # (A single zone is fine-tuned by scaling instead.)
        small = settled & np.array([a < 16.0 * radius_of(t) ** 2 for a, t in zip(zone_areas.tolist(), targets)])
        small &= np.count_nonzero(settled) > 1
        # Zones under about 6 x 6 of their radii hold a few dozen samples: one sampling to the
        # next moves them by several points, so re-sampling for them alone is noise.
        coarse = settled & np.array([a < _COARSE * radius_of(t) ** 2 for a, t in zip(zone_areas.tolist(), targets)])
        # A single zone is calibrated by scaling one sampling (continuous, cheap) as soon as
        # the scale needed is within reach; re-sampling only moves it by jumps of 1-2 points.
        single = calibration == "measured" and np.count_nonzero(settled) == 1
        limit = scale_limit(area, reach)
        growing_wanted = not single and calibration == "measured"

        def attempt(factors, iteration, between_seed=None) -> _Sampling:
            scaled = dmap.with_densities(targets * factors)

            def radius_fn(xy, scaled=scaled):
                return radius_of(scaled.at(xy))

            # Several zones may be balanced afterwards: it goes on from a growing triangulation.
            points, fixed, growing = _sample(sampling_area, radius_fn, seed, sampler, relax,
                                             growing=growing_wanted, between_seed=between_seed)
            triangles, edges = _triangulate(points, growing, radius_fn, dmap, width)
            segments = points[edges]
            inside = meter.inside_all(segments)
            measured = meter.densities_of(inside, width)
            error = np.abs(measured - targets)
            # Small zones above target can be thinned afterwards; shortfalls cannot.
            error = np.where(small & (measured > targets), 0.25 * error, error)
            worst = float(np.nanmax(np.where(settled, error, 0.0))) if len(error) else 0.0
            return _Sampling(worst, points, triangles, segments, measured, iteration, edges, inside, growing,
                             fixed, factors.copy())

        def calibrated(between_seed=None) -> _Sampling:
            """The calibration loop: the best of up to `_MAX_ITERATIONS` samplings at corrected densities."""
            factors = np.ones(len(targets))
            bracket = np.array([0.0, np.inf])  # single zone: factors known to print too sparse / too dense
            best = None
            for iteration in range(1, _MAX_ITERATIONS + 1):
                tried = attempt(factors, iteration, between_seed)
                measured, worst = tried.measured, tried.worst
                if best is None or worst < best.worst:
                    best = tried
                if calibration == "paper" or worst <= (TOLERANCE if single else _LOOP_TOLERANCE):
                    break
                ok = settled & np.isfinite(measured) & (measured > 0)
                step = np.where(ok, targets / np.where(ok, measured, 1.0), 1.0)
                step = np.where(settled & ~ok, 2.0, step)  # a zone with nothing printed: denser
                step = np.clip(step, 0.5, 2.0)
                if single:
                    # density ~ 1 / scale: the scale that hits the target is 1 / step
                    k = int(np.flatnonzero(settled)[0])
                    if ok[k] and abs(1.0 / float(step[k]) - 1.0) <= 0.8 * limit:
                        break
                    # Newton step (density ~ 1 / r), kept inside the bracket of factors printing too
                    # sparse / too dense (coarse patterns print in jumps): else its geometric middle.
                    if measured[k] > targets[k]:
                        bracket[1] = min(bracket[1], float(factors[k]))
                    else:
                        bracket[0] = max(bracket[0], float(factors[k]))
                    proposal = float(factors[k] * step[k])
                    if not bracket[0] < proposal < bracket[1]:
                        proposal = math.sqrt(bracket[0] * bracket[1]) if np.isfinite(bracket).all() else proposal
                    factors[k] = proposal
                    continue
                if iteration - best.iteration >= 2:  # two samplings without improvement: the rest is noise
                    break
                if not (settled & ~coarse & (np.abs(measured - targets) > _LOOP_TOLERANCE)).any():
                    break  # only coarse zones are off: balancing (below) does better than re-sampling
                # Half steps (in log scale) down: small zones respond in jumps and
                # full steps would oscillate; zones that fall short take full steps
                # up, since what ends up too dense can be thinned afterwards.
                factors = factors * np.where(small & (step > 1.0), step, np.sqrt(step))
            return best

        def finished(best: _Sampling) -> _Sampling:
            """The sampling calibrated on: what the radius could not reach, and crowded nodes thinned."""
            points, triangles, segments, measured = best.points, best.triangles, best.segments, best.measured
            if single and best.worst > TOLERANCE / 4:
                points, segments, measured = fine_tune_scale(points, best.edges, meter, targets, measured, width,
                                                             limit, area)
            elif calibration == "measured" and best.worst > TOLERANCE and np.count_nonzero(settled) > 1:
                # Zones still off target after calibration (small ones, or dense ones next to a
                # sparse neighbour that keeps their samples apart) are balanced edge by edge.
                off = small | (settled & np.isfinite(measured) & (np.abs(measured - targets) > TOLERANCE))
                # The edges' inside lengths are known already: balancing measures only new edges.
                points, triangles, segments, measured = balance_zones(
                    points, triangles, meter, targets, width, off, known=edge_cache(best.edges, best.inside),
                    growing=best.growing, limit=lambda segs: _uncrowded(segs, dmap, width), fixed=best.fixed)
            keep = _uncrowded(segments, dmap, width)
            if not keep.all():
                segments = segments[keep]
                measured = meter.densities_of(meter.inside_all(segments), width)
            error = np.where(settled, np.abs(measured - targets), 0.0)
            return dataclasses.replace(best, points=points, triangles=triangles, segments=segments,
                                       measured=np.asarray(measured),
                                       worst=float(np.nanmax(error)) if len(error) else 0.0)

        done = finished(calibrated())
        if sampler == "lattice" and growing_wanted and np.count_nonzero(settled) > 1:
            # (a coarse zone's band: one sampling to the next moves it by jumps, as the zone itself)
            done = settled_bands(done, lambda between_seed: finished(calibrated(between_seed)),
                                 dmap.zones(printed), targets, width, settled & ~coarse, printed)
        points, triangles, segments, measured, iteration = (
            done.points, done.triangles, done.segments, done.measured, done.iteration)
        return cls(segments, points, triangles, area, dmap, width, "seamless", calibration, list(measured), iteration)

    @classmethod
    def _build_paper(cls, area, dmap, width, seed, calibration, relax, sampler, printed_area):
        parts = []
        for zone_index, zone in enumerate(dmap.zones(area)):
            for polygon in polygons_of(zone):
                if polygon.area < 1e-3 * width * width:
                    continue  # a sliver between zones: no line fits in it
                parts.extend((convex, zone_index) for convex in decompose_convex(polygon))
        targets = dmap.densities
        tried, printed_areas = [], []  # per part: its samplings [(printed mm, points, triangles, segments)]
        for part_index, (part, zone_index) in enumerate(parts):
            target = targets[zone_index]
            radius = sampling_radius(target, width, calibration)
            # what will be printed of the part: its lines inside the infill area, to its edge as Cura's
            # (the footprint's own border shrunk, not the borders between its parts)
            kept = None if printed_area is area else to_multipolygon(part.intersection(printed_area))
            infill_area = part.area if kept is None else kept.area
            # (clipped lines come and go with the samples: half a point is as close as a resampling gets)
            tolerance = TOLERANCE if kept is None else max(TOLERANCE, _PRINTED_TOLERANCE)
            samplings = []
            # a part a few samples across is as dense as its samples fall: four tries
            tries = _MAX_ITERATIONS if part.area > 30.0 * radius * radius else 4
            for _ in range(tries if calibration == "measured" else 1):
                points = sample_poisson_disk(part, radius, seed=seed + part_index, method=sampler)
                if relax:
                    points = relax_points(points, part, lambda xy, r=radius: np.full(len(xy), r), relax, seed=seed)
                triangles = delaunay_triangles(points)
                segments = points[unique_edges(triangles)] if len(triangles) else np.zeros((0, 2, 2))
                printed = segments if kept is None else clip_segments(segments, kept) if not kept.is_empty else segments[:0]
                length = segment_length(printed)
                samplings.append((length, points, triangles, segments))
                got = length * width / infill_area if infill_area > 0 else 0.0
                if calibration == "paper" or abs(got - target) <= tolerance or (got <= 0 and kept is None):
                    break
                # (nothing printed of a small part: halve the radius, its lines come inside)
                radius *= float(np.clip(got / target, 0.5, 2.0)) if got > 0 else 0.5
            tried.append(samplings)
            printed_areas.append(infill_area)
        zone_of = np.array([zone_index for _, zone_index in parts], dtype=np.intp)
        chosen = paper_choices(tried, zone_of, np.asarray(printed_areas), np.asarray(targets), width)
        all_points, all_triangles, all_segments = [], [], []
        offset = 0
        for samplings, choice in zip(tried, chosen):
            _, points, triangles, segments = samplings[choice]
            all_points.append(points)
            all_triangles.append(triangles + offset)
            all_segments.append(segments)
            offset += len(points)
        points = np.concatenate(all_points) if all_points else np.zeros((0, 2))
        triangles = np.concatenate(all_triangles) if all_triangles else np.zeros((0, 3), np.intp)
        segments = np.concatenate(all_segments) if all_segments else np.zeros((0, 2, 2))
        segments = segments[_uncrowded(segments, dmap, width)]
        measured = [measured_density(segments, z, width) for z in dmap.zones(area)]
        return cls(segments, points, triangles, area, dmap, width, "paper", calibration, measured)

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


@dataclass
class _Sampling:
    """One sampling of the seamless build's calibration: its pattern and how far its zones are off."""

    worst: float  # the worst zone's error (fraction; in the loop small zones above target count a quarter)
    points: np.ndarray  # (n, 2) mm
    triangles: np.ndarray  # (t, 3) indices into points
    segments: np.ndarray  # (e, 2, 2) mm: the edges kept
    measured: np.ndarray  # (zones,) fractions
    iteration: int  # of the calibration loop
    edges: np.ndarray  # (e, 2) indices into points (as sampled: balancing changes `segments` only)
    inside: np.ndarray  # (zones, e) mm of each of those edges inside each zone
    growing: object  # its GrowingDelaunay, or None
    fixed: int  # how many of the first points lie on a lattice
    factors: np.ndarray  # (zones,) the density factors it was sampled at
    band_error: float = 0.0  # the worst border band's error (fraction), where measured


def _sample(area, radius_fn, seed: int, sampler: str, relax: int, growing: bool, between_seed: int | None = None):
    """Samples of `area` at the radius field `radius_fn` (one pass of the seamless build).

    Parameters
    ----------
    area : shapely MultiPolygon
        The sampling area (the footprint grown by the largest radius), mm.
    radius_fn : callable
        Points (m, 2) mm -> radius (m,) mm.
    seed : int
    sampler : {"lattice", "fast", "bridson"}
    relax : int
        Lloyd relaxation steps.
    growing : bool
        Also a growing triangulation of the samples (balancing refines it): qhull's
        incremental one, the sampler's own when it made one (the same triangles).
    between_seed : int, optional
        ``"lattice"``: another sampling of the Poisson-disk samples between the lattices.

    Returns
    -------
    (points, fixed, growing)
        The samples (n, 2) mm; how many of the first lie on a lattice; a `GrowingDelaunay`
        of them, or None (not asked for, or qhull refuses the points).
    """
    if growing and sampler in ("fast", "lattice") and not relax:
        points, qhull, fixed = sample_triangulated(area, radius_fn, seed=seed, lattice=sampler == "lattice",
                                                   between_seed=between_seed if sampler == "lattice" else None)
        return points, fixed, GrowingDelaunay(points, qhull) if qhull is not None else growing_delaunay(points)
    fixed = 0  # relaxation leaves lattice points where they are (they are the regular part)
    if sampler == "lattice":
        points, fixed = sample_lattice(area, radius_fn, seed=seed, between_seed=between_seed)
    else:
        points = sample_poisson_disk(area, radius_fn, seed=seed, method=sampler)
    if relax:
        points = relax_points(points, area, radius_fn, relax, seed=seed, fixed=fixed)
    return points, fixed, growing_delaunay(points) if growing else None


def _triangulate(points: np.ndarray, growing, radius_fn, dmap: DensityMap, width: float):
    """The pattern of samples (n, 2) mm: Delaunay triangles without hull slivers, and their edges.

    Crowded nodes are thinned before anything is measured (`_uncrowded`): the calibration makes
    up for what they lose.  `growing` (`GrowingDelaunay`, optional): the samples' triangulation.

    Returns
    -------
    (triangles, edges)
        Triangles (t, 3) and the edges kept (e, 2), indices into `points`.
    """
    triangles = delaunay_triangles(points) if growing is None else growing.add(np.zeros((0, 2)))
    triangles = _drop_slivers(points, triangles, radius_fn)
    edges = unique_edges(triangles)
    return triangles, edges[_uncrowded(points[edges], dmap, width)]


def _uncrowded(segments: np.ndarray, dmap: DensityMap, width: float) -> np.ndarray:
    """`uncrowded_edges` of segments (k, 2, 2) with the shortest edge a quarter of the local spacing: keep mask (k,)."""
    return uncrowded_edges(segments, _shortest_edges(segments, dmap, width))


def _shortest_edges(segments: np.ndarray, dmap: DensityMap, width: float) -> np.ndarray:
    """A quarter of the local spacing (the lattice side at the wanted density) per segment (k, 2, 2), mm.

    Across a border the denser side's spacing (the densest of the two ends and the middle).
    """
    if len(segments) == 0:
        return np.zeros(0)
    at = np.concatenate((segments[:, 0], segments[:, 1], segments.mean(axis=1)))
    densest = dmap.at(at).reshape(3, -1).max(axis=0)
    return 0.25 * _LATTICE_SIDE * width / densest


def _drop_slivers(points: np.ndarray, triangles: np.ndarray, radius_fn) -> np.ndarray:
    """Remove hull triangles whose circumradius exceeds 1.5 x the local radius."""
    if len(triangles) == 0:
        return triangles
    a, b, c = (points[triangles[:, k]] for k in range(3))
    la = np.hypot(*(b - c).T)
    lb = np.hypot(*(c - a).T)
    lc = np.hypot(*(a - b).T)
    twice_area = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    circumradius = la * lb * lc / np.maximum(2.0 * twice_area, 1e-300)
    local = radius_fn(points)[triangles].max(axis=1)  # the radius at each corner, the largest
    return triangles[circumradius <= _SLIVER * local]


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
