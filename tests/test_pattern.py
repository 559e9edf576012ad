"""generate_infill / InfillPattern: calibration, regions, layouts, stacking, bad input."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree
from shapely.geometry import MultiLineString, Point, Polygon, box
from shapes import SHAPES, star, star_regions

from DelaunayInfill import InfillPattern, generate_infill
from DelaunayInfill.density import LATTICE_SIDE
from DelaunayInfill.decomposition import cross_turn, decompose_convex, is_convex, reflex_vertices
from DelaunayInfill.geometry import contains_xy, unary_union
from DelaunayInfill.metering import measured_density


def length_in(segments, area):
    return area.intersection(MultiLineString([s.tolist() for s in segments])).length


@pytest.mark.parametrize("shape", sorted(SHAPES))
@pytest.mark.parametrize("width", [0.4, 1.2])
@pytest.mark.parametrize("target", [0.05, 0.1, 0.2, 0.4, 0.6, 0.8])
def test_measured_calibration_within_1_5_points(shape, width, target):
    region = SHAPES[shape]()
    result = generate_infill(region, target, width, seed=0)
    # measured independently of the engine: shapely length x width / area
    independent = length_in(result.segments, region) * width / region.area
    assert abs(independent - result.density) < 1e-6
    assert abs(independent - target) <= 0.015


def test_paper_calibration_is_formula_6_and_reported():
    region = SHAPES["square"]()
    ours = generate_infill(region, 0.3, 1.2, calibration="measured")
    paper = generate_infill(region, 0.3, 1.2, calibration="paper")
    assert abs(ours.density - 0.3) <= 0.015
    # Formula (6) with our minimum-distance radius prints denser than asked
    assert abs(paper.density - 0.3) > abs(ours.density - 0.3)


def test_infill_lies_inside_the_region_and_paths_are_the_segments():
    region = star()
    result = generate_infill(region, 0.25, 0.4, seed=2)
    pts = np.concatenate(result.paths)
    assert contains_xy(region.buffer(1e-6), pts[:, 0], pts[:, 1]).all()
    assert abs(sum(np.hypot(*np.diff(p, axis=0).T).sum() for p in result.paths) - result.extrude_mm) < 1e-6


def test_same_seed_identical_output():
    a = generate_infill(star(), 0.3, 0.4, seed=11)
    b = generate_infill(star(), 0.3, 0.4, seed=11)
    assert len(a.paths) == len(b.paths)
    for p, q in zip(a.paths, b.paths):
        np.testing.assert_array_equal(p, q)


def test_regions_get_their_density_later_regions_win():
    region = box(0, 0, 120, 60)
    left = box(0, 0, 60, 60)
    overlap = box(40, 0, 80, 60)
    result = generate_infill(region, 0.2, 0.4, regions=[(left, 0.5), (overlap, 0.1)], seed=1)
    base, first, second = result.region_densities
    assert abs(base - 0.2) <= 0.015
    assert abs(first - 0.5) <= 0.015  # left minus the overlap
    assert abs(second - 0.1) <= 0.015


def test_seamless_has_no_doubled_lines_at_borders_but_paper_layout_does():
    region = box(0, 0, 80, 40)
    regions = [(box(40, 0, 80, 40), 0.4)]

    def doubled(segments, width=0.4):
        """Pairs of nearly parallel segments side by side (< 2 widths apart, > 1 mm overlap)."""
        mid = segments.mean(axis=1)
        d = segments[:, 1] - segments[:, 0]
        ang = np.arctan2(d[:, 1], d[:, 0]) % np.pi
        pairs = cKDTree(mid).query_pairs(6.0, output_type="ndarray")
        dang = np.abs(ang[pairs[:, 0]] - ang[pairs[:, 1]])
        pairs = pairs[np.minimum(dang, np.pi - dang) < np.radians(10)]
        a, b = segments[pairs[:, 0]], segments[pairs[:, 1]]
        length = np.linalg.norm(a[:, 1] - a[:, 0], axis=1)
        u = (a[:, 1] - a[:, 0]) / length[:, None]
        rel = b - a[:, :1]  # b's endpoints relative to a's start
        along = (rel * u[:, None]).sum(-1)
        across = np.abs(rel[..., 0] * u[:, None, 1] - rel[..., 1] * u[:, None, 0]).max(axis=1)
        overlap = np.minimum(along.max(1), length) - np.maximum(along.min(1), 0.0)
        return int(np.count_nonzero((across < 2 * width) & (overlap > 1.0)))

    seamless = generate_infill(region, 0.2, 0.4, regions=regions, layout="seamless")
    paper = generate_infill(region, 0.2, 0.4, regions=regions, layout="paper", sampler="fast")
    assert doubled(seamless.segments) == 0
    assert doubled(paper.segments) > 0


def test_seamless_density_changes_within_two_radii_of_a_border():
    region = box(0, 0, 120, 60)
    result = generate_infill(region, 0.1, 0.4, regions=[(box(60, 0, 120, 60), 0.5)], seed=3)
    r_sparse = 2.7 * 0.4 / 0.1
    r_dense = 2.7 * 0.4 / 0.5

    def strip(x0, x1):
        s = box(x0, 0, x1, 60)
        return length_in(result.segments, s) * 0.4 / s.area

    assert abs(strip(0, 60 - 2 * r_sparse) - 0.1) <= 0.03
    assert abs(strip(60 + 2 * r_dense, 120) - 0.5) <= 0.03


def test_feather_blends_across_the_border():
    region = box(0, 0, 120, 60)
    sharp = generate_infill(region, 0.1, 0.4, regions=[(box(60, 0, 120, 60), 0.5)])
    soft = generate_infill(region, 0.1, 0.4, regions=[(box(60, 0, 120, 60), 0.5)], feather=20.0)

    def strip(result, x0, x1):
        s = box(x0, 0, x1, 60)
        return length_in(result.segments, s) * 0.4 / s.area

    # the band next to the border holds intermediate densities ...
    assert 0.15 < strip(soft, 60, 70) < strip(sharp, 60, 70) - 0.05
    # ... while the zones' cores keep their targets, up to the outer edge of the part
    assert abs(strip(soft, 0, 40) - 0.1) < 0.03
    assert abs(strip(soft, 80, 120) - 0.5) < 0.04


def stacked_share(lower, upper, tol):
    """Share of `upper` length within `tol` of `lower` (sampled every 0.1 mm)."""
    pts = []
    for a, b in upper:
        n = max(2, int(np.hypot(*(b - a)) / 0.1))
        t = np.linspace(0, 1, n)[:, None]
        pts.append(a + (b - a) * t)
    pts = np.concatenate(pts)
    lower_pts = []
    for a, b in lower:
        n = max(2, int(np.hypot(*(b - a)) / 0.05))
        t = np.linspace(0, 1, n)[:, None]
        lower_pts.append(a + (b - a) * t)
    d, _ = cKDTree(np.concatenate(lower_pts)).query(pts)
    return float(np.mean(d <= tol))


def test_layers_clipped_from_one_pattern_stack():
    footprint = star().buffer(2.0)
    pattern = InfillPattern.build(footprint, 0.2, 0.4, seed=4)
    layer_a = pattern.clip(star())
    layer_b = pattern.clip(star())
    shrunk = pattern.clip(star().buffer(-1.0))
    assert stacked_share(layer_a.segments, layer_b.segments, 0.2) == 1.0
    assert stacked_share(layer_a.segments, shrunk.segments, 0.2) >= 0.95
    assert abs(layer_a.density - 0.2) <= 0.02


def test_clip_start_point_begins_near_the_nozzle():
    pattern = InfillPattern.build(box(0, 0, 50, 50), 0.2, 0.4)
    far = pattern.clip(box(0, 0, 50, 50), start=(50.0, 50.0))
    assert np.hypot(*(far.paths[0][0] - [50, 50])) < 10


def test_figure_10_star_regions_in_both_layouts():
    seamless = generate_infill(star(), 0.3, 0.4, regions=star_regions())
    for got, (_, want) in zip(seamless.region_densities[1:], star_regions()):
        # every region, the 10 % pentagon included (thinned, it is smaller
        # than two of its own radii), within 3 points
        assert abs(got - want) <= 0.03
    paper = generate_infill(star(), 0.3, 0.4, regions=star_regions(), layout="paper", sampler="fast")
    assert all(np.isfinite(paper.region_densities[1:]))


def test_thinning_leaves_no_loose_ends_and_keeps_the_triangulation():
    pattern = InfillPattern.build(star(), 0.3, 0.4, regions=star_regions(), seed=1)
    edges_printed = len(pattern.segments)
    from DelaunayInfill.triangulation import unique_edges

    assert edges_printed < len(unique_edges(pattern.triangles))  # the 10 % centre was thinned
    assert pattern.quality()["lop_violations"] == 0
    ends = np.round(pattern.segments.reshape(-1, 2), 6)
    _, counts = np.unique(ends, axis=0, return_counts=True)
    full = np.round(pattern.points[unique_edges(pattern.triangles)].reshape(-1, 2), 6)
    _, full_counts = np.unique(full, axis=0, return_counts=True)
    assert np.count_nonzero(counts == 1) <= np.count_nonzero(full_counts == 1)


def test_paper_layout_decomposes_into_convex_parts():
    pattern = InfillPattern.build(star(), 0.3, 0.4, layout="paper", sampler="fast")
    assert pattern.quality()["lop_violations"] == 0
    assert abs(pattern.calibrated_densities[0] - 0.3) <= 0.05


def test_reflex_vertices_by_formula_3():
    ring = np.array([[0, 0], [2, 0], [2, 2], [1, 1], [0, 2]], float)  # (1, 1) is concave
    assert list(np.flatnonzero(cross_turn(ring) < 0)) == [3]
    np.testing.assert_array_equal(reflex_vertices(Polygon(ring)), [[1, 1]])
    np.testing.assert_array_equal(reflex_vertices(Polygon(ring[::-1])), [[1, 1]])  # orientation handled


@pytest.mark.parametrize(
    "region",
    [
        star(),
        Point(0, 0).buffer(30, 8).difference(Point(0, 0).buffer(10, 8)),
        Polygon([(0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30)]),
    ],
)
def test_decomposition_is_exact_and_convex(region):
    parts = decompose_convex(region)
    assert all(is_convex(p) for p in parts)
    assert math.isclose(sum(p.area for p in parts), region.area, rel_tol=1e-9)
    from shapely.ops import unary_union

    assert unary_union(parts).symmetric_difference(region).area < 1e-6 * region.area


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(region=Polygon(), density=0.2, line_width=0.4), "empty"),
        (dict(region=box(0, 0, 10, 10), density=0.0, line_width=0.4), "density"),
        (dict(region=box(0, 0, 10, 10), density=-0.1, line_width=0.4), "density"),
        (dict(region=box(0, 0, 10, 10), density=1.5, line_width=0.4), "density"),
        (dict(region=box(0, 0, 10, 10), density=float("nan"), line_width=0.4), "density"),
        (dict(region=box(0, 0, 10, 10), density=0.2, line_width=0.0), "line width"),
        (dict(region=box(0, 0, 10, 10), density=0.2, line_width=-1), "line width"),
        (dict(region=Polygon([(0, 0), (1, float("nan")), (2, 0)]), density=0.2, line_width=0.4), "NaN"),
        (dict(region=box(0, 0, 10, 10), density=0.2, line_width=0.4, layout="spiral"), "layout"),
        (dict(region=box(0, 0, 10, 10), density=0.2, line_width=0.4, calibration="guess"), "calibration"),
        (dict(region=box(0, 0, 10, 10), density=0.2, line_width=0.4, regions=[(box(0, 0, 1, 1), 2.0)]), "region 1"),
    ],
)
def test_bad_input_gets_a_clear_value_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        generate_infill(**kwargs)


def test_self_intersecting_region_is_repaired():
    bowtie = Polygon([(0, 0), (30, 30), (30, 0), (0, 30)])
    result = generate_infill(bowtie, 0.3, 0.4)
    assert abs(result.density - 0.3) <= 0.015


def test_figure_10_regions_within_two_points_measured_whole():
    """Each region is calibrated whole, the bands along its borders with other regions (where the
    pattern changes density) included: measured so, Figure 10's regions are within 2 points."""
    pattern = InfillPattern.build(star(), 0.3, 0.4, regions=star_regions(), seed=0)
    printed = pattern.clip(star()).segments
    for zone, (_, want) in zip(pattern.density_map.zones(star())[1:], star_regions()):
        got = measured_density(printed, zone, 0.4)
        assert abs(got - want) <= 0.02, (got, want)


