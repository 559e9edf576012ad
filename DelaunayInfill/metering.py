"""Metering: how densely a set of segments fills each density zone.

A zone's printed density is the length of line inside it times the line
width over its area (a fraction; lengths in mm, areas in mm^2).
`measured_density` measures one zone exactly by clipping.  Calibration
measures the same segments against the same zones many times, so it uses a
meter built once per set of zones:

`ZoneMeter`
    Zones given as polygons, measured exactly (up to rounding): segments
    are cut where they cross a zone boundary.
`RasterMeter`
    Several sharp-border zones given as a `ZoneRaster`: each segment counts
    piece by piece for the zone of the cell under the piece.

Both have the same interface: ``areas`` (zones,) mm^2, ``inside_all``
(lengths inside every zone), ``inside`` (one zone), ``contains`` (points in
a zone), ``densities`` and ``densities_of``.  `meter_for` picks the meter
the pattern build calibrates a density map with.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .density import LATTICE_SIDE, DensityMap, ZoneRaster
from .geometry import boundary_segments, contains_xy, empty_area, to_multipolygon, unary_union
from .routing import clip_segments, split_segments

__all__ = ["RasterMeter", "ZoneMeter", "border_bands", "measured_density", "meter_for", "raster_meter",
           "segment_length", "zone_interiors"]

_THIN = 1.4  # zone interiors: a zone of mean width under this many line widths is kept whole
_FEW = 48  # zone meter: up to this many pieces to cut query the edges' tree (no tree of their own)
_CELL = 0.45  # several sharp-border zones: raster cell side, in line widths
_MAX_CELLS = 120_000  # ... the cell grows beyond that when the footprint's box would need more cells
_FEW_CELLS = 400  # ... cells wider than a line: a zone of fewer cells is measured exactly instead


def segment_length(segments: np.ndarray) -> float:
    """Total length of segments.

    Parameters
    ----------
    segments : array_like, shape (k, 2, 2)
        Segments (start, end), mm.

    Returns
    -------
    float
        Their total length, mm.
    """
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    return float(np.hypot(*(segments[:, 1] - segments[:, 0]).T).sum())


def measured_density(segments: np.ndarray, zone, line_width: float) -> float:
    """Printed fill fraction of `zone`, measured exactly by clipping.

    Parameters
    ----------
    segments : array_like, shape (k, 2, 2)
        Lines, mm.
    zone : shapely (Multi)Polygon
        The zone, mm.
    line_width : float
        mm.

    Returns
    -------
    float
        Length inside the zone x line width / the zone's area, a fraction
        (NaN if the zone has no area).
    """
    if zone.is_empty or zone.area <= 0:
        return float("nan")
    return segment_length(clip_segments(segments, zone)) * line_width / zone.area


class _Meter:
    """What both meters share; a meter sets ``areas`` and implements `inside_all` and `contains`.

    Attributes
    ----------
    areas : ndarray, shape (zones,)
        Each zone's area, mm^2 (0: a zone without area).
    """

    areas: np.ndarray

    def inside_all(self, segments: np.ndarray) -> np.ndarray:
        """Length of each segment inside each zone.

        Parameters
        ----------
        segments : array_like, shape (m, 2, 2)
            mm.

        Returns
        -------
        ndarray, shape (zones, m)
            mm.
        """
        raise NotImplementedError

    def contains(self, k: int, xy: np.ndarray) -> np.ndarray:
        """Indices of the points (m, 2) mm inside zone k, shape (h,) ascending."""
        raise NotImplementedError

    def inside(self, segments: np.ndarray, k: int) -> np.ndarray:
        """Length (mm) of each segment (m, 2, 2) inside zone k, shape (m,)."""
        return self.inside_all(segments)[k]

    def densities(self, segments: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone of segments (m, 2, 2) mm at line width `width` mm.

        Returns
        -------
        ndarray, shape (zones,)
            Fractions; NaN where a zone has no area.
        """
        return self.densities_of(self.inside_all(segments), width)

    def densities_of(self, inside: np.ndarray, width: float) -> np.ndarray:
        """Measured density per zone from `inside_all`'s lengths.

        Parameters
        ----------
        inside : ndarray, shape (zones, m)
            Lengths inside each zone, mm.
        width : float
            Line width, mm.

        Returns
        -------
        ndarray, shape (zones,)
            Fractions; NaN where a zone has no area.
        """
        return _densities(inside.sum(axis=1), self.areas, width)


