"""Density-region geometry of the Cura tool (DelaunayInfill/cura/region_shapes.py)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from DelaunayInfill.cura.region_shapes import (
    SHAPES,
    SceneRegion,
    clamp_density_percent,
    clamp_size_mm,
    gcode_to_scene,
    infer_shape,
    mesh_volume,
    next_region_number,
    order_regions,
    pipeline_regions,
    region_name,
    region_number,
    scene_to_gcode,
    shape_triangles,
    transform_points,
)

ANALYTIC_VOLUME = {
    "sphere": lambda s: math.pi / 6 * s**3,
    "cube": lambda s: s**3,
    "cylinder": lambda s: math.pi / 4 * s**3,
}


def _edges_paired(triangles):
    """Every directed edge appears once and its reverse once: closed and consistently wound."""
    tri = np.round(np.asarray(triangles, dtype=float), 6)
    starts = tri.reshape(-1, 3)
    ends = np.roll(tri, -1, axis=1).reshape(-1, 3)
    directed = {tuple(a) + tuple(b) for a, b in zip(starts, ends)}
    reverse = {tuple(b) + tuple(a) for a, b in zip(starts, ends)}
    return len(directed) == len(starts) and directed == reverse


@pytest.mark.parametrize("shape", SHAPES)
def test_shapes_are_closed_outward_meshes_of_the_right_size(shape):
    size = 12.0
    tri = shape_triangles(shape, size, segments=48)
    assert tri.shape[1:] == (3, 3)
    assert _edges_paired(tri), "mesh has holes or inconsistent winding"
    volume = mesh_volume(tri)
    assert volume > 0, "triangles must face outwards"
    assert volume == pytest.approx(ANALYTIC_VOLUME[shape](size), rel=0.02)
    pts = tri.reshape(-1, 3)
    np.testing.assert_allclose(pts.max(axis=0) - pts.min(axis=0), [size] * 3, atol=1e-4)
    np.testing.assert_allclose((pts.max(axis=0) + pts.min(axis=0)) / 2, 0, atol=1e-4)


@pytest.mark.parametrize("shape", SHAPES)
def test_infer_shape_recovers_the_shape_from_the_triangle_count(shape):
    assert infer_shape(len(shape_triangles(shape, 7.0))) == shape
    assert infer_shape(5) == "mesh"


def test_unknown_shape_and_bad_numbers_are_refused():
    with pytest.raises(ValueError, match="unknown region shape"):
        shape_triangles("torus", 10)
    with pytest.raises(ValueError):
        clamp_density_percent(float("nan"))
    with pytest.raises(ValueError):
        clamp_size_mm("abc")
    assert clamp_density_percent(140) == 100
    assert clamp_density_percent(-3) == 0
    assert clamp_size_mm(0) > 0


def test_scene_to_gcode_matches_curaengine_placement():
    # Cura's scene: Y up, +Z towards the front; CuraEngine shifts by half the bed.
    pts = np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 20.0]])
    out = scene_to_gcode(pts, 220, 200)
    np.testing.assert_allclose(out[0], [110, 100, 0])
    np.testing.assert_allclose(out[1], [120, 80, 5])  # front (scene +z) is smaller G-code Y
    np.testing.assert_allclose(scene_to_gcode(pts, 220, 200, center_is_zero=True)[1], [10, -20, 5])


@given(st.lists(st.floats(-500, 500), min_size=3, max_size=3), st.booleans())
@settings(max_examples=50, deadline=None)
def test_gcode_to_scene_inverts_scene_to_gcode(point, centred):
    back = gcode_to_scene(scene_to_gcode(point, 235, 190, centred), 235, 190, centred)
    np.testing.assert_allclose(back, point, atol=1e-9)


def test_scene_to_gcode_keeps_meshes_outward():
    tri = shape_triangles("cube", 10)
    assert mesh_volume(scene_to_gcode(tri, 220, 220)) == pytest.approx(1000.0)


def test_transform_points_applies_translation_and_scale():
    matrix = np.diag([2.0, 2.0, 2.0, 1.0])
    matrix[:3, 3] = [1, 2, 3]
    np.testing.assert_allclose(transform_points(matrix, [[1, 1, 1]]), [[3, 4, 5]])


def test_region_names_are_numbered_uniquely():
    assert region_name(3) == "DelaunayRegion_3"
    assert region_number("DelaunayRegion_12") == 12
    assert region_number("DelaunayRegion_x") is None
    assert region_number("hbracket.stl") is None
    assert next_region_number(["a.stl", "DelaunayRegion_2", "DelaunayRegion_7"]) == 8
    assert next_region_number([]) == 1


def test_order_regions_puts_newer_tool_regions_last_so_they_win():
    empty = np.zeros((0, 3, 3))
    regions = [
        SceneRegion("DelaunayRegion_10", 0.5, empty, 10, mesh_order=11),
        SceneRegion("box.stl", 0.3, empty, None),
        SceneRegion("DelaunayRegion_2", 0.1, empty, 2, mesh_order=3),
        SceneRegion("other.stl", 0.2, empty, None),
    ]
    assert [r.name for r in order_regions(regions)] == ["box.stl", "other.stl", "DelaunayRegion_2", "DelaunayRegion_10"]
    pairs = pipeline_regions(regions)
    assert [density for _tri, density in pairs] == [0.3, 0.2, 0.1, 0.5]


def test_a_higher_infill_mesh_order_wins_as_in_curaengine():
    empty = np.zeros((0, 3, 3))
    regions = [SceneRegion("top.stl", 0.3, empty, None, mesh_order=50), SceneRegion("DelaunayRegion_1", 0.1, empty, 1, mesh_order=2)]
    assert [r.name for r in order_regions(regions)] == ["DelaunayRegion_1", "top.stl"]


def test_a_placed_sphere_slices_to_a_circle_at_its_centre_height():
    """The G-code triangles the tool hands over slice to the expected cross-section."""
    from DelaunayInfill.meshslice import slice_mesh

    centre_scene = np.array([5.0, 6.0, -10.0])  # 6 mm above the plate, 10 mm towards the back
    tri = scene_to_gcode(shape_triangles("sphere", 20, segments=64) + centre_scene, 220, 220)
    section = slice_mesh(tri, 6.0)
    assert section.area == pytest.approx(math.pi * 10**2, rel=0.02)
    assert section.centroid.x == pytest.approx(115.0, abs=0.05)
    assert section.centroid.y == pytest.approx(120.0, abs=0.05)
    assert slice_mesh(tri, 16.5).is_empty