_WHOLE_REGION_CASES = {
    # name: (base density, region, its density); regions two of their own spacings across and more
    "box 12 mm at 60 % in 20 %": (0.2, box(34, 34, 46, 46), 0.6),
    "disk 20 mm at 60 % in 20 %": (0.2, Point(40, 40).buffer(10, 32), 0.6),
    "strip 8 mm at 60 % in 20 %": (0.2, box(36, 0, 44, 80), 0.6),
    "box 24 mm at 10 % in 40 %": (0.4, box(28, 28, 52, 52), 0.1),
}


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("case", list(_WHOLE_REGION_CASES))
def test_whole_regions_print_their_density(case, seed):
    """Issue 15: a region measured whole (the band where the pattern changes included) and the rest
    of the part both print their density within 2 points; the region prints its own density right up
    to its border (its 2 mm along it within 5 points: the change lies outside it) and the sparse side
    stays sparse beside it (2 mm along the border, or beyond a dense region's last lattice triangles,
    which reach past its border by up to their height)."""
    base, region, density = _WHOLE_REGION_CASES[case]
    part = box(0, 0, 80, 80)
    printed = InfillPattern.build(part, base, 0.4, regions=[(region, density)], seed=seed).clip(part).segments
    rest = part.difference(region)
    assert abs(measured_density(printed, region, 0.4) - density) <= 0.02
    assert abs(measured_density(printed, rest, 0.4) - base) <= 0.02
    inner_band = region.difference(region.buffer(-2.0))
    assert abs(measured_density(printed, inner_band, 0.4) - density) <= 0.05
    height = math.sqrt(3.0) / 2.0 * LATTICE_SIDE * 0.4 / max(base, density) if density > base else 0.0
    sparse_band = (rest.intersection(region.buffer(height + 2.0)).difference(region.buffer(height))
                   if density > base else inner_band)
    assert measured_density(printed, sparse_band, 0.4) <= min(base, density) + 0.05


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("case", list(_WHOLE_REGION_CASES))
def test_the_change_of_density_lies_in_one_band_beside_the_border(case, seed):
    """Issue 15: across a region's border the sparse side prints the sparse density within 2 points
    (2.5 beside a dense region) in a band one sparse spacing s wide (the sparse lattice's side
    2 sqrt(3) w / d), and so does the dense side from s on: the change lies in one band.  Beside a
    sparse region, or a dense one on the part's edge, that band is the dense side's first; a dense
    region enclosed by the part is its own lattice in whole triangles, so the change lies in the
    triangles' reach past its border (up to their height h), and the sparse band starts there.  (The
    sparse band swung by up to 4.6 points from seed to seed before session 12; a uniform pattern's
    same band by 0.3.)"""
    base, region, density = _WHOLE_REGION_CASES[case]
    part = box(0, 0, 80, 80)
    printed = InfillPattern.build(part, base, 0.4, regions=[(region, density)], seed=seed).clip(part).segments
    sparse, dense = min(base, density), max(base, density)
    s = 2.0 * math.sqrt(3.0) * 0.4 / sparse
    inner = part.buffer(-s)  # (the part's own edge stays out of the bands)
    tolerance = 0.02
    if density > base:
        enclosed = part.buffer(-1.0).covers(region)
        h = math.sqrt(3.0) / 2.0 * LATTICE_SIDE * 0.4 / dense if enclosed else 0.0
        tolerance = 0.025 if enclosed else tolerance
        sparse_band, dense_beyond = region.buffer(h + s).difference(region.buffer(h)), region.buffer(-s)
    else:
        sparse_band, dense_beyond = region.difference(region.buffer(-s)), part.difference(region.buffer(s))
    got = measured_density(printed, sparse_band.intersection(inner), 0.4)
    assert abs(got - sparse) <= tolerance, (got, sparse)
    dense_beyond = dense_beyond.intersection(inner)
    if dense_beyond.area > (2 * s) ** 2:
        got = measured_density(printed, dense_beyond, 0.4)
        assert abs(got - dense) <= 0.025, (got, dense)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_zone_meter_measures_like_clipping(seed):
    """The calibration's fast zone measurement equals exact clipping, crossings included."""
    from DelaunayInfill.metering import ZoneMeter

    rng = np.random.default_rng(seed)
    zones = [star(), *[p for p, _ in star_regions()], box(-5, -5, 5, 5).difference(Point(0, 0).buffer(2))]
    starts = rng.uniform(-35, 35, (400, 2))
    ends = starts + rng.normal(0, 4, (400, 2)) * rng.choice([0.2, 1.0, 5.0], (400, 1))
    segments = np.stack([starts, ends], axis=1)
    meter = ZoneMeter(zones)
    for k, zone in enumerate(zones):
        exact = measured_density(segments, zone, 0.4)
        assert meter.densities(segments, 0.4)[k] == pytest.approx(exact, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_zone_meter_cuts_a_few_segments_as_it_cuts_many(seed, monkeypatch):
    """A few segments at a time (balancing's new edges: pairs found in the edges' tree) measure
    bit for bit as through the many-segment path (a tree of their own), and as clipping does."""
    from DelaunayInfill import metering
    from DelaunayInfill.metering import ZoneMeter

    rng = np.random.default_rng(seed)
    zones = [star(), *[p for p, _ in star_regions()], box(-5, -5, 5, 5).difference(Point(0, 0).buffer(2))]
    starts = rng.uniform(-35, 35, (240, 2))
    ends = starts + rng.normal(0, 4, (240, 2))
    segments = np.stack([starts, ends], axis=1)
    meter = ZoneMeter(zones)
    chunks = np.array_split(segments, 60)  # 4 segments a call
    measured = {}
    for few in (0, 10**6):
        monkeypatch.setattr(metering, "_FEW", few)
        measured[few] = np.concatenate([meter.inside_all(chunk) for chunk in chunks], axis=1)
    assert np.array_equal(measured[0], measured[10**6])
    for k, zone in enumerate(zones):
        exact = measured_density(segments, zone, 0.4) * zone.area / 0.4
        assert measured[10**6][k].sum() == pytest.approx(exact, rel=1e-9, abs=1e-12)


def test_balancing_cache_measures_like_a_fresh_meter():
    """Edge lengths cached between balancing rounds (points appended) equal a fresh measurement."""
    from DelaunayInfill.calibration import _inside_lengths
    from DelaunayInfill.metering import ZoneMeter
    from DelaunayInfill.triangulation import delaunay_triangles, unique_edges

    rng = np.random.default_rng(4)
    zones = [star().difference(unary_union([p for p, _ in star_regions()])), *[p for p, _ in star_regions()]]
    meter = ZoneMeter(zones)
    points = rng.uniform(-35, 35, (300, 2))
    known = {}
    for extra in (0, 40, 80):
        pts = np.r_[points, rng.uniform(-10, 10, (extra, 2))] if extra else points
        points = pts
        edges = unique_edges(delaunay_triangles(points))
        cached = _inside_lengths(edges, points[edges], meter, known)
        fresh = meter.inside_all(points[edges])
        np.testing.assert_allclose(cached, fresh, rtol=0, atol=1e-12)
        assert cached.sum() > 0


@pytest.mark.parametrize(("region", "target", "width"), [(star(), 0.05, 1.2), (star(), 0.2, 0.4),
                                                          (box(0, 0, 100, 60), 0.2, 0.4)])
def test_single_zone_scaling_keeps_a_delaunay_pattern_covering_the_footprint(region, target, width):
    """Calibration by scaling one sampling: the pattern stays Delaunay and still covers the footprint
    (the 100 x 60 box at a 5.4 mm radius allows only about 7 % of scaling)."""
    pattern = InfillPattern.build(region, target, width, seed=3)
    assert abs(pattern.calibrated_densities[0] - target) <= 0.015
    assert pattern.quality()["lop_violations"] == 0
    covered = unary_union([Polygon(pattern.points[t]) for t in pattern.triangles])
    assert region.difference(covered).area <= 1e-9 * region.area


@pytest.mark.parametrize("seed", [0, 1])
def test_density_at_sharp_borders_is_the_last_region_holding_the_point(seed):
    """DensityMap.at without feathering: each point gets the density of the last region whose
    interior holds it (base elsewhere), checked point by point with shapely."""
    from DelaunayInfill.density import DensityMap

    rng = np.random.default_rng(seed)
    regions = [(p, d) for (p, _), d in zip(star_regions(), rng.uniform(0.05, 0.9, 6))]
    regions.append((box(-8, -8, 8, 8).difference(Point(0, 0).buffer(3)), 0.6))  # a hole
    regions.append((unary_union([box(20, -40, 40, -20), box(-60, 30, -50, 60)]), 0.7))  # partly outside
    dmap = DensityMap.create(0.2, regions)
    xy = np.r_[rng.uniform(-45, 45, (3000, 2)), np.asarray(star().exterior.coords)]
    want = np.full(len(xy), 0.2)
    for poly, dens in regions:
        for i, (x, y) in enumerate(xy):
            if poly.contains(Point(x, y)):
                want[i] = dens
    got = dmap.at(xy)
    assert np.array_equal(got, want)
    assert len(set(got.tolist())) == len(regions) + 1  # every region holds some point


def test_only_coarse_zones_off_target_are_balanced_without_resampling(monkeypatch):
    """A small part whose zones hold a few dozen samples each: one sampling, then balancing, and
    the zones still end within 2.5 points of their targets (measured whole, border bands included)."""
    from DelaunayInfill import seamless_layout

    calls = []
    for name in ("sample_poisson_disk", "sample_triangulated"):  # (the latter: the sampler's triangulation too)
        sample = getattr(seamless_layout, name)
        monkeypatch.setattr(seamless_layout, name, lambda *a, _sample=sample, **k: calls.append(1) or _sample(*a, **k))
    scale = 0.5  # a 30 mm star: its tips are under 6 x 6 radii at every density here
    small_star = Polygon(np.asarray(star().exterior.coords) * scale)
    regions = [(Polygon(np.asarray(p.exterior.coords) * scale), d) for p, d in star_regions()]
    pattern = InfillPattern.build(small_star, 0.3, 0.4, regions=regions, seed=0)
    assert len(calls) == 1
    targets = [0.3] + [d for _, d in regions]
    measured = [(got, want) for got, want in zip(pattern.calibrated_densities, targets) if not math.isnan(got)]
    assert len(measured) == len(regions)  # the regions tile the star: the base zone has no area
    for got, want in measured:
        # Measured whole (border bands included) zones this small (tips under two of their own
        # spacings across, the centre one) end up to 2.6 points off (seed 0, numpy 2.x); the 2 points
        # of issue 15 hold from two spacings across (test_whole_regions_print_their_density).
        assert abs(got - want) <= 0.03, (pattern.calibrated_densities, targets)


@pytest.mark.parametrize("seed", [0, 1])
def test_zones_are_each_region_minus_later_ones_overlapping_or_touching(seed):
    """DensityMap.zones: region k's zone is region k inside the area minus every later region
    (whether it overlaps, touches or is apart), the base the rest; the zones tile the area."""
    from DelaunayInfill.density import DensityMap

    rng = np.random.default_rng(seed)
    area = star()
    regions = [(p, 0.3) for p, _ in star_regions()]  # touching along their borders
    regions.append((Point(rng.uniform(-5, 5), rng.uniform(-5, 5)).buffer(12), 0.5))  # overlaps several
    regions.append((box(-70, -70, -60, -60), 0.6))  # outside the area
    regions.insert(2, (box(-10, -10, 10, 10), 0.4))  # overlapped by a later one
    zones = DensityMap.create(0.2, regions).zones(area)
    later = None
    for k in range(len(regions) - 1, -1, -1):
        want = regions[k][0].intersection(area)
        if later is not None:
            want = want.difference(later)
        later = regions[k][0] if later is None else unary_union([later, regions[k][0]])
        assert zones[k + 1].symmetric_difference(want).area < 1e-9
    assert zones[0].symmetric_difference(area.difference(later)).area < 1e-9
    assert abs(sum(z.area for z in zones) - area.area) < 1e-9
    assert zones[-1].is_empty and zones[3].area < box(-10, -10, 10, 10).area


def test_zone_interiors_drop_a_band_along_borders_with_other_zones_only():
    """zone_interiors (a feathered map's zone cores): each zone loses the points within a line width
    of another zone (not of the outline); a zone the band would
    (nearly) swallow, or a strip narrower than 1.4 widths, is kept whole."""
    from DelaunayInfill.geometry import to_multipolygon
    from DelaunayInfill.metering import zone_interiors

    width = 0.4
    area = box(0, 0, 60, 40)
    left, right = box(0, 0, 30, 40), box(30, 0, 60, 40)
    strip = box(0, 0, 60, 0.5)  # between the outline and the other zones
    zones = [to_multipolygon(z) for z in (left.difference(strip), right.difference(strip), strip)]
    inner = zone_interiors(zones, width)
    for k in range(2):
        others = area.difference(zones[k])
        want = zones[k].difference(others.buffer(width, 4))
        assert inner[k].symmetric_difference(want).area < 1e-9
        assert abs(inner[k].area - (zones[k].area - width * (39.5 + 30) + width**2)) < 1e-6  # bands on 2 sides
    assert inner[2].equals(zones[2])  # narrow strip: whole
    # The same strip wider than 1.4 widths but swallowed by bands along both long sides: whole too.
    strip = box(0, 10, 60, 11)
    zones = [to_multipolygon(z) for z in (box(0, 0, 60, 10), strip, box(0, 11, 60, 40))]
    assert zone_interiors(zones, width)[1].equals(zones[1])
    # A strip narrower than 1.4 widths mostly along the outline (its band would take 15 %): whole.
    tower = box(0, 0.5, 10, 40)
    strip = box(0, 0, 60, 0.5)
    zones = [to_multipolygon(strip), to_multipolygon(tower)]
    inner = zone_interiors(zones, width)
    assert inner[0].equals(zones[0])
    assert abs(inner[1].area - (tower.area - width * 10)) < 1e-6  # the tower loses its band
    # Zones side by side: each loses the band along the other.
    apart = [to_multipolygon(box(0, 0, 10, 10)), to_multipolygon(box(10, 0, 20, 10))]
    inner = zone_interiors(apart, width)
    assert abs(inner[0].area - (100 - 10 * width)) < 1e-6


def test_raster_meter_measures_like_clipping_within_its_cells():
    """Several sharp-border zones are measured on a raster: each segment in pieces no longer than
    a cell, each piece counted in the zone of its midpoint's cell.  Per zone the length is the
    exact clipped length up to about a cell per boundary crossing."""
    from DelaunayInfill.density import DensityMap
    from DelaunayInfill.metering import RasterMeter

    rng = np.random.default_rng(7)
    area = star()
    dmap = DensityMap.create(0.2, star_regions())
    cell = 0.18
    meter = RasterMeter(dmap.raster(area, cell), len(dmap.densities))
    starts = rng.uniform(-35, 35, (600, 2))
    segments = np.stack([starts, starts + rng.normal(0, 3, (600, 2))], axis=1)
    inside = meter.inside_all(segments)
    assert inside.shape == (7, 600)
    lengths = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    assert (inside.sum(axis=0) <= lengths + 1e-9).all()
    for k, zone in enumerate(dmap.zones(area)):
        if zone.area < 1:  # (the regions tile the star: no base zone)
            assert meter.areas[k] == 0 and inside[k].sum() == 0
            continue
        exact = length_in(segments, zone)
        cut = zone.boundary.intersection(MultiLineString([s.tolist() for s in segments]))
        crossings = len(cut.geoms) if hasattr(cut, "geoms") else int(not cut.is_empty)
        assert exact > 20
        assert abs(inside[k].sum() - exact) <= 1.5 * cell * crossings, k
        assert abs(meter.areas[k] - zone.area) <= 0.5 * cell * zone.length
    # Points: the zone of their cell.
    xy = rng.uniform(-30, 30, (500, 2))
    for k in range(7):
        assert np.array_equal(meter.contains(k, xy), np.flatnonzero(meter.raster.at(xy) == k))


def test_balancing_keeps_its_best_round(monkeypatch):
    """Balancing stops two rounds after the largest shortfall last got smaller and keeps the round
    that had it (refinement can go back and forth between neighbouring zones)."""
    from DelaunayInfill import calibration
    from DelaunayInfill.density import DensityMap
    from DelaunayInfill.metering import raster_meter

    area = star()
    dmap = DensityMap.create(0.2, star_regions())
    meter = raster_meter(area, dmap, 0.4)
    targets = np.array(dmap.densities)
    rng = np.random.default_rng(1)
    points = rng.uniform(-32, 32, (300, 2))
    from DelaunayInfill.triangulation import delaunay_triangles

    triangles = delaunay_triangles(points)
    shortfalls = iter([0.02, 0.008, 0.012, 0.011, 0.001, 0.0])  # round 2 best, then no better twice
    rounds = []

    def scripted(points, triangles, meter, targets, width, small, known=None, limit=None, fixed=0):
        measured = list(targets)
        measured[3] = targets[3] - next(shortfalls)
        rounds.append(len(points))
        return np.full((len(rounds), 2, 2), float(len(rounds))), measured

    monkeypatch.setattr(calibration, "_thin_dense_zones", scripted)
    small = np.ones(len(targets), dtype=bool)
    out_points, _, segments, measured = calibration.balance_zones(points, triangles, meter, targets, 0.4, small)
    assert len(rounds) == 4  # rounds 3 and 4 did not beat round 2
    assert len(segments) == 2 and measured[3] == pytest.approx(targets[3] - 0.008)
    assert len(out_points) == rounds[1]  # round 2's points (before its refinement)


def test_balancing_starts_a_zone_no_circumcentre_falls_in():
    """A sparse zone with no sample of its own and no edge across it, whose triangles' circumcentres all lie
    outside it, gets its emptiest point inserted (random regions 171: a 5 % zone of 391 mm² printed nothing).
    Here a 20 mm square's two triangles share their circumcentre (10, 10), outside the zone, and neither
    diagonal crosses it.  A zone that misses less line than twice its emptiest point's distance to a sample
    is left as it is: one sample in it would print it far over its target."""
    from DelaunayInfill import calibration
    from DelaunayInfill.metering import ZoneMeter
    from DelaunayInfill.triangulation import delaunay_triangles, unique_edges

    zone = box(2.0, 7.5, 6.5, 12.5)
    meter = ZoneMeter([box(0.0, 0.0, 20.0, 20.0).difference(zone), zone])
    points = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0], [20.0, 20.0]])
    triangles = delaunay_triangles(points)
    small = np.array([False, True])
    assert meter.densities(points[unique_edges(triangles)], 0.4)[1] == 0.0
    targets = np.array([0.05, 0.5])  # (28 mm of line missing, the emptiest point 11.9 mm from a corner)
    out_points, _, segments, measured = calibration.balance_zones(points, triangles, meter, targets, 0.4, small)
    assert len(out_points) > 4 and zone.contains(Point(out_points[4]))
    assert measured[1] > 0.2 and measured_density(segments, zone, 0.4) == pytest.approx(measured[1], abs=0.01)
    targets = np.array([0.05, 0.3])  # (17 mm missing)
    out_points, _, _, measured = calibration.balance_zones(points, triangles, meter, targets, 0.4, small)
    assert len(out_points) == 4 and measured[1] == 0.0


