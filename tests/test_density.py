"""Density maps on a raster: zone labels by scanline fill agree with point-in-polygon tests."""

import numpy as np
import pytest
from shapely.geometry import MultiPolygon, Point, box
from shapes import star, star_regions

from DelaunayInfill.density import DensityMap, ZoneRaster, coverage_runs
from DelaunayInfill.geometry import contains_xy


def cell_centres(raster):
    ny, nx = raster.labels.shape
    x = raster.x0 + (np.arange(nx) + 0.5) * raster.cell
    y = raster.y0 + (np.arange(ny) + 0.5) * raster.cell
    gx, gy = np.meshgrid(x, y)  # rows are y: as the labels
    return np.c_[gx.ravel(), gy.ravel()]


def holed_star():
    return star().difference(Point(0, 0).buffer(4, 16))


def mixed_regions():
    """Overlapping regions (later ones win), one partly outside the star, one with a hole, one of two parts."""
    ring = Point(8, -4).buffer(9, 24).difference(Point(8, -4).buffer(3, 24))
    pair = MultiPolygon([box(-30, 5, -12, 9), box(-6, 14, 3, 40)])
    return [*star_regions(), (box(-3, -40, 6, 40), 0.35), (ring, 0.45), (pair, 0.15)]


@pytest.mark.parametrize("cell", [0.13, 0.2, 0.37])
@pytest.mark.parametrize("regions", [star_regions(), mixed_regions()], ids=["figure10", "mixed"])
def test_raster_labels_are_the_zones_at_cell_centres(regions, cell):
    """Every cell takes the zone its centre lies in: -1 outside the area, 0 the base, k the
    last region holding it (as DensityMap.labels says), holes and several parts included."""
    area = holed_star()
    dmap = DensityMap.create(0.2, regions)
    raster = dmap.raster(area, cell)
    xy = cell_centres(raster)
    want = np.where(contains_xy(area, xy[:, 0], xy[:, 1]), dmap.labels(xy), -1)
    assert np.array_equal(raster.labels.ravel(), want)
    # The cell counts kept from the runs are the labels' counts.
    zones = len(dmap.densities)
    assert np.array_equal(raster.counts(zones), np.bincount(want[want >= 0], minlength=zones))
    # ... and the zones' areas within the rounding of their outlines.
    for k, zone in enumerate(dmap.zones(area)):
        assert abs(raster.counts(zones)[k] * cell**2 - zone.area) <= 0.5 * cell * zone.length


def test_raster_looks_up_points_and_nothing_off_the_grid():
    dmap = DensityMap.create(0.2, star_regions())
    raster = dmap.raster(star(), 0.25)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-32, 32, (5000, 2))
    ny, nx = raster.labels.shape
    i = np.floor((xy[:, 0] - raster.x0) / raster.cell).astype(int)
    j = np.floor((xy[:, 1] - raster.y0) / raster.cell).astype(int)
    on = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    assert on.any() and (~on).any()
    got = raster.at(xy)
    assert np.array_equal(got[on], raster.labels[j[on], i[on]])
    assert (got[~on] == -1).all()
    assert raster.at(np.array([[np.nan, 0.0], [0.0, np.inf], [-np.inf, 1.0]])).tolist() == [-1, -1, -1]


def test_coverage_runs_sum_the_bits_of_the_polygons_covering_each_cell():
    grid = ZoneRaster.grid_over((0, 0, 10, 6), 0.5)
    polygons = [box(1, 1, 6, 5), box(4, 0, 9, 3), box(2.2, 2.2, 2.8, 2.8)]
    start, covered = coverage_runs(polygons, grid)
    ny, nx = grid.labels.shape
    assert start[0] == 0 and (np.diff(start) > 0).all()
    sums = np.repeat(covered, np.diff(np.append(start, ny * (nx + 1)))).reshape(ny, nx + 1)
    assert (sums[:, nx] == 0).all()  # the cell past each row's end: covered by none
    xy = cell_centres(grid)
    want = sum(contains_xy(p, xy[:, 0], xy[:, 1]) * 2.0**k for k, p in enumerate(polygons))
    assert np.array_equal(sums[:, :nx].ravel(), want)


def test_raster_declines_more_regions_than_bits():
    """Past 51 regions (one float64 bit each, and one for the area) there is no raster: None."""
    regions = [(box(i, 0, i + 1, 1), 0.3) for i in range(52)]
    assert DensityMap.create(0.2, regions).raster(box(0, 0, 60, 2), 0.2) is None
    assert DensityMap.create(0.2, regions[:51]).raster(box(0, 0, 60, 2), 0.2) is not None
    with pytest.raises(ValueError):
        coverage_runs([p for p, _ in regions] * 2, ZoneRaster.grid_over((0, 0, 60, 2), 0.2))
