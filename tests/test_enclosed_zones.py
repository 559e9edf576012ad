"""Zones enclosed by denser or by sparser ones (`DelaunayInfill.enclosed_zones`): which zones, and their lines."""

import numpy as np
import pytest
from shapely.geometry import LineString, MultiLineString, Point, Polygon, box
from shapely.ops import unary_union

from DelaunayInfill.density import LATTICE_SIDE, DensityMap, sampling_radius
from DelaunayInfill.enclosed_zones import border_samples, enclosed_zones, hole_lines, lattice_edges, lattice_patch
from DelaunayInfill.geometry import to_multipolygon
from DelaunayInfill.metering import measured_density
from DelaunayInfill.pattern import InfillPattern
from DelaunayInfill.sampling import LATTICE_SPACING, lattice_frame, lattice_points
from DelaunayInfill.triangulation import delaunay_triangles

PART = to_multipolygon(box(0, 0, 100, 100))


def _enclosed(base, regions, part=PART, denser=False):
    dmap = DensityMap.create(base, regions)
    radii = np.array([sampling_radius(d, 0.4) for d in dmap.densities])
    zones = dmap.zones(part)
    return enclosed_zones(dmap, zones, part, radii, np.array([not z.is_empty for z in zones]), denser)


def test_a_sparse_region_inside_a_denser_part_is_enclosed_by_the_part():
    assert _enclosed(0.4, [(box(30, 30, 66, 66), 0.1)]).tolist() == [-1, 0]


@pytest.mark.parametrize("regions", [
    [(box(0, 30, 36, 66), 0.1)],  # on the part's edge: a base of the part, not enclosed
    [(box(30, 30, 66, 66), 0.6)],  # denser than the part
    [(box(48, 48, 52, 52), 0.1)],  # too small for its lattice (under 4 squared radii)
])
def test_a_region_on_the_edge_denser_or_too_small_is_not(regions):
    assert (_enclosed(0.4, regions) == -1).all()


def test_a_dense_region_inside_a_sparser_part_is_enclosed_the_other_way():
    assert _enclosed(0.2, [(box(30, 30, 66, 66), 0.6)], denser=True).tolist() == [-1, 0]
    assert _enclosed(0.2, [(box(30, 30, 66, 66), 0.6)], denser=False).tolist() == [-1, -1]
    assert _enclosed(0.2, [(box(0, 30, 36, 66), 0.6)], denser=True).tolist() == [-1, -1]  # on the edge


def test_a_region_beside_a_sparser_one_is_not_but_the_sparser_one_inside_both_is():
    regions = [(box(20, 20, 80, 80), 0.2), (box(30, 30, 70, 70), 0.1), (box(50, 20, 80, 80), 0.3)]
    # the 10 % box's visible half touches the 20 % and the 30 % zones (both denser): enclosed, mostly by the 20 %
    # one; the 20 % zone touches the 10 % box and the part's 40 %: not enclosed
    assert _enclosed(0.4, regions).tolist() == [-1, -1, 1, -1]


def test_lattice_edges_are_the_lattice_sides_between_its_nodes_each_once():
    side, seed = 5.0, 3
    edges = lattice_edges(box(0, 0, 30, 30), side, seed)
    assert np.allclose(np.hypot(*(edges[:, 1] - edges[:, 0]).T), side)
    nodes = lattice_points(box(-10, -10, 40, 40), side, seed)
    ends = edges.reshape(-1, 2)
    assert np.min(np.linalg.norm(ends[:, None] - nodes[None], axis=2), axis=1).max() < 1e-9
    keys = {tuple(sorted(map(tuple, np.round(e, 6).tolist()))) for e in edges}
    assert len(keys) == len(edges)


def test_border_samples_keep_their_distance_and_lie_on_the_border():
    zone = to_multipolygon(Point(50, 50).buffer(15, 32))
    rng = np.random.default_rng(0)
    points = rng.uniform(0, 100, (400, 2))
    points = points[~np.array([zone.contains(Point(*p)) for p in points])]
    border = border_samples(zone, points, 2.0)
    assert len(border) >= 20
    assert np.allclose([zone.boundary.distance(Point(*b)) for b in border], 0.0, atol=1e-9)
    gaps = np.linalg.norm(border[:, None] - np.concatenate((points, border))[None], axis=2)
    gaps[np.arange(len(border)), len(points) + np.arange(len(border))] = np.inf
    assert gaps.min() >= 0.6 * 2.0 - 1e-9


