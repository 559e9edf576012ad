"""The speed-ups of the modifier split and the per-layer bookkeeping give what the plain forms give.

* `_OwnerGrid.polygon` / `_OwnerGrid.regions` (the cell borders traced, faces built once) cover
  exactly the cells of each label and nothing else, as valid polygons;
* `_inside_lattice` (even-odd along rows) equals shapely's point-in-area test;
* `_owner_grid` (a bounded nearest-line search first) gives the owners of a full search;
* `between_lines` (runs of quadrilaterals as one polygon) covers what the union of its quadrilaterals covers;
* `split_by_line_ends` splits its area into disjoint parts, the host being all the modifiers leave,
  and two box modifiers come back as their boxes;
* `span_pieces` (all meshes' families in one pass) gives each mesh's `between_lines`, and growing its
  overlapping pieces grows their union;
* `_nearest_mesh` (all at once, or a bounded pass first) gives the owners of a full search;
* `infer.nearest_sample_distance` (closed form per segment) equals a tree of all the samples;
* `median_of`, `_nearest_within` and the geometry helpers equal numpy's / shapely's plain forms;
* `geometry.distances` equals shapely's distance one geometry at a time;
* `_has_both_walls` (one set of printed features per layer) equals the mask test;
* `_Run._fraction_inside` remembers modifiers with as many lines separately.
"""

from __future__ import annotations

import gzip
import os

import numpy as np
import pytest
from scipy.spatial import cKDTree
from shapely.geometry import LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon, box
from shapely.ops import polygonize, unary_union

from DelaunayInfill.gcode import ProcessSettings, process
from DelaunayInfill.gcode.area import closed_loops, median_of, mesh_layer, piece_centres, sample_segments, without_foreign
from DelaunayInfill.gcode.infer import nearest_sample_distance
from DelaunayInfill.gcode.read import (
    WALL_INNER,
    WALL_OUTER,
    MachineState,
    RetractionModel,
    as_cura_list,
    parse_layer,
)
from DelaunayInfill.gcode.split import (
    _inside_lattice,
    _nearest_mesh,
    _nearest_within,
    _owner_grid,
    _OwnerGrid,
    between_lines,
    line_families,
    span_pieces,
    split_by_line_ends,
)
from DelaunayInfill.geometry import (
    contains_xy,
    convex_hull_of,
    distances,
    multilinestring_of,
    points_on_surface,
    polygons_of,
    polygonize_segments,
)

DATA = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data")


