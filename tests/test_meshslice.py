"""Slicing triangle meshes into density-region polygons; STL reading."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from DelaunayInfill.meshslice import read_stl, slice_mesh, slice_segments
from DelaunayInfill.models import box, h_bracket, h_bracket_outline, prism, star, star_outline, write_stl


def test_box_section_is_the_box():
    section = slice_mesh(box(30, 20, 10, 5, -3, 0), 4.0)
    assert section.area == pytest.approx(600.0)
    assert section.bounds == pytest.approx((-10.0, -13.0, 20.0, 7.0))


@pytest.mark.parametrize("z", [-1.0, 10.5])
def test_planes_outside_the_mesh_give_nothing(z):
    assert slice_mesh(box(10, 10, 10), z).is_empty


def test_concave_prisms_keep_their_shape():
    for tri, outline in ((star(), star_outline()), (h_bracket(), h_bracket_outline())):
        section = slice_mesh(tri, 5.0)
        expected = Polygon(outline)
        assert section.symmetric_difference(expected).area < 1e-6 * expected.area


def test_nested_shells_give_holes_even_odd():
    outer = box(40, 40, 10)
    inner = box(20, 20, 10)[:, ::-1]  # reversed winding: an inside surface
    island = box(6, 6, 10)
    section = slice_mesh(np.concatenate([outer, inner, island]), 5.0)
    assert section.area == pytest.approx(1600 - 400 + 36)
    assert len(section.geoms) == 2


def test_shared_edges_give_identical_points():
    segs = slice_segments(star(), 3.3)
    ends = np.round(segs.reshape(-1, 2), 12)
    _, counts = np.unique(ends, axis=0, return_counts=True)
    assert np.all(counts == 2), "every cut point must be shared by exactly two segments"


@settings(max_examples=30, deadline=None)
@given(
    sx=st.floats(1, 50), sy=st.floats(1, 50), sz=st.floats(1, 30),
    cx=st.floats(-50, 50), cy=st.floats(-50, 50), frac=st.floats(0.05, 0.95),
)
def test_any_box_slices_to_its_rectangle(sx, sy, sz, cx, cy, frac):
    section = slice_mesh(box(sx, sy, sz, cx, cy, 1.0), 1.0 + frac * sz)
    assert section.area == pytest.approx(sx * sy, rel=1e-9)


def test_binary_and_ascii_stl_read_the_same(tmp_path):
    tri = prism(star_outline(), 7.0)
    binary = tmp_path / "s.stl"
    write_stl(binary, tri)
    lines = ["solid s"]
    for t in tri:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {x!r} {y!r} {z!r}" for x, y, z in t.tolist()]
        lines += ["    endloop", "  endfacet"]
    lines.append("endsolid s")
    ascii_path = tmp_path / "a.stl"
    ascii_path.write_text("\n".join(lines))
    a, b = read_stl(binary), read_stl(ascii_path)
    assert a.shape == b.shape == tri.shape
    assert np.allclose(a, b, atol=1e-4)  # binary STL stores float32


@pytest.mark.parametrize("content", [b"", b"hello world", b"solid x\nfacet normal 0 0 0\nvertex 1 2\n", b"\0" * 84 + b"\1"])
def test_bad_stl_is_refused(tmp_path, content):
    path = tmp_path / "bad.stl"
    path.write_bytes(content)
    with pytest.raises(ValueError):
        read_stl(path)


def test_sections_carry_no_collinear_vertices():
    """Where a flat side's triangles meet the plane the section gets extra points on a straight edge:
    they go, so a prism gives the same polygon at every height."""
    tri = box(12, 12, 30, 110, 112)
    a, b = slice_mesh(tri, 1.1), slice_mesh(tri, 7.3)
    assert a.wkb == b.wkb
    assert len(a.geoms[0].exterior.coords) == 5
    assert a.area == pytest.approx(144.0)