def test_hole_lines_stay_out_of_the_denser_triangles_and_end_on_their_nodes():
    zone = to_multipolygon(box(32, 32, 68, 68))
    dense_side = 3.5
    points = lattice_points(box(0, 0, 100, 100).difference(zone), dense_side, 1)
    triangles = delaunay_triangles(points)
    corners = points[triangles]
    longest = np.max(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2), axis=1)
    triangles = triangles[longest < 1.1 * dense_side]  # (the ones across the zone go)
    reach = dense_side / LATTICE_SPACING
    lines = hole_lines(zone, points, triangles, 14.0, 1, reach)
    assert len(lines) > 10
    inside = to_multipolygon(unary_union([Polygon(c) for c in points[triangles]])).buffer(-1e-6)
    assert MultiLineString([tuple(map(tuple, s)) for s in lines]).intersection(inside).length < 1e-6
    # every end outside the zone is one of the denser zone's nodes or of the zone's own lattice
    ends = lines.reshape(-1, 2)
    out = ~np.array([zone.buffer(1e-9).contains(Point(*e)) for e in ends])
    nodes = np.concatenate((points, lattice_points(box(0, 0, 100, 100), 14.0, 1)))
    assert (np.min(np.linalg.norm(ends[out][:, None] - points[None], axis=2), axis=1) < 1e-9).sum() >= 10
    assert np.min(np.linalg.norm(ends[out][:, None] - nodes[None], axis=2), axis=1).max() < 1e-9


def _crossings(lines: np.ndarray) -> int:
    """How many pairs of segments (k, 2, 2) cross at a point inside both (not where they share an end)."""
    a, d = lines[:, 0], lines[:, 1] - lines[:, 0]
    count = 0
    for lo in range(0, len(lines), 256):
        p, r = a[lo:lo + 256, None], d[lo:lo + 256, None]
        denom = r[..., 0] * d[None, :, 1] - r[..., 1] * d[None, :, 0]
        qp = a[None] - p
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (qp[..., 0] * d[None, :, 1] - qp[..., 1] * d[None, :, 0]) / denom
            u = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / denom
        inner = (np.abs(denom) > 1e-12) & (t > 1e-6) & (t < 1 - 1e-6) & (u > 1e-6) & (u < 1 - 1e-6)
        count += int(inner.sum())
    return count // 2


def _built_on_target(base, region, density, seed):
    """The pattern of PART at `base` with one region, clipped (k, 2, 2) mm; both zones measured whole
    within 1.5 points of their densities."""
    pattern = InfillPattern.build(PART, base, 0.4, regions=[(region, density)], seed=seed)
    lines = pattern.clip(PART).segments
    for zone, target in zip(pattern.density_map.zones(PART), pattern.density_map.densities, strict=True):
        length = MultiLineString([tuple(map(tuple, s)) for s in lines]).intersection(zone).length
        assert length * 0.4 / zone.area == pytest.approx(target, abs=0.015)
    return lines


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_enclosed_region_prints_its_density_and_nothing_crosses_it(seed):
    """Built whole: the region's and the part's densities on target, no line of the denser zone
    across the region (every line inside the region shrunk by a millimetre is the region's lattice's,
    as long as its side)."""
    region = box(32, 32, 68, 68)
    lines = _built_on_target(0.4, region, 0.1, seed)
    side = LATTICE_SPACING * sampling_radius(0.1, 0.4)
    core = region.buffer(-1.0)
    crossing = [s for s in lines if core.intersects(MultiLineString([tuple(map(tuple, s))]))]
    length = np.array([np.hypot(*(s[1] - s[0])) for s in crossing])
    # the region's own sides (calibration scales them a little) and pieces of them cut at the border
    assert (length < 1.2 * side).all()
    assert (np.abs(length / side - 1.0) < 0.2).sum() >= 10


@pytest.mark.parametrize("base, density, seed", [(0.4, 0.1, 12), (0.4, 0.1, 16), (0.6, 0.2, 12)])
def test_an_enclosed_sparse_region_keeps_its_density_to_its_border(base, density, seed):
    """The denser zone's ring of lines round the region lies outside it (`RING_OUTSIDE`), not on its border:
    measured whole, border included, the region is within 0.9 points of its density (11.29, 12.53 and
    18.76 % with the ring on the border)."""
    region = box(32, 32, 68, 68)
    lines = InfillPattern.build(PART, base, 0.4, regions=[(region, density)], seed=seed).clip(PART).segments
    printed = MultiLineString([tuple(map(tuple, s)) for s in lines]).intersection(region).length * 0.4 / region.area
    assert printed == pytest.approx(density, abs=0.009)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_sparse_region_inside_a_dense_one_inside_the_part_keeps_its_density(seed):
    """10 % inside 60 % inside a 20 % part: the 10 % region is sampled round (its ring outside it), the 60 %
    one is sampled too (no patch round a hole); each measured whole within 0.8 points (the 10 % region
    printed 9.0 % with the ring on its border)."""
    part = to_multipolygon(box(0, 0, 140, 140))
    regions = [(box(20, 20, 80, 80), 0.6), (box(35, 35, 65, 65), 0.1)]
    pattern = InfillPattern.build(part, 0.2, 0.4, regions=regions, seed=seed)
    lines = pattern.clip(part).segments
    for zone, target in zip(pattern.density_map.zones(part), pattern.density_map.densities, strict=True):
        assert measured_density(lines, zone, 0.4) == pytest.approx(target, abs=0.008)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_enclosed_sparse_region_prints_no_line_twice(seed):
    """A piece of the region's lattice whose two ends joined the two nodes of a denser edge (or of another
    piece) is that edge: it is left out (4, 2 and 3 lines printed twice before)."""
    lines = InfillPattern.build(PART, 0.6, 0.4, regions=[(box(32, 32, 68, 68), 0.2)], seed=seed).clip(PART).segments
    ends = np.round(lines * 1e5).astype(np.int64)
    forward = (ends[:, 0, 0] < ends[:, 1, 0]) | ((ends[:, 0, 0] == ends[:, 1, 0]) & (ends[:, 0, 1] <= ends[:, 1, 1]))
    keys = np.where(forward[:, None], ends.reshape(-1, 4), ends[:, ::-1].reshape(-1, 4))
    assert len(np.unique(keys, axis=0)) == len(lines)