def test_several_zone_build_calibrates_each_zone_measured_exactly():
    """Through the raster meter, Figure 10's zones (measured exactly, by clipping, each zone whole:
    the bands along other zones included) land within 2 points of their targets."""
    regions = star_regions()
    pattern = InfillPattern.build(star(), 0.2, 0.4, regions=regions, seed=0)
    zones = pattern.density_map.zones(star())
    for zone, target in zip(zones[1:], [d for _, d in regions]):
        got = measured_density(pattern.clip(star()).segments, zone, 0.4)
        assert abs(got - target) <= 0.02, (got, target)


def test_raster_meter_only_where_it_measures_well():
    """The raster meter serves several sharp-border zones; one zone, or a zone of a few cells once
    a large part's cells grew wider than a line, is measured exactly instead (None)."""
    from DelaunayInfill.density import DensityMap
    from DelaunayInfill.metering import RasterMeter, raster_meter

    width = 0.4
    assert isinstance(raster_meter(star(), DensityMap.create(0.2, star_regions()), width), RasterMeter)
    whole = DensityMap.create(0.2, [(star().buffer(1), 0.4)])  # one region over all: one zone
    assert raster_meter(star(), whole, width) is None
    large = box(0, 0, 400, 400)  # 0.4 x 400 x 400 / 120000 cells: 1.15 mm cells
    assert raster_meter(large, DensityMap.create(0.2, [(box(10, 10, 14, 14), 0.4)]), width) is None
    meter = raster_meter(large, DensityMap.create(0.2, [(box(10, 10, 60, 60), 0.4)]), width)
    assert isinstance(meter, RasterMeter) and meter.raster.cell > width


