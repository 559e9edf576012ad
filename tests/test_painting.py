"""Painted density regions (issue 14): `DelaunayInfill.painting`, its CLI option and its use in the G-code pass.

The sections are checked against a brute-force distance of grid points to the painted triangles
(written here, independently of the module: projection on the plane, else the nearest edge).
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from shapely.geometry import Point, box

from DelaunayInfill import models
from DelaunayInfill.geometry import contains_xy
from DelaunayInfill.meshslice import slice_mesh
from DelaunayInfill.painting import (
    DEFAULT_TOLERANCE,
    PaintedRegion,
    cone_angles,
    load_faces,
    neighbourhood_corners,
    neighbourhood_section,
    painted_section,
    point_distances,
)

# --------------------------------------------------------------------------- brute force


def _segment_distance(points, a, b):
    ab = b - a
    t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def brute_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Distance (mm) of each point (m, 3) to the nearest triangle (n, 3, 3), one triangle at a time."""
    best = np.full(len(points), np.inf)
    for a, b, c in np.asarray(triangles, dtype=float):
        d = np.minimum(np.minimum(_segment_distance(points, a, b), _segment_distance(points, b, c)),
                       _segment_distance(points, c, a))
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) > 1e-12:
            n = n / np.linalg.norm(n)
            h = (points - a) @ n
            foot = points - h[:, None] * n
            inside = ((np.cross(b - a, foot - a) @ n >= 0) & (np.cross(c - b, foot - b) @ n >= 0)
                      & (np.cross(a - c, foot - c) @ n >= 0))
            d = np.where(inside, np.minimum(np.abs(h), d), d)
        best = np.minimum(best, d)
    return best


def assert_section_matches(section, triangles, depth, z, tolerance=DEFAULT_TOLERANCE, grid=160, within=None):
    """Every grid point within `depth` of the triangles is in `section`; every point of `section`
    more than `tolerance` inside it is within `depth` (its one-sided Hausdorff error <= tolerance)."""
    if section.is_empty:
        x0, y0, x1, y1 = -1, -1, 1, 1
    else:
        x0, y0, x1, y1 = section.bounds
    pad = 0.5
    xs, ys = np.meshgrid(np.linspace(x0 - pad, x1 + pad, grid), np.linspace(y0 - pad, y1 + pad, grid))
    pts = np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, z)]
    dist = brute_distance(pts, triangles)
    truth = dist <= depth
    if within is not None:
        truth &= contains_xy(within, pts[:, 0], pts[:, 1])
    inside = contains_xy(section, pts[:, 0], pts[:, 1]) if not section.is_empty else np.zeros(len(pts), bool)
    # points clearly inside the truth (more than 1e-6 mm from its border) must be in the section
    missed = truth & ~inside & (dist < depth - 1e-6)
    if within is not None:
        missed &= contains_xy(within.buffer(-1e-6), pts[:, 0], pts[:, 1])
    assert not missed.any(), f"{missed.sum()} points within {depth} mm are missing, e.g. {pts[missed][:3]}"
    if not section.is_empty:
        core = section.buffer(-tolerance - 1e-9)
        deep = contains_xy(core, pts[:, 0], pts[:, 1]) if not core.is_empty else np.zeros(len(pts), bool)
        far = deep & (dist > depth + 1e-9)
        assert not far.any(), f"{far.sum()} points more than {tolerance} mm inside the section are farther " \
                              f"than {depth} mm, e.g. {pts[far][:3]} at {dist[far][:3]}"


