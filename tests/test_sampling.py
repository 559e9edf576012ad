"""Poisson-disk sampling: minimum distance, maximality, variable radius, determinism."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay, cKDTree
from shapely.geometry import Point, Polygon, box
from shapes import annulus, star

from DelaunayInfill import sample_poisson_disk
from DelaunayInfill.geometry import contains_xy
from DelaunayInfill.sampling import (
    LATTICE_SPACING,
    _fill_gaps_constant,
    _grid_cells,
    _grid_independent_set,
    _uniform_level,
    close_pairs,
    greedy_independent_set,
    hash_uniform,
    lattice_points,
    sample_lattice,
    uncovered_fraction,
)

METHODS = ["fast", "lattice", "bridson"]


def min_pair_distance(points):
    if len(points) < 2:  # no pair (a region too small for a candidate: no sample at all)
        return np.inf
    d, _ = cKDTree(points).query(points, k=2)
    return d[:, 1].min()


def wide_interior_circles(region, points, r):
    """Delaunay circumcircles wider than r centred inside `region` farther than r from its border.

    Each one's centre is an uncovered point: a maximal sampling has none.
    """
    deep_area = region.buffer(-r)
    if deep_area.is_empty:  # no circle centre can lie that deep inside
        return 0
    if len(points) < 3:  # no triangulation: look for uncovered places of the deep area on a fine grid
        x0, y0, x1, y1 = deep_area.bounds
        gx, gy = np.meshgrid(np.arange(x0, x1 + r / 8, r / 8), np.arange(y0, y1 + r / 8, r / 8))
        grid = np.c_[gx.ravel(), gy.ravel()]
        grid = grid[contains_xy(deep_area, grid[:, 0], grid[:, 1])]
        if not len(points):
            return len(grid)
        far = np.hypot(*(grid[:, None, :] - points[None, :, :]).transpose(2, 0, 1)).min(axis=1) > r * (1 + 1e-9)
        return int(far.sum())
    tri = Delaunay(points).simplices
    a, b, c = (points[tri[:, k]] for k in range(3))
    d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
    sa, sb, sc = ((p * p).sum(axis=1) for p in (a, b, c))
    centre = np.c_[
        (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d,
        (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d,
    ]
    wide = np.hypot(*(centre - a).T) > r * (1 + 1e-9)
    deep = contains_xy(deep_area, centre[:, 0], centre[:, 1])
    return np.count_nonzero(wide & deep)


def random_region(seed):
    """A star-shaped polygon, sometimes with a hole and a thin appendix."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(3, 12))
    angle = np.sort(rng.uniform(0, 2 * np.pi, k))
    radius = rng.uniform(10, 40, k)
    region = Polygon(np.c_[radius * np.cos(angle), radius * np.sin(angle)]).buffer(0)
    if region.area < 1.0:  # three corners almost in a line: a disc instead (the tests need an area)
        region = Point(0, 0).buffer(float(radius[0]))
    if rng.random() < 0.5:
        holed = region.difference(Point(region.centroid).buffer(rng.uniform(1, 6)))
        region = holed if holed.area >= 1.0 else region  # (a hole that would take it all is left out)
    if rng.random() < 0.3:
        x1 = region.bounds[2]
        region = region.union(box(x1 - 2, 0, x1 + 15, rng.uniform(1, 5)))
    return region


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shape", [lambda: box(0, 0, 60, 40), star, annulus])
def test_uniform_radius_is_poisson_and_maximal(method, shape):
    region = shape()
    r = 2.5
    pts = sample_poisson_disk(region, r, seed=4, method=method)
    assert len(pts) > 50
    assert contains_xy(region.buffer(1e-9), pts[:, 0], pts[:, 1]).all()
    assert min_pair_distance(pts) >= r * (1 - 1e-9)
    assert uncovered_fraction(region, pts, r) <= 0.01


@pytest.mark.parametrize("method", METHODS)
def test_variable_radius_respects_local_radius_and_is_maximal(method):
    region = box(0, 0, 60, 30)

    def radius(xy):
        return np.where(xy[:, 0] < 30, 1.5, 4.0)

    pts = sample_poisson_disk(region, radius, seed=2, method=method)
    i, j = close_pairs(pts, radius(pts))
    assert i.size == 0, "two samples closer than the larger of their radii"
    assert uncovered_fraction(region, pts, radius) <= 0.01
    left = np.count_nonzero(pts[:, 0] < 30)
    right = len(pts) - left
    # point density scales with 1 / r^2: (4 / 1.5)^2 = 7.1
    assert 5.0 < left / right < 9.5


def test_fast_sampler_covers_better_than_scipy_poisson_disk():
    from scipy.stats import qmc

    region = box(0, 0, 100, 100)
    ours = sample_poisson_disk(region, 3.3, seed=1)
    theirs = qmc.PoissonDisk(2, radius=0.033, seed=1).fill_space() * 100
    assert uncovered_fraction(region, ours, 3.3) <= uncovered_fraction(region, theirs, 3.3)