@pytest.mark.parametrize("seed", range(12))
def test_grid_polygon_covers_exactly_the_masked_cells(seed):
    rng = np.random.default_rng(seed)
    rows, cols = int(rng.integers(1, 30)), int(rng.integers(1, 30))
    mask = rng.random((rows, cols)) < rng.uniform(0.1, 0.9)
    if seed % 3 == 0:  # blocks of equal runs in consecutive rows (the merged case)
        mask[:] = False
        mask[2 : rows - 1, 1 : max(2, cols // 2)] = True
    grid = _OwnerGrid(x0=-3.0, y0=5.0, step=0.5, owner=np.zeros((rows, cols), dtype=np.int64))
    poly = grid.polygon(mask)
    assert poly.area == pytest.approx(mask.sum() * 0.25, abs=1e-9)
    centres = grid.centres().reshape(-1, 2)
    inside = contains_xy(poly, centres[:, 0], centres[:, 1])
    assert np.array_equal(inside, mask.ravel())


def _random_mask(rng, rows: int, cols: int) -> np.ndarray:
    """Noise, a checkerboard with holes (corners where cells touch diagonally) or smooth blobs."""
    kind = int(rng.integers(3))
    if kind == 0:
        return rng.random((rows, cols)) < rng.uniform(0.05, 0.95)
    if kind == 1:
        return (np.add.outer(np.arange(rows), np.arange(cols)) % 2 == 0) ^ (rng.random((rows, cols)) < 0.3)
    yy, xx = np.mgrid[:rows, :cols]
    return np.sin(xx / rng.uniform(1, 5)) + np.cos(yy / rng.uniform(1, 5)) + rng.normal(0, 0.5, (rows, cols)) > 0


@pytest.mark.parametrize("seed", range(40))
def test_traced_mask_polygon_is_valid_and_exact(seed):
    """Diagonal touches, rings inside rings, cells alone: every masked cell and no other, a valid area."""
    rng = np.random.default_rng(100 + seed)
    rows, cols = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    mask = _random_mask(rng, rows, cols)
    grid = _OwnerGrid(x0=-3.1, y0=5.3, step=0.37, owner=np.zeros((rows, cols), dtype=np.int64))
    poly = grid.polygon(mask)
    assert poly.is_valid
    assert poly.area == pytest.approx(mask.sum() * 0.37**2, abs=1e-9)
    centres = grid.centres().reshape(-1, 2)
    assert np.array_equal(contains_xy(poly, centres[:, 0], centres[:, 1]), mask.ravel())
    # the plain form: a union of one square per cell
    x, y = centres[mask.ravel()].T
    squares = [box(a - 0.185, b - 0.185, a + 0.185, b + 0.185) for a, b in zip(x, y, strict=True)]
    if squares:
        assert poly.symmetric_difference(unary_union(squares)).area < 1e-9


@pytest.mark.parametrize("seed", range(30))
def test_regions_cover_each_label_and_the_free_cells_exactly(seed):
    rng = np.random.default_rng(200 + seed)
    rows, cols, count = int(rng.integers(1, 35)), int(rng.integers(1, 35)), int(rng.integers(1, 6))
    labels = rng.integers(-1, count, (rows, cols))
    if seed % 2:  # larger patches of one label, with T-junctions between three labels
        yy, xx = np.mgrid[:rows, :cols]
        field = np.sin(xx / rng.uniform(1, 6)) * 2 + np.cos(yy / rng.uniform(1, 6)) * 2 + rng.normal(0, 0.3, (rows, cols))
        labels = (np.floor(field) % (count + 1)).astype(np.int64) - 1
    step = 0.37
    grid = _OwnerGrid(x0=-3.1, y0=5.3, step=step, owner=np.zeros((rows, cols), dtype=np.int64))
    parts, free = grid.regions(labels, count)
    centres = grid.centres().reshape(-1, 2)
    for k in range(count):
        assert parts[k].is_valid
        assert parts[k].area == pytest.approx((labels == k).sum() * step**2, abs=1e-9)
        assert np.array_equal(contains_xy(parts[k], centres[:, 0], centres[:, 1]), (labels == k).ravel())
    # free: the free cells and one ring of cells round the grid
    framed = (rows + 2) * (cols + 2) - rows * cols + (labels == -1).sum()
    assert free.is_valid
    assert free.area == pytest.approx(framed * step**2, abs=1e-9)
    assert np.array_equal(contains_xy(free, centres[:, 0], centres[:, 1]), (labels == -1).ravel())


@pytest.mark.parametrize("seed", range(25))
def test_inside_lattice_equals_shapely(seed):
    rng = np.random.default_rng(300 + seed)
    area = Point(rng.uniform(-5, 5, 2)).buffer(rng.uniform(2, 20), int(rng.integers(1, 16)))
    for _ in range(int(rng.integers(0, 4))):  # holes and bites
        area = area.difference(Point(rng.uniform(-10, 10, 2)).buffer(rng.uniform(0.5, 6)))
    if seed % 3 == 0:
        area = area.union(box(*rng.uniform(-20, 0, 2), *rng.uniform(0, 20, 2)))
    minx, miny, maxx, maxy = area.bounds
    step = rng.uniform(0.1, 1.0)
    xs, ys = np.arange(minx - 1 + step / 2, maxx + 1, step), np.arange(miny - 1 + step / 2, maxy + 1, step)
    gx, gy = np.meshgrid(xs, ys)
    expected = contains_xy(area, gx.ravel(), gy.ravel()).reshape(gx.shape)
    assert expected.any() and not expected.all()
    assert np.array_equal(_inside_lattice(area, xs, ys), expected)


@pytest.mark.parametrize("seed", range(25))
def test_inside_lattice_equals_shapely_on_the_border(seed):
    """Points exactly on edges: boxes on a 0.1 mm grid (a grid's points fall on their edges) and
    polygons with corners at lattice points (slanted edges through lattice points): on the border
    is not inside, as shapely has it."""
    rng = np.random.default_rng(700 + seed)
    step = 0.4
    if seed % 2:
        area = unary_union([box(x, y, x + w, y + h) for x, y, w, h in np.round(rng.uniform([0, 0, 1, 1], [20, 20, 15, 15], (4, 4)), 1)])
        area = area.difference(box(*(xy := np.round(rng.uniform(2, 15, 2), 1)), *(xy + [2.2, 1.8])))
        minx, miny, maxx, maxy = area.bounds
        xs, ys = np.arange(minx + step / 2, maxx, step), np.arange(miny + step / 2, maxy, step)
    else:
        xs = ys = np.arange(0.2, 30, step)
        corners = np.column_stack([xs[rng.integers(0, len(xs), 6)], ys[rng.integers(0, len(ys), 6)]])
        area = Polygon(corners).buffer(0) if not Polygon(corners).is_valid else Polygon(corners)
    gx, gy = np.meshgrid(xs, ys)
    expected = contains_xy(area, gx.ravel(), gy.ravel()).reshape(gx.shape)
    assert np.array_equal(_inside_lattice(area, xs, ys), expected)


def _between_lines_plain(fill: np.ndarray, max_gap_factor: float = 1.6):
    """The quadrilateral of every facing pair of pieces on neighbouring lines, one by one, united."""
    quads = []
    for theta, member in line_families(fill):
        u = np.array([np.cos(theta), np.sin(theta)])
        n = np.array([-u[1], u[0]])
        seg = fill[member]
        offset = 0.5 * (seg[:, 0] + seg[:, 1]) @ n
        lo, hi = (seg @ u).min(axis=1), (seg @ u).max(axis=1)
        order = np.lexsort((lo, offset))
        offset, lo, hi = offset[order], lo[order], hi[order]
        line = np.cumsum(np.r_[True, np.diff(offset) > 0.05]) - 1
        line_off = np.array([offset[line == i][0] for i in range(line[-1] + 1)])
        if len(line_off) < 2:
            continue
        spacing = np.median(np.diff(line_off))
        for i in range(len(line_off) - 1):
            if line_off[i + 1] - line_off[i] > max_gap_factor * spacing:
                continue
            for a in np.flatnonzero(line == i):
                for b in np.flatnonzero(line == i + 1):
                    if lo[a] < hi[b] and lo[b] < hi[a]:
                        quads.append(Polygon([lo[a] * u + line_off[i] * n, hi[a] * u + line_off[i] * n,
                                              hi[b] * u + line_off[i + 1] * n, lo[b] * u + line_off[i + 1] * n]))
    return unary_union(quads) if quads else None


@pytest.mark.parametrize("seed", range(30))
def test_between_lines_equals_the_union_of_its_quadrilaterals(seed):
    """Lines of one piece (joined into runs), of two pieces, missing lines, short pieces."""
    rng = np.random.default_rng(400 + seed)
    segments = []
    for angle in rng.choice([0.0, 45.0, 60.0, 90.0, 135.0], size=int(rng.integers(1, 4)), replace=False):
        t = np.radians(angle + rng.normal(0, 0.5))
        u, n = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
        spacing = rng.uniform(0.5, 3.0)
        for k in range(int(rng.integers(2, 12))):
            if rng.random() < 0.1:
                continue
            lo, hi = rng.uniform(-10, 0), rng.uniform(0.01, 10)
            pieces = [(lo, hi)]
            if rng.random() < 0.3:
                mid, gap = rng.uniform(lo, hi), rng.uniform(0, 2)
                pieces = [(lo, mid), (mid + gap, hi + gap)]
            segments += [[a * u + k * spacing * n, b * u + k * spacing * n] for a, b in pieces]
    fill = np.array(segments)
    got, expected = between_lines(fill), _between_lines_plain(fill)
    assert (got is None) == (expected is None)
    if got is not None:
        assert got.is_valid
        assert got.symmetric_difference(expected).area < 1e-9


def _layout(seed: int):
    """A host area with two to four box modifiers, each with grid lines of its own spacing."""
    rng = np.random.default_rng(500 + seed)
    area = Polygon([(0, 0), (60, 0), (60, 40), (30, 55), (0, 40)])
    boxes = [box(*(xy := rng.uniform([2, 2], [40, 30])), *(xy + rng.uniform(8, 18, 2))) for _ in range(int(rng.integers(2, 5)))]
    spacings = [2.0] + [float(rng.uniform(0.8, 4.0)) for _ in boxes]
    host_region = area.buffer(-0.16).difference(unary_union(boxes))
    fills = [_grid_fill(host_region, spacings[0], 0.3)]
    fills += [_grid_fill(b.intersection(area).buffer(-0.16, join_style=2), s, float(rng.uniform(0, 1)))
              for b, s in zip(boxes, spacings[1:], strict=True)]
    return area, fills, spacings


def _grid_fill(region, spacing: float, phase: float) -> np.ndarray:
    """Lines at 45 and 135 degrees `spacing` apart clipped to `region`, shape (k, 2, 2)."""
    minx, miny, maxx, maxy = region.bounds
    centre, reach = np.array([(minx + maxx) / 2, (miny + maxy) / 2]), np.hypot(maxx - minx, maxy - miny)
    out = []
    for angle in (45.0, 135.0):
        u = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
        n = np.array([-u[1], u[0]])
        for off in np.arange(-reach, reach, spacing) + phase:
            piece = LineString([centre + off * n - reach * u, centre + off * n + reach * u]).intersection(region)
            for line in getattr(piece, "geoms", [piece]):
                if not line.is_empty and line.length > 1e-6:
                    coords = np.asarray(line.coords)
                    out.extend(np.stack([coords[:-1], coords[1:]], axis=1))
    return np.array(out).reshape(-1, 2, 2)


@pytest.mark.parametrize("seed", range(6))
def test_split_by_line_ends_is_a_partition_of_the_area(seed):
    area, fills, spacings = _layout(seed)
    parts = split_by_line_ends(area, fills, spacings, 0.16, step=0.4)
    assert len(parts) == len(fills)
    assert all(p.is_valid for p in parts)
    assert sum(p.area for p in parts) == pytest.approx(area.area, abs=1e-6)
    for i, a in enumerate(parts):
        assert a.difference(area).area < 1e-9
        for b in parts[i + 1 :]:
            assert a.intersection(b).area < 1e-9
    # the host is what the modifiers leave (the plain form of its last step)
    assert parts[0].symmetric_difference(area.difference(unary_union(parts[1:]))).area < 1e-9
    assert all(not p.is_empty for p in parts[1:])


def test_split_of_two_box_modifiers_follows_the_boxes():
    """Two touching boxes of other densities in a host: each part is its box (less what the later one
    wins), within 6 % of its area (the 4 mm lines of the sparse box cut its corners: 5.5 %; the split
    before the gap rework gave 5.7 %); lines clipped as Cura clips them (half a line width less the overlap in)."""
    inset = 0.16
    area = Polygon([(0, 0), (60, 0), (60, 40), (30, 55), (0, 40)])
    boxes = [box(8, 6, 30, 26), box(30, 10, 50, 34)]  # they share the side x = 30
    spacings = [2.0, 4.0, 0.8]
    host_region = area.buffer(-inset).difference(unary_union(boxes).buffer(inset, join_style=2))
    fills = [_grid_fill(host_region, spacings[0], 0.3)]
    fills += [_grid_fill(b.buffer(-inset, join_style=2), s, 0.7) for b, s in zip(boxes, spacings[1:], strict=True)]
    host, first, second = split_by_line_ends(area, fills, spacings, inset, step=0.4)
    for part, true in ((first, boxes[0]), (second, boxes[1])):
        assert part.symmetric_difference(true).area <= 0.06 * true.area, (part.area, true.area)
    assert host.symmetric_difference(area.difference(unary_union(boxes))).area <= 0.03 * host.area


@pytest.mark.parametrize("seed", range(6))
def test_a_modifier_without_families_gets_its_nearest_line_share(seed):
    """Short lines in all directions (no families, as gyroid): the modifier's part comes from the
    nearest-line cells alone; the parts still make the area, and it holds its lines."""
    rng = np.random.default_rng(900 + seed)
    area, fills, spacings = _layout(seed)
    # short lines in the first modifier's box (the host's lines keep out of it)
    minx, miny, maxx, maxy = fills[1].reshape(-1, 2).min(axis=0).tolist() + fills[1].reshape(-1, 2).max(axis=0).tolist()
    angle = rng.uniform(0, np.pi, 40)
    start = rng.uniform([minx + 0.5, miny + 0.5], [maxx - 0.5, maxy - 0.5], (40, 2))
    fills[1] = np.stack([start, start + 0.4 * np.column_stack([np.cos(angle), np.sin(angle)])], axis=1)
    assert not line_families(fills[1])
    parts = split_by_line_ends(area, fills, spacings, 0.16, step=0.4)
    assert sum(p.area for p in parts) == pytest.approx(area.area, abs=1e-6)
    for i, a in enumerate(parts):
        for b in parts[i + 1 :]:
            assert a.intersection(b).area < 1e-9
    mids = 0.5 * (fills[1][:, 0] + fills[1][:, 1])
    later = unary_union(parts[2:])  # later modifiers win where they overlap
    free = ~contains_xy(later, mids[:, 0], mids[:, 1])
    assert free.sum() >= 5
    assert contains_xy(parts[1], mids[free, 0], mids[free, 1]).mean() >= 0.9


@pytest.mark.parametrize("seed", range(20))
def test_span_pieces_of_many_meshes_equal_between_lines_one_by_one(seed):
    rng = np.random.default_rng(700 + seed)
    fills = []
    for _ in range(int(rng.integers(1, 6))):
        segments = []
        for angle in rng.choice([0.0, 45.0, 60.0, 90.0, 135.0], size=int(rng.integers(1, 4)), replace=False):
            t = np.radians(angle + rng.normal(0, 0.5))
            u, n = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
            spacing, shift = rng.uniform(0.5, 3.0), rng.uniform(-20, 20, 2)
            for k in range(int(rng.integers(0, 12))):
                if rng.random() < 0.1:
                    continue
                lo, hi = rng.uniform(-10, 0), rng.uniform(0.01, 10)
                pieces = [(lo, hi)] if rng.random() < 0.7 else [(lo, lo / 2), (hi / 2, hi)]
                segments += [[shift + a * u + k * spacing * n, shift + b * u + k * spacing * n] for a, b in pieces]
        fills.append(np.array(segments).reshape(-1, 2, 2))
    pieces = span_pieces(fills)
    assert len(pieces) == len(fills)
    for fill, got in zip(fills, pieces, strict=True):
        expected = between_lines(fill) if len(fill) else None
        if expected is None:
            assert not got
            continue
        assert expected.symmetric_difference(unary_union(got)).area < 1e-9
        # growing the overlapping pieces grows their union (the split grows them so, without the union)
        grown = MultiPolygon(got).buffer(0.16, 4)
        assert grown.is_valid
        assert grown.symmetric_difference(expected.buffer(0.16, 4)).area < 0.01


@pytest.mark.parametrize("seed", range(10))
def test_nearest_mesh_equals_a_full_search(seed):
    rng = np.random.default_rng(800 + seed)
    fills, spacings = [], []
    for k in range(int(rng.integers(1, 6))):
        n = int(rng.integers(0 if k else 1, 30))
        fills.append(rng.uniform(-8, 8, 2) + rng.uniform(-4, 4, (n, 2, 2)))
        spacings.append(float(rng.uniform(0.6, 4.0)))
    pts = rng.uniform(-20, 20, (int(rng.choice([5, 40, 600])), 2))  # all at once, or the bounded pass
    dist = np.full((len(fills), len(pts)), np.inf)
    for k, (fill, spacing) in enumerate(zip(fills, spacings, strict=True)):
        for a, b in fill:
            d = b - a
            t = np.clip(((pts - a) @ d) / max(d @ d, 1e-300), 0, 1)
            dist[k] = np.minimum(dist[k], np.hypot(*(pts - a - t[:, None] * d).T) / spacing)
    expected = np.argmin(dist, axis=0)
    got = _nearest_mesh(pts, fills, spacings, 0.2)
    gap = np.sort(dist, axis=0)[1] - np.sort(dist, axis=0)[0] if len(fills) > 1 else np.inf
    clear = gap > 1e-9  # exact ties may go either way with rounding
    assert np.array_equal(got[clear], expected[clear])
    assert _nearest_mesh(np.zeros((0, 2)), fills, spacings, 0.2).shape == (0,)


@pytest.mark.parametrize("seed", range(40))
def test_nearest_sample_distance_equals_a_tree_of_all_samples(seed):
    rng = np.random.default_rng(600 + seed)
    segments = rng.uniform(-20, 20, (int(rng.integers(1, 40)), 2, 2))
    if seed % 5 == 0:
        segments[0, 1] = segments[0, 0]  # a point
    if seed % 7 == 0:
        segments = np.round(segments, 1)
    step = float(rng.choice([0.02, 0.1, 0.5, 2.0]))
    pts = rng.uniform(-25, 25, (int(rng.integers(1, 300)), 2))
    if seed % 3 == 0:  # points close to the segments
        near = sample_segments(segments, 0.37)
        pts = near + rng.normal(0, 0.4, near.shape)
    expected = cKDTree(sample_segments(segments, step)).query(pts, distance_upper_bound=3.0)[0]
    got = nearest_sample_distance(segments, step, pts, 3.0)
    assert np.isfinite(expected).any()
    assert np.array_equal(got, expected)


def test_median_of_equals_numpy():
    rng = np.random.default_rng(7)
    for size in range(1, 40):
        values = np.round(rng.normal(size=size), int(rng.integers(0, 3)))
        assert median_of(values) == float(np.median(values))


def test_nearest_within_equals_argmin_of_all_distances():
    rng = np.random.default_rng(8)
    pieces = [box(*xy, *(xy + rng.uniform(0.1, 1.5, 2))) for xy in rng.uniform(-10, 10, (60, 2))]
    targets = [Point(rng.uniform(-8, 8, 2)).buffer(rng.uniform(1, 4)) for _ in range(5)]
    targets.insert(2, Polygon())  # an empty target is never nearest
    limit = 0.8
    dist = np.array([[p.distance(t) if not t.is_empty else np.inf for p in pieces] for t in targets])
    best = np.argmin(dist, axis=0)
    expected = np.where(dist[best, np.arange(len(pieces))] <= limit, best, -1)
    got = _nearest_within(pieces, targets, limit)
    assert np.array_equal(got, expected)
    assert (got >= 0).any() and (got < 0).any()


def test_geometry_helpers_equal_shapely():
    rng = np.random.default_rng(9)
    paths = [rng.uniform(-5, 5, (int(rng.integers(2, 6)), 2)) for _ in range(7)]
    assert multilinestring_of(paths).equals_exact(MultiLineString([LineString(p) for p in paths]), 0)
    points = rng.uniform(-5, 5, (30, 2))
    assert convex_hull_of(points).equals(MultiPoint([tuple(p) for p in points]).convex_hull)
    # the unit edges of a 3 x 3 grid of squares (they meet only at their ends): nine faces
    edges = [[(x, y), (x + 1, y)] for x in range(3) for y in range(4)] + [[(x, y), (x, y + 1)] for x in range(4) for y in range(3)]
    faces = polygonize_segments(np.array(edges, dtype=float))
    assert len(faces) == len(list(polygonize([LineString(e) for e in edges]))) == 9
    assert sum(f.area for f in faces) == pytest.approx(9.0)
    inside = points_on_surface(faces)
    assert all(f.contains(Point(p)) for f, p in zip(faces, inside, strict=True))


@pytest.mark.parametrize("seed", range(8))
def test_owner_grid_equals_a_full_nearest_line_search(seed):
    rng = np.random.default_rng(seed)
    area = Point(0, 0).buffer(rng.uniform(8, 15), 8)
    fills, spacings = [], []
    for k in range(int(rng.integers(2, 6))):
        n = int(rng.integers(0 if k else 1, 12))
        centre = rng.uniform(-8, 8, 2)
        fills.append(centre + rng.uniform(-4, 4, (n, 2, 2)))
        spacings.append(float(rng.uniform(0.6, 4.0)))
    grid = _owner_grid(area, fills, spacings, 0.4)
    step = grid.step
    rows, cols = grid.owner.shape
    gx, gy = np.meshgrid(grid.x0 + step / 2 + np.arange(cols) * step, grid.y0 + step / 2 + np.arange(rows) * step)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    centred = contains_xy(area, pts[:, 0], pts[:, 1]).reshape(rows, cols)
    # the cells round those whose centre is inside have an owner too (the area's border runs through them)
    padded = np.pad(centred, 1)
    inside = np.zeros_like(centred)
    for di in range(3):
        for dj in range(3):
            inside |= padded[di:di + rows, dj:dj + cols]
    assert np.array_equal(grid.centred, centred)
    inside = inside.ravel()
    dist = np.full((len(fills), inside.sum()), np.inf)
    for k, (fill, spacing) in enumerate(zip(fills, spacings, strict=True)):
        if len(fill):
            dist[k] = cKDTree(sample_segments(fill, step / 2)).query(pts[inside])[0] / spacing
    expected = np.full(len(pts), -1)
    expected[inside] = np.argmin(dist, axis=0)
    assert np.array_equal(grid.owner.ravel(), expected)
    # probes (`at`) see an owner only in cells whose centre is inside the area
    assert np.array_equal(grid.at(pts), np.where(centred.ravel(), expected, -1))


def test_distances_equal_shapely_one_by_one():
    rng = np.random.default_rng(4)
    pieces = [box(*xy, *(xy + rng.uniform(0.1, 2, 2))) for xy in rng.uniform(-10, 10, (25, 2))]
    other = Point(1, 2).buffer(3)
    assert np.array_equal(distances(pieces, other), np.array([p.distance(other) for p in pieces]))
    assert distances([], other).shape == (0,)


@pytest.fixture(scope="module")
def bracket_parses():
    with gzip.open(os.path.join(DATA, "hbracket_modifier.gcode.gz"), "rt", encoding="utf-8", newline="") as f:
        chunks = as_cura_list(f.read())
    state, retraction = MachineState(), RetractionModel()
    return [parse_layer(chunk, state, retraction) for chunk in chunks]


def test_has_both_walls_equals_the_mask_test(bracket_parses):
    seen = set()
    for parse in bracket_parses:
        for mesh in [*parse.meshes, "no such mesh"]:
            printed = parse.mesh_mask(mesh) & parse.extruding()
            expected = bool((printed & parse.kind_mask(WALL_OUTER)).any()) and bool((printed & parse.kind_mask(WALL_INNER)).any())
            assert process._has_both_walls(parse, mesh) == expected
            seen.add(expected)
    assert seen == {True, False}, "both answers must be exercised"


def test_fraction_inside_memo_keeps_lines_of_the_same_shape_apart(monkeypatch):
    calls = []
    real = process.fraction_inside

    def counted(fill, area, step):
        calls.append(1)
        return real(fill, area, step)

    monkeypatch.setattr(process, "fraction_inside", counted)
    run = process._Run(ProcessSettings(), [], process.HeaderInfo(), process.Survey())
    area = box(0, 0, 10, 10)
    inside = np.array([[[1.0, 1.0], [9.0, 1.0]], [[1.0, 2.0], [9.0, 2.0]]])
    outside = inside + 20.0  # the same shape, other lines
    for _ in range(5):
        assert run._fraction_inside(inside, area, 0.4) == 1.0
        assert run._fraction_inside(outside, area, 0.4) == 0.0
    assert len(calls) == 2, "each set of lines is measured once, however they alternate"


def test_closed_loops_are_the_runs_that_come_back_to_their_start():
    """Cura's infill walls: closed FILL runs; open runs (the infill lines) are not taken."""
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]], dtype=float)
    loop = np.stack([square[:-1], square[1:]], axis=1)  # 4 segments, last end = first start
    zigzag = np.array([[[1, 1], [9, 1]], [[9, 1], [9, 2]], [[9, 2], [1, 2]]], dtype=float)  # open
    line = np.array([[[2, 5], [8, 5]]], dtype=float)
    segments = np.concatenate([zigzag, loop, line, loop + 20.0])
    loops, in_loops = closed_loops(segments)
    assert len(loops) == 2
    np.testing.assert_allclose(loops[0], square)
    np.testing.assert_allclose(loops[1], square + 20.0)
    assert in_loops.tolist() == [False] * 3 + [True] * 4 + [False] + [True] * 4
    # a loop left 0.2 mm open is no loop
    opened = loop.copy()
    opened[-1, 1] += 0.2
    assert closed_loops(opened)[0] == []