_NODE_CASES = {
    "a 60 % box in 20 %": (box(0, 0, 80, 80), 0.2, [(box(30, 30, 50, 50), 0.6)]),
    "a 10 % box in 40 %": (box(0, 0, 80, 80), 0.4, [(box(28, 28, 52, 52), 0.1)]),
    "Figure 10": (star(), 0.2, star_regions()),
}


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("case", list(_NODE_CASES))
def test_no_node_with_more_than_eight_edges_and_no_short_edge(case, seed):
    """Issue 15: where zones meet (Poisson-disk bands, balancing's inserted points) no node of the
    pattern has more than 8 edges (9 and 10 were measured there), and no edge inside the part is shorter
    than a quarter of the local spacing (the triangular lattice's side at the denser end's density)."""
    footprint, base, regions = _NODE_CASES[case]
    pattern = InfillPattern.build(footprint, base, 0.4, regions=regions, seed=seed)
    segments = pattern.segments
    ends = np.round(segments.reshape(-1, 2), 9)
    nodes, index, counts = np.unique(ends, axis=0, return_inverse=True, return_counts=True)
    inside = np.array([footprint.contains(Point(*xy)) for xy in nodes])
    assert counts[inside].max() <= 8
    both_inside = inside[index.reshape(-1, 2)].all(axis=1)
    density = np.maximum(pattern.density_map.at(segments[:, 0]), pattern.density_map.at(segments[:, 1]))
    spacing = 2.0 * np.sqrt(3.0) * 0.4 / density
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    assert (length[both_inside] >= 0.25 * spacing[both_inside]).all()