class ZoneMeter(_Meter):
    """Length of segments inside fixed zones, fast enough to call in calibration loops.

    All zones are measured in one pass.  A segment whose midpoint lies
    farther from every zone boundary than half its length is wholly inside
    or outside each zone (a point-in-area test on the midpoint says which);
    only the others are cut where they cross any zone boundary (as
    `clip_segments` does, against boundary edges prepared once), and each
    piece is tested by its midpoint.  Boundary distances come from the
    edges' midpoints, the edges being at most `piece` mm long (an error of
    at most piece / 2, allowed for).

    Parameters
    ----------
    zones : list of shapely (Multi)Polygon
        The zones, mm; empty ones (or ones without area) measure nothing.
    piece : float
        Longest boundary edge, mm (boundaries are split to it).

    Attributes
    ----------
    areas : ndarray, shape (zones,)
        Each zone's area, mm^2 (0 where empty).
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
        """Indices of the points inside zone k.

        Only points inside the zone's bounding box are tested (the rest cannot be inside).

        Parameters
        ----------
        k : int
            Zone index.
        xy : ndarray, shape (m, 2)
            Points, mm.

        Returns
        -------
        ndarray of int, shape (h,)
            Ascending.
        """
        x0, y0, x1, y1 = self.bounds[k]
        x, y = xy[:, 0], xy[:, 1]
        near = ((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).nonzero()[0]
        return near[contains_xy(self.zones[k], x[near], y[near])]

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


def _densities(lengths: np.ndarray, areas: np.ndarray, width: float) -> np.ndarray:
    """Fill fraction per zone from line lengths (zones,) mm and areas (zones,) mm^2; NaN where no area."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(areas > 0, lengths * width / np.where(areas > 0, areas, 1.0), np.nan)


class RasterMeter(_Meter):
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

    Attributes
    ----------
    areas : ndarray, shape (zones,)
        Each zone's cells' area, mm^2.
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

    def contains(self, k: int, xy: np.ndarray) -> np.ndarray:
        """Indices of the points (m, 2) mm in zone k's cells, shape (h,) ascending."""
        return np.flatnonzero(self.raster.at(xy) == k)


def _quick_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree built for a few queries: midpoint splits build faster than median ones."""
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def raster_meter(area, dmap: DensityMap, width: float) -> RasterMeter | None:
    """A `RasterMeter` of the zones of a sharp-border density map over `area`.

    The zones are measured whole inside `area` (the infill area), border
    bands included: a region prints its density over all of itself, the
    band where the pattern changes included.  The cell is `_CELL` line
    widths, larger when the footprint's box would need more than
    `_MAX_CELLS` cells.

    Parameters
    ----------
    area : shapely (Multi)Polygon
        Where the zones are measured, mm.
    dmap : DensityMap
        Sharp borders (no feather).
    width : float
        Line width, mm.

    Returns
    -------
    RasterMeter or None
        None (measure exactly, `ZoneMeter`) when fewer than two zones have
        cells (a single zone is calibrated to a tighter tolerance), or when
        the cell grew wider than a line and a zone has under `_FEW_CELLS`
        cells.
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
    return RasterMeter(raster, zones)