@pytest.mark.parametrize("base, region, density, seed", [
    (0.2, Point(40, 40).buffer(6, 32), 0.6, 5), (0.2, Point(40, 40).buffer(6, 32), 0.6, 11),
    (0.1, box(32, 32, 48, 48), 0.4, 9), (0.1, box(32, 32, 48, 48), 0.4, 14)])
def test_a_small_dense_region_prints_its_density(base, region, density, seed):
    """A 12 mm disk at 60 % in 20 %, a 16 mm box at 40 % in 10 %: the lattice's whole triangles print too
    little of such a zone for the joining lines to make up (54.4, 57.6, 37.0 and 37.4 % as patches); it is
    sampled with the rest and balanced instead, within 1.5 points measured whole."""
    part = to_multipolygon(box(0, 0, 80, 80))
    pattern = InfillPattern.build(part, base, 0.4, regions=[(region, density)], seed=seed)
    lines = pattern.clip(part).segments
    for zone, target in zip(pattern.density_map.zones(part), pattern.density_map.densities, strict=True):
        assert measured_density(lines, zone, 0.4) == pytest.approx(target, abs=0.015)


def test_a_lattice_patch_is_the_lattice_triangles_with_two_corners_in_the_zone():
    """Every line a lattice side; each lattice triangle with at least two corners in the zone is in
    the patch and no other, so the patch covers the zone but for corners of triangles with one corner
    in it (within a side of the border) and reaches past the border by at most a triangle's height."""
    zone = to_multipolygon(Point(50, 50).buffer(12, 32))
    side, seed = 2.5, 4
    patch = lattice_patch(zone, side, seed)
    assert np.allclose(np.hypot(*(patch.lines[:, 1] - patch.lines[:, 0]).T), side)
    nodes = lattice_points(box(0, 0, 100, 100), side, seed)
    triangles = nodes[delaunay_triangles(nodes)]
    inside = np.array([[zone.contains(Point(*c)) for c in t] for t in triangles]).sum(axis=1)
    centres = triangles.mean(axis=1)
    in_patch = np.array([patch.area.contains(Point(*c)) for c in centres])
    assert (in_patch == (inside >= 2)).all()
    assert zone.buffer(-side).difference(patch.area).area < 1e-9
    assert zone.buffer(np.sqrt(3) / 2 * side + 1e-6).covers(patch.area)
    # the outline's nodes: lattice nodes on the patch's boundary, all of them
    assert np.allclose([patch.area.boundary.distance(Point(*p)) for p in patch.outline], 0.0, atol=1e-9)
    ends = np.unique(np.round(patch.lines.reshape(-1, 2), 6), axis=0)
    on_boundary = np.array([patch.area.boundary.distance(Point(*p)) < 1e-6 for p in ends])
    assert on_boundary.sum() == len(patch.outline)


def test_lines_on_a_patch_are_told_from_lines_that_end_on_it():
    """On the patch (its own lines are there): a chord between two of its outline's nodes along it or
    across it, a line through it or along its outline.  Not: a line from an outline node outwards, or
    ending on one."""
    zone = to_multipolygon(box(30, 30, 60, 60))
    patch = lattice_patch(zone, 3.0, 1)
    centre = np.array([45.0, 45.0])
    a, b = patch.outline[0], patch.outline[np.argsort(np.linalg.norm(patch.outline - patch.outline[0], axis=1))[3]]
    outward = a + 4.0 * (a - centre) / np.linalg.norm(a - centre)
    far = patch.outline[np.argmax(np.linalg.norm(patch.outline - a, axis=1))]  # across the patch
    segments = np.array([[a, b], [a, far], [outward, 2 * centre - outward], [a, outward], [outward, a]])
    assert patch.over(segments).tolist() == [True, True, True, False, False]
    # a line from an outline node along one of the outline's edges and on outwards prints that edge twice
    on_outline = [e for e in patch.lines if patch.area.boundary.distance(LineString(e).interpolate(0.5)) < 1e-9]
    start, end = on_outline[0]
    assert patch.over(np.array([[start, start + 3.0 * (end - start)]])).tolist() == [True]