def _square_ring(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], dtype=float)


def _layer_gcode(blocks: list) -> str:
    """One layer of G-code: blocks of (mesh, feature type, [polyline (k, 2), ...]), absolute E."""
    out, e = [";LAYER:3", "G0 Z1.0"], 0.0
    for mesh, kind, polylines in blocks:
        out += [f";MESH:{mesh}", f";TYPE:{kind}"]
        for line in polylines:
            out.append(f"G0 X{line[0, 0]:.3f} Y{line[0, 1]:.3f}")
            for a, b in zip(line[:-1], line[1:]):
                e += 0.033 * float(np.hypot(*(b - a)))
                out.append(f"G1 X{b[0]:.3f} Y{b[1]:.3f} E{e:.5f}")
    return "\n".join(out) + "\n"


def _hatch(area, spacing: float) -> list:
    lines = []
    x0, y0, x1, y1 = area.bounds
    for y in np.arange(y0 + spacing / 2, y1, spacing):
        cut = area.intersection(LineString([(x0 - 1, y), (x1 + 1, y)]))
        for piece in getattr(cut, "geoms", [cut]):
            if not piece.is_empty:
                lines.append(np.asarray(piece.coords))
    return lines


def _host_and_box(box_walls: bool, box_xy=(104.0, 104.0)) -> tuple:
    """A 24 mm square (two walls) and an 8 mm box mesh at `box_xy` with two walls of its own (or
    none: an infill mesh of FILL only); the host's FILL stops at the box, as Cura's does."""
    lw = 0.4
    host = box(98, 98, 122, 122)
    inner = box(box_xy[0], box_xy[1], box_xy[0] + 8, box_xy[1] + 8)
    host_area = host.buffer(-2 * lw, join_style=2)
    blocks = [("host", "WALL-OUTER", [_square_ring(*host.buffer(-lw / 2, join_style=2).bounds)]),
              ("host", "WALL-INNER", [_square_ring(*host.buffer(-1.5 * lw, join_style=2).bounds)]),
              ("host", "FILL", _hatch(host_area.difference(inner), 2.0))]
    if box_walls:
        blocks += [("box", "WALL-OUTER", [_square_ring(*inner.buffer(-lw / 2, join_style=2).bounds)]),
                   ("box", "WALL-INNER", [_square_ring(*inner.buffer(-1.5 * lw, join_style=2).bounds)]),
                   ("box", "FILL", _hatch(inner.buffer(-2 * lw, join_style=2), 1.0))]
    else:
        blocks += [("box", "FILL", _hatch(inner.intersection(host_area), 1.0))]
    parse = parse_layer(_layer_gcode(blocks), MachineState(), RetractionModel())
    return parse, mesh_layer(parse, "host", lw, 0.0, 2.0), inner, host_area, lw


