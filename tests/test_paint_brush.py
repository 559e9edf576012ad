"""The paint brush and ray pick of the Density regions tool (DelaunayInfill/cura/paint.py, pure numpy)."""

from __future__ import annotations

import numpy as np
import pytest

from DelaunayInfill.cura import paint
from DelaunayInfill.cura.region_shapes import shape_triangles


def _grid(n=10, size=10.0):
    """A flat n x n grid of 2 n^2 triangles in the plane z = 0 (normals +z), x, y in [0, size]."""
    xs = np.linspace(0.0, size, n + 1)
    tri = []
    for i in range(n):
        for j in range(n):
            a, b = (xs[i], xs[j], 0.0), (xs[i + 1], xs[j], 0.0)
            c, d = (xs[i + 1], xs[j + 1], 0.0), (xs[i], xs[j + 1], 0.0)
            tri += [(a, b, c), (a, c, d)]
    return np.array(tri, dtype=float)


def test_the_brush_paints_every_triangle_within_its_radius():
    tri = _grid()
    centre = np.array([5.0, 5.0, 0.0])
    faces = paint.brush_faces(tri, centre, 1.5)
    # independent: dense samples of each triangle, nearest sample within the radius
    w = np.random.default_rng(0).dirichlet((1, 1, 1), 4000)
    samples = np.einsum("sk,tkd->tsd", w, tri)
    samples = np.concatenate([samples, tri], axis=1)
    near = np.flatnonzero(np.linalg.norm(samples - centre, axis=2).min(axis=1) <= 1.5)
    assert set(near) <= set(faces)  # every sampled-near triangle is painted
    far = np.linalg.norm(samples - centre, axis=2).min(axis=1)
    assert far[faces].max() <= 1.5 + 0.05  # and none farther away (up to the sampling)
    assert 8 <= len(faces) < len(tri)


def test_a_small_brush_still_paints_the_triangle_under_it_and_big_triangles_count_by_their_surface():
    top = np.array([[[0, 0, 10], [40, 0, 10], [40, 40, 10]], [[0, 0, 10], [40, 40, 10], [0, 40, 10]]], dtype=float)
    # the brush is far from every vertex and centroid of the far triangle but touches its surface
    assert list(paint.brush_faces(top, [30.0, 10.0, 10.0], 0.5)) == [0]
    assert list(paint.brush_faces(top, [20.0, 20.5, 10.0], 1.0)) == [0, 1]
    assert list(paint.brush_faces(top, [30.0, 10.0, 10.0], 0.1, hit_face=1)) == [0, 1]


def test_only_faces_towards_the_camera_are_painted():
    box = shape_triangles("cube", 10.0)  # centred, edge 10
    down = np.array([0.0, 0.0, -1.0])  # looking down the -z axis onto the +z face
    all_near = paint.brush_faces(box, [0, 0, 5.0], 20.0)
    facing = paint.brush_faces(box, [0, 0, 5.0], 20.0, view_direction=down)
    assert len(all_near) == 12
    normals = paint.unit_normals(box[facing])
    assert len(facing) == 2 and np.allclose(normals, [0, 0, 1])


def test_the_ray_hits_the_nearest_triangle_and_gives_the_point():
    box = shape_triangles("cube", 10.0)
    hit = paint.ray_hit([1.0, 2.0, 50.0], [0, 0, -3.0], box)
    assert hit is not None
    face, distance, point = hit
    assert distance == pytest.approx(45.0) and np.allclose(point, [1, 2, 5])
    assert np.allclose(paint.unit_normals(box[[face]]), [0, 0, 1])
    assert paint.ray_hit([20.0, 0, 50.0], [0, 0, -1.0], box) is None  # beside it
    assert paint.ray_hit([0, 0, 50.0], [0, 0, 1.0], box) is None  # pointing away


def test_a_fast_drag_is_filled_in_between_points():
    points = paint.stroke_points([0, 0, 0], [10, 0, 0], 2.0)
    assert np.allclose(points[-1], [10, 0, 0])
    assert np.diff(points[:, 0]).max() <= 1.0 + 1e-9


def test_the_overlay_sits_just_above_the_painted_faces():
    box = shape_triangles("cube", 10.0)
    up = np.flatnonzero(np.isclose(paint.unit_normals(box)[:, 2], 1.0))
    over = paint.overlay_triangles(box, up, 0.1)
    assert over.shape == (2, 3, 3) and np.allclose(over[:, :, 2], 5.1)
    assert np.allclose(over[:, :, :2], box[up][:, :, :2])


def test_mesh_order_and_transform():
    v = np.arange(18, dtype=float).reshape(6, 3)
    assert np.array_equal(paint.mesh_triangles(v), v.reshape(2, 3, 3))
    assert np.array_equal(paint.mesh_triangles(v, np.array([[5, 4, 3]])), v[[5, 4, 3]][None])
    m = np.eye(4)
    m[:3, :3] = np.diag([-1.0, 2.0, 1.0])  # a mirror and a scale
    m[:3, 3] = [1, 2, 3]
    out = paint.transform_triangles(m, v.reshape(2, 3, 3))
    assert np.allclose(out[0, 0], [1 - 0, 2 + 2, 3 + 2])


def test_a_mesh_wound_inwards_is_turned_outwards_so_the_brush_still_paints_the_faces_it_sees():
    """After Multiply Selected, mirroring one copy re-winds the mesh both copies share (Cura):
    the other copy's triangles then face inwards; the stroke turns them out again (same rows)."""
    box = shape_triangles("cube", 10.0)
    assert paint.signed_volume(box) == pytest.approx(1000.0)
    inward = box[:, [1, 0, 2]]
    assert paint.signed_volume(inward) == pytest.approx(-1000.0)
    turned = paint.outward(inward)
    assert paint.signed_volume(turned) == pytest.approx(1000.0)
    assert np.allclose(np.sort(turned, axis=1), np.sort(box, axis=1))  # the same faces in the same rows
    up = np.flatnonzero(np.isclose(paint.unit_normals(box)[:, 2], 1.0))
    down = [0.0, 0.0, -1.0]  # looking down at the top
    top_centre = [0.0, 0.0, 5.0]
    assert list(paint.brush_faces(turned, top_centre, 3.0, view_direction=down)) == list(up)
    assert list(paint.brush_faces(inward, top_centre, 3.0, view_direction=down)) != list(up)  # what it fixes
    assert paint.outward(box) is not None and np.array_equal(paint.outward(box), box)