def zone_interiors(zones: list, width: float) -> list:
    """Zones without a band of one line width along their borders with other zones.

    Across a border between two densities the pattern changes over a few
    samples; with a feather the band where it does is the map's blend, so each
    zone's core is calibrated on the rest.  Borders with the
    footprint's outline are kept; a zone that the band would (nearly) swallow
    is kept whole, as is a zone narrower on average than 1.4 widths (twice
    its area over its perimeter: a strip that narrow loses over 70 % to a
    band along one side).

    Parameters
    ----------
    zones : list of shapely MultiPolygon
        The zones (as `DensityMap.zones` gives them), mm.
    width : float
        Line width, mm: the band's width.

    Returns
    -------
    list of shapely MultiPolygon
        One per zone, in the same order.
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


def meter_for(area, dmap: DensityMap, width: float) -> ZoneMeter | RasterMeter:
    """The meter the seamless build calibrates `dmap`'s zones with, over `area`.

    Several sharp-border zones: a `RasterMeter` where it measures well
    (`raster_meter`).  Else a `ZoneMeter` of the whole zones, border bands
    included (what a region prints is what it is asked for); a feathered
    map's zones are its cores instead (`zone_interiors` of the zones shrunk
    by half the feather: the blend between them is the map's).

    Parameters
    ----------
    area : shapely (Multi)Polygon
        Where the lines are printed (the infill area), mm.
    dmap : DensityMap
    width : float
        Line width, mm.

    Returns
    -------
    ZoneMeter or RasterMeter
        One zone per density of `dmap` (index 0 the base).
    """
    meter = raster_meter(area, dmap, width) if dmap.feather <= 0 and dmap.regions else None
    if meter is None:
        zones = dmap.zones(area)
        if dmap.feather > 0:  # calibrate the zone cores, not the blend bands between them
            cores = [to_multipolygon(z.buffer(-0.5 * dmap.feather)) for z in zones]
            zones = [core if core.area > 0 else z for core, z in zip(cores, zones)]
        # Whole zones, border bands included: what a region prints is what it is asked for.  (A
        # feathered map calibrates the zone cores without a band: the blend between them is the map's.)
        meter = ZoneMeter(zone_interiors(zones, width) if dmap.feather > 0 else zones)
    return meter


def border_bands(zones: list, densities, width: float, printed=None) -> ZoneMeter | None:
    """A `ZoneMeter` of each zone's band along its borders with denser zones, one sparse spacing wide.

    Issue 15's transition lies on the denser side: a zone's band of one of its own lattice sides
    s = 2 sqrt(3) w / d next to any denser zone is to print the zone's own density.  Zone k's band
    is measured as zone k of the meter (empty where no denser zone borders it).  With `printed`
    (where the layer prints), the band's part within s of its outline is left out where enough
    of the band stays (a quarter): lines clipped at the part's own edge are not the border's.

    Parameters
    ----------
    zones : list of shapely MultiPolygon
        The zones (as `DensityMap.zones` gives them, clipped to where the layer prints), mm.
    densities : sequence of float
        Each zone's density, fractions.
    width : float
        Line width, mm.
    printed : shapely (Multi)Polygon, optional
        Where the layer prints, mm.

    Returns
    -------
    ZoneMeter or None
        None when no zone borders a denser one.
    """
    densities = [float(d) for d in densities]
    bands, any_band = [], False
    for zone, d in zip(zones, densities):
        denser = [z for z, other in zip(zones, densities) if other > d and not z.is_empty and z.area > 0]
        if zone.is_empty or zone.area <= 0 or d <= 0 or not denser:
            bands.append(empty_area())
            continue
        reach = LATTICE_SIDE * width / d
        band = to_multipolygon(zone.intersection(unary_union(denser).buffer(reach, 8)))
        if printed is not None and band.area > 0:
            core = to_multipolygon(band.intersection(printed.buffer(-reach, 8)))
            band = core if core.area >= 0.25 * band.area else band
        any_band |= band.area > 0
        bands.append(band)
    return ZoneMeter(bands) if any_band else None
