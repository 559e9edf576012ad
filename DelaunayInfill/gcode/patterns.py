"""Patterns per mesh for the G-code pass: one pattern reused over a mesh's layers while it covers them.

`PatternCache` hands the layer step a pattern whose footprint covers the layer's infill area: a part that
stays the same or shrinks upwards uses one pattern for all its layers (its infill stacks); a section that
grows gets one planned over where the mesh's outer walls ever are; a thin area that comes back layer after
layer gets one calibrated on it where the wider section's pattern prints it off its density.
"""

from __future__ import annotations

import dataclasses
import hashlib
import weakref
from dataclasses import dataclass

import numpy as np
from shapely.geometry import box as shapely_box

from ..density import LATTICE_SIDE
from ..geometry import covers, polygons_of, to_multipolygon, unary_union
from ..metering import measured_density
from .settings import ProcessSettings

__all__ = ["PatternCache", "REFIT_AFTER", "REFIT_MISS", "RegionSoFar", "shape_key"]


def _build_pattern(footprint, density, line_width, regions, settings: ProcessSettings, infill_area=None):
    from ..pattern import InfillPattern

    return InfillPattern.build(
        footprint,
        density,
        line_width,
        regions=[(a, d) for a, d, _ in regions],
        seed=settings.seed,
        layout=settings.layout,
        calibration=settings.calibration,
        relax=settings.relax,
        feather=settings.feather,
        infill_area=infill_area,
    )