def test_a_patch_joins_at_outline_nodes_a_radius_apart_clear_of_the_samples():
    zone = to_multipolygon(box(30, 30, 60, 60))
    patch = lattice_patch(zone, 2.0, 2)
    radius = 6.0
    points = np.array([[29.0, 45.0], [45.0, 80.0]])  # one close to the left side
    chosen = patch.joins(zone, points, radius)
    assert len(chosen) >= 0.8 * zone.length / radius - 1
    assert np.min(np.linalg.norm(chosen[:, None] - patch.outline[None], axis=2), axis=1).max() < 1e-9
    assert np.linalg.norm(chosen[:, None] - points[None], axis=2).min() >= 0.6 * radius
    gaps = np.linalg.norm(chosen[:, None] - chosen[None], axis=2) + np.eye(len(chosen)) * 1e9
    assert gaps.min() > 0.3 * radius


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_dense_region_prints_its_density_as_its_own_lattice(seed):
    """A 60 % region in a 20 % part: both densities on target measured whole, every line that meets the
    region but for its outer side's strip a side of one lattice (none of the sparser zone's lines crosses
    into it: they end on the lattice's outline), the lattice reaching past the border by at most a
    triangle's height."""
    region = box(35, 35, 65, 65)
    lines = _built_on_target(0.2, region, 0.6, seed)
    side = LATTICE_SIDE * 0.4 / 0.6
    core = region.buffer(-side)
    meets = np.array([core.intersects(MultiLineString([tuple(map(tuple, s))])) for s in lines])
    assert meets.sum() > 400
    length = np.hypot(*(lines[meets, 1] - lines[meets, 0]).T)
    assert np.allclose(length, side)
    angle = np.arctan2(*(lines[meets, 1] - lines[meets, 0])[:, ::-1].T)
    turn = np.mod(angle - lattice_frame(seed)[0], np.pi / 3)
    assert np.minimum(turn, np.pi / 3 - turn).max() < 1e-6
    reach = np.sqrt(3) / 2 * side + 1e-6
    assert region.buffer(reach).covers(MultiLineString([tuple(map(tuple, s)) for s in lines[meets]]))
    assert _crossings(lines) == 0  # (a junction edge across a corner of the lattice: 2-3 before it went)


@pytest.mark.parametrize("densities", [(0.6, 0.6), (0.6, 0.4)])
def test_two_dense_regions_a_millimetre_apart_keep_their_lattices_to_themselves(densities):
    """Each patch reaches only into the zone round it and keeps clear of the other by the other's reach:
    without that the two lattices overlapped in the 1 mm between them (the same lattice twice at equal
    densities: 6 segments printed twice; 9 and 10 pairs of crossing lines)."""
    left, right = box(30, 30, 49.5, 70), box(50.5, 30, 70, 70)
    pattern = InfillPattern.build(PART, 0.2, 0.4, regions=[(left, densities[0]), (right, densities[1])], seed=0)
    lines = pattern.clip(PART).segments
    keys = np.round(np.sort(lines, axis=1).reshape(-1, 4), 5)
    assert len(np.unique(keys, axis=0)) == len(lines)
    for zone, target in zip(pattern.density_map.zones(PART), pattern.density_map.densities, strict=True):
        assert measured_density(lines, zone, 0.4) == pytest.approx(target, abs=0.015)
    assert _crossings(lines) == 0


def test_a_dense_zone_round_a_sparse_one_is_sampled_not_patched():
    """A 10 % region inside a 60 % one inside a 20 % part: the 10 % zone is sampled round (its lines
    join the 60 % zone's samples), so the 60 % zone is not a patch, though denser than all round it."""
    from DelaunayInfill.seamless_layout import plan

    part = to_multipolygon(box(0, 0, 100, 100))
    dmap = DensityMap.create(0.2, [(box(20, 20, 80, 80), 0.6), (box(35, 35, 65, 65), 0.1)])
    build = plan(part, dmap, 0.4, 0, "measured", 0, "lattice", part)
    assert build.surround.tolist() == [-1, -1, 1] and not build.patches
    dmap = DensityMap.create(0.2, [(box(20, 20, 80, 80), 0.6)])
    assert list(plan(part, dmap, 0.4, 0, "measured", 0, "lattice", part).patches) == [1]