def test_thinning_leaves_a_lattice_whole_while_other_edges_can_go():
    """A zone printing too dense is thinned by the edges that are not between two lattice points
    first (a lattice missing diagonals is a grid of rhombi: far less stiff per gram); only when
    those are not enough does the lattice lose edges.  Without the preference the longest edges
    go first, and the lattice's (the longest here) would."""
    from DelaunayInfill.calibration import _thin_dense_zones
    from DelaunayInfill.metering import ZoneMeter
    from DelaunayInfill.sampling import lattice_points
    from DelaunayInfill.triangulation import delaunay_triangles, unique_edges

    zone = box(0, 0, 30, 30)
    lattice = lattice_points(zone.buffer(-2.5), 6.0, seed=1)
    ring = zone.buffer(-1.0).exterior  # a band of closer samples along the border, as between two lattices
    extras = np.array([ring.interpolate(t).coords[0] for t in np.arange(0.0, ring.length, 1.5)])
    points = np.concatenate((lattice, extras))
    triangles = delaunay_triangles(points)
    edges = unique_edges(triangles)
    both = (edges < len(lattice)).all(axis=1)
    lattice_edges = {tuple(e) for e in np.sort(edges[both], axis=1).tolist()}
    meter = ZoneMeter([zone])
    full = meter.densities(points[edges], 0.4)[0]
    target = full * 0.9  # a tenth too dense: the other edges can make that up
    segments, measured = _thin_dense_zones(points, triangles, meter, [target], 0.4, np.array([True]),
                                           fixed=len(lattice))
    kept = {tuple(sorted(map(tuple, np.round(s, 9).tolist()))) for s in segments}
    lattice_kept = sum(tuple(sorted(map(tuple, np.round(points[list(e)], 9).tolist()))) in kept for e in lattice_edges)
    assert measured[0] == pytest.approx(target, abs=0.01)
    assert lattice_kept == len(lattice_edges)
    # without knowing the lattice, some of its edges go
    segments, _ = _thin_dense_zones(points, triangles, meter, [target], 0.4, np.array([True]))
    kept = {tuple(sorted(map(tuple, np.round(s, 9).tolist()))) for s in segments}
    assert sum(tuple(sorted(map(tuple, np.round(points[list(e)], 9).tolist()))) in kept for e in lattice_edges) \
        < len(lattice_edges)