class PatternCache:
    """Patterns per (mesh, density, line width), reused while they still fit.

    A cached pattern is reused for a layer when its footprint covers the
    layer's infill area and its density regions match the layer's: a region
    matches when the symmetric difference is below 2 % of its area or half a
    line width along its perimeter, whichever is larger.  Otherwise a new
    pattern is built over the union of the old footprint and the new area, so
    a part that stays the same or shrinks upwards uses one pattern for all its
    layers (its infill stacks), and the pattern is calibrated on the area that
    is really printed.  A thin area that comes back layer after layer (a cup's
    or a box's wall over its floor) gets a pattern of its own where the wider
    section's pattern prints it off its density (`REFIT_AFTER`).
    """

    def __init__(self, settings: ProcessSettings, per_key: int = 6, extents: dict | None = None):
        self.settings = settings
        self.extents = extents or {}  # mesh -> its outer walls' [x0, y0, x1, y1] over the print, mm
        self.per_key = per_key
        self.entries: dict[tuple, list[tuple[object, list, object]]] = {}
        self.builds = 0
        self._covered: dict[int, object] = {}  # id(footprint) -> last area found inside it
        self._same_memo: dict[tuple, bool] = {}
        self._thin_runs: dict[tuple, _ThinRun] = {}  # per key: the thin area that came last, and how often
        # the patterns planned over a growing mesh's extent, by id (gone with the pattern: ids are reused)
        self._planned_ahead: weakref.WeakValueDictionary = weakref.WeakValueDictionary()

    def _same(self, a, b, line_width: float) -> bool:
        if a is b:
            return True
        fa, fb = _fingerprint(a), _fingerprint(b)
        if fa == fb:  # the same polygon rebuilt: no boolean operation needed
            return True
        if abs(a.area - b.area) > 0.5 * max(a.area, b.area) + 1e-9:
            return False
        key = (fa, fb, round(line_width, 4))
        hit = self._same_memo.get(key)
        if hit is None:
            tol = max(0.02 * max(a.area, b.area), 0.5 * line_width * max(a.length, b.length), 1e-6)
            hit = a.symmetric_difference(b).area <= tol
            if len(self._same_memo) >= 4096:
                self._same_memo.clear()
            self._same_memo[key] = hit
        return hit

    def _regions_match(self, cached: list, regions: list, line_width: float) -> bool:
        return len(cached) == len(regions) and all(
            abs(cd - d) < 1e-6 and self._same(ca, a, line_width)
            for (ca, cd, _), (a, d, _) in zip(cached, regions, strict=True)
        )

    def get(self, mesh: str, area, density: float, line_width: float, regions: list,
            so_far: RegionSoFar | None = None):
        """A pattern whose footprint covers `area`; returns (pattern, footprint, regions used).

        `so_far`: what the region of `density` has printed so far and how many layers the mesh has left,
        for a thin area's refit (without it the area alone is judged)."""
        key = (mesh, round(density, 4), round(line_width, 3), round(self.settings.feather, 3))
        bucket = self.entries.setdefault(key, [])
        grow_from = None
        for i, (footprint, cached_regions, pattern) in enumerate(bucket):
            if not self._regions_match(cached_regions, regions, line_width):
                continue
            # (the usual answer, inside, from a predicate; the overlay only for an area that leaves it)
            if (self._covered.get(id(footprint)) is area or covers(footprint, area)
                    or area.difference(footprint).area <= max(1e-6, 0.25 * line_width * area.length)):
                self._covered[id(footprint)] = area
                if not regions and self._refit_due(key, area, density, line_width, pattern, so_far):
                    return self._refit(bucket, area, density, line_width)
                bucket.insert(0, bucket.pop(i))
                return pattern, footprint, cached_regions
            if grow_from is None:
                grow_from = footprint
        footprint = area if grow_from is None else unary_union([grow_from, area])
        # (the paper's pipeline plans nothing beyond the infill area: it decomposes that area itself)
        extent = self.extents.get(mesh) if self.settings.layout != "paper" else None
        grows = extent is not None and (grow_from is not None or _reaches_past(extent, area.bounds, _GROWTH_MM))
        if grows:
            # Where the mesh's infill can ever be, once its section is seen to grow upwards (a sphere's
            # lower half, a cone on its tip, a flaring vase): the pattern is already there for the
            # layers above, and their infill stacks.  (A prism, or a section that only shrinks, keeps
            # the pattern of its own area.)
            footprint = unary_union([footprint, shapely_box(*extent)])
        footprint = to_multipolygon(footprint.buffer(line_width, 4))
        # Calibrated where this layer prints (not over the rest of the footprint: a mesh's extent holds
        # its holes and the places round it); a pattern for a section that grows, over its footprint:
        # the layers above print it too, and a first section a few spacings wide would scale the
        # lattice for its own few lines (a sphere's bottom cap: the whole sphere printed 16.8 % for 20 %).
        # With density regions, on this layer's area all the same: a sparse zone's lines keep their distance
        # from a dense one, a band that is a small share of the zone over the footprint and a large one in a
        # thin part (random regions 120: the rest printed 27.6 % for 30 %, calibrated over the footprint).
        planned = (grows or grow_from is not None) and not regions
        printed = to_multipolygon(footprint.buffer(-line_width, 4)) if planned else area
        pattern = self._built(bucket, footprint, density, line_width, regions, printed)
        if grows:
            self._planned_ahead[id(pattern)] = pattern
        return pattern, footprint, regions

    def _built(self, bucket: list, footprint, density: float, line_width: float, regions: list, printed):
        """A pattern over `footprint` calibrated where `printed`, first in `bucket`."""
        pattern = _build_pattern(footprint, density, line_width, regions, self.settings, infill_area=printed)
        self.builds += 1
        bucket.insert(0, (footprint, regions, pattern))
        del bucket[self.per_key :]
        return pattern

    def _refit_due(self, key: tuple, area, density: float, line_width: float, pattern,
                   so_far: RegionSoFar | None) -> bool:
        """Whether `area` has been a thin area `REFIT_AFTER` times in a row and, printed with `pattern` for
        the mesh's layers left, would bring its region more than `REFIT_MISS` off `density` (once a run)."""
        if self._planned_ahead.get(id(pattern)) is pattern:  # (a growing section's: its layers above print it)
            return False
        run = self._thin_runs.get(key)
        if run is not None and _nearly_same(run.area, area, line_width):
            run = dataclasses.replace(run, area=area, layers=run.layers + 1)
        else:
            run = _ThinRun(area, 1)
        if run.layers >= REFIT_AFTER and not run.refitted and run.thin is None:
            run = dataclasses.replace(run, thin=_thin(area, 0.5 * LATTICE_SIDE * line_width / density))
        self._thin_runs[key] = run
        if run.layers < REFIT_AFTER or run.refitted or not run.thin:
            return False
        if run.measured is None or run.measured[0] is not pattern:  # (once a run: its areas are nearly the same)
            run = dataclasses.replace(run, measured=(pattern, measured_density(pattern.segments, area, line_width)))
            self._thin_runs[key] = run
        here = run.measured[1]
        whole = here if so_far is None else so_far.projected(here, area.area)
        if abs(whole - density) <= REFIT_MISS:
            return False
        self._thin_runs[key] = dataclasses.replace(run, refitted=True)
        return True

    def _refit(self, bucket: list, area, density: float, line_width: float):
        """A pattern calibrated on `area` alone, first in `bucket`; returns what `get` returns."""
        footprint = to_multipolygon(area.buffer(line_width, 4))
        self._covered[id(footprint)] = area
        return self._built(bucket, footprint, density, line_width, [], area), footprint, []


def _nearly_same(a, b, tolerance: float) -> bool:
    """Whether two areas are within 2 % of each other's size and their bounds within `tolerance` (mm): a wall
    that comes back, not a section that grows or shrinks every layer (cheap: `shape_key`'s remembered figures)."""
    size_a, _, bounds_a = shape_key(a)
    size_b, _, bounds_b = shape_key(b)
    return (abs(size_a - size_b) <= 0.02 * max(size_a, size_b)
            and max(abs(u - v) for u, v in zip(bounds_a, bounds_b, strict=True)) <= tolerance)