@pytest.mark.parametrize("box_xy", [(104.0, 104.0), (94.0, 106.0)], ids=["inside", "across-the-edge"])
def test_a_mesh_with_walls_inside_the_host_is_cut_out_of_its_area(box_xy):
    """Cura's host walls do not go round an infill mesh with walls: its walls and inside are not
    the host's infill area; the rest of it is, whole."""
    parse, geo, inner, host_area, lw = _host_and_box(True, box_xy)
    assert geo.area.intersection(inner.buffer(-lw)).area > 10.0, "the walls alone do not show the box"
    cut = without_foreign(parse, geo, lw)
    on_box_walls = inner.buffer(-0.01).difference(inner.buffer(-2 * lw + 0.01))  # the wall lines' width
    # (the round buffer of the wall lines leaves the square's four outer corner tips, 0.003 mm2 each)
    assert cut.area.intersection(on_box_walls).area < 0.02
    if box_xy == (104.0, 104.0):  # nested: its inside is Cura's infill of the box
        assert cut.area.intersection(inner).area < 0.02
    rest = host_area.difference(inner.buffer(lw))
    assert rest.difference(cut.area).area < 0.02 * rest.area


def test_an_infill_mesh_without_walls_leaves_the_host_area_as_it_is():
    parse, geo, inner, host_area, lw = _host_and_box(False)
    assert without_foreign(parse, geo, lw) is geo


