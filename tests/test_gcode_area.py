"""The speed-ups of the modifier split and the per-layer bookkeeping give what the plain forms give.

* `_OwnerGrid.polygon` (runs merged across rows) covers exactly the cells of its mask;
* `_owner_grid` (a bounded nearest-line search first) gives the owners of a full search;
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
from shapely.geometry import Point, box

from DelaunayInfill.gcode import ProcessSettings, process
from DelaunayInfill.gcode.area import _owner_grid, _OwnerGrid, sample_segments
from DelaunayInfill.gcode.read import (
    WALL_INNER,
    WALL_OUTER,
    MachineState,
    RetractionModel,
    as_cura_list,
    parse_layer,
)
from DelaunayInfill.geometry import contains_xy, distances

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
    inside = contains_xy(area, pts[:, 0], pts[:, 1])
    dist = np.full((len(fills), inside.sum()), np.inf)
    for k, (fill, spacing) in enumerate(zip(fills, spacings, strict=True)):
        if len(fill):
            dist[k] = cKDTree(sample_segments(fill, step / 2)).query(pts[inside])[0] / spacing
    expected = np.full(len(pts), -1)
    expected[inside] = np.argmin(dist, axis=0)
    assert np.array_equal(grid.owner.ravel(), expected)


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