def test_same_seed_same_samples_other_seed_other_samples():
    a = sample_poisson_disk(star(), 2.0, seed=7)
    b = sample_poisson_disk(star(), 2.0, seed=7)
    c = sample_poisson_disk(star(), 2.0, seed=8)
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def test_pattern_is_local_a_larger_region_keeps_the_interior():
    """Hashed candidates: growing the region changes the samples only near its border."""
    small = sample_poisson_disk(box(0, 0, 40, 40), 2.0, seed=3)
    large = sample_poisson_disk(box(-20, -20, 60, 60), 2.0, seed=3)
    core = small[(np.abs(small - 20) < 12).all(axis=1)]
    d, _ = cKDTree(large).query(core)
    assert np.mean(d < 1e-9) > 0.9


def test_multipolygon_and_holes_are_filled_everywhere():
    region = Point(0, 0).buffer(10).union(Point(40, 0).buffer(6)).difference(Point(0, 0).buffer(3))
    for method in METHODS:
        pts = sample_poisson_disk(region, 1.5, seed=0, method=method)
        assert uncovered_fraction(region, pts, 1.5) <= 0.01
        assert not contains_xy(Point(0, 0).buffer(3 - 1e-6), pts[:, 0], pts[:, 1]).any()


@pytest.mark.parametrize(
    "region, radius, message",
    [
        (Polygon(), 1.0, "empty"),
        (Polygon([(0, 0), (1, 1), (2, 2)]), 1.0, "no area"),
        (box(0, 0, 10, 10), 0.0, "radius"),
        (box(0, 0, 10, 10), -1.0, "radius"),
        (box(0, 0, 10, 10), float("nan"), "radius"),
        (Polygon([(0, 0), (float("nan"), 1), (2, 0)]), 1.0, "NaN"),
        ("not a polygon", 1.0, "Polygon"),
    ],
)
def test_bad_input_raises_clear_value_error(region, radius, message):
    with pytest.raises(ValueError, match=message):
        sample_poisson_disk(region, radius)


def test_unknown_method_and_bad_radius_function():
    with pytest.raises(ValueError, match="method"):
        sample_poisson_disk(box(0, 0, 5, 5), 1.0, method="magic")
    with pytest.raises(ValueError, match="radius function"):
        sample_poisson_disk(box(0, 0, 5, 5), lambda xy: -np.ones(len(xy)))


def test_self_intersecting_region_is_repaired():
    bowtie = Polygon([(0, 0), (20, 20), (20, 0), (0, 20)])
    pts = sample_poisson_disk(bowtie, 1.0)
    assert len(pts) > 20
    assert uncovered_fraction(bowtie, pts, 1.0) <= 0.01


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 60), st.integers(0, 10_000))
def test_greedy_independent_set_is_independent_and_maximal(n, seed):
    rng = np.random.default_rng(seed)
    a = rng.integers(0, n, 3 * n)
    b = rng.integers(0, n, 3 * n)
    keep = a != b
    a, b = a[keep], b[keep]
    priority = rng.permutation(n).astype(float)
    chosen = greedy_independent_set(n, a, b, priority)
    assert not (chosen[a] & chosen[b]).any()
    covered = chosen.copy()
    covered[b[chosen[a]]] = True
    covered[a[chosen[b]]] = True
    assert covered.all()
    # equals the sequential greedy in priority order
    seq = np.zeros(n, bool)
    for v in np.argsort(priority):
        nbrs = np.r_[b[a == v], a[b == v]]
        if not seq[nbrs].any():
            seq[v] = True
    np.testing.assert_array_equal(chosen, seq)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.4, 3.0))
@example(791, 1.0)  # a region of 0.87 mm²: two samples, nothing to triangulate
@example(343, 1.0)  # a region of 0.13 mm², no point of it a radius deep: no sample
def test_fast_sampler_leaves_no_gap_inside(seed, r):
    """Exact maximality away from the border, also in pockets open to it (min angle >= 30 deg there)."""
    region = random_region(seed)
    pts = sample_poisson_disk(region, r, seed=seed)
    assert min_pair_distance(pts) >= r * (1 - 1e-9)
    assert contains_xy(region, pts[:, 0], pts[:, 1]).all()
    assert wide_interior_circles(region, pts, r) == 0