@pytest.mark.parametrize("strip_widths, kept", [(0.5, False), (1.5, True)])
def test_a_strip_between_a_hole_s_wall_and_the_outline_s_is_area_only_when_a_line_fits(strip_widths, kept):
    """A square hole near a 24 mm square's side, one wall each, no skin: the strip between the two
    walls' lines is infill area when it is 1.5 line widths wide, and not when it is 0.5 (random shape
    10: the pass joined a pocket to the rest through such a strip, so the pocket lost Cura's line)."""
    lw = 0.4
    host = box(98, 98, 122, 122)
    inner_wall_x = 98 + 1.5 * lw  # the host's inner wall line
    hole_x = inner_wall_x + lw + strip_widths * lw + 1.5 * lw  # the hole's edge: its inner wall 1.5 lw out
    hole = box(hole_x, 105, hole_x + 6, 111)
    part = host.difference(hole)
    blocks = [("host", "WALL-OUTER", [_square_ring(*host.buffer(-lw / 2, join_style=2).bounds),
                                      _square_ring(*hole.buffer(lw / 2, join_style=2).bounds)]),
              ("host", "WALL-INNER", [_square_ring(*host.buffer(-1.5 * lw, join_style=2).bounds),
                                      _square_ring(*hole.buffer(1.5 * lw, join_style=2).bounds)]),
              ("host", "FILL", _hatch(part.buffer(-2 * lw, join_style=2), 2.0))]
    parse = parse_layer(_layer_gcode(blocks), MachineState(), RetractionModel())
    geo = mesh_layer(parse, "host", lw, 0.0, 2.0)
    strip = box(inner_wall_x + lw / 2, 106, hole_x - 1.5 * lw - lw / 2, 110)
    assert strip.area > 0
    got = geo.area.intersection(strip).area / strip.area
    assert (got > 0.9) if kept else (got < 0.05), got
    assert geo.area.area > 0.9 * part.buffer(-2 * lw, join_style=2).area  # the rest is area, whole