def test_a_small_sparse_region_is_its_own_lattice_up_to_its_border():
    """A 30 mm region at 20 % in a 60 % part, about four of its lattice sides across, enclosed by the
    denser zone.  Joined to it by Delaunay triangles, it held few points of its own and long edges
    fanning in from the 60 % border row (0.811 of a uniform 20 % pattern's C_min / rho over seeds 0-4
    in session 17, 0.872 with session 18's lattice to a quarter radius of the border).  Now the 60 %
    zone is sampled around it as around a hole and the region gets its own lattice's lines up to its
    border: inside it every line lies on that lattice, and measured as `bench/bench_regions.py` does
    (the frame model over the region, against a uniform 20 % pattern in the same window) it is as
    stiff per gram as the uniform pattern within 5 %; the densities stay on target."""
    from bench.stiffness import stiffness

    from DelaunayInfill.sampling import lattice_frame

    part, region = box(0, 0, 100, 100), box(35, 35, 65, 65)
    ratios = []
    for seed in range(5):
        pattern = InfillPattern.build(part, 0.6, 0.4, regions=[(region, 0.2)], seed=seed)
        lines = pattern.clip(part).segments
        zones = pattern.density_map.zones(part)
        for zone, target in zip(zones, pattern.density_map.densities, strict=True):
            length = MultiLineString([tuple(map(tuple, s)) for s in lines]).intersection(zone).length
            assert length * 0.4 / zone.area == pytest.approx(target, abs=0.015)
        # the lines well inside the region run along the lattice's three directions
        inner = lines[(np.abs(lines - 50.0) < 12.0).all(axis=(1, 2))]
        assert len(inner) >= 20
        angle = np.arctan2(*(inner[:, 1] - inner[:, 0])[:, ::-1].T)
        turn = np.mod(angle - lattice_frame(seed)[0], np.pi / 3)
        assert np.minimum(turn, np.pi / 3 - turn).max() < 1e-6, seed
        uniform = InfillPattern.build(part, 0.2, 0.4, seed=seed).clip(part).segments
        ratios.append(stiffness(lines, 0.4, window=30.0, centre=(50.0, 50.0)).c_min
                      / stiffness(uniform, 0.4, window=30.0, centre=(50.0, 50.0)).c_min)
    assert np.mean(ratios) >= 0.95, ratios


