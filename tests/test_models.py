"""Tests for DelaunayInfill.models: the STL writer/reader and the test models."""

from collections import Counter

import numpy as np
import pytest
from shapely.geometry import Polygon
from shapely.ops import unary_union

from DelaunayInfill import models


def _edge_balance(tris):
    """Directed edges that are not matched by the reverse edge (empty for a closed, oriented mesh)."""
    v = np.round(tris, 6)
    edges = np.concatenate([np.stack([v[:, i], v[:, (i + 1) % 3]], axis=1) for i in range(3)])
    count = Counter(tuple(e.ravel()) for e in edges)
    count.subtract(Counter(tuple(e[::-1].ravel()) for e in edges))
    return {k: c for k, c in count.items() if c}


def _volume(tris):
    """Signed volume (divergence theorem); positive for outward-oriented closed meshes."""
    return float(np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6.0)


MODELS = {
    "cube": (models.cube, models.cube_outline, 20.0),
    "hbracket": (models.h_bracket, models.h_bracket_outline, 10.0),
    "star": (models.star, models.star_outline, 10.0),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_models_are_closed_oriented_and_have_the_right_volume(name):
    make, outline, height = MODELS[name]
    tris = make()
    assert not _edge_balance(tris), "mesh has unmatched edges (not watertight or inconsistently wound)"
    expected = Polygon(outline()).area * height
    assert _volume(tris) == pytest.approx(expected, rel=1e-9)
    v = tris.reshape(-1, 3)
    assert v[:, 2].min() == 0.0
    # centred on X/Y = 0 (bounding box centre) as CuraEngine's CLI placement expects
    centre = (v[:, :2].min(0) + v[:, :2].max(0)) / 2
    assert np.abs(centre).max() < 1e-9 or name == "star"


def test_model_dimensions():
    for make, size in ((models.cube, (20, 20, 20)), (models.h_bracket, (60, 40, 10))):
        v = make().reshape(-1, 3)
        np.testing.assert_allclose(v.max(0) - v.min(0), size)
    ring = models.star_outline()
    np.testing.assert_allclose(np.hypot(*ring[0::2].T), 30.0)
    np.testing.assert_allclose(np.hypot(*ring[1::2].T), 30.0 * 0.45)
    np.testing.assert_allclose(ring[0], [0.0, 30.0], atol=1e-12)


def test_stl_round_trip(tmp_path):
    tris = models.h_bracket()
    path = tmp_path / "h.stl"
    n = models.write_stl(path, tris)
    assert n == len(tris)
    assert path.stat().st_size == 84 + 50 * n
    back = models.read_stl(path)
    np.testing.assert_allclose(back, tris, atol=1e-5)  # float32 storage
    # stored normals point outward: for the top cap +Z
    raw = np.frombuffer(path.read_bytes()[84:], dtype=models._STL_RECORD)
    top = np.all(raw["vertices"][:, :, 2] == 10.0, axis=1)
    np.testing.assert_allclose(raw["normal"][top], [[0, 0, 1]] * int(top.sum()))


def test_read_stl_rejects_truncated_files(tmp_path):
    path = tmp_path / "t.stl"
    models.write_stl(path, models.cube())
    data = path.read_bytes()
    (tmp_path / "short.stl").write_bytes(data[:-10])
    with pytest.raises(ValueError, match="announces 12 triangles"):
        models.read_stl(tmp_path / "short.stl")
    (tmp_path / "tiny.stl").write_bytes(b"solid x\n")
    with pytest.raises(ValueError, match="too short"):
        models.read_stl(tmp_path / "tiny.stl")


def test_star_regions_tile_the_star():
    regions = models.star_regions()
    assert list(regions) == ["tip1", "tip2", "tip3", "tip4", "tip5", "centre"]
    star = Polygon(models.star_outline())
    union = unary_union(list(regions.values()))
    assert union.symmetric_difference(star).area < 1e-9
    assert sum(p.area for p in regions.values()) == pytest.approx(star.area)
    # tip1 holds the +Y tip, and regions go counter-clockwise
    assert regions["tip1"].contains(Polygon([(0, 29), (0.1, 28.5), (-0.1, 28.5)]))
    angles = [(np.arctan2(p.centroid.y, p.centroid.x) - np.pi / 2) % (2 * np.pi) for k, p in regions.items() if k != "centre"]
    assert np.all(np.diff(angles) > 0)
    assert regions["centre"].centroid.distance(Polygon([(0, 0), (1, 0), (0, 1)]).centroid) < 1
    assert set(models.STAR_FIGURE10_DENSITIES) == set(regions)


def test_star_region_prisms_are_closed_and_cover_the_star_height():
    prisms = models.star_region_prisms(height=10.0, margin=1.0)
    regions = models.star_regions()
    for name, tris in prisms.items():
        assert not _edge_balance(tris)
        assert _volume(tris) == pytest.approx(regions[name].area * 11.0)
        assert tris[..., 2].max() == 11.0


def test_triangulate_rejects_self_intersecting_polygons():
    bowtie = [(0, 0), (2, 2), (2, 0), (0, 2)]
    with pytest.raises(ValueError):
        models.prism(bowtie, 1.0)


def test_write_test_models(tmp_path):
    paths = models.write_test_models(tmp_path / "m")
    assert sorted(paths) == ["cube", "hbracket", "star"]
    for path in paths.values():
        assert len(models.read_stl(path)) > 0


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        models.write_stl(tmp_path / "c.stl", models.cube())
    finally:
        os.umask(umask)
    assert (tmp_path / "c.stl").stat().st_mode & 0o777 == 0o644
