"""Painted sets from Cura's scene to the pass: snapshot data -> PaintedRegion, and the CLI export."""

from __future__ import annotations

import json

import numpy as np
import pytest

from DelaunayInfill.cura import paint
from DelaunayInfill.cura.adapter import build_settings
from DelaunayInfill.cura.region_shapes import scene_to_gcode, shape_triangles
from DelaunayInfill.cura.snapshot import MeshSnapshot, SceneSnapshot
from DelaunayInfill.meshslice import read_stl
from DelaunayInfill.painting import PaintedRegion, load_faces

WIDTH, DEPTH = 220.0, 220.0


def _box_local():
    """A 40 x 40 x 20 mm box in scene axes (Y up), centred on the origin, and its top (+Y) faces."""
    tri = shape_triangles("cube", 1.0) * np.array([40.0, 20.0, 40.0])
    top = np.flatnonzero(np.isclose(paint.unit_normals(tri)[:, 1], 1.0))
    return tri, top


def _transform():
    """Scene transform: rotate 90 degrees about Y, scale 1.5 in X, move to (10, 10, -5) (10 mm up)."""
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    m = np.eye(4)
    m[:3, :3] = rot @ np.diag([1.5, 1.0, 1.0])
    m[:3, 3] = [10.0, 10.0, -5.0]
    return m


def _snapshot(painted, enabled=True):
    model = MeshSnapshot(name="box.stl", enabled=enabled, values={
        "infill_sparse_density": 20, "infill_line_width": 0.4, "speed_infill": 50, "infill_overlap_mm": 0.04})
    return SceneSnapshot(global_values={"machine_width": WIDTH, "machine_depth": DEPTH},
                         extruder_values={0: {"material_diameter": 1.75}}, meshes=[model], painted_sets=painted)


def test_the_snapshot_becomes_painted_regions_under_the_painted_faces():
    local, top = _box_local()
    data = paint.PaintData(len(local))
    data.add_set(60, 6)
    data.paint(1, top)
    world = paint.transform_triangles(_transform(), local)
    gcode = scene_to_gcode(world, WIDTH, DEPTH, False)
    items = paint.painted_snapshots("box.stl", data, gcode)
    assert len(items) == 1 and list(items[0].faces) == list(top)
    settings, regions = build_settings(_snapshot(items))
    assert len(regions) == 1 and isinstance(regions[0], PaintedRegion)
    region = regions[0]
    assert region.density == pytest.approx(0.6) and region.depth == 6.0
    # the box after the transform: X 30 mm wide (40 deep rotated), Y 60 (40 x 1.5 rotated), Z 0..20 (centre 10)
    # G-code: x = scene x + 110, y = -scene z + 110: centre (120, 115); top at G-code z 20
    assert region.z_max == pytest.approx(20.0) and region.z_min == pytest.approx(14.0)
    section = region.at(17.0)
    lo_x, lo_y, hi_x, hi_y = section.bounds
    assert (lo_x, hi_x) == pytest.approx((120 - 20 - 1, 120 + 20 + 1), abs=0.05)  # + the 1 mm margin
    assert (lo_y, hi_y) == pytest.approx((115 - 30 - 1, 115 + 30 + 1), abs=0.05)
    assert region.at(12.0).is_empty
    assert settings.meshes["box.stl"].enabled


def test_painted_sets_of_a_model_with_delaunay_off_are_ignored_and_a_raft_lifts_them():
    local, top = _box_local()
    data = paint.PaintData(len(local))
    data.add_set(60, 6)
    data.paint(1, top)
    items = paint.painted_snapshots("box.stl", data, scene_to_gcode(local + [0, 10, 0], WIDTH, DEPTH, False))
    other = paint.painted_snapshots("other.stl", data, scene_to_gcode(local + [0, 10, 0], WIDTH, DEPTH, False))
    assert paint.painted_regions(items + other, {"box.stl"}, 0.0)[0].name == "painted box.stl #1"
    assert len(paint.painted_regions(items + other, {"box.stl"}, 0.0)) == 1
    lifted = paint.painted_regions(items, {"box.stl"}, 2.5)[0]
    assert lifted.z_max == pytest.approx(22.5)
    with pytest.raises(ValueError, match="the painting has 12 triangles, the mesh 11"):
        paint.painted_snapshots("box.stl", data, local[:11])