def test_a_dense_region_is_as_stiff_per_gram_as_a_uniform_pattern_of_its_density():
    """A 30 mm region at 60 % in a 20 % part, enclosed by it: its own lattice in whole triangles
    (`enclosed_zones.lattice_patch`).  Measured as `bench/bench_regions.py` does (the frame model in a
    window exactly over the region, against a uniform 60 % pattern in the same window): 0.909 over
    seeds 0-4 in session 20, when the lattice ended a radius short of the border, 0.98 now; the
    densities stay on target."""
    from bench.stiffness import stiffness

    part, region = box(0, 0, 100, 100), box(35, 35, 65, 65)
    ratios = []
    for seed in range(3):
        pattern = InfillPattern.build(part, 0.2, 0.4, regions=[(region, 0.6)], seed=seed)
        lines = pattern.clip(part).segments
        for zone, target in zip(pattern.density_map.zones(part), pattern.density_map.densities, strict=True):
            assert measured_density(lines, zone, 0.4) == pytest.approx(target, abs=0.015)
        uniform = InfillPattern.build(part, 0.6, 0.4, seed=seed).clip(part).segments
        ratios.append(stiffness(lines, 0.4, window=30.0, centre=(50.0, 50.0)).c_min
                      / stiffness(uniform, 0.4, window=30.0, centre=(50.0, 50.0)).c_min)
    assert min(ratios) >= 0.95, ratios


