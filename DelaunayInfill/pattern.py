"""Infill patterns: built once per footprint and density map, clipped per layer.

`InfillPattern.build` samples, triangulates and calibrates a pattern over a
footprint (an area that covers every layer it will serve).  `clip` cuts it
to one layer's infill area and routes it.  Layers clipped from the same
pattern print the same edges, so infill walls stack layer on layer.

Layouts
-------
``seamless`` (default)
    One variable-radius Poisson-disk sampling of the footprint grown by the
    largest radius, one Delaunay triangulation, edges clipped to the layer:
    no doubled lines along region borders, the density changes within about
    2 r of a border, and lines end cleanly at the infill boundary.
``paper``
    The paper's pipeline: every density zone is decomposed into convex parts,
    each sampled and triangulated on its own (Bridson sampling by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .decomposition import decompose_convex
from .density import KAPPA, DensityMap, check_line_width, paper_radius
from .geometry import as_area, boundary_segments, contains_xy, polygons_of, to_multipolygon, unary_union
from .routing import chain_segments, clip_segments, odd_vertex_count, order_paths
from .sampling import sample_poisson_disk
from .triangulation import (
    delaunay_triangles,
    edge_length_stats,
    lop_violations,
    relax_points,
    triangle_angles,
    unique_edges,
)

__all__ = ["InfillPattern", "InfillResult", "generate_infill", "segment_length"]

LAYOUTS = ("seamless", "paper")
CALIBRATIONS = ("measured", "paper")
_TOLERANCE = 0.0015  # calibration stops within 0.15 percentage points
_MAX_ITERATIONS = 8
_SLIVER = 1.5  # hull triangles with a circumradius above 1.5 r are not part of the pattern


def segment_length(segments: np.ndarray) -> float:
    """Total length of segments (k, 2, 2), mm."""
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    return float(np.hypot(*(segments[:, 1] - segments[:, 0]).T).sum())


def measured_density(segments: np.ndarray, zone, line_width: float) -> float:
    """Printed fill fraction of `zone`: length inside x line width / area (NaN if no area)."""
    if zone.is_empty or zone.area <= 0:
        return float("nan")
    return segment_length(clip_segments(segments, zone)) * line_width / zone.area


class _ZoneMeter:
    """Length of segments inside fixed zones, fast enough to call in calibration loops.

    A segment whose midpoint lies farther from a zone's boundary than half
    its length is wholly inside or outside that zone (a point-in-area test
    on the midpoint says which); only the others are cut where they cross
    the boundary (as `clip_segments` does, against boundary edges prepared
    once per zone).  Boundary distances come from the edges' midpoints, the
    edges being at most `piece` mm long (an error of at most piece / 2,
    allowed for).
    """

    def __init__(self, zones: list, piece: float = 0.5):
        self.zones = zones
        self.piece = piece
        self.edges = []
        self.trees = []
        for zone in zones:
            edges = boundary_segments(zone) if zone.area > 0 else np.zeros((0, 2, 2))
            if len(edges) == 0:
                self.edges.append(edges)
                self.trees.append(None)
                continue
            d = edges[:, 1] - edges[:, 0]
            n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / piece).astype(np.int64))
            seg = np.repeat(np.arange(len(edges)), n)
            k = np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)
            t0, t1 = (k / n[seg])[:, None], ((k + 1) / n[seg])[:, None]
            edges = np.stack([edges[seg, 0] + d[seg] * t0, edges[seg, 0] + d[seg] * t1], axis=1)
            self.edges.append(edges)
            self.trees.append(cKDTree(edges.mean(axis=1)))

    def inside(self, segments: np.ndarray, k: int) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside zone k, shape (m,)."""
        out = np.zeros(len(segments))
        tree = self.trees[k]
        if tree is None or len(segments) == 0:
            return out
        zone = self.zones[k]
        length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
        mid = 0.5 * (segments[:, 0] + segments[:, 1])
        dist = tree.query(mid)[0]
        sure = dist - 0.5 * self.piece > 0.5 * length + 1e-9
        sure_idx = np.flatnonzero(sure)
        hit = contains_xy(zone, mid[sure_idx, 0], mid[sure_idx, 1])
        out[sure_idx[hit]] = length[sure_idx[hit]]
        unsure = np.flatnonzero(~sure)
        if unsure.size:
            # Long segments near the boundary: split into short pieces first, most of which
            # are then sure; the few left are cut against nearby boundary edges only.
            pieces, source = _split_segments(segments[unsure], 2.0 * self.piece)
            plen = np.hypot(*(pieces[:, 1] - pieces[:, 0]).T)
            pmid = 0.5 * (pieces[:, 0] + pieces[:, 1])
            near = tree.query(pmid)[0] - 0.5 * self.piece <= 0.5 * plen + 1e-9
            got = np.zeros(len(pieces))
            far = np.flatnonzero(~near)
            got[far] = np.where(contains_xy(zone, pmid[far, 0], pmid[far, 1]), plen[far], 0.0)
            close = np.flatnonzero(near)
            if close.size:
                got[close] = self._cut(pieces[close], plen[close], k)
            out[unsure] = np.bincount(source, got, unsure.size)
        return out

    def _cut(self, segments: np.ndarray, length: np.ndarray, k: int) -> np.ndarray:
        """Inside length of segments near zone k's boundary: cut at every crossing, midpoints tested."""
        edges = self.edges[k]
        reach = 0.5 * (float(length.max()) + self.piece) + 1e-6
        sdm = cKDTree(segments.mean(axis=1)).sparse_distance_matrix(self.trees[k], reach, output_type="ndarray")
        ia, ib = sdm["i"].astype(np.intp), sdm["j"].astype(np.intp)
        p, r = segments[ia, 0], segments[ia, 1] - segments[ia, 0]
        q, e = edges[ib, 0], edges[ib, 1] - edges[ib, 0]
        denom = r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]
        ok = np.abs(denom) > 1e-15
        safe = np.where(ok, denom, 1.0)
        qp = q - p
        t = (qp[:, 0] * e[:, 1] - qp[:, 1] * e[:, 0]) / safe
        u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / safe
        cross = ok & (t > 1e-9) & (t < 1 - 1e-9) & (u >= -1e-9) & (u <= 1 + 1e-9)
        m = len(segments)
        seg_id = np.r_[np.arange(m), np.arange(m), ia[cross]]
        param = np.r_[np.zeros(m), np.ones(m), t[cross]]
        order = np.lexsort((param, seg_id))
        seg_id, param = seg_id[order], param[order]
        same = seg_id[1:] == seg_id[:-1]
        sid, t0, t1 = seg_id[:-1][same], param[:-1][same], param[1:][same]
        a, b = segments[sid, 0], segments[sid, 1]
        mid = a + (b - a) * (0.5 * (t0 + t1))[:, None]
        inside = contains_xy(self.zones[k], mid[:, 0], mid[:, 1])
        return np.bincount(sid[inside], (t1 - t0)[inside] * length[sid[inside]], m)

    def densities(self, segments: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone (NaN where a zone has no area)."""
        return np.array([
            self.inside(segments, k).sum() * width / z.area if z.area > 0 else np.nan
            for k, z in enumerate(self.zones)
        ])


def _split_segments(segments: np.ndarray, longest: float) -> tuple[np.ndarray, np.ndarray]:
    """Segments (m, 2, 2) cut into equal pieces at most `longest` mm; returns (pieces, source index)."""
    d = segments[:, 1] - segments[:, 0]
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / longest).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n)
    k = np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)
    t0, t1 = (k / n[seg])[:, None], ((k + 1) / n[seg])[:, None]
    return np.stack([segments[seg, 0] + d[seg] * t0, segments[seg, 0] + d[seg] * t1], axis=1), seg


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
        Straight travel between consecutive paths (from the start point when given).
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
        Measured density per zone of the footprint after calibration (away
        from borders between zones: `_zone_interiors`).
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
            ``measured``: iterate until the printed density of every zone
            (away from its borders with other zones) is within 0.15 points
            of its target, then balance the zones still off by single edges;
            ``paper``: Formula (6).
        relax : int
            Lloyd relaxation steps (more regular triangles).
        feather : float
            Blend width across region borders, mm (seamless layout).
        sampler : {"fast", "bridson"}, optional
            Default: ``fast`` for seamless, ``bridson`` for paper.

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
        sampler = sampler or ("bridson" if layout == "paper" else "fast")
        if layout == "seamless":
            return cls._build_seamless(area, dmap, width, int(seed), calibration, relax, sampler)
        return cls._build_paper(area, dmap, width, int(seed), calibration, relax, sampler)

    @classmethod
    def _build_seamless(cls, area, dmap, width, seed, calibration, relax, sampler):
        zones = dmap.zones(area)
        if dmap.feather > 0:  # calibrate the zone cores, not the blend bands between them
            cores = [to_multipolygon(z.buffer(-0.5 * dmap.feather)) for z in zones]
            zones = [core if core.area > 0 else z for core, z in zip(cores, zones)]
        zones = _zone_interiors(zones, width, None if dmap.feather > 0 else area)
        targets = np.array(dmap.densities)
        lowest = float(min(targets))
        reach = 1.3 * (paper_radius(lowest, width) if calibration == "paper" else KAPPA * width / lowest)
        sampling_area = to_multipolygon(area.buffer(reach, 8))
        radius_of = (lambda d: paper_radius(d, width)) if calibration == "paper" else (lambda d: KAPPA * width / d)
        settled = np.array([z.area > 0 for z in zones])
        # Zones under about 4 x 4 of their own radii cannot be calibrated by the
        # radius alone; they are balanced by thinning or refinement at the end.
        # (A single zone is fine-tuned by scaling instead.)
        small = settled & np.array([z.area < 16.0 * radius_of(t) ** 2 for z, t in zip(zones, targets)])
        small &= np.count_nonzero(settled) > 1
        factors = np.ones(len(targets))
        meter = _ZoneMeter(zones)
        best = None
        for iteration in range(1, _MAX_ITERATIONS + 1):
            scaled = dmap.with_densities(targets * factors)

            def radius_fn(xy, scaled=scaled):
                return radius_of(scaled.at(xy))

            points = sample_poisson_disk(sampling_area, radius_fn, seed=seed, method=sampler)
            if relax:
                points = relax_points(points, sampling_area, radius_fn, relax, seed=seed)
            triangles = _drop_slivers(points, delaunay_triangles(points), radius_fn)
            segments = points[unique_edges(triangles)]
            measured = meter.densities(segments, width)
            error = np.abs(measured - targets)
            # Small zones above target can be thinned afterwards; shortfalls cannot.
            error = np.where(small & (measured > targets), 0.25 * error, error)
            worst = float(np.nanmax(np.where(settled, error, 0.0))) if len(error) else 0.0
            if best is None or worst < best[0]:
                best = (worst, points, triangles, segments, measured, iteration)
            if calibration == "paper" or worst <= _TOLERANCE:
                break
            ok = settled & np.isfinite(measured) & (measured > 0)
            step = np.where(ok, targets / np.where(ok, measured, 1.0), 1.0)
            step = np.where(settled & ~ok, 2.0, step)  # a zone with nothing printed: denser
            # Half steps (in log scale) down: small zones respond in jumps and
            # full steps would oscillate; zones that fall short take full steps
            # up, since what ends up too dense can be thinned afterwards.
            step = np.clip(step, 0.5, 2.0)
            factors = factors * np.where(small & (step > 1.0), step, np.sqrt(step))
        worst, points, triangles, segments, measured, iteration = best
        if calibration == "measured" and worst > _TOLERANCE and np.count_nonzero(settled) == 1:
            points, segments, measured = _fine_tune_scale(points, triangles, zones, targets, width, reach, area)
        elif calibration == "measured" and worst > _TOLERANCE and np.count_nonzero(settled) > 1:
            # Zones still off target after calibration (small ones, or dense ones next to a
            # sparse neighbour that keeps their samples apart) are balanced edge by edge.
            off = small | (settled & np.isfinite(measured) & (np.abs(measured - targets) > _TOLERANCE))
            points, triangles, segments, measured = _balance_zones(points, triangles, meter, targets, width, off)
        return cls(segments, points, triangles, area, dmap, width, "seamless", calibration, list(measured), iteration)

    @classmethod
    def _build_paper(cls, area, dmap, width, seed, calibration, relax, sampler):
        parts = []
        for zone_index, zone in enumerate(dmap.zones(area)):
            for polygon in polygons_of(zone):
                parts.extend((convex, zone_index) for convex in decompose_convex(polygon))
        targets = dmap.densities
        all_points, all_triangles, all_segments = [], [], []
        offset = 0
        for part_index, (part, zone_index) in enumerate(parts):
            target = targets[zone_index]
            radius = paper_radius(target, width) if calibration == "paper" else KAPPA * width / target
            best = None
            for _ in range(_MAX_ITERATIONS if calibration == "measured" else 1):
                points = sample_poisson_disk(part, radius, seed=seed + part_index, method=sampler)
                if relax:
                    points = relax_points(points, part, lambda xy, r=radius: np.full(len(xy), r), relax, seed=seed)
                triangles = delaunay_triangles(points)
                segments = points[unique_edges(triangles)] if len(triangles) else np.zeros((0, 2, 2))
                got = segment_length(segments) * width / part.area
                if best is None or abs(got - target) < best[0]:
                    best = (abs(got - target), points, triangles, segments)
                if calibration == "paper" or abs(got - target) <= _TOLERANCE or got <= 0:
                    break
                radius *= float(np.clip(got / target, 0.5, 2.0))
            _, points, triangles, segments = best
            all_points.append(points)
            all_triangles.append(triangles + offset)
            all_segments.append(segments)
            offset += len(points)
        points = np.concatenate(all_points) if all_points else np.zeros((0, 2))
        triangles = np.concatenate(all_triangles) if all_triangles else np.zeros((0, 3), np.intp)
        segments = np.concatenate(all_segments) if all_segments else np.zeros((0, 2, 2))
        measured = [measured_density(segments, z, width) for z in dmap.zones(area)]
        return cls(segments, points, triangles, area, dmap, width, "paper", calibration, measured)

    # ------------------------------------------------------------------ use
    def clip(self, area, *, start=None) -> InfillResult:
        """The pattern inside one area, chained and ordered.

        Parameters
        ----------
        area : shapely (Multi)Polygon
            A layer's infill area (inside the footprint).
        start : (x, y), optional
            Nozzle position before the infill; the first path starts near it.

        Returns
        -------
        InfillResult
        """
        area = as_area(area, what="infill area")
        segments = clip_segments(self.segments, area)
        paths, travel = order_paths(chain_segments(segments), start)
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


def _zone_interiors(zones: list, width: float, tiled=None) -> list:
    """Zones without a band of one line width along their borders with other zones.

    Across a border between two densities the pattern changes over a few
    samples; the band where it does belongs to neither zone, so each zone is
    calibrated on the rest (as a region's density is measured: away from its
    border, where lines on the border do not count twice).  Borders with the
    footprint's outline are kept; a zone that the band would (nearly) swallow
    is kept whole.  `tiled`: the area the zones tile, when they do (the
    others are then its difference with a zone).
    """
    present = [k for k, z in enumerate(zones) if z.area > 0]
    if len(present) < 2:
        return zones
    out = list(zones)
    for k in present:
        others = tiled.difference(zones[k]) if tiled is not None else unary_union([zones[j] for j in present if j != k])
        inner = to_multipolygon(zones[k].difference(others.buffer(width, 4)))
        if inner.area >= 0.3 * zones[k].area:
            out[k] = inner
    return out


def _fine_tune_scale(points, triangles, zones, targets, width, reach, area):
    """Scale a coarse single-zone pattern about the footprint centre to hit its target.

    When the radius is large against the region, re-sampling changes the
    printed length in jumps.  Scaling the points keeps the triangulation (it
    stays Delaunay) and changes the length inside the zone continuously, so a
    bisection finds the scale.  The scale is limited so that the pattern
    still covers the footprint.
    """
    zone_index = next(k for k, z in enumerate(zones) if z.area > 0)
    zone, target = zones[zone_index], targets[zone_index]
    center = np.asarray(area.centroid.coords[0])
    extent = float(np.hypot(*(np.asarray(area.envelope.exterior.coords) - center).T).max())
    limit = min(0.3, 0.6 * reach / max(extent, 1e-9))
    edges = unique_edges(triangles)

    def density_at(scale):
        scaled = center + (points - center) * scale
        segments = scaled[edges]
        return measured_density(segments, zone, width), scaled, segments

    lo, hi = 1.0 - limit, 1.0 + limit  # density falls as the scale grows
    best = None
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        got, scaled, segments = density_at(mid)
        if best is None or abs(got - target) < abs(best[0] - target):
            best = (got, scaled, segments)
        if abs(got - target) <= _TOLERANCE / 4:
            break
        lo, hi = (mid, hi) if got > target else (lo, mid)
    _, scaled, segments = best
    return scaled, segments, [measured_density(segments, z, width) for z in zones]


def _balance_zones(points, triangles, meter, targets, width, small, rounds: int = 12):
    """Bring zones that calibration cannot reach to their targets.

    A zone smaller than about two of its own radii cannot reach its target in
    one triangulation: a sparse one is crossed by its denser neighbours'
    edges, a dense one loses samples near a sparse neighbour (whose samples
    keep their larger radius free).  Each round thins the zones that print
    too dense (`_thin_dense_zones`), then inserts circumcentres of the widest
    triangles in zones that print too sparse (Delaunay refinement: edges go
    where the zone is emptiest and the triangulation stays Delaunay).

    Only the zones flagged in `small` are balanced; `meter` (`_ZoneMeter`)
    holds the zones and measures them.

    Returns
    -------
    (points, triangles, segments, measured)
    """
    for _ in range(rounds):
        segments, measured = _thin_dense_zones(points, triangles, meter, targets, width, small)
        short = [k for k in np.flatnonzero(small) if measured[k] < targets[k] - _TOLERANCE]
        if not short:
            break
        a, b, c = (points[triangles[:, k]] for k in range(3))
        d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
        ok = np.abs(d) > 1e-12
        d = np.where(ok, d, 1.0)
        sa, sb, sc = ((p * p).sum(axis=1) for p in (a, b, c))
        center = np.c_[
            (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d,
            (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d,
        ]
        radius = np.where(ok, np.hypot(*(center - a).T), 0.0)
        added = []
        for k in short:
            inside = np.flatnonzero(contains_xy(meter.zones[k], center[:, 0], center[:, 1]))
            if inside.size == 0:
                continue
            # About 3 circumradii of line per insertion; at most a third of
            # the zone's triangles per round.
            missing = (targets[k] - measured[k]) * meter.zones[k].area / width
            widest = inside[np.argsort(-radius[inside])]
            count = int(np.clip(missing / max(3.0 * radius[widest[0]], 1e-9), 1, max(1, inside.size // 3)))
            added.append(center[widest[:count]])
        if not added:
            break
        points = np.r_[points, np.concatenate(added)]
        triangles = delaunay_triangles(points)
    else:
        segments, measured = _thin_dense_zones(points, triangles, meter, targets, width, small)
    return points, triangles, segments, measured


def _thin_dense_zones(points, triangles, meter, targets, width, small):
    """Leave out edges in zones that print denser than their target.

    A zone smaller than about two of its own radii cannot reach a low target
    in one triangulation: the edges between its denser neighbours' samples
    cross it.  Such a zone gets its longest edges left out (first at most one
    per triangle, so cells become quadrilaterals; never leaving a loose end)
    until its printed density is as close to the target as whole edges allow.

    Returns
    -------
    (segments, measured)
        Printed edges (k, 2, 2) and the measured density per zone.
    """
    edges = unique_edges(triangles)
    segments = points[edges]
    keep = np.ones(len(edges), dtype=bool)
    # Triangles on each side of every edge (-1 on the hull).
    n = len(points)
    tri_edges = np.sort(np.stack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=1), axis=2)
    edge_key = edges[:, 0].astype(np.int64) * n + edges[:, 1]
    tri_edge_ids = np.searchsorted(edge_key, tri_edges[..., 0].astype(np.int64) * n + tri_edges[..., 1])
    owners = np.full((len(edges), 2), -1, dtype=np.int64)
    flat_edge = tri_edge_ids.ravel()
    flat_tri = np.repeat(np.arange(len(triangles)), 3)
    order = np.argsort(flat_edge, kind="stable")
    first = np.r_[True, flat_edge[order][1:] != flat_edge[order][:-1]]
    owners[flat_edge[order][first], 0] = flat_tri[order][first]
    owners[flat_edge[order][~first], 1] = flat_tri[order][~first]
    opened = np.zeros(len(triangles) + 1, dtype=bool)  # last slot stands for "no triangle"
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    # Length of every edge inside every zone: leaving edges out does not change it.
    inside_of = [meter.inside(segments, k) if meter.zones[k].area > 0 else np.zeros(len(edges))
                 for k in range(len(meter.zones))]
    for k, (zone, target, thin) in enumerate(zip(meter.zones, targets, small)):
        if not thin or zone.is_empty or zone.area <= 0:
            continue
        inside = np.where(keep, inside_of[k], 0.0)
        excess = (inside.sum() * width / zone.area - target) * zone.area / width  # mm of line too many
        if excess <= 0:
            continue
        candidates = np.flatnonzero(keep & (inside >= 0.5 * length))
        candidates = candidates[np.argsort(-length[candidates])]
        degree = np.bincount(edges[keep].ravel(), minlength=n)
        # First one edge per triangle; then any edge that leaves no loose end.
        for strict in (True, False):
            for e in candidates:
                if excess - 0.5 * inside[e] <= 0:
                    break
                if not keep[e] or (strict and opened[owners[e]].any()) or degree[edges[e]].min() <= 2:
                    continue
                keep[e] = False
                degree[edges[e]] -= 1
                opened[owners[e]] = True
                opened[-1] = False
                excess -= inside[e]
    measured = [float(inside_of[k][keep].sum()) * width / z.area if z.area > 0 else float("nan")
                for k, z in enumerate(meter.zones)]
    return segments[keep], measured


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
    local = radius_fn(points[triangles].reshape(-1, 2)).reshape(-1, 3).max(axis=1)
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