@pytest.mark.parametrize("drop", [0.2, 0.6, 0.95])
def test_gap_filling_closes_big_holes_in_several_passes(drop):
    """Start from a maximal set with most samples removed: the filler alone must make it maximal again."""
    region = box(0, 0, 50, 40).difference(Point(20, 20).buffer(6))
    r = 1.5
    full = _uniform_level(region, 0.5 * r, r, seed=5)
    keep = np.random.default_rng(1).random(len(full)) >= drop
    sparse = full[keep]
    filled = _fill_gaps_constant(region, sparse, r)
    np.testing.assert_array_equal(filled[: len(sparse)], sparse)  # existing samples stay, new ones follow
    assert min_pair_distance(filled) >= r * (1 - 1e-9)
    assert wide_interior_circles(region, filled, r) == 0
    assert uncovered_fraction(region, filled, r) < 0.002


def test_single_sample_grows_into_a_maximal_set():
    region = Point(0, 0).buffer(8)
    filled = _fill_gaps_constant(region, np.array([[0.0, 0.0], [1.2, 0.5]]), 1.0)
    assert len(filled) > 40
    assert min_pair_distance(filled) >= 1.0 - 1e-9
    assert wide_interior_circles(region, filled, 1.0) == 0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.3, 0.9))
def test_grid_independent_set_equals_the_greedy_one(seed, spacing):
    """The array-shift first round + edge-list rounds give the sequential greedy set."""
    region = Point(0, 0).buffer(12).difference(box(-2, -20, 2, 3))
    r = 1.0
    ii, jj = _grid_cells(region, spacing)
    x = (ii + hash_uniform(ii, jj, 0, seed)) * spacing
    y = (jj + hash_uniform(ii, jj, 1, seed)) * spacing
    inside = contains_xy(region, x.ravel(), y.ravel()).reshape(x.shape)
    priority = hash_uniform(ii, jj, 3, seed)
    reach = int(np.ceil(r / spacing - 1e-9))
    chosen = _grid_independent_set(x, y, inside, priority, r, reach)
    pts = np.c_[x[inside], y[inside]]
    pairs = cKDTree(pts).query_pairs(r, output_type="ndarray")
    close = np.hypot(*(pts[pairs[:, 0]] - pts[pairs[:, 1]]).T) < r
    expected = greedy_independent_set(len(pts), pairs[close, 0], pairs[close, 1], priority[inside])
    np.testing.assert_array_equal(chosen[inside], expected)
    assert not chosen[~inside].any()


def test_greedy_independent_set_with_equal_priorities_ends_and_prefers_lower_index():
    a = np.array([0, 1, 2, 3])
    b = np.array([1, 2, 0, 4])  # a triangle 0-1-2 and an edge 3-4
    chosen = greedy_independent_set(5, a, b, np.zeros(5))
    np.testing.assert_array_equal(chosen, [True, False, False, True, False])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("n", "m"), [(40, None), (30, 200), (300, None), (150, 400)])
def test_close_pairs_with_and_without_trees_agree(monkeypatch, seed, n, m):
    """close_pairs tests few pairs directly, many through k-d trees: the same pairs either way,
    each within the larger radius of its two points (checked by brute force)."""
    from DelaunayInfill import sampling

    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 30, (n, 2))
    rp = rng.uniform(0.5, 4.0, n)  # three radius classes
    q, rq = (None, None) if m is None else (rng.uniform(0, 30, (m, 2)), rng.uniform(0.5, 4.0, m))
    d = np.hypot(*(p[:, None] - (p if q is None else q)[None]).transpose(2, 0, 1))
    want = d < np.maximum(rp[:, None], (rp if q is None else rq)[None])
    if q is None:
        want = np.triu(want, 1)
    for limit in (0, 10**9):  # trees always / never
        monkeypatch.setattr(sampling, "_ALL_PAIRS", limit)
        i, j = close_pairs(p, rp, q, rq)
        assert len(i) == np.count_nonzero(want)  # each pair once
        if q is None:  # either order
            i, j = np.minimum(i, j), np.maximum(i, j)
        got = np.zeros_like(want)
        got[i, j] = True
        assert np.array_equal(got, want)


@pytest.mark.parametrize("seed", [0, 3])
def test_sampling_with_its_triangulation_hands_over_the_delaunay_of_the_samples(seed):
    """sample_triangulated: the fast sampler's samples, and its gap filling's open triangulation of
    exactly them, which goes on taking points (balancing) as a fresh one would."""
    from DelaunayInfill.sampling import sample_triangulated
    from DelaunayInfill.triangulation import GrowingDelaunay, canonical_triangles, delaunay_triangles

    region = Point(0, 0).buffer(30, 32).difference(box(-4, -4, 4, 4))

    def radius(xy):
        return np.where(xy[:, 0] < 0, 1.5, 3.0)

    points, qhull, _ = sample_triangulated(region, radius, seed=seed)
    np.testing.assert_array_equal(points, sample_poisson_disk(region, radius, seed=seed))
    assert qhull is not None
    growing = GrowingDelaunay(points, qhull)
    same = canonical_triangles(growing.add(np.zeros((0, 2))))
    np.testing.assert_array_equal(same, canonical_triangles(delaunay_triangles(points)))
    extra = np.random.default_rng(seed).uniform(-20, 20, (15, 2))
    grown = canonical_triangles(growing.add(extra))
    np.testing.assert_array_equal(grown, canonical_triangles(delaunay_triangles(np.r_[points, extra])))
    # A constant radius fills its gaps without a triangulation: none to hand over.
    assert sample_triangulated(region, 2.0, seed=seed)[1] is None