#: random shape 111, layer 53 (CuraEngine 4.13, 4 walls, 0.4 mm lines): the rebuilt area where a pocket
#: between two holes' inner walls meets the rest through a neck 0.15 mm wide (rounded to 0.001 mm)
POCKET_BEHIND_A_NECK = (
    "POLYGON ((111.409 110.370, 111.409 110.330, 111.505 109.367, 111.540 109.014, 111.794 108.399, "
    "111.809 108.363, 112.266 107.505, 112.288 107.472, 112.477 107.243, 112.484 107.229, 112.486 107.213, "
    "112.480 107.198, 112.470 107.186, 112.455 107.179, 112.155 107.107, 111.292 106.900, 111.277 106.899, "
    "111.263 106.904, 111.252 106.913, 111.245 106.926, 111.243 106.937, 111.254 106.976, 111.411 107.505, "
    "111.418 107.542, 111.474 108.092, 111.474 108.132, 111.418 108.682, 111.388 108.986, 111.398 108.988, "
    "111.239 109.286, 110.975 109.778, 110.953 109.811, 110.601 110.236, 110.600 110.237, 110.600 110.500, "
    "111.422 110.500, 111.409 110.370))"
)


def test_a_neck_between_two_sharp_tips_is_cut_where_their_grown_back_spikes_meet():
    """The opening's mitred growth of two sharp cores reached across the 0.15 mm neck between them and
    joined the pocket to the rest again (random shape 111: the pocket's Cura line was dropped, 'taken
    over' by new infill 10 mm away).  The neck goes; each side keeps its own area."""
    from shapely import wkt

    from DelaunayInfill.gcode.area import _opened, _without_necks

    area = wkt.loads(POCKET_BEHIND_A_NECK)
    for opened in (_without_necks(area, 0.4), _opened(area, 0.4)):
        pieces = sorted(polygons_of(opened), key=lambda p: p.centroid.y)
        assert len(pieces) == 2, [p.area for p in pieces]
        pocket, rest = pieces
        assert pocket.area > 1.0 and rest.area > 0.6  # both sides kept, nearly whole
        assert pocket.bounds[3] < 109.1 < rest.bounds[1] + 0.2
        assert area.area - pocket.area - rest.area < 0.1


