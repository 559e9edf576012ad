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
    2 r of a border, and lines end cleanly at the infill boundary.  Where
    the density is uniform the samples are a triangular lattice (sampler
    ``lattice``, the default): its Delaunay triangles are equilateral, as
    stiff per gram as a line network gets and the same in every direction;
    Poisson-disk samples fill the bands between zones.
``paper``
    The paper's pipeline: every density zone is decomposed into convex parts,
    each sampled and triangulated on its own (Bridson sampling by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import QhullError, cKDTree

from .decomposition import decompose_convex
from .density import KAPPA, DensityMap, ZoneRaster, check_line_width, paper_radius
from .geometry import as_area, boundary_segments, contains_xy, polygons_of, to_multipolygon, unary_union
from .routing import chain_segments, clip_segments, odd_vertex_count, order_paths, split_segments
from .sampling import sample_lattice, sample_poisson_disk, sample_triangulated
from .triangulation import (
    GrowingDelaunay,
    canonical_triangles,
    delaunay_triangles,
    edge_length_stats,
    lop_violations,
    relax_points,
    triangle_angles,
    uncrowded_edges,
    unique_edges,
)

__all__ = ["InfillPattern", "InfillResult", "generate_infill", "segment_length"]

LAYOUTS = ("seamless", "paper")
CALIBRATIONS = ("measured", "paper")
_TOLERANCE = 0.0015  # calibration stops within 0.15 percentage points
_PRINTED_TOLERANCE = 0.005  # paper layout calibrated on its clipped lines (`InfillPattern.build`'s infill_area)
_MAX_ITERATIONS = 8
_LOOP_TOLERANCE = 0.003  # several zones: the loop stops within 0.3 points (balancing does the rest)
_SLIVER = 1.5  # hull triangles with a circumradius above 1.5 r are not part of the pattern
_COARSE = 36.0  # several zones: a zone under this many squared radii is only balanced once off target
_THIN = 1.4  # zone interiors: a zone of mean width under this many line widths is kept whole
_FEW = 48  # zone meter: up to this many pieces to cut query the edges' tree (no tree of their own)
_CELL = 0.45  # several sharp-border zones: raster cell side, in line widths
_MAX_CELLS = 120_000  # ... the cell grows beyond that when the footprint's box would need more cells
_FEW_CELLS = 400  # ... cells wider than a line: a zone of fewer cells is measured exactly instead
_LATTICE_SIDE = 2.0 * math.sqrt(3.0)  # triangular lattice of density d: side 2 sqrt(3) w / d


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

    All zones are measured in one pass.  A segment whose midpoint lies
    farther from every zone boundary than half its length is wholly inside
    or outside each zone (a point-in-area test on the midpoint says which);
    only the others are cut where they cross any zone boundary (as
    `clip_segments` does, against boundary edges prepared once), and each
    piece is tested by its midpoint.  Boundary distances come from the
    edges' midpoints, the edges being at most `piece` mm long (an error of
    at most piece / 2, allowed for).
    """

    def __init__(self, zones: list, piece: float = 0.5):
        self.zones = zones
        self.piece = piece
        self.areas = np.array([0.0 if zone.is_empty else zone.area for zone in zones])  # (zones,) mm^2
        self.present = [k for k, zone in enumerate(zones) if not zone.is_empty and zone.area > 0]
        self.bounds = {k: zones[k].bounds for k in self.present}
        corners = np.array(list(self.bounds.values()), dtype=float).reshape(-1, 4)
        self.boxes = corners  # (present, 4): x0, y0, x1, y1 of each zone present
        self.extent = (*corners[:, :2].min(axis=0), *corners[:, 2:].max(axis=0)) if len(corners) else None
        edges = [boundary_segments(zones[k]) for k in self.present]
        edges = np.concatenate(edges) if edges else np.zeros((0, 2, 2))
        self.edges, self.tree = edges, None
        if len(edges):
            self.edges, _ = split_segments(edges, piece)
            self.tree = cKDTree(self.edges.mean(axis=1))
        self.edge_dirs = self.edges[:, 1] - self.edges[:, 0]  # (pieces, 2): `_cut` reads them per pair

    def inside_all(self, segments: np.ndarray) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside each zone, shape (zones, m)."""
        segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
        out = np.zeros((len(self.zones), len(segments)))
        if self.tree is None or len(segments) == 0:
            return out
        # Segments clear of the zones' common bounding box have nothing inside (a pattern
        # covers its footprint grown by about a radius: many of its edges are out there).
        x0, y0, x1, y1 = self.extent
        lo, hi = segments.min(axis=1), segments.max(axis=1)
        touching = np.flatnonzero((hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1))
        if touching.size < len(segments):
            out[:, touching] = self.inside_all(segments[touching])
            return out
        length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
        mid = 0.5 * (segments[:, 0] + segments[:, 1])
        # Distances beyond `reach` only need to be known as "far" (inf): the tree prunes them.
        reach = 0.5 * self.piece + 0.5 * float(length.max()) + 1e-3
        sure = self.tree.query(mid, distance_upper_bound=reach)[0] - 0.5 * self.piece > 0.5 * length + 1e-9
        sure_idx = np.flatnonzero(sure)
        unsure = np.flatnonzero(~sure)
        if unsure.size == 0:
            for k, hit in self._hits(mid[sure_idx]):
                hit = sure_idx[hit]
                out[k, hit] = length[hit]
            return out
        # Long segments near a boundary: split into short pieces first, most of which are
        # then sure; the few left are cut against nearby boundary edges only.
        pieces, source = split_segments(segments[unsure], 2.0 * self.piece)
        plen = np.hypot(*(pieces[:, 1] - pieces[:, 0]).T)
        pmid = 0.5 * (pieces[:, 0] + pieces[:, 1])
        reach = 0.5 * self.piece + 0.5 * float(plen.max()) + 1e-3
        near = self.tree.query(pmid, distance_upper_bound=reach)[0] - 0.5 * self.piece <= 0.5 * plen + 1e-9
        far, close = np.flatnonzero(~near), np.flatnonzero(near)
        sub_source, sub_length, sub_mid = source[far], plen[far], pmid[far]
        if close.size:
            sid, sub, smid = self._cut(pieces[close], plen[close])
            sub_source = np.concatenate((sub_source, source[close][sid]))
            sub_length = np.concatenate((sub_length, sub))
            sub_mid = np.concatenate((sub_mid, smid))
        # One point-in-zone test per zone for the sure midpoints and the pieces' together.
        tested = np.concatenate((mid[sure_idx], sub_mid))
        for k, hit in self._hits(tested):
            split = np.searchsorted(hit, sure_idx.size)
            out[k, sure_idx[hit[:split]]] = length[sure_idx[hit[:split]]]
            hit = hit[split:] - sure_idx.size
            out[k, unsure] = np.bincount(sub_source[hit], sub_length[hit], unsure.size)
        return out

    def _hits(self, xy: np.ndarray):
        """Yield (zone index, indices of the points (m, 2) inside it, ascending) for each zone
        whose bounding box holds any of the points (the others hold none of them).

        One bounding-box test for all zones at once; only the points in a zone's box are
        tested against the zone.
        """
        x, y = xy[:, 0], xy[:, 1]
        box_of = self.boxes
        in_box = (x >= box_of[:, 0:1]) & (x <= box_of[:, 2:3]) & (y >= box_of[:, 1:2]) & (y <= box_of[:, 3:4])
        for row in np.flatnonzero(in_box.any(axis=1)):
            k = self.present[row]
            near = np.flatnonzero(in_box[row])
            yield k, near[contains_xy(self.zones[k], x[near], y[near])]

    def contains(self, k: int, xy: np.ndarray) -> np.ndarray:
        """Indices of the points (m, 2) inside zone k, shape (h,) ascending.

        Only points inside the zone's bounding box are tested (the rest cannot be inside).
        """
        x0, y0, x1, y1 = self.bounds[k]
        x, y = xy[:, 0], xy[:, 1]
        near = ((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).nonzero()[0]
        return near[contains_xy(self.zones[k], x[near], y[near])]

    def inside(self, segments: np.ndarray, k: int) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside zone k, shape (m,)."""
        return self.inside_all(segments)[k]

    def _cut(self, segments: np.ndarray, length: np.ndarray):
        """Segments near a boundary cut at every crossing.

        Returns
        -------
        (segment index, length, midpoint) of every sub-segment: (s,), (s,), (s, 2).
        """
        reach = 0.5 * (float(length.max()) + self.piece) + 1e-6
        # Every pair within reach (a crossing pair is nearer by far more than rounding): a few
        # segments are looked up in the edges' tree, many get a tree of their own.
        m = len(segments)
        if m <= _FEW:
            found = self.tree.query_ball_point(segments.mean(axis=1), reach)
            ia = np.repeat(np.arange(m), [len(f) for f in found])
            ib = np.array([j for f in found for j in f], dtype=np.intp)
        else:
            sdm = _quick_tree(segments.mean(axis=1)).sparse_distance_matrix(self.tree, reach, output_type="ndarray")
            ia, ib = sdm["i"].astype(np.intp), sdm["j"].astype(np.intp)
        pair = segments[ia]  # one gather per side (the pairs outnumber the segments)
        p = pair[:, 0]
        r = pair[:, 1] - p
        q, e = self.edges[ib, 0], self.edge_dirs[ib]
        denom = r[:, 0] * e[:, 1] - r[:, 1] * e[:, 0]
        ok = np.abs(denom) > 1e-15
        safe = np.where(ok, denom, 1.0)
        qp = q - p
        t = (qp[:, 0] * e[:, 1] - qp[:, 1] * e[:, 0]) / safe
        u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / safe
        cross = ok & (t > 1e-9) & (t < 1 - 1e-9) & (u >= -1e-9) & (u <= 1 + 1e-9)
        seg_id = np.concatenate((np.arange(m), np.arange(m), ia[cross]))
        param = np.concatenate((np.zeros(m), np.ones(m), t[cross]))
        order = np.lexsort((param, seg_id))
        seg_id, param = seg_id[order], param[order]
        same = seg_id[1:] == seg_id[:-1]
        sid, t0, t1 = seg_id[:-1][same], param[:-1][same], param[1:][same]
        a, b = segments[sid, 0], segments[sid, 1]
        mid = a + (b - a) * (0.5 * (t0 + t1))[:, None]
        return sid, (t1 - t0) * length[sid], mid

    def densities(self, segments: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone (NaN where a zone has no area)."""
        return self.densities_of(self.inside_all(segments), width)

    def densities_of(self, inside: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone from `inside_all`'s lengths (zones, m) (NaN where a zone has no area)."""
        return _densities(inside.sum(axis=1), self.areas, width)


def _densities(lengths: np.ndarray, areas: np.ndarray, width: float) -> np.ndarray:
    """Fill fraction per zone from line lengths (zones,) mm and areas (zones,) mm^2; NaN where no area."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(areas > 0, lengths * width / np.where(areas > 0, areas, 1.0), np.nan)


class _RasterMeter:
    """Length of segments inside zones given as a `ZoneRaster` (several sharp-border zones).

    Each segment is cut into equal pieces no longer than a cell and each
    piece counts for the zone of the cell holding its midpoint.  A zone's
    area is its cells' area, so a density (length x width / area) is measured
    on one and the same raster shape: the rounding of the border moves the
    line and the area alike and the ratio stays that of the pattern.

    Parameters
    ----------
    raster : ZoneRaster
        Labels 0 .. zones - 1 (-1: in no zone): where lengths and areas are measured.
    zones : int
        Number of zones.
    """

    def __init__(self, raster: ZoneRaster, zones: int):
        self.raster = raster
        self.count = zones
        self.areas = raster.counts(zones) * raster.cell**2  # (zones,) mm^2
        labelled = raster.labels >= 0
        rows, cols = np.flatnonzero(labelled.any(axis=1)), np.flatnonzero(labelled.any(axis=0))
        cell = raster.cell
        self.extent = None if rows.size == 0 else (  # the labelled cells' box, mm
            raster.x0 + cell * cols[0], raster.y0 + cell * rows[0],
            raster.x0 + cell * (cols[-1] + 1), raster.y0 + cell * (rows[-1] + 1))

    def inside_all(self, segments: np.ndarray) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside each zone, shape (zones, m)."""
        segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
        out = np.zeros((self.count, len(segments)))
        if self.extent is None or len(segments) == 0:
            return out
        x0, y0, x1, y1 = self.extent
        lo, hi = segments.min(axis=1), segments.max(axis=1)
        touching = np.flatnonzero((hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1))
        if touching.size == 0:
            return out
        start = segments[touching, 0]
        step = segments[touching, 1] - start
        length = np.hypot(step[:, 0], step[:, 1])
        n = np.maximum(1, np.ceil(length / self.raster.cell)).astype(np.intp)
        seg = np.repeat(np.arange(touching.size), n)
        frac = (np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n) + 0.5) / n[seg]
        label = self.raster.at(start[seg] + step[seg] * frac[:, None])
        hit = label >= 0
        total = np.bincount(label[hit] * touching.size + seg[hit], (length / n)[seg[hit]], self.count * touching.size)
        out[:, touching] = total.reshape(self.count, touching.size)
        return out

    def inside(self, segments: np.ndarray, k: int) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside zone k, shape (m,)."""
        return self.inside_all(segments)[k]

    def contains(self, k: int, xy: np.ndarray) -> np.ndarray:
        """Indices of the points (m, 2) inside zone k (of `inner`), shape (h,) ascending."""
        return np.flatnonzero(self.raster.at(xy) == k)

    def densities_of(self, inside: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone from `inside_all`'s lengths (zones, m) (NaN where a zone has no area)."""
        return _densities(inside.sum(axis=1), self.areas, width)


def _quick_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree built for a few queries: midpoint splits build faster than median ones."""
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


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
        Measured density per zone after calibration: each zone whole, the
        bands along other zones included, inside the infill area (`build`'s
        `infill_area`); with a feather, the zone cores (`_zone_interiors`).
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
        meter = _raster_meter(printed, dmap, width) if dmap.feather <= 0 and dmap.regions else None
        if meter is None:
            zones = dmap.zones(printed)
            if dmap.feather > 0:  # calibrate the zone cores, not the blend bands between them
                cores = [to_multipolygon(z.buffer(-0.5 * dmap.feather)) for z in zones]
                zones = [core if core.area > 0 else z for core, z in zip(cores, zones)]
            # Whole zones, border bands included: what a region prints is what it is asked for.  (A
            # feathered map calibrates the zone cores without a band: the blend between them is the map's.)
            meter = _ZoneMeter(_zone_interiors(zones, width) if dmap.feather > 0 else zones)
        zone_areas = meter.areas
        targets = np.array(dmap.densities)
        lowest = float(min(targets))
        reach = 1.3 * (paper_radius(lowest, width) if calibration == "paper" else KAPPA * width / lowest)
        # Simplified first: buffering a footprint with many short (rounded) edges by a large
        # reach is slow; the simplified outline is within `tol` of it, so grow by reach + tol.
        tol = 0.05 * reach
        sampling_area = to_multipolygon(area.simplify(tol).buffer(reach + tol, 8))
        radius_of = (lambda d: paper_radius(d, width)) if calibration == "paper" else (lambda d: KAPPA * width / d)
        settled = zone_areas > 0
        # Zones under about 4 x 4 of their own radii cannot be calibrated by the
        # radius alone; they are balanced by thinning or refinement at the end.
        # (A single zone is fine-tuned by scaling instead.)
        small = settled & np.array([a < 16.0 * radius_of(t) ** 2 for a, t in zip(zone_areas.tolist(), targets)])
        small &= np.count_nonzero(settled) > 1
        # Zones under about 6 x 6 of their radii hold a few dozen samples: one sampling to the
        # next moves them by several points, so re-sampling for them alone is noise.
        coarse = settled & np.array([a < _COARSE * radius_of(t) ** 2 for a, t in zip(zone_areas.tolist(), targets)])
        factors = np.ones(len(targets))
        # A single zone is calibrated by scaling one sampling (continuous, cheap) as soon as
        # the scale needed is within reach; re-sampling only moves it by jumps of 1-2 points.
        single = calibration == "measured" and np.count_nonzero(settled) == 1
        scale_limit = _scale_limit(area, reach)
        bracket = np.array([0.0, np.inf])  # single zone: factors known to print too sparse / too dense
        best = None
        fixed = 0  # how many of the first samples lie on a lattice
        for iteration in range(1, _MAX_ITERATIONS + 1):
            scaled = dmap.with_densities(targets * factors)

            def radius_fn(xy, scaled=scaled):
                return radius_of(scaled.at(xy))

            # Several zones may be balanced by refinement afterwards: it goes on from qhull's
            # incremental triangulation of the samples (the same triangles), the sampler's own
            # when it made one.
            growing = None
            if not single and calibration == "measured" and sampler in ("fast", "lattice") and not relax:
                points, qhull, fixed = sample_triangulated(sampling_area, radius_fn, seed=seed,
                                                           lattice=sampler == "lattice")
                growing = GrowingDelaunay(points, qhull) if qhull is not None else _growing_delaunay(points)
            else:
                fixed = 0  # relaxation leaves lattice points where they are (they are the regular part)
                if sampler == "lattice":
                    points, fixed = sample_lattice(sampling_area, radius_fn, seed=seed)
                else:
                    points = sample_poisson_disk(sampling_area, radius_fn, seed=seed, method=sampler)
                if relax:
                    points = relax_points(points, sampling_area, radius_fn, relax, seed=seed, fixed=fixed)
                if not single and calibration == "measured":
                    growing = _growing_delaunay(points)
            triangles = delaunay_triangles(points) if growing is None else growing.add(np.zeros((0, 2)))
            triangles = _drop_slivers(points, triangles, radius_fn)
            edges = unique_edges(triangles)
            # crowded nodes thinned before measuring: the calibration makes up for what they lose
            edges = edges[_uncrowded(points[edges], dmap, width)]
            segments = points[edges]
            inside = meter.inside_all(segments)
            measured = meter.densities_of(inside, width)
            error = np.abs(measured - targets)
            # Small zones above target can be thinned afterwards; shortfalls cannot.
            error = np.where(small & (measured > targets), 0.25 * error, error)
            worst = float(np.nanmax(np.where(settled, error, 0.0))) if len(error) else 0.0
            if best is None or worst < best[0]:
                best = (worst, points, triangles, segments, measured, iteration, edges, inside, growing, fixed)
            if calibration == "paper" or worst <= (_TOLERANCE if single else _LOOP_TOLERANCE):
                break
            ok = settled & np.isfinite(measured) & (measured > 0)
            step = np.where(ok, targets / np.where(ok, measured, 1.0), 1.0)
            step = np.where(settled & ~ok, 2.0, step)  # a zone with nothing printed: denser
            step = np.clip(step, 0.5, 2.0)
            if single:
                # density ~ 1 / scale: the scale that hits the target is 1 / step
                k = int(np.flatnonzero(settled)[0])
                if ok[k] and abs(1.0 / float(step[k]) - 1.0) <= 0.8 * scale_limit:
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
            if iteration - best[5] >= 2:  # two samplings without improvement: the rest is noise
                break
            if not (settled & ~coarse & (np.abs(measured - targets) > _LOOP_TOLERANCE)).any():
                break  # only coarse zones are off: balancing (below) does better than re-sampling
            # Half steps (in log scale) down: small zones respond in jumps and
            # full steps would oscillate; zones that fall short take full steps
            # up, since what ends up too dense can be thinned afterwards.
            factors = factors * np.where(small & (step > 1.0), step, np.sqrt(step))
        worst, points, triangles, segments, measured, iteration, edges, inside, growing, fixed = best
        if single and worst > _TOLERANCE / 4:
            points, segments, measured = _fine_tune_scale(points, edges, meter, targets, measured, width,
                                                          scale_limit, area)
        elif calibration == "measured" and worst > _TOLERANCE and np.count_nonzero(settled) > 1:
            # Zones still off target after calibration (small ones, or dense ones next to a
            # sparse neighbour that keeps their samples apart) are balanced edge by edge.
            off = small | (settled & np.isfinite(measured) & (np.abs(measured - targets) > _TOLERANCE))
            # The edges' inside lengths are known already: balancing measures only new edges.
            known = {"keys": _edge_keys(edges), "values": inside}
            points, triangles, segments, measured = _balance_zones(
                points, triangles, meter, targets, width, off, known=known, growing=growing,
                limit=lambda segs: _uncrowded(segs, dmap, width), fixed=fixed)
        keep = _uncrowded(segments, dmap, width)
        if not keep.all():
            segments = segments[keep]
            measured = meter.densities_of(meter.inside_all(segments), width)
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
            radius = paper_radius(target, width) if calibration == "paper" else KAPPA * width / target
            # what will be printed of the part: its lines inside the infill area, to its edge as Cura's
            # (the footprint's own border shrunk, not the borders between its parts)
            kept = None if printed_area is area else to_multipolygon(part.intersection(printed_area))
            infill_area = part.area if kept is None else kept.area
            # (clipped lines come and go with the samples: half a point is as close as a resampling gets)
            tolerance = _TOLERANCE if kept is None else max(_TOLERANCE, _PRINTED_TOLERANCE)
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
        chosen = _paper_choices(tried, zone_of, np.asarray(printed_areas), np.asarray(targets), width)
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


def _raster_meter(area, dmap: DensityMap, width: float):
    """A `_RasterMeter` of the zones of a sharp-border density map over `area`.

    The zones are measured whole inside `area` (the infill area), border
    bands included: a region prints its density over all of itself, the
    band where the pattern changes included.  The cell is `_CELL` line
    widths, larger when the footprint's box would need more than
    `_MAX_CELLS` cells.  None (measure exactly, `_ZoneMeter`)
    when fewer than two zones have cells (a single zone is calibrated to a
    tighter tolerance), or when the cell grew wider than a line and a zone
    has under `_FEW_CELLS` cells.
    """
    x0, y0, x1, y1 = area.bounds
    cell = max(_CELL * width, math.sqrt(max(x1 - x0, 0.0) * max(y1 - y0, 0.0) / _MAX_CELLS))
    zones = len(dmap.densities)
    raster = dmap.raster(area, cell)
    if raster is None:
        return None
    counts = raster.counts(zones)
    present = counts[counts > 0]
    if present.size < 2 or (cell > width and present.min() < _FEW_CELLS):
        return None  # one zone; or a zone of a few cells wider than a line (a large part): exact
    return _RasterMeter(raster, zones)


def _zone_interiors(zones: list, width: float) -> list:
    """Zones without a band of one line width along their borders with other zones.

    Across a border between two densities the pattern changes over a few
    samples; with a feather the band where it does is the map's blend, so each
    zone's core is calibrated on the rest.  Borders with the
    footprint's outline are kept; a zone that the band would (nearly) swallow
    is kept whole, as is a zone narrower on average than 1.4 widths (twice
    its area over its perimeter: a strip that narrow loses over 70 % to a
    band along one side).
    """
    present = [k for k, z in enumerate(zones) if z.area > 0]
    if len(present) < 2:
        return zones
    out = list(zones)
    for k in present:
        zone = zones[k]
        # Narrow zones are kept whole without cutting (thin strips between the walls and the
        # regions have long ragged outlines that are costly to cut).
        if 2.0 * zone.area < _THIN * width * zone.length:
            continue
        others = unary_union([zones[j] for j in present if j != k])
        inner = to_multipolygon(zone.difference(others.buffer(width, 4)))
        if inner.area >= 0.3 * zone.area:
            out[k] = inner
    return out


def _scale_limit(area, reach: float) -> float:
    """Largest relative scaling of a pattern about the footprint's centre that still covers it."""
    center = np.asarray(area.centroid.coords[0])
    extent = float(np.hypot(*(np.asarray(area.envelope.exterior.coords) - center).T).max())
    return min(0.3, 0.6 * reach / max(extent, 1e-9))


def _fine_tune_scale(points, edges, meter, targets, measured, width, limit, area, evaluations: int = 12):
    """Scale a single-zone pattern about the footprint centre to hit its target.

    When the radius is large against the region, re-sampling changes the
    printed length in jumps.  Scaling the points keeps the triangulation (it
    stays Delaunay) and changes the length inside the zone continuously
    (about as 1 / scale), so secant steps on log density against log scale,
    kept inside a bracket, find the scale in a few measurements.  The scale
    is limited to 1 +- `limit` so that the pattern still covers the footprint.

    Returns
    -------
    (points, segments, measured)
        Scaled points (n, 2), their edges (k, 2, 2), measured density per zone.
    """
    zone_index = int(np.flatnonzero(meter.areas > 0)[0])
    zone_area, target = float(meter.areas[zone_index]), targets[zone_index]
    center = np.asarray(area.centroid.coords[0])
    base = points[edges]

    def density_at(scale):
        return meter.inside(center + (base - center) * scale, zone_index).sum() * width / zone_area

    lo, hi = 1.0 - limit, 1.0 + limit  # density falls as the scale grows
    s0, d0 = 1.0, float(measured[zone_index])  # `measured`: the unscaled pattern's densities
    best = (abs(d0 - target), 1.0, d0)
    s1 = float(np.clip(s0 * d0 / target, lo, hi)) if d0 > 0 else hi
    for _ in range(evaluations):
        d1 = density_at(s1)
        if abs(d1 - target) < best[0]:
            best = (abs(d1 - target), s1, d1)
        if best[0] <= _TOLERANCE / 4 or d1 <= 0:
            break
        lo, hi = (s1, hi) if d1 > target else (lo, s1)
        # secant in log-log (exponent about -1), bisection when it leaves the bracket
        slope = (math.log(d1) - math.log(d0)) / (math.log(s1) - math.log(s0)) if d0 > 0 and s1 != s0 else -1.0
        slope = slope if slope < -0.2 else -1.0
        s2 = s1 * math.exp((math.log(target) - math.log(d1)) / slope)
        if not lo < s2 < hi:
            s2 = 0.5 * (lo + hi)
        s0, d0, s1 = s1, d1, s2
        if hi - lo < 1e-9:
            break
    _, scale, density = best
    scaled = center + (points - center) * scale
    measured = [float(density) if k == zone_index else float("nan") for k in range(len(meter.areas))]
    return scaled, scaled[edges], measured


def _paper_choices(tried: list, zone_of: np.ndarray, areas: np.ndarray, targets: np.ndarray,
                   width: float) -> list[int]:
    """Which sampling of each convex part the paper layout keeps: its zone's whole printed density closest.

    Each part's closest sampling first; then, zone by zone, the one change of one
    part's sampling that brings the zone's printed length nearest its target,
    while one does (a small part prints in jumps of several points; over a
    zone of many parts the jumps are traded against each other).

    Parameters
    ----------
    tried : list of list of (float, ...)
        Per part, its samplings; each starts with its printed length, mm.
    zone_of : ndarray of int, shape (parts,)
    areas : ndarray, shape (parts,)
        Each part's printed area, mm^2.
    targets : ndarray, shape (zones,)
        Density per zone, a fraction.
    width : float
        Line width, mm.

    Returns
    -------
    list of int
        The index into each part's samplings.
    """
    most = max((len(samplings) for samplings in tried), default=0)
    lengths = np.full((len(tried), most), np.nan)  # (parts, tries) printed mm; NaN: no such try
    for i, samplings in enumerate(tried):
        lengths[i, : len(samplings)] = [t[0] for t in samplings]
    wanted = targets[zone_of] * areas / width  # mm of line each part would print at its target
    chosen = np.nanargmin(np.abs(lengths - wanted[:, None]), axis=1) if len(tried) else np.zeros(0, np.intp)
    for zone in np.unique(zone_of).tolist():
        members = np.flatnonzero(zone_of == zone)
        goal = float(wanted[members].sum())
        own = lengths[members]
        for _ in range(4 * len(members)):  # (each change makes the error smaller: this bounds the walk)
            current = own[np.arange(len(members)), chosen[members]]
            total = float(current.sum())
            # every part's every try in place of its current one: the zone's error, (members, tries)
            error = np.abs(total - current[:, None] + own - goal)
            flat = int(np.nanargmin(error))
            if not error.flat[flat] < abs(total - goal) - 1e-9:
                break
            chosen[members[flat // own.shape[1]]] = flat % own.shape[1]
    return chosen.tolist()


def _balance_zones(points, triangles, meter, targets, width, small, rounds: int = 12, known=None, growing=None,
                   limit=None, fixed: int = 0):
    """Bring zones that calibration cannot reach to their targets.

    A zone smaller than about two of its own radii cannot reach its target in
    one triangulation: a sparse one is crossed by its denser neighbours'
    edges, a dense one loses samples near a sparse neighbour (whose samples
    keep their larger radius free).  Each round thins the zones that print
    too dense (`_thin_dense_zones`), then inserts circumcentres of the widest
    triangles in zones that print too sparse (Delaunay refinement: edges go
    where the zone is emptiest and the triangulation stays Delaunay).  The
    rounds stop when no zone is short, or after two rounds that did not make
    the largest shortfall smaller (the best round is kept).

    Only the zones flagged in `small` are balanced; `meter` (`_ZoneMeter` or
    `_RasterMeter`) holds the zones and measures them; `known` (see
    `_inside_lengths`) may hold the inside lengths of the triangles' edges
    already; `growing` (`GrowingDelaunay`), a triangulation of `points` to
    go on from; `limit` and `fixed`, passed to `_thin_dense_zones`.

    Returns
    -------
    (points, triangles, segments, measured)
    """
    known = {} if known is None else known  # edges measured (points are only appended: indices stay)
    # `growing`: qhull's triangulation, points added round by round
    best = None  # (largest shortfall, round, points, triangles, segments, measured) of the best round
    for turn in range(rounds):
        segments, measured = _thin_dense_zones(points, triangles, meter, targets, width, small, known, limit, fixed)
        short, shortfall = _shortfall(measured, targets, small)
        if best is None or shortfall < best[0]:
            best = (shortfall, turn, points, triangles, segments, measured)
        # Done; or two rounds without a smaller shortfall: refining one zone takes from
        # another (they share the new edges), the rounds go back and forth.
        if not short or turn - best[1] >= 2:
            break
        # In a fixed order from a fixed corner: the centres do not depend on how qhull lists them.
        tri = canonical_triangles(triangles)
        a, b, c = (points[tri[:, k]] for k in range(3))
        d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
        ok = np.abs(d) > 1e-12
        d = np.where(ok, d, 1.0)
        sa, sb, sc = ((p * p).sum(axis=1) for p in (a, b, c))
        center = np.stack((
            (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d,
            (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d,
        ), axis=1)
        radius = np.where(ok, np.hypot(*(center - a).T), 0.0)
        added = []
        for k in short:
            inside = meter.contains(k, center)  # ascending, as flatnonzero of the full test
            if inside.size == 0:
                continue
            # About 3 circumradii of line per insertion; at most a third of
            # the zone's triangles per round.
            missing = (targets[k] - measured[k]) * meter.areas[k] / width
            widest = inside[np.argsort(-radius[inside])]
            count = int(np.clip(missing / max(3.0 * radius[widest[0]], 1e-9), 1, max(1, inside.size // 3)))
            added.append(center[widest[:count]])
        if not added:
            break
        added = np.concatenate(added)
        triangles = None
        if growing is None:
            growing = _growing_delaunay(points)
        if growing is not None:
            try:
                triangles = growing.add(added)
            except (QhullError, ValueError):  # qhull refuses: triangulate afresh (and start over next round)
                growing = None
        points = np.concatenate((points, added))
        if triangles is None:
            triangles = delaunay_triangles(points)
    else:
        segments, measured = _thin_dense_zones(points, triangles, meter, targets, width, small, known, limit, fixed)
        if best is None or _shortfall(measured, targets, small)[1] < best[0]:
            return points, triangles, segments, measured
    _, _, points, triangles, segments, measured = best
    return points, triangles, segments, measured


def _shortfall(measured, targets, small) -> tuple[list, float]:
    """The zones flagged in `small` that print below target (by more than the tolerance), and the largest gap."""
    short = [k for k in np.flatnonzero(small) if measured[k] < targets[k] - _TOLERANCE]
    return short, max((targets[k] - measured[k] for k in short), default=0.0)


def _growing_delaunay(points):
    """A `GrowingDelaunay` of the points (n, 2), or None where qhull refuses them (degenerate)."""
    try:
        return GrowingDelaunay(points)
    except (QhullError, ValueError):
        return None


def _thin_dense_zones(points, triangles, meter, targets, width, small, known=None, limit=None, fixed: int = 0):
    """Leave out edges in zones that print denser than their target.

    A zone smaller than about two of its own radii cannot reach a low target
    in one triangulation: the edges between its denser neighbours' samples
    cross it.  Such a zone gets its longest edges left out (first at most one
    per triangle, so cells become quadrilaterals; never leaving a loose end)
    until its printed density is as close to the target as whole edges allow.

    `known` caches the edges' inside lengths between calls on the same
    points (more appended), so only new edges are measured; `limit`
    (segments (e, 2, 2) -> bool (e,)), the edges kept before any thinning
    (`uncrowded_edges`); `fixed`, how many of the first points lie on a
    lattice: edges between two of them are left out last (a lattice with a
    diagonal missing is a grid of rhombi, far less stiff per gram).

    Returns
    -------
    (segments, measured)
        Printed edges (k, 2, 2) and the measured density per zone.
    """
    # The edges (as `unique_edges` gives them) and the triangles on each side of every edge
    # (-1 on the hull), from one sort of the triangles' sides by vertex pair.
    n = len(points)
    t = np.asarray(triangles, dtype=np.int64)
    u, v = t.ravel(), t[:, [1, 2, 0]].ravel()  # side k of triangle i at 3 i + k
    side_key = np.minimum(u, v) * n + np.maximum(u, v)
    order = np.argsort(side_key, kind="stable")
    sorted_key = side_key[order]
    first = np.ones(len(sorted_key), dtype=bool)
    first[1:] = sorted_key[1:] != sorted_key[:-1]
    edge_of = np.cumsum(first) - 1
    key = sorted_key[first]
    edges = np.stack((key // n, key % n), axis=1).astype(np.intp)
    owners = np.full((len(edges), 2), -1, dtype=np.int64)
    owners[edge_of[first], 0] = order[first] // 3
    owners[edge_of[~first], 1] = order[~first] // 3
    segments = points[edges]
    keep = np.ones(len(edges), dtype=bool) if limit is None else limit(segments)  # (crowded nodes thinned first)
    opened = set()  # triangles with an edge left out
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    # Length of every edge inside every zone: leaving edges out does not change it.
    inside_of = _inside_lengths(edges, segments, meter, {} if known is None else known)
    # Edges at each vertex, kept up to date as edges are left out (plain ints: the walk below
    # is sequential, and plain Python numbers are cheaper there than numpy scalars).
    degree = np.bincount(edges[keep].ravel(), minlength=n).tolist()
    for k, (zone_area, target, thin) in enumerate(zip(meter.areas.tolist(), targets, small)):
        if not thin or zone_area <= 0:
            continue
        inside = np.where(keep, inside_of[k], 0.0)
        excess = (inside.sum() * width / zone_area - target) * zone_area / width  # mm of line too many
        if excess <= 0:
            continue
        candidates = np.flatnonzero(keep & (inside >= 0.5 * length))
        on_lattice = (edges[candidates] < fixed).all(axis=1)
        candidates = candidates[np.lexsort((-length[candidates], on_lattice))]
        ends, sides = edges[candidates].tolist(), owners[candidates].tolist()
        pieces = inside[candidates].tolist()
        excess = float(excess)
        left_out, taken = [], [False] * len(pieces)
        # First one edge per triangle; then any edge that leaves no loose end.
        for strict in (True, False):
            for i, ((a, b), (one, other), piece) in enumerate(zip(ends, sides, pieces)):
                if excess - 0.5 * piece <= 0:
                    break
                if taken[i] or (strict and (one in opened or other in opened)) or min(degree[a], degree[b]) <= 2:
                    continue
                left_out.append(i)
                taken[i] = True
                degree[a] -= 1
                degree[b] -= 1
                opened.update((one, other))
                opened.discard(-1)  # -1: no triangle on that side
                excess -= piece
        keep[candidates[left_out]] = False
    measured = [float(inside_of[k][keep].sum()) * width / area if area > 0 else float("nan")
                for k, area in enumerate(meter.areas.tolist())]
    return segments[keep], measured


def _inside_lengths(edges, segments, meter, known: dict) -> np.ndarray:
    """Length of every edge (e, 2) inside every zone of `meter`, shape (zones, e), cached in `known`.

    `known` holds ``"keys"`` (sorted int64 edge keys) and ``"values"``
    (zones, keys) from earlier calls on the same points.
    """
    key = _edge_keys(edges)
    old_keys = known.get("keys", np.zeros(0, np.int64))
    old_values = known.get("values", np.zeros((len(meter.areas), 0)))
    slot = np.minimum(np.searchsorted(old_keys, key), max(len(old_keys) - 1, 0))
    hit = (old_keys[slot] == key) if len(old_keys) else np.zeros(len(key), dtype=bool)
    values = np.zeros((len(meter.areas), len(edges)))
    values[:, hit] = old_values[:, slot[hit]]
    new = np.flatnonzero(~hit)
    if new.size:
        values[:, new] = meter.inside_all(segments[new])
    if np.all(key[1:] > key[:-1]):  # as `_thin_dense_zones` lists them: sorted already
        known["keys"], known["values"] = key, values
        return values
    order = np.argsort(key, kind="stable")
    known["keys"], known["values"] = key[order], values[:, order]
    return values


def _edge_keys(edges: np.ndarray) -> np.ndarray:
    """One int64 per edge (e, 2) of vertex indices, ordered as the rows are (lexicographically)."""
    return edges[:, 0].astype(np.int64) * (1 << 32) + edges[:, 1]


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
