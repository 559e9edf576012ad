"""Delaunay triangulation, the paper's LOP criterion, angles, relaxation."""

import numpy as np
from shapely.geometry import box

from DelaunayInfill import InfillPattern, sample_poisson_disk
from DelaunayInfill.triangulation import (
    GrowingDelaunay,
    canonical_triangles,
    delaunay_triangles,
    lop_violations,
    node_edge_counts,
    relax_points,
    triangle_angles,
    uncrowded_edges,
    unique_edges,
)


def test_lop_counts_zero_on_delaunay_and_flags_a_flipped_edge():
    pts = sample_poisson_disk(box(0, 0, 40, 40), 2.0, seed=1)
    tri = delaunay_triangles(pts)
    assert lop_violations(pts, tri) == 0
    # A convex quadrilateral split along its longer diagonal breaks the criterion.
    quad = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 1.0], [0.0, 1.0]])
    good = np.array([[0, 1, 2], [0, 2, 3]])
    assert lop_violations(quad, good) == 0
    kite = np.array([[0.0, 0.0], [4.0, -1.0], [8.0, 0.0], [4.0, 1.0]])
    bad = np.array([[0, 1, 3], [1, 2, 3]])  # diagonal 1-3 is short; opposite angles at 0 and 2 are wide
    good_kite = np.array([[0, 1, 2], [0, 2, 3]])
    assert lop_violations(kite, bad) == 0 or lop_violations(kite, good_kite) == 1
    assert lop_violations(kite, good_kite) + lop_violations(kite, bad) == 1