def _box(x0, y0, z0, x1, y1, z1):
    """A closed box, 12 triangles counter-clockwise seen from outside."""
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=float)
    f = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
         (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    return v[np.array(f)]


def _normals(tri):
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _cylinder(radius, z0, z1, segments=48, inward=False):
    """Side wall of a cylinder (no caps): 2 * segments triangles; normals out (or in)."""
    a = np.arange(segments) * 2 * math.pi / segments
    b = np.roll(a, -1)
    p = lambda ang, z: np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full_like(ang, z)], axis=1)  # noqa: E731
    t1 = np.stack([p(a, z0), p(b, z0), p(b, z1)], axis=1)
    t2 = np.stack([p(a, z0), p(b, z1), p(a, z1)], axis=1)
    tri = np.concatenate([t1, t2])
    return tri[:, ::-1] if inward else tri


def _bushing(r_in=7.0, r_out=12.0, height=10.0, segments=48):
    """A closed tube: outer wall, bore (normals inward to the hole), top and bottom rings."""
    outer = _cylinder(r_out, 0.0, height, segments)
    bore = _cylinder(r_in, 0.0, height, segments, inward=True)
    a = np.arange(segments) * 2 * math.pi / segments
    b = np.roll(a, -1)

    def ring(z, up):
        pi = lambda ang, r: np.stack([r * np.cos(ang), r * np.sin(ang), np.full_like(ang, z)], axis=1)  # noqa: E731
        t1 = np.stack([pi(a, r_in), pi(a, r_out), pi(b, r_out)], axis=1)
        t2 = np.stack([pi(a, r_in), pi(b, r_out), pi(b, r_in)], axis=1)
        t = np.concatenate([t1, t2])
        return t if up else t[:, ::-1]

    return np.concatenate([outer, bore, ring(height, True), ring(0.0, False)]), len(outer) + np.arange(len(bore))


def _dome(radius=20.0, rings=16, segments=48):
    """A closed hemisphere on z = 0 (a UV sphere's upper half and a flat bottom)."""
    lat = np.linspace(0, math.pi / 2, rings + 1)
    lon = np.arange(segments) * 2 * math.pi / segments
    pts = lambda la, lo: radius * np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo),  # noqa: E731
                                            np.sin(la) + 0 * lo], -1)
    tris = []
    for i in range(rings):
        lo0, lo1 = lon, np.roll(lon, -1)
        a, b = pts(lat[i], lo0), pts(lat[i], lo1)
        c, d = pts(lat[i + 1], lo1), pts(lat[i + 1], lo0)
        tris.append(np.stack([a, b, c], 1))
        if i < rings - 1:
            tris.append(np.stack([a, c, d], 1))
    curved = np.concatenate(tris)
    rim = pts(np.zeros(segments), lon)
    bottom = np.stack([np.zeros((segments, 3)), np.roll(rim, -1, axis=0), rim], 1)
    return np.concatenate([curved, bottom]), np.arange(len(curved))


# --------------------------------------------------------------------------- FACES.json