def test_a_wall_less_modifier_loses_half_a_line_width_along_the_area_s_border_only():
    """CuraEngine 4.13 insets a wall-less infill mesh's part of the host's infill area by half a line
    width: the rim along the area's border inside the modifier goes; the host's part and the border
    between host and modifier stay."""
    from DelaunayInfill.gcode.area import carved_as_cura4

    lw = 0.4
    area = MultiPolygon([box(0, 0, 20, 10)])
    got = carved_as_cura4(area, [box(10, -5, 30, 15)], lw).area
    inside = contains_xy(got, np.array([15.0, 15.0, 19.9, 5.0, 10.05, 12.0]), np.array([0.1, 0.3, 5.0, 0.1, 5.0, 9.9]))
    assert inside.tolist() == [False, True, False, True, True, False]
    assert got.area == pytest.approx(200 - (10 + 10 + 10 - 0.2 * 2) * lw / 2, abs=0.05)
    assert carved_as_cura4(area, [box(30, 0, 40, 10)], lw).area is area  # no overlap: as it was


def test_a_modifier_inside_another_is_inset_twice_and_a_narrow_strip_of_it_is_no_mesh_s():
    """CuraEngine 4.13 carves wall-less infill meshes in their order: the later one takes its share of the
    earlier one's own area (already inset by half a line width) and insets it again, then opens it.  In
    a part 1 mm across, an 80 % modifier over all of it keeps a 0.6 mm strip, and a 60 % one over its
    right half keeps nothing there (random regions 104: a third of a small part that no mesh fills)."""
    from DelaunayInfill.gcode.area import carved_as_cura4, cura4_infill_areas

    lw = 0.4
    area = MultiPolygon([box(0, 0, 10, 1.0)])
    dense, denser = box(-5, -5, 15, 5), box(5, -5, 15, 5)
    host, first, second = cura4_infill_areas(area, [dense, denser], lw)
    assert host.is_empty and second.is_empty
    assert first.bounds == pytest.approx((0.2, 0.2, 5.0, 0.8), abs=0.02)  # (GEOS 3.10 mitres the corners a little)
    alone = cura4_infill_areas(area, [denser], lw)
    assert alone[1].area == pytest.approx((5.0 - 0.4) * 0.6, abs=0.15)  # (without the first: kept, inset once)
    carved = carved_as_cura4(area, [dense, denser], lw)
    got = carved.area
    inside = contains_xy(got, np.array([2.0, 5.1, 6.0, 9.0]), np.array([0.5, 0.5, 0.5, 0.5]))
    assert inside.tolist() == [True, True, False, False]  # up to half a line width past the first's own area
    assert carved.pieces.equals(first)  # (the islands of Cura's infill: each mesh's own area)
    # where Cura printed, its area is, whatever the model says
    line = np.array([[[7.0, 0.5], [8.0, 0.5]]])
    assert contains_xy(carved_as_cura4(area, [dense, denser], lw, line).area, np.array([7.5]), np.array([0.5]))[0]


def test_cura_s_lines_do_not_join_two_meshes_islands():
    """Cura's lines count as islands of its infill where the model of its carving has none, but as thin
    strips: buffered by half a line width, a host's line ending at its own area's edge and a modifier's
    line 0.1 mm beside it bridged the 0.2 mm between the two meshes' areas, and a small island of one
    became part of the other's (random regions 148: a 0.88 mm² tip lost Cura's line, which the new lines
    of the region beyond "took over")."""
    from DelaunayInfill.gcode.area import carved_as_cura4

    lw = 0.4
    area = MultiPolygon([box(0, 0, 20, 10)])
    lines = np.array([[[5.0, 5.0], [10.0, 5.0]], [[10.2, 5.1], [15.0, 5.1]]])
    carved = carved_as_cura4(area, [box(10, -5, 30, 15)], lw, lines)
    assert len(polygons_of(carved.pieces)) == 2
    assert contains_xy(carved.pieces, np.array([10.0, 10.2]), np.array([5.0, 5.1])).all()  # (Cura's ends)


def test_an_opening_survives_a_mitred_buffer_that_crosses_itself():
    """Random regions 35 (CuraEngine 5.0): GEOS grew this piece of an infill area's shrunk core back into
    a polygon that crosses itself near (106.2, 120.5), and the overlay with the area raised a
    TopologyException: the layer failed and kept Cura's infill."""
    from shapely import wkt

    from DelaunayInfill.gcode.area import _opened

    piece = wkt.loads(
        "POLYGON ((106.09195151130308 120.97865749386347, 106.0919388572774 120.96153659711818, "
        "106.09330515830628 120.95464110660598, 106.12051050032345 120.88882405344144, "
        "106.13965757206219 120.86012253610966, 106.20056461910735 120.7129211830205, "
        "106.2005954266246 120.62075389692517, 106.20591264746413 120.62075757666277, "
        "106.20598981214589 120.50925461153128, 106.20736598018155 120.50236108344751, "
        "106.25010760846709 120.3993753057934, 106.24805219849382 120.39852226014911, "
        "106.27765489050012 120.33330616980791, 106.29080489342758 120.20069400766674, "
        "106.27010722920456 120.11166717121847, 106.26194255283951 120.07048393204936, 106.2619873045424 120, "
        "105.7 120, 105.7 121, 106.08771430939998 121, 106.09195151130308 120.97865749386347))")
    lw = 0.1840588017455287 / 0.45  # (the slice's opening radius, 0.45 line widths)
    opened = _opened(MultiPolygon([piece]), lw)
    assert opened.is_valid and 0.9 * piece.area < opened.area <= piece.area + 1e-9


def test_the_header_tells_curaengine_s_version():
    from DelaunayInfill.gcode.read import read_header

    assert read_header(";FLAVOR:Marlin\n;Generated with Cura_SteamEngine 4.13.1\n").engine_version == (4, 13)
    assert read_header(";FLAVOR:Griffin\n;GENERATOR.NAME:Cura_SteamEngine\n;GENERATOR.VERSION:5.7.2\n"
                       ).engine_version == (5, 7)
    assert read_header(";FLAVOR:Marlin\n;Generated with Cura_SteamEngine master\n").engine_version is None


