"""`PatternCache`: one pattern per mesh reused while it covers the layer's area, and a pattern of its own
for a thin area that comes back layer after layer where the wider section's pattern prints it off its density.

Densities are measured here by clipping with shapely (independent of the pattern's own meter).
"""

from __future__ import annotations

import numpy as np
from shapely.geometry import MultiLineString, Point, Polygon, box

from DelaunayInfill.gcode import ProcessSettings
from DelaunayInfill.gcode.patterns import REFIT_AFTER, REFIT_MISS, PatternCache, RegionSoFar

WIDTH = 0.4
DENSITY = 0.2
# A floor 38.4 mm across inside its walls; over it a tube whose infill is a 3.4 mm ring (a bushing), or a
# 2.4 mm ring along the floor's edge (a cup's wall)
FLOOR = Point(0.0, 0.0).buffer(19.2, 64)
TUBE = Point(0.0, 0.0).buffer(11.2, 64).difference(Point(0.0, 0.0).buffer(7.8, 64))
RING = FLOOR.difference(Point(0.0, 0.0).buffer(16.8, 64))


def _density(pattern, area) -> float:
    lines = MultiLineString([tuple(map(tuple, s)) for s in pattern.segments])
    return lines.intersection(area).length * WIDTH / area.area


def _floor_then(wall, layers: int, so_far=None, seed: int = 0):
    """The cache after 3 floor layers and `layers` of `wall`: (floor pattern, the wall's patterns, cache)."""
    cache = PatternCache(ProcessSettings(seed=seed))
    for _ in range(3):
        floor_pattern, _, _ = cache.get("part", FLOOR, DENSITY, WIDTH, [])
    assert cache.builds == 1
    return floor_pattern, [cache.get("part", wall, DENSITY, WIDTH, [], so_far)[0] for _ in range(layers)], cache


def test_a_thin_wall_the_floor_s_pattern_prints_off_target_gets_a_pattern_of_its_own():
    floor_pattern, patterns, cache = _floor_then(TUBE, REFIT_AFTER + 3)
    # the floor's pattern crosses the tube with the phase it happens to have there (17.2 % at seed 0)
    assert abs(_density(floor_pattern, TUBE) - DENSITY) > REFIT_MISS
    # the first layers of the wall keep the floor's pattern (they stack on it), then the wall has its own
    assert all(p is floor_pattern for p in patterns[: REFIT_AFTER - 1])
    own = patterns[REFIT_AFTER - 1]
    assert own is not floor_pattern and all(p is own for p in patterns[REFIT_AFTER:])
    assert cache.builds == 2
    assert abs(_density(own, TUBE) - DENSITY) < 0.005


def test_a_wall_that_keeps_its_region_within_the_target_keeps_the_floor_s_pattern():
    """Judged over the whole region: what it printed so far and the mesh's layers left (`RegionSoFar`);
    without them over the wall alone. Within REFIT_MISS the floor's pattern stays: the wall stacks on it."""
    so_far = RegionSoFar(printed_mm2=DENSITY * 40 * FLOOR.area, area_mm2=40 * FLOOR.area, layers_left=10)
    assert abs(so_far.projected(_density(_floor_then(TUBE, 1)[0], TUBE), TUBE.area) - DENSITY) < REFIT_MISS
    floor_pattern, patterns, cache = _floor_then(TUBE, REFIT_AFTER + 3, so_far)
    assert all(p is floor_pattern for p in patterns) and cache.builds == 1
    # the cup's ring at seed 0: 21.7 %, 1.7 points over
    floor_pattern, patterns, cache = _floor_then(RING, REFIT_AFTER + 3)
    assert REFIT_MISS / 2 < abs(_density(floor_pattern, RING) - DENSITY) <= REFIT_MISS
    assert all(p is floor_pattern for p in patterns) and cache.builds == 1


def test_a_wide_or_changing_section_keeps_its_pattern():
    """A section that shrinks layer by layer (a dome) or a wide one over a wider one (a column on a base)
    keeps the first pattern: its infill stacks."""
    cache = PatternCache(ProcessSettings(seed=0))
    for radius in np.linspace(19.2, 6.0, 40):
        cache.get("dome", Point(0.0, 0.0).buffer(float(radius), 64), DENSITY, WIDTH, [])
    assert cache.builds == 1
    cache = PatternCache(ProcessSettings(seed=0))
    cache.get("column", FLOOR, DENSITY, WIDTH, [])
    column = Point(3.0, 0.0).buffer(9.0, 64)
    for _ in range(REFIT_AFTER + 3):
        cache.get("column", column, DENSITY, WIDTH, [])
    assert cache.builds == 1


def test_a_growing_section_with_regions_is_calibrated_where_the_layer_prints():
    """A mesh whose section grows upwards gets a pattern planned over its whole extent; with density regions
    each zone is calibrated on the layer's own area, not over the extent: the sparse zone's lines keep their
    distance from a dense region, and over a box of the extent that band is a small share of the zone, over a
    thin part a large one (random regions 120: the rest printed 27.6 % for 30 %, Cura 29.5 %)."""
    part = box(-12.0, -3.0, 12.0, 3.0).union(Polygon([(-12.0, 6.0), (-4.0, 6.0), (-12.0, 14.0)]))
    region = Point(2.0, 0.0).buffer(5.0, 32).intersection(part)
    rest = part.difference(region)
    for seed in range(3):  # (calibrated over the extent: 35.4, 33.9, 34.2 % in the rest)
        cache = PatternCache(ProcessSettings(seed=seed), extents={"part": (-20.0, -20.0, 20.0, 20.0)})
        pattern, footprint, _ = cache.get("part", part, 0.3, WIDTH, [(region, 0.6, "region")])
        assert footprint.contains(box(-19.0, -19.0, 19.0, 19.0))  # (planned for the layers above)
        assert abs(_density(pattern, rest) - 0.3) < 0.01
        assert abs(_density(pattern, region) - 0.6) < 0.015
