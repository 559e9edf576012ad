"""The paper's layout (Qiao et al. 2022): each density zone decomposed into convex parts, each part
sampled and triangulated on its own.

`build_paper` is ``layout="paper"`` of `pattern.InfillPattern.build`: the zones are cut into
convex parts (`decomposition.decompose_convex`), every part gets Poisson-disk samplings at its
zone's radius (Bridson's by default) until one prints its target where it is printed, and
`calibration.paper_choices` picks one sampling per part so that every zone as a whole prints
closest to its target.  Densities are fractions, lengths mm.
"""

from __future__ import annotations

import numpy as np

from .calibration import TOLERANCE, paper_choices
from .decomposition import decompose_convex
from .density import DensityMap, sampling_radius, shortest_edges
from .geometry import polygons_of, to_multipolygon
from .metering import measured_density, segment_length
from .routing import clip_segments
from .sampling import sample_poisson_disk
from .triangulation import delaunay_triangles, relax_points, uncrowded_edges, unique_edges

__all__ = ["build_paper"]

_PRINTED_TOLERANCE = 0.005  # a part calibrated on its clipped lines: half a point is as close as a resampling gets
_MAX_TRIES = 8
_FEW_TRIES = 4  # a part a few samples across is as dense as its samples fall
_FEW_SAMPLES = 30.0  # ... under this many squared radii of area


def build_paper(area, dmap: DensityMap, width: float, seed: int, calibration: str, relax: int, sampler: str,
                printed_area) -> tuple:
    """The paper layout's pattern over `area`, each part calibrated where it is `printed_area`.

    Parameters
    ----------
    area : shapely MultiPolygon
        The footprint, mm.
    dmap : DensityMap
    width : float
        Line width, mm.
    seed : int
    calibration : {"measured", "paper"}
        ``paper``: one sampling per part at Formula (6)'s radius.
    relax : int
        Lloyd relaxation steps per part.
    sampler : {"bridson", "fast"}
    printed_area : shapely MultiPolygon
        Where the lines will be printed, inside `area` (`area` itself: the whole parts).

    Returns
    -------
    (segments, points, triangles, measured)
        Edges (k, 2, 2) mm, samples (n, 2) mm, triangles (t, 3) indices into them, and the
        density of each zone (list, fractions).
    """
    parts = _convex_parts(area, dmap, width)
    targets = dmap.densities
    tried, printed_areas = [], []  # per part: its samplings [(printed mm, points, triangles, segments)]
    for part_index, (part, zone_index) in enumerate(parts):
        # what will be printed of the part: its lines inside the infill area, to its edge as Cura's
        # (the footprint's own border shrunk, not the borders between its parts)
        kept = None if printed_area is area else to_multipolygon(part.intersection(printed_area))
        samplings = _part_samplings(part, kept, targets[zone_index], width, seed + part_index, seed, calibration,
                                    relax, sampler)
        tried.append(samplings)
        printed_areas.append(part.area if kept is None else kept.area)
    zone_of = np.array([zone_index for _, zone_index in parts], dtype=np.intp)
    chosen = paper_choices(tried, zone_of, np.asarray(printed_areas), np.asarray(targets), width)
    points, triangles, segments = _joined([samplings[choice][1:] for samplings, choice in zip(tried, chosen)])
    segments = segments[uncrowded_edges(segments, shortest_edges(segments, dmap, width))]
    measured = [measured_density(segments, zone, width) for zone in dmap.zones(area)]
    return segments, points, triangles, measured


def _convex_parts(area, dmap: DensityMap, width: float) -> list:
    """The zones' convex parts: [(Polygon, zone index)], slivers no line fits in left out."""
    parts = []
    for zone_index, zone in enumerate(dmap.zones(area)):
        for polygon in polygons_of(zone):
            if polygon.area < 1e-3 * width * width:
                continue  # a sliver between zones: no line fits in it
            # (a decomposition of a needle-thin zone can leave pieces thinner still)
            parts.extend((convex, zone_index) for convex in decompose_convex(polygon)
                         if convex.area >= 1e-3 * width * width)
    return parts


def _part_samplings(part, kept, target: float, width: float, part_seed: int, seed: int, calibration: str,
                    relax: int, sampler: str) -> list:
    """One convex part's samplings [(printed mm, points, triangles, segments)], the last the closest tried.

    The radius is corrected after each sampling (density ~ 1 / r) until the part prints `target`
    within the tolerance where it is printed (`kept`, a MultiPolygon, or None: the whole part).
    """
    radius = sampling_radius(target, width, calibration)
    infill_area = part.area if kept is None else kept.area
    # (clipped lines come and go with the samples: half a point is as close as a resampling gets)
    tolerance = TOLERANCE if kept is None else max(TOLERANCE, _PRINTED_TOLERANCE)
    samplings = []
    tries = _MAX_TRIES if part.area > _FEW_SAMPLES * radius * radius else _FEW_TRIES
    for _ in range(tries if calibration == "measured" else 1):
        points = sample_poisson_disk(part, radius, seed=part_seed, method=sampler)
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
    return samplings


def _joined(chosen: list) -> tuple:
    """The parts' (points, triangles, segments) as one pattern, triangle indices offset."""
    all_points, all_triangles, all_segments = [], [], []
    offset = 0
    for points, triangles, segments in chosen:
        all_points.append(points)
        all_triangles.append(triangles + offset)
        all_segments.append(segments)
        offset += len(points)
    points = np.concatenate(all_points) if all_points else np.zeros((0, 2))
    triangles = np.concatenate(all_triangles) if all_triangles else np.zeros((0, 3), np.intp)
    segments = np.concatenate(all_segments) if all_segments else np.zeros((0, 2, 2))
    return points, triangles, segments