def test_the_export_is_what_the_command_line_reads(tmp_path):
    local, top = _box_local()
    gcode = scene_to_gcode(local + [0, 10, 0], WIDTH, DEPTH, False)
    stl, faces = paint.export_paths(tmp_path / "box_paint1.stl")
    assert stl.endswith("box_paint1.stl") and faces.endswith("box_paint1.faces.json")
    paint.export_painting(stl, faces, gcode, top)
    back = read_stl(stl)
    assert back.shape == gcode.shape and np.allclose(back, gcode, atol=1e-4)
    assert list(load_faces(faces, len(back))) == sorted(top)
    assert json.loads(open(faces).read()) == {"faces": [int(f) for f in sorted(top)]}
    from_files = PaintedRegion.from_files(stl, faces, 0.6, 6.0)
    direct = PaintedRegion(gcode, top, 0.6, 6.0)
    assert from_files.at(17.0).symmetric_difference(direct.at(17.0)).area < 1e-3
    with pytest.raises(ValueError, match="nothing is painted"):
        paint.export_painting(stl, faces, gcode, [])


def _rotation_x(degrees):
    a = np.radians(degrees)
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


TRANSFORMS = {  # scene transforms (Y up) of the 40 x 20 x 40 box centred on the origin; then lifted onto the plate
    "moved": (np.eye(3), [30.0, 0.0, -20.0]),
    "rotated": (_rotation_x(90.0), [0.0, 0.0, 0.0]),  # the painted top now faces the front (-Z scene: +Y G-code)
    "scaled": (np.diag([0.5, 1.5, 1.0]), [0.0, 0.0, 0.0]),
    "mirrored": (np.diag([1.0, -1.0, 1.0]), [0.0, 0.0, 0.0]),  # upside down: the painted top is the bottom
}


@pytest.mark.parametrize("name", sorted(TRANSFORMS))
def test_the_painting_follows_the_model_when_moved_rotated_scaled_or_mirrored(name):
    """The region is the part of the transformed box within 6 mm of the transformed painted face.

    Checked on a grid of points against the box and that face's plane (inside a box the distance to
    one of its faces is the distance to the face's plane), away from borders by 0.3 mm.  A mirror
    is applied as Cura applies it: the transform's scale -1 and the mesh re-wound (same face rows).
    """
    local, top = _box_local()
    matrix, move = TRANSFORMS[name]
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = matrix, move
    world = paint.transform_triangles(m, local)
    if np.linalg.det(matrix) < 0:
        world = world[:, [1, 0, 2]]  # MeshData.invertNormals, as Cura's MirrorOperation does
    world[..., 1] -= world[..., 1].min()  # onto the build plate
    data = paint.PaintData(len(local))
    data.add_set(60, 6)
    data.paint(1, top)
    gcode = scene_to_gcode(world, WIDTH, DEPTH, False)
    (region,) = paint.painted_regions(paint.painted_snapshots("box.stl", data, gcode), {"box.stl"})
    lo, hi = gcode.reshape(-1, 3).min(axis=0), gcode.reshape(-1, 3).max(axis=0)
    face = gcode[top]
    normal = paint.unit_normals(face[:1])[0]
    plane = float(face[0, 0] @ normal)
    from shapely.geometry import Point

    checked = 0
    for z in np.linspace(lo[2] + 0.5, hi[2] - 0.5, 7):
        section = region.at(float(z))
        for x in np.linspace(lo[0] + 0.5, hi[0] - 0.5, 9):
            for y in np.linspace(lo[1] + 0.5, hi[1] - 0.5, 9):
                distance = abs(float(np.array([x, y, z]) @ normal) - plane)
                if abs(distance - 6.0) < 0.3:
                    continue
                assert section.contains(Point(x, y)) == (distance < 6.0), (name, x, y, z, distance)
                checked += 1
    assert checked > 300
    painted_z = face[:, :, 2]
    if name == "mirrored":
        assert painted_z.max() == pytest.approx(0.0) and region.z_max == pytest.approx(6.0)
    if name == "rotated":
        assert np.ptp(painted_z) == pytest.approx(40.0) and abs(normal[1]) == pytest.approx(1.0)