def _thin(area, depth: float) -> bool:
    """Whether no point of `area` lies further than `depth` (mm) from its edge."""
    # (no point of a set lies further from its edge than area / perimeter allows: most areas end here; an
    # area rebuilt from the G-code has many short edges, which a deep inward buffer pays for: simplified first)
    size, perimeter, _ = shape_key(area)  # (remembered: the run's test of sameness has just asked for them)
    return size < depth * perimeter and area.simplify(0.05 * depth).buffer(-0.95 * depth, 1).is_empty


@dataclass(frozen=True)
class RegionSoFar:
    """What a density region has printed so far and how long a mesh of it goes on (`PatternCache.get`)."""

    printed_mm2: float  # line length x line width, mm^2
    area_mm2: float  # the area it was printed over, mm^2
    layers_left: int  # the mesh's layers above this one

    def projected(self, density: float, area_mm2: float) -> float:
        """The region's density (fraction) once an area of `area_mm2` at `density` is printed in this layer
        and every layer left."""
        layers = 1 + max(self.layers_left, 0)
        return (self.printed_mm2 + density * area_mm2 * layers) / max(self.area_mm2 + area_mm2 * layers, 1e-9)


@dataclass(frozen=True)
class _ThinRun:
    """A run of layers whose infill area is the same thin area (`PatternCache`)."""

    area: object  # the last layer's area
    layers: int  # how many layers in a row
    refitted: bool = False  # a pattern of its own was built for the run
    thin: bool | None = None  # whether the area is thin (found once a run is REFIT_AFTER layers long)
    measured: tuple | None = None  # (a pattern, the density it prints on the run's area)


# A thin area (no point more than half a lattice side from its edge) printed this many layers in a row with a
# wider section's pattern gets a pattern calibrated on it where the wider one, printed there for the rest of
# the mesh, would bring the region more than REFIT_MISS (a fraction, issue 15's 2 points) off its density: that
# pattern crosses it with whatever phase it has there (a cup's 2.4 mm wall over its floor at 20 %: 17.0 %,
# the cup 17.9 %).  The new pattern does not stack on the one below for one layer: within the target the
# wider pattern stays (the bushing's tube: 1.6 points over, stacked).  From the wall's first processed layer:
# the layers above that repeat one of its layers are written from it (`replay`), and with a later refit some
# would copy the wider pattern's layer and some the new one's, and the wall would not stack.
REFIT_AFTER = 1
REFIT_MISS = 0.02


# A mesh's extent reaching this far (mm) past a layer's infill area (walls and all) means its section
# grows further up: more than any wall thickness or skin overlap.
_GROWTH_MM = 4.0


def _reaches_past(extent, bounds, margin: float) -> bool:
    """Whether the rectangle `extent` (x0, y0, x1, y1) reaches more than `margin` past `bounds`."""
    x0, y0, x1, y1 = bounds
    return extent[0] < x0 - margin or extent[1] < y0 - margin or extent[2] > x1 + margin or extent[3] > y1 + margin


_FINGERPRINTS: dict[int, tuple] = {}
_SHAPE_KEYS: dict[int, tuple] = {}


def shape_key(area) -> tuple:
    """(area rounded to 1e-6 mm², perimeter rounded to 1e-6 mm, bounds) of a polygon, a cache key.

    Remembered per object (by id, checked against the object kept alongside): the
    cached areas come back layer after layer, and shapely's properties cost more than the lookup.
    """
    hit = _SHAPE_KEYS.get(id(area))
    if hit is not None and hit[0] is area:
        return hit[1]
    key = (round(area.area, 6), round(area.length, 6), area.bounds)
    if len(_SHAPE_KEYS) >= 256:
        _SHAPE_KEYS.clear()
    _SHAPE_KEYS[id(area)] = (area, key)
    return key


def _fingerprint(area) -> tuple:
    """A cheap identity of a polygon: bounds, area, vertex count and a hash of its rounded coordinates.

    Remembered per object (weakly: by id, checked against the object kept alongside).
    """
    hit = _FINGERPRINTS.get(id(area))
    if hit is not None and hit[0] is area:
        return hit[1]
    coords = [np.asarray(ring.coords) for poly in polygons_of(area) for ring in (poly.exterior, *poly.interiors)]
    flat = np.round(np.concatenate(coords), 3) if coords else np.zeros((0, 2))
    digest = hashlib.blake2b(flat.tobytes(), digest_size=12).digest()
    fp = (tuple(round(v, 3) for v in area.bounds) if not area.is_empty else (), round(area.area, 3), len(flat), digest)
    if len(_FINGERPRINTS) >= 1024:
        _FINGERPRINTS.clear()
    _FINGERPRINTS[id(area)] = (area, fp)
    return fp