def test_lattice_sampling_is_an_equilateral_lattice_fixed_in_the_plane():
    r = 2.0
    pts = sample_poisson_disk(box(0, 0, 60, 40), r, seed=5, method="lattice")
    side = LATTICE_SPACING * r
    d, _ = cKDTree(pts).query(pts, k=7)
    inner = (np.abs(pts - [30, 20]) < [25, 15]).all(axis=1)
    np.testing.assert_allclose(d[inner, 1:], side, rtol=1e-9)  # six neighbours at one side
    assert side > r and side / np.sqrt(3) < r  # a Poisson-disk set, and maximal
    # the same lattice in another region (a fixed function of the plane), another per seed
    other = sample_poisson_disk(box(20, 10, 90, 70), r, seed=5, method="lattice")
    core = pts[(np.abs(pts - [40, 25]) < 8).all(axis=1)]
    assert len(core) > 10
    assert cKDTree(other).query(core)[0].max() < 1e-9
    assert not np.allclose(lattice_points(box(0, 0, 30, 30), side, 6)[:3], lattice_points(box(0, 0, 30, 30), side, 5)[:3])


def test_lattice_sampling_with_a_variable_radius_keeps_lattices_in_the_uniform_parts():
    region = box(0, 0, 80, 40)

    def radius(xy):
        return np.where(xy[:, 0] < 40, 1.5, 4.0)

    pts = sample_poisson_disk(region, radius, seed=1, method="lattice")
    i, _ = close_pairs(pts, radius(pts))
    assert i.size == 0
    assert uncovered_fraction(region, pts, radius) <= 0.01
    d, _ = cKDTree(pts).query(pts, k=7)
    for x0, x1, r in ((3, 35, 1.5), (50, 77, 4.0)):
        core = (pts[:, 0] > x0) & (pts[:, 0] < x1) & (pts[:, 1] > 5) & (pts[:, 1] < 35)
        regular = np.all(np.abs(d[core, 1:] / (LATTICE_SPACING * r) - 1) < 1e-9, axis=1)
        assert regular.mean() > 0.8


def test_sample_lattice_lists_its_lattice_points_first():
    region = box(0, 0, 80, 40)
    pts, k = sample_lattice(region, 2.0, seed=3)
    np.testing.assert_array_equal(pts[:k], lattice_points(region, LATTICE_SPACING * 2.0, 3))

    def radius(xy):
        return np.where(xy[:, 0] < 40, 1.5, 4.0)

    pts, k = sample_lattice(region, radius, seed=3)
    np.testing.assert_array_equal(pts, sample_poisson_disk(region, radius, seed=3, method="lattice"))
    assert 0 < k < len(pts)
    on_lattice = np.zeros(len(pts), dtype=bool)
    for r in (1.5, 4.0):
        d, _ = cKDTree(lattice_points(region, LATTICE_SPACING * r, 3)).query(pts)
        on_lattice |= d < 1e-9
    assert on_lattice[:k].all()


def test_lattice_sampling_of_a_continuous_radius_is_the_fast_sampling():
    region = box(0, 0, 60, 30)

    def radius(xy):
        return 1.5 + 0.05 * xy[:, 0]  # no two probes share a radius: no lattice anywhere

    pts, k = sample_lattice(region, radius, seed=2)
    assert k == 0
    np.testing.assert_array_equal(pts, sample_poisson_disk(region, radius, seed=2, method="fast"))


def test_another_sampling_between_the_lattices_keeps_the_lattices():
    """`between_seed` resamples only the Poisson-disk samples between the lattices (the build tries
    another where a border band prints off its density): the lattice points are the seed's."""
    region = box(0, 0, 80, 40)

    def radius(xy):
        return np.where(xy[:, 0] < 40, 1.5, 4.0)

    first, k = sample_lattice(region, radius, seed=3)
    other, j = sample_lattice(region, radius, seed=3, between_seed=1)
    np.testing.assert_array_equal(np.unique(first[:k], axis=0), np.unique(other[:j], axis=0))
    between, between_other = first[k:], other[j:]
    assert len(between) and len(between_other)
    assert not np.array_equal(np.unique(between, axis=0), np.unique(between_other, axis=0))
    np.testing.assert_array_equal(sample_lattice(region, radius, seed=3, between_seed=None)[0], first)