def test_balancing_inserts_no_two_circumcentres_close_together():
    """Two neighbouring triangles that are nearly cocircular have nearly the same circumcentre;
    inserting both made a 0.48 mm edge among 40 % samples (a 14 mm strip at 10 % in a 40 % part,
    seed 4, with the small-zone lattices).  Of centres within half a circumradius, the first wins."""
    from DelaunayInfill.calibration import _apart_centres

    centres = np.array([[0.0, 0.0], [0.3, 0.0], [5.0, 0.0], [5.0, 0.9], [5.0, 1.2]])
    kept = _apart_centres(centres, np.full(5, 2.0))
    assert kept.tolist() == [[0.0, 0.0], [5.0, 0.0], [5.0, 1.2]]
    part = box(0, 0, 80, 80)
    pattern = InfillPattern.build(part, 0.4, 0.4, regions=[(box(33, 0, 47, 80), 0.1)], seed=4)
    segments = pattern.segments
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    both_inside = contains_xy(part, *segments[:, 0].T) & contains_xy(part, *segments[:, 1].T)
    density = np.maximum(pattern.density_map.at(segments[:, 0]), pattern.density_map.at(segments[:, 1]))
    assert (length[both_inside] >= 0.25 * 2.0 * np.sqrt(3.0) * 0.4 / density[both_inside]).all()


def test_border_bands_are_each_zone_one_of_its_spacings_along_denser_zones():
    """`border_bands`: the sparse zone's band is its part within its own lattice side of the denser
    zone; the densest zone (no denser neighbour) has none; a zone apart from any denser one neither."""
    from DelaunayInfill.metering import border_bands

    part = box(0, 0, 80, 80)
    dense, far = box(30, 30, 50, 50), box(70, 70, 78, 78)
    zones = [part.difference(dense).difference(far), dense, far]
    meter = border_bands(zones, [0.2, 0.6, 0.2], 0.4)
    s = 2.0 * math.sqrt(3.0) * 0.4 / 0.2
    want = dense.buffer(s, 8).difference(dense).area
    assert meter.areas[0] == pytest.approx(want, rel=1e-6)
    assert meter.areas[1] == 0.0 and meter.areas[2] == 0.0
    assert border_bands(zones[:1], [0.2], 0.4) is None