def test_piece_centres_count_a_line_clipped_at_the_border_whole():
    """Lines clipped to a strip 0.85 mm wide (a cup's wall between its walls) end on its border: the
    pieces' centres lie inside and their lengths sum to the lines' length; samples that include the ends
    (`sample_segments`) put two of a short line's few samples on the border."""
    strip = box(0.0, 0.0, 60.0, 0.85)
    angles = np.linspace(0.3, 2.8, 40)
    x0 = np.linspace(2.0, 58.0, 40)
    long_lines = np.stack([np.c_[x0 - 3 * np.cos(angles), -3 * np.sin(angles)],
                           np.c_[x0 + 3 * np.cos(angles), 3 * np.sin(angles)]], axis=1)
    clipped = MultiLineString([s.tolist() for s in long_lines]).intersection(strip)
    segments = np.array([np.asarray(g.coords) for g in clipped.geoms])
    length = float(np.hypot(*(segments[:, 1] - segments[:, 0]).T).sum())
    centres, lengths = piece_centres(segments, 0.2)
    assert lengths.sum() == pytest.approx(length)
    core = strip.buffer(-1e-9)
    assert all(core.contains(Point(p)) for p in centres.tolist())
    # what the ends-included samples say of the same lines (weighted as the report weighted them)
    samples = sample_segments(segments, 0.2)
    n = np.maximum(1, np.ceil(np.hypot(*(segments[:, 1] - segments[:, 0]).T) / 0.2)).astype(int) + 1
    weight = np.repeat(np.hypot(*(segments[:, 1] - segments[:, 0]).T) / n, n)
    on_ends = ~np.array([core.contains(Point(p)) for p in samples.tolist()])
    assert weight[~on_ends].sum() < 0.8 * length  # the bias the report had: a fifth and more of the length


def test_the_split_s_opening_survives_a_buffer_that_crosses_itself():
    """Random regions 176 (CuraEngine 4.13, from the G-code alone): GEOS grew this host's part, shrunk by
    half its line spacing, back into a polygon that crosses itself near (98.3, 115.3); the overlay with the
    part raised a TopologyException and the layer failed, keeping Cura's infill."""
    from shapely import wkt

    from DelaunayInfill.gcode.split import _opened_round

    part = wkt.loads(
        "POLYGON ((90.73126566520293 123.31, 101.49023323742836 123.31, "
        "105.51129123878896 122.15424808337244, 106.3 121.92755360094463, 106.3 107.31, "
        "99.7888481261073 107.31, 99.7888481261073 107.4391682979561, "
        "100.18852157436783 107.4391682979561, 100.18852157436783 107.83884174621662, "
        "100.58819502262834 107.83884174621662, 100.58819502262834 108.23851519447715, "
        "100.98786847088887 108.23851519447715, 100.98786847088887 108.63818864273766, "
        "101.27964133114922 108.63818864273766, 100.58819502262834 110.30597265257916, "
        "100.58819502262834 109.83720898751923, 100.18852157436783 109.83720898751923, "
        "100.18852157436783 109.4375355392587, 99.38917467784678 109.4375355392587, "
        "99.38917467784678 109.03786209099819, 98.98950122958627 109.03786209099819, "
        "98.98950122958627 108.63818864273766, 98.58982778132574 108.63818864273766, "
        "98.58982778132574 108.23851519447715, 98.19015433306522 108.23851519447715, "
        "98.19015433306522 107.83884174621662, 97.7904808848047 107.83884174621662, "
        "97.7904808848047 107.4391682979561, 97.39080743654418 107.4391682979561, "
        "97.39080743654418 107.31, 96.21574221979267 107.31, 92.51901560134385 109.23198439841009, "
        "96.21574221979266 107.31, 90.3 107.31, 90.3 109.83720898751923, "
        "90.99603226437584 109.83720898751923, 90.99603226437584 110.23688243577975, "
        "91.39570571263637 110.23688243577975, 91.39570571263637 110.63655588404026, "
        "91.79537916089689 110.63655588404026, 91.79537916089689 111.03622933230079, "
        "92.1950526091574 111.03622933230079, 92.1950526091574 111.4359027805613, "
        "92.99439950567844 111.4359027805613, 92.99439950567844 111.83557622882184, "
        "93.79374640219949 111.83557622882184, 93.79374640219949 112.63492312534288, "
        "94.19341985046 112.63492312534288, 94.19341985046 113.0345965736034, "
        "94.59309329872053 113.0345965736034, 94.59309329872053 113.43427002186391, "
        "95.39244019524158 113.43427002186391, 95.39244019524158 113.83394347012444, "
        "95.79211364350209 113.83394347012444, 95.79211364350209 114.63329036664547, "
        "96.19178709176262 114.63329036664547, 96.19178709176262 115.032963814906, "
        "96.59146054002314 115.032963814906, 96.59146054002314 115.73739599643125, "
        "98.53806306380967 115.25093693519572, 93.369742710646 116.54250839698233, "
        "94.99276674698105 116.13691211349327, 94.99276674698105 115.83231071142704, "
        "94.59309329872053 115.83231071142704, 94.59309329872053 115.43263726316653, "
        "94.19341985046 115.43263726316653, 94.19341985046 114.63329036664547, "
        "93.79374640219949 114.63329036664547, 93.79374640219949 114.23361691838495, "
        "93.39407295393897 114.23361691838495, 93.39407295393897 113.83394347012444, "
        "92.99439950567844 113.83394347012444, 92.99439950567844 113.43427002186391, "
        "92.1950526091574 113.43427002186391, 92.1950526091574 113.0345965736034, "
        "91.39570571263637 113.0345965736034, 91.39570571263637 112.63492312534288, "
        "90.59635881611533 112.63492312534288, 90.59635881611533 112.23524967708235, "
        "90.3 112.23524967708235, 90.3 121.80938951054647, 90.73126566520293 123.31))")
    width = 2.4982711555959978
    core = _opened_round(part, width)
    assert core.is_valid and not core.is_empty
    assert core.difference(part).area < 1e-6  # inside the part
    assert 0.8 * part.area < core.area < part.area