def _write(tmp_path, text, name="faces.json"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def test_load_faces_sorted_unique(tmp_path):
    faces = load_faces(_write(tmp_path, json.dumps({"faces": [5, 2, 2, 0]})), 6)
    assert faces.tolist() == [0, 2, 5] and faces.dtype == np.int64


@pytest.mark.parametrize("text, words", [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "must be a JSON object"),
    ('{"face": [1]}', "must be a JSON object"),
    ('{"faces": 3}', "must be a list"),
    ('{"faces": []}', "lists no faces"),
    ('{"faces": [1, 2.5]}', "whole numbers"),
    ('{"faces": [1, true]}', "whole numbers"),
    ('{"faces": [-1]}', "indices start at 0"),
    ('{"faces": [0, 9001]}', "lists face 9001 but model.stl has 1200 triangles"),
])
def test_load_faces_errors(tmp_path, text, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        load_faces(_write(tmp_path, text), 1200, model_name="model.stl")


# --------------------------------------------------------------------------- one triangle


def _random_triangles(seed, count):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        size = [0.5, 3.0, 12.0, 40.0][k % 4]
        t = rng.normal(size=(3, 3)) * size
        if k % 5 == 0:
            t[:, 2] = t[0, 2]  # horizontal triangle
        if k % 7 == 0:
            t[1, 2] = t[0, 2]  # horizontal edge
        if k % 11 == 0:
            t[1, :2] = t[0, :2]  # vertical edge
        depth = [0.3, 1.0, 3.0, 8.0][(k // 4) % 4]
        z = rng.uniform(t[:, 2].min() - depth, t[:, 2].max() + depth)
        out.append((t, depth, z))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_triangle_section_against_brute_force(seed):
    for tri, depth, z in _random_triangles(seed, 8):
        section = neighbourhood_section(tri[None], depth, z)
        assert_section_matches(section, tri[None], depth, z, grid=120)


@pytest.mark.parametrize("seed", range(4))
def test_triangle_section_is_convex_and_holds_the_triangles_own_section(seed):
    from DelaunayInfill.meshslice import slice_segments

    for tri, depth, z in _random_triangles(100 + seed, 10):
        section = neighbourhood_section(tri[None], depth, z)
        if section.is_empty:
            continue
        assert len(section.geoms) == 1
        poly = section.geoms[0]
        assert poly.is_valid and not poly.interiors
        assert poly.convex_hull.area - poly.area <= 1e-9 * max(1.0, poly.area)
        # where the plane cuts the triangle itself (a segment), and the segment grown by the depth
        seg = slice_segments(tri[None], z)
        if len(seg):
            from shapely.geometry import LineString

            line = LineString(seg[0])
            assert poly.buffer(1e-7).covers(line)
            assert poly.buffer(1e-6).covers(line.buffer(depth, 64).buffer(-2e-3 * depth))


@pytest.mark.parametrize("seed", range(3))
def test_touching_points_are_on_the_sections_border_and_their_support_lines(seed):
    """The refinement's error bound rests on them: each known touching point lies on its direction's
    support line and at exactly `depth` from the triangle (the section's border)."""
    from DelaunayInfill.painting import _support

    checked = 0
    for tri, depth, z in _random_triangles(200 + seed, 10):
        phi = np.linspace(0.0, 2.0 * np.pi, 90, endpoint=False)
        p = np.repeat(tri[None, :, :2], len(phi), axis=0)
        a = np.repeat(tri[None, :, 2] - z, len(phi), axis=0)
        h, touch, touched = _support(p, a, depth, phi)
        ok = touched & np.isfinite(h)
        if not ok.any():
            continue
        u = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        assert np.allclose(np.einsum("ij,ij->i", touch[ok], u[ok]), h[ok], atol=1e-7)
        distance = point_distances(np.c_[touch[ok], np.full(ok.sum(), z)], tri[None])
        assert np.allclose(distance, depth, atol=1e-6)
        checked += int(ok.sum())
    assert checked > 500


def test_the_polygons_built_as_wkb_are_the_corners_rings():
    from shapely.geometry import Polygon

    from DelaunayInfill.painting import _multipolygon_wkb, _union_of_convex

    squares = np.array([[0, 0], [2, 0], [2, 2], [0, 2], [1, 1], [3, 1], [3, 3], [1, 3]], dtype=float)
    owner = np.array([0, 0, 0, 0, 5, 5, 5, 5])
    from shapely import wkb

    parts = list(wkb.loads(_multipolygon_wkb(squares, owner)).geoms)
    assert [list(p.exterior.coords) for p in parts] == [list(Polygon(squares[:4]).exterior.coords),
                                                        list(Polygon(squares[4:]).exterior.coords)]
    assert _union_of_convex(squares, owner).area == pytest.approx(7.0)
    bowtie = np.array([[0, 0], [2, 2], [2, 0], [0, 2]], dtype=float)  # not convex: its hull is used
    assert _union_of_convex(bowtie, np.zeros(4, dtype=np.int64)).area == pytest.approx(4.0)


def test_corners_are_in_order_and_tolerance_tightens():
    tri = np.array([[0.0, 0.0, 0.0], [30.0, 2.0, 4.0], [5.0, 25.0, 1.0]])
    loose = neighbourhood_section(tri[None], 2.0, 1.5, tolerance=0.2)
    tight = neighbourhood_section(tri[None], 2.0, 1.5, tolerance=0.005)
    assert tight.area < loose.area and loose.buffer(1e-9).covers(tight)
    assert_section_matches(tight, tri[None], 2.0, 1.5, tolerance=0.005)
    corners, owner = neighbourhood_corners(np.stack([tri, tri + [0, 0, 50]]), 2.0, 1.5)
    assert set(owner.tolist()) == {0}  # the second triangle is 50 mm up: culled by z
    assert corners.shape == (len(owner), 2)


def test_plane_beyond_the_depth_gives_nothing():
    tri = np.array([[[0.0, 0.0, 5.0], [10.0, 0.0, 6.0], [0.0, 10.0, 7.0]]])
    assert neighbourhood_section(tri, 1.0, 3.9).is_empty
    assert neighbourhood_section(tri, 1.0, 8.1).is_empty
    assert not neighbourhood_section(tri, 1.0, 4.1).is_empty


def test_bad_depth():
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    for depth in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="depth"):
            neighbourhood_corners(tri, depth, 0.5)


def test_point_distances_match_brute_force():
    rng = np.random.default_rng(7)
    tri = rng.normal(size=(20, 3, 3)) * 5
    pts = rng.normal(size=(200, 3)) * 8
    assert np.allclose(point_distances(pts, tri), brute_distance(pts, tri), atol=1e-9)


# --------------------------------------------------------------------------- painted models


def test_box_top_face_gives_the_top_band():
    model = _box(0, 0, 0, 40, 30, 20)
    top = np.flatnonzero(_normals(model)[:, 2] > 0.99)
    depth = 3.0
    whole = box(0, 0, 40, 30)
    for z in (10.0, 16.9, 17.1, 18.5, 19.9):
        section = painted_section(model, model[top], depth, z)
        if z < 20.0 - depth:
            assert section.is_empty, z
        else:
            assert section.symmetric_difference(whole).area < 1e-6, z
    assert_section_matches(painted_section(model, model[top], depth, 18.0), model[top], depth, 18.0, within=whole)


def test_box_side_face_gives_a_slab():
    model = _box(0, 0, 0, 40, 30, 20)
    side = np.flatnonzero(_normals(model)[:, 0] > 0.99)  # the face at x = 40
    depth = 4.0
    for z in (0.5, 10.0, 19.5):
        section = painted_section(model, model[side], depth, z)
        assert section.symmetric_difference(box(36, 0, 40, 30)).area < 1e-6, z
        assert_section_matches(section, model[side], depth, z, within=box(0, 0, 40, 30))


def test_bushing_bore_gives_a_ring_round_the_hole():
    model, bore = _bushing()
    depth = 2.5
    ring = Point(0, 0).buffer(7.0 + depth, 256).difference(Point(0, 0).buffer(6.9, 64))
    for z in (0.3, 5.0, 9.7):
        section = painted_section(model, model[bore], depth, z)
        # the bore is a 48-gon of radius 7: the ring reaches from it to 7 + depth (within the 48-gon's sag)
        assert len(section.geoms) == 1 and len(section.geoms[0].interiors) == 1
        assert section.difference(ring).area < 0.05
        assert abs(section.area - (math.pi * (9.5 ** 2 - 7.0 ** 2))) < 0.6
        assert_section_matches(section, model[bore], depth, z, within=slice_mesh(model, z), grid=120)


def test_dome_curved_face_gives_a_shell():
    model, curved = _dome()
    depth = 4.0
    cone = cone_angles(model[curved])
    for z in (1.0, 8.0, 14.0, 17.5):
        section = painted_section(model, model[curved], depth, z, cone=cone)
        outer = slice_mesh(model, z)
        inner_r2 = (20.0 - depth) ** 2 - z * z
        if inner_r2 <= 0:
            assert section.symmetric_difference(outer).area < 1e-6, z
        else:
            # the faceted sphere lies inside the true one: the shell is a ring a little inside radius 16
            assert len(section.geoms[0].interiors) == 1
            hole = section.geoms[0].interiors[0]
            r = np.hypot(*(np.asarray(hole.coords) - 0).T[:2])
            assert math.sqrt(inner_r2) - 0.6 < r.min() and r.max() < math.sqrt(inner_r2) + 0.05, z
        assert_section_matches(section, model[curved], depth, z, within=outer, grid=120)


@pytest.mark.parametrize("depth, z", [(2.0, 16.7), (1.0, 18.9), (2.0, 12.0)])
def test_a_gap_between_the_inner_and_outer_borders_is_filled(depth, z):
    """On a fine dome only the triangles near the inner and the outer border are cut; between the two
    rings they leave a gap that lies inside the region.  It is a hole of the outer ring that holds
    the inner ring: the gap is that hole less the inner ring (the hole's own representative point
    may lie in the inner ring or in its hole, which said nothing about the gap)."""
    model, curved = _dome(rings=32, segments=96)
    section = neighbourhood_section(model[curved], depth, z)
    assert_section_matches(section, model[curved], depth, z, grid=70)


def test_border_culling_changes_nothing():
    """Only triangles that may hold a border point are cut; the holes the others fill are filled."""
    from DelaunayInfill.painting import _union_of_convex

    model, curved = _dome()
    tri = model[curved]
    for depth, z in ((1.0, 3.0), (3.0, 10.1), (6.0, 16.0)):
        culled = neighbourhood_section(tri, depth, z)
        corners, owner = neighbourhood_corners(tri, depth, z)
        full = _union_of_convex(corners, owner)
        assert culled.symmetric_difference(full).area < 1e-6 * full.area


def test_a_big_flat_patch_fills_its_middle():
    """A top face of many triangles: only its rim bounds the section; the middle is the filled hole."""
    n = 8
    xs = np.linspace(0, 40, n + 1)
    quads = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = ([xs[i], xs[j], 10.0], [xs[i + 1], xs[j], 10.0], [xs[i + 1], xs[j + 1], 10.0],
                          [xs[i], xs[j + 1], 10.0])
            quads += [[a, b, c], [a, c, d]]
    patch = np.array(quads)
    section = neighbourhood_section(patch, 2.0, 8.5)
    grown = box(0, 0, 40, 40).buffer(math.sqrt(4.0 - 1.5 ** 2), 256)
    assert len(section.geoms) == 1 and not section.geoms[0].interiors
    assert section.symmetric_difference(grown).area < 0.05
    assert_section_matches(section, patch, 2.0, 8.5, grid=120)


# --------------------------------------------------------------------------- the region record


def test_painted_region_is_a_region(tmp_path):
    from DelaunayInfill.gcode import Region

    model = _box(100, 100, 0, 140, 130, 20)
    stl = tmp_path / "box.stl"
    models.write_stl(stl, model - [100, 100, 0], name="box")
    top = np.flatnonzero(_normals(model)[:, 2] > 0.99)
    faces = _write(tmp_path, json.dumps({"faces": top.tolist()}))
    region = PaintedRegion.from_files(stl, faces, 0.6, 5.0, offset=(100, 100))
    assert isinstance(region, Region)
    assert region.density == 0.6 and region.name == "painted box.stl:faces.json"
    assert region.z_min == pytest.approx(15.0) and region.z_max == pytest.approx(20.0)
    assert region.at(10.0).is_empty
    whole = box(100, 100, 140, 130)
    assert region.at(17.5).intersection(whole).symmetric_difference(whole).area < 1e-6
    # it reaches 1 mm past the model's surface (region.margin), so that no border blends at the part's own
    assert region.margin == 1.0 and whole.buffer(1.0 + 1e-6).covers(region.at(17.5))
    assert region.at(17.5).area > whole.buffer(0.99).area
    assert region.at(17.5) is region.at(17.5)  # cached per height
    with pytest.raises(ValueError, match="lists face 12 but box.stl has 12 triangles"):
        PaintedRegion.from_files(stl, _write(tmp_path, '{"faces": [12]}', "bad.json"), 0.6, 5.0)
    with pytest.raises(ValueError, match="depth"):
        PaintedRegion(model, top, 0.6, 0.0)
    with pytest.raises(ValueError, match="density"):
        PaintedRegion(model, top, 1.5, 1.0)


def test_process_gcode_with_a_painted_region():
    """The G-code pass takes a PaintedRegion as it takes a mesh Region; the report measures it."""
    import gzip

    from DelaunayInfill import process_gcode
    from DelaunayInfill.gcode import ProcessSettings
    from DelaunayInfill.gcode.read import as_cura_list

    data = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "DelaunayInfill", "data")
    with gzip.open(os.path.join(data, "star.gcode.gz"), "rt", encoding="utf-8", newline="") as f:
        star = as_cura_list(f.read())
    # a block round the star's centre (G-code coordinates): paint its x = 115 side 6 mm deep
    model = _box(95, 95, 0, 115, 125, 30)
    side = np.flatnonzero(_normals(model)[:, 0] > 0.99)
    region = PaintedRegion(model, side, 0.5, 6.0, name="painted side")
    block = box(95, 95, 115, 125)
    assert region.at(2.0).intersection(block).symmetric_difference(box(109, 95, 115, 125)).area < 1e-6
    out, report = process_gcode(star, ProcessSettings(density=0.15, seed=5), regions=[region])
    got = {r.name: r for r in report.regions}
    assert set(got) == {"base", "painted side"}, report.format_table()
    for r in got.values():
        assert abs(r.measured - r.target) <= 0.03, report.format_table()


# --------------------------------------------------------------------------- the command line


def test_cli_paint_errors(tmp_path, capsys):
    from DelaunayInfill.cli import main

    gcode = tmp_path / "in.gcode"
    gcode.write_text(";FLAVOR:Marlin\n", encoding="utf-8")
    stl = tmp_path / "model.stl"
    models.write_stl(stl, _box(0, 0, 0, 10, 10, 10), name="model")
    good = _write(tmp_path, '{"faces": [0, 1]}')
    out = tmp_path / "out.gcode"
    cases = [
        (f"{stl}:{_write(tmp_path, json.dumps({'faces': [9001]}), 'big.json')}:60:2",
         "--paint: big.json lists face 9001 but model.stl has 12 triangles"),
        (f"{stl}:{_write(tmp_path, '{}', 'empty.json')}:60:2", "--paint: empty.json must be a JSON object"),
        (f"{stl}:{_write(tmp_path, json.dumps({'faces': []}), 'none.json')}:60:2", "--paint: none.json lists no faces"),
        (f"{stl}:{good}:60", "--paint: expected MODEL.stl:FACES.json:PCT:DEPTH"),
        (f"{stl}:{good}:160:2", "--paint: a density must be in (0, 100] %"),
        (f"{stl}:{good}:60:-1", "--paint: the depth must be a positive number of mm"),
        (f"{stl}:{good}:60:deep", "--paint: the depth must be a number of mm"),
        (f"{tmp_path / 'nope.stl'}:{good}:60:2", "--paint: no such file"),
    ]
    for spec, words in cases:
        assert main(["process", str(gcode), "-o", str(out), "--paint", spec]) == 2, spec
        err = capsys.readouterr().err
        assert words in err, (spec, err)
        assert "Traceback" not in err
        assert not out.exists()
