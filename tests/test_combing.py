"""Combed travel: inside the part, short, and refused where no inside path exists."""

import numpy as np
from shapely.geometry import LineString, MultiPolygon, Point, Polygon, box

from DelaunayInfill.combing import CombingArea, reflex_vertices, segments_inside

U_SHAPE = Polygon([(0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30)])


def _route(start, bends, end) -> LineString:
    return LineString(np.vstack([start, bends, end]))


def test_reflex_vertices_of_a_u_and_of_a_hole():
    corners = reflex_vertices(U_SHAPE)
    assert sorted(map(tuple, corners)) == [(10.0, 10.0), (20.0, 10.0)]
    ring = box(0, 0, 40, 40).difference(box(15, 15, 25, 25))
    assert sorted(map(tuple, reflex_vertices(ring))) == [(15, 15), (15, 25), (25, 15), (25, 25)]


def test_travel_between_the_arms_of_a_u_goes_round_the_inner_corners():
    comb = CombingArea(U_SHAPE, margin=0.5)
    start, end = np.array([5.0, 25.0]), np.array([25.0, 25.0])
    bends = comb.path(start, end)
    assert bends is not None and len(bends) == 2
    route = _route(start, bends, end)
    assert route.within(U_SHAPE)
    assert min(Point(b).distance(U_SHAPE.exterior) for b in bends) >= 0.5 - 1e-6  # clear of the wall
    # between the shortest path through the corners themselves and the one through the corners
    # of the square of side `margin` round them (the shrunk part rounds them in between)
    lower = 2 * np.hypot(5, 15) + 10
    upper = 2 * np.hypot(4.5, 15.5) + 11
    assert lower < route.length <= upper


def test_straight_travel_inside_needs_no_bend():
    comb = CombingArea(U_SHAPE, margin=0.5)
    assert comb.path((2.0, 2.0), (28.0, 5.0)).shape == (0, 2)


def test_travel_round_a_hole_stays_inside_and_is_shortest():
    part = box(0, 0, 40, 40).difference(box(15, 15, 25, 25))
    comb = CombingArea(part, margin=1.0)
    start, end = np.array([20.0, 5.0]), np.array([20.0, 35.0])
    bends = comb.path(start, end)
    route = _route(start, bends, end)
    assert route.within(part)
    # round one side of the hole: through its corners at best, through its corners pushed out
    # diagonally by the margin at worst
    assert 2 * np.hypot(5, 10) + 10 < route.length <= 2 * np.hypot(6, 9) + 12
    assert Point(bends[0]).distance(box(15, 15, 25, 25)) >= 1.0 - 1e-6


def test_islands_and_unseen_ends_have_no_combed_path():
    islands = MultiPolygon([box(0, 0, 10, 10), box(20, 0, 30, 10)])
    assert CombingArea(islands, margin=0.4).path((5, 5), (25, 5)) is None
    assert CombingArea(U_SHAPE, margin=0.5).path((5, 25), (50, 50)) is None  # an end outside the part


def test_many_random_travels_in_a_star_stay_inside():
    angles = np.linspace(np.pi / 2, np.pi / 2 + 2 * np.pi, 11)[:-1]
    radii = np.where(np.arange(10) % 2 == 0, 50.0, 20.0)
    star = Polygon(np.c_[radii * np.cos(angles), radii * np.sin(angles)])
    comb = CombingArea(star, margin=0.4)
    rng = np.random.default_rng(3)
    points = rng.uniform(-50, 50, (400, 2))
    points = points[[star.buffer(-1.0).contains(Point(p)) for p in points]][:60]
    tips = 40.0 * np.c_[np.cos(angles[::2]), np.sin(angles[::2])]  # tip to next tip: never straight
    points = np.vstack([points, np.c_[tips, np.roll(tips, -1, axis=0)].reshape(-1, 2)])
    found = 0
    for a, b in zip(points[::2], points[1::2]):
        bends = comb.path(a, b)
        assert bends is not None  # a star is one island: every pair has an inside path
        route = _route(a, bends, b)
        assert route.within(star.buffer(1e-6))
        assert route.length >= np.linalg.norm(b - a) - 1e-9
        found += len(bends) > 0
    assert found >= 5  # the test crosses the star's concave corners, not only straight travels


def test_segments_inside_against_shapely():
    rng = np.random.default_rng(0)
    starts, ends = rng.uniform(-5, 35, (300, 2)), rng.uniform(-5, 35, (300, 2))
    got = segments_inside(starts, ends, U_SHAPE)
    expected = [LineString([a, b]).within(U_SHAPE) for a, b in zip(starts, ends)]
    assert got.tolist() == expected
    assert not segments_inside([[np.nan, 0]], [[1, 1]], U_SHAPE)[0]


def test_an_end_on_the_outline_is_reached_within_the_tolerance():
    start, end = np.array([5.0, 25.0]), np.array([25.0, 30.04])  # the end just above the right arm's top
    assert CombingArea(U_SHAPE, margin=0.5).path(start, end) is None
    bends = CombingArea(U_SHAPE, margin=0.5, tolerance=0.1).path(start, end)
    assert bends is not None and len(bends) >= 2
    assert _route(start, bends, end).within(U_SHAPE.buffer(0.1))


def test_segments_inside_with_unknown_and_zero_length_rows():
    """Rows with a non-finite end are outside, a zero-length row is inside where its point is; the others as shapely says."""
    starts = np.array([[5, 5], [np.nan, 5], [5, 5], [15, 20], [5, 5], [np.inf, 0], [25, 25], [5, 25]], dtype=float)
    ends = np.array([[5, 25], [5, 25], [5, 5], [15, 20], [25, 25], [5, 5], [25, 25], [25, 25]], dtype=float)
    expected = [True, False, True, False, False, False, True, False]
    assert segments_inside(starts, ends, U_SHAPE).tolist() == expected
    for keep in ([0, 2, 3], [1, 5], [0, 4, 7], [2]):  # every row alone or in any company: the same answer
        assert segments_inside(starts[keep], ends[keep], U_SHAPE).tolist() == [expected[k] for k in keep]
    assert segments_inside(np.zeros((0, 2)), np.zeros((0, 2)), U_SHAPE).tolist() == []
    assert segments_inside(starts, ends, None).tolist() == [False] * len(starts)