def test_triangles_are_counter_clockwise_and_edges_unique():
    pts = np.random.default_rng(0).uniform(0, 10, (200, 2))
    tri = delaunay_triangles(pts)
    a, b, c = (pts[tri[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (cross > 0).all()
    edges = unique_edges(tri)
    assert len(edges) == len({tuple(e) for e in edges})
    # Euler: E = V + T - 1 for a triangulated convex hull
    assert len(edges) == len(pts) + len(tri) - 1


def test_degenerate_inputs_give_no_triangles():
    assert delaunay_triangles(np.zeros((2, 2))).shape == (0, 3)
    assert delaunay_triangles(np.c_[np.arange(5.0), np.arange(5.0)]).shape == (0, 3)


def test_angles_sum_to_180():
    pts = np.random.default_rng(1).uniform(0, 10, (50, 2))
    tri = delaunay_triangles(pts)
    np.testing.assert_allclose(triangle_angles(pts, tri).sum(axis=1), 180.0, atol=1e-6)


def test_maximal_uniform_samples_meet_the_30_degree_bar():
    pattern = InfillPattern.build(box(0, 0, 80, 80), 0.25, 0.4, seed=3)
    q = pattern.quality()
    assert q["lop_violations"] == 0
    assert q["min_angle_deg"] >= 30.0


def test_relaxation_makes_triangles_more_regular_and_keeps_density():
    # against the Poisson-disk pattern (the default samples a uniform density on a lattice)
    plain = InfillPattern.build(box(0, 0, 100, 100), 0.2, 0.4, seed=5, sampler="fast")
    relaxed = InfillPattern.build(box(0, 0, 100, 100), 0.2, 0.4, seed=5, relax=8, sampler="fast")
    qp, qr = plain.quality(), relaxed.quality()
    assert qr["lop_violations"] == 0
    assert qr["mean_min_angle_deg"] > qp["mean_min_angle_deg"] + 2.0
    assert qr["sharp_triangle_share"] < 0.5 * qp["sharp_triangle_share"]
    assert abs(relaxed.calibrated_densities[0] - 0.2) <= 0.015


def test_relax_points_keeps_points_near_their_area_and_count():
    area = box(0, 0, 30, 30)
    pts = sample_poisson_disk(area, 2.0, seed=0)
    moved = relax_points(pts, area, lambda xy: np.full(len(xy), 2.0), 3)
    assert moved.shape == pts.shape
    assert (moved >= -1e-9).all() and (moved <= 30 + 1e-9).all()


def test_unique_edges_are_the_sorted_distinct_vertex_pairs():
    pts = np.random.default_rng(5).uniform(0, 10, (500, 2))
    tri = delaunay_triangles(pts)
    rows = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    want = np.array(sorted({tuple(r) for r in rows.tolist()}))
    got = unique_edges(tri)
    assert got.dtype == np.intp
    assert np.array_equal(got, want)
    assert unique_edges(np.zeros((0, 3), dtype=np.intp)).shape == (0, 2)


def test_growing_delaunay_is_the_delaunay_of_all_points_so_far():
    """Points added in rounds: the same triangles as triangulating them all at once, counter-clockwise."""
    rng = np.random.default_rng(3)
    pts = sample_poisson_disk(box(0, 0, 40, 40), 2.5, seed=2)
    growing = GrowingDelaunay(pts)
    for _ in range(3):
        pts = np.r_[pts, rng.uniform(0, 40, (7, 2))]
        tri = growing.add(pts[-7:])
        want = delaunay_triangles(pts)
        assert np.array_equal(canonical_triangles(tri), canonical_triangles(want))
        a, b, c = (pts[tri[:, k]] for k in range(3))
        assert (((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) > 0).all()
    assert np.array_equal(growing.add(np.zeros((0, 2))), tri)


def test_canonical_triangles_ignore_order_and_starting_corner():
    tri = delaunay_triangles(sample_poisson_disk(box(0, 0, 30, 30), 2.0, seed=4))
    rng = np.random.default_rng(0)
    shuffled = np.roll(tri[rng.permutation(len(tri))], 1, axis=1)  # other order, other first corner
    canon = canonical_triangles(shuffled)
    assert np.array_equal(canon, canonical_triangles(tri))
    assert (canon[:, 0] < canon[:, 1:].min(axis=1)).all()  # smallest index first
    assert {tuple(np.roll(t, -int(np.argmin(t)))) for t in tri.tolist()} == set(map(tuple, canon.tolist()))


# ----------------------------------------------------------------------------- crowded nodes
def _fan(spokes: int, radius=3.0):
    """A hub joined to `spokes` rim points, the rim closed, each rim point also joined outwards.

    Segments (3 spokes, 2, 2): the spokes, the rim, the outer spokes (rim points have 4 edges).
    """
    angle = np.linspace(0.0, 2.0 * np.pi, spokes, endpoint=False)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), angle.shape)  # mm, one per spoke
    rim = np.c_[radius * np.cos(angle), radius * np.sin(angle)]
    hub = np.zeros((spokes, 2))
    return np.concatenate((np.stack((hub, rim), axis=1), np.stack((rim, np.roll(rim, -1, axis=0)), axis=1),
                           np.stack((rim, 2.0 * rim), axis=1)))


def test_a_hub_with_twelve_spokes_keeps_eight_spread_round_it():
    segments = _fan(12)
    keep = uncrowded_edges(segments)
    _, ends, counts = node_edge_counts(segments[keep])
    hub = np.flatnonzero((node_edge_counts(segments[keep])[0] == 0).all(axis=1))[0]
    assert counts[hub] == 8
    assert keep[12:].all()  # the rim and the outer spokes stay
    # the spokes left are spread: no gap wider than a quarter turn opened
    kept = segments[:12][keep[:12]][:, 1]
    angles = np.sort(np.degrees(np.arctan2(kept[:, 1], kept[:, 0])))
    gaps = np.diff(np.append(angles, angles[0] + 360.0))
    assert gaps.max() <= 90.0 + 1e-9


def test_a_crowded_node_between_two_densities_gives_up_its_short_edges():
    """At a node with long edges on one side and short ones on the other (a sparse sample next to a
    dense band), the short edges go: they print the least."""
    segments = _fan(12, np.r_[np.full(6, 1.2), np.full(6, 3.0)])  # one half turn of short spokes
    keep = uncrowded_edges(segments)
    assert keep[6:12].all() and (~keep[:6]).sum() == 4


def test_fixed_edges_count_at_a_crowded_node_but_stay():
    """A dense zone's own lattice lines (`enclosed_zones`) are never left out, but a node where the
    sparser zone's lines meet them counts them: the others go until it has eight."""
    segments = _fan(12, np.r_[np.full(6, 1.2), np.full(6, 3.0)])
    fixed = np.zeros(len(segments), bool)
    fixed[:6] = True  # the short spokes, which would go first
    keep = uncrowded_edges(segments, fixed=fixed)
    assert keep[:6].all() and (~keep[6:12]).sum() == 4 and keep[12:].all()
    keep = uncrowded_edges(segments, shortest=2.0, fixed=fixed)  # nor are they too short
    assert keep[:6].all()


def test_nodes_keep_their_edges_when_no_node_is_crowded():
    segments = _fan(8)
    assert uncrowded_edges(segments).all()


def test_a_short_edge_goes_while_both_ends_keep_three():
    segments = _fan(6)
    # a second hub 0.2 mm from the first, joined to it and to the rim
    near = np.array([0.2, 0.0])
    rim = segments[:6, 1]
    extra = np.concatenate((np.array([[[0.0, 0.0], near]]), np.stack((np.tile(near, (6, 1)), rim), axis=1)))
    segments = np.concatenate((segments, extra))
    keep = uncrowded_edges(segments, shortest=0.5)
    assert not keep[18]  # the 0.2 mm edge between the hubs
    assert keep.sum() == len(segments) - 1
