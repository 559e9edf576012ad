"""DelaunayInfill.curaengine against the real CuraEngine: the settings really reach the engine."""

from __future__ import annotations

import re

import numpy as np
import pytest

from DelaunayInfill import curaengine, models

from . import gcode_check as gc
from .conftest import MATRIX


def _fill_spacing(text: str, mesh: str | None = None) -> float:
    """Median distance between neighbouring parallel FILL lines of one middle layer (mm)."""
    parsed = gc.parse_gcode(text)
    fill = parsed.fill_moves(extruding=True)
    if mesh is not None:
        fill = fill[fill[:, gc.C_MESH] == parsed.meshes.index(mesh)]
    layers = np.unique(fill[:, gc.C_LAYER])
    layer = layers[len(layers) // 2]
    seg = fill[fill[:, gc.C_LAYER] == layer]
    d = seg[:, [gc.C_X1, gc.C_Y1]] - seg[:, [gc.C_X0, gc.C_Y0]]
    up = np.sign(d[:, 0] * d[:, 1]) > 0  # one of the two grid directions
    mid = (seg[up][:, [gc.C_X0, gc.C_Y0]] + seg[up][:, [gc.C_X1, gc.C_Y1]]) / 2
    offsets = np.sort(np.unique(np.round((mid[:, 1] - mid[:, 0]) / np.sqrt(2), 2)))
    return float(np.median(np.diff(offsets)))


@pytest.mark.parametrize("density, spacing", [(10, 8.0), (20, 4.0), (50, 1.6)])
def test_infill_density_reaches_the_engine(slices, density, spacing):
    """The engine reads infill_line_distance, never infill_sparse_density: the formula must be resolved."""
    sliced = slices.get(MATRIX["hbracket" if density == 20 else f"density_{density}"])
    text = open(sliced.gcode, encoding="utf-8").read()
    assert _fill_spacing(text) == pytest.approx(spacing, abs=0.05)


def test_extruder_settings_reach_the_engine(slices):
    """1.75 mm filament (an extruder key): E per mm of a 0.4 x 0.2 mm line is 0.08 / (pi 0.875^2)."""
    sliced = slices.get(MATRIX["cube"])
    parsed = gc.parse_gcode(open(sliced.gcode, encoding="utf-8").read())
    fill = parsed.fill_moves(extruding=True)
    length = np.hypot(fill[:, gc.C_X1] - fill[:, gc.C_X0], fill[:, gc.C_Y1] - fill[:, gc.C_Y0])
    expected = 0.4 * 0.2 / (np.pi * 0.875**2)
    assert fill[:, gc.C_DE].sum() / length.sum() == pytest.approx(expected, rel=0.02)


def test_models_land_at_the_bed_centre(slices):
    sliced = slices.get(MATRIX["hbracket"])
    parsed = gc.parse_gcode(open(sliced.gcode, encoding="utf-8").read())
    walls = parsed.moves[(parsed.moves[:, gc.C_FILL] == 0) & (parsed.moves[:, gc.C_DE] > 0)
                         & (parsed.moves[:, gc.C_LAYER] == 10)]
    xs, ys = walls[:, gc.C_X1], walls[:, gc.C_Y1]
    assert xs.min() == pytest.approx(80.2, abs=0.05) and xs.max() == pytest.approx(139.8, abs=0.05)
    assert ys.min() == pytest.approx(90.2, abs=0.05) and ys.max() == pytest.approx(129.8, abs=0.05)


def test_modifier_meshes_print_only_infill(slices):
    sliced = slices.get(MATRIX["star_modifiers"])
    text = open(sliced.gcode, encoding="utf-8").read()
    parsed = gc.parse_gcode(text)
    for name in ("box_dense.stl", "box_sparse.stl"):
        mine = parsed.moves[(parsed.moves[:, gc.C_MESH] == parsed.meshes.index(name)) & (parsed.moves[:, gc.C_DE] > 0)]
        assert len(mine) > 0 and (mine[:, gc.C_FILL] == 1).all(), f"{name} prints more than infill"
    assert _fill_spacing(text, "box_dense.stl") == pytest.approx(1.6, abs=0.05)
    assert _fill_spacing(text, "star.stl") == pytest.approx(4.0, abs=0.05)


def test_one_at_a_time_prints_objects_one_after_the_other_at_their_places(slices):
    sliced = slices.get(MATRIX["one_at_a_time"])
    text = open(sliced.gcode, encoding="utf-8").read()
    assert len(re.findall(r"(?m)^;LAYER:0$", text)) == 2
    parsed = gc.parse_gcode(text)
    fill = parsed.fill_moves(extruding=True)
    first, second = fill[fill[:, gc.C_LAYER] < 100], fill[fill[:, gc.C_LAYER] >= 100]
    # the cube (model x -45..-25) comes first, shifted to the bed like the star (model x -5..55)
    assert 110 - 45 < first[:, gc.C_X1].min() and first[:, gc.C_X1].max() < 110 - 25
    assert 110 - 5 < second[:, gc.C_X1].min() and second[:, gc.C_X1].max() < 110 + 55


def test_relative_extrusion_and_support_settings_take_effect(slices):
    relative = open(slices.get(MATRIX["relative_e"]).gcode, encoding="utf-8").read()
    assert "\nM83" in relative
    support = open(slices.get(MATRIX["support"]).gcode, encoding="utf-8").read()
    assert ";TYPE:SUPPORT" in support
    every2 = gc.parse_gcode(open(slices.get(MATRIX["infill_every_2nd"]).gcode, encoding="utf-8").read())
    fill_layers = np.unique(every2.fill_moves(extruding=True)[:, gc.C_LAYER])
    assert len(fill_layers) > 5 and (np.diff(fill_layers)[:-1] == 2).all()


def test_a_failing_slice_raises_and_leaves_no_file(engine_info, tmp_path):
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"hello")  # the engine cannot load it
    out = tmp_path / "out.gcode"
    with pytest.raises(curaengine.CuraEngineError, match="Failed to load model"):
        curaengine.slice_models([(str(bad), {})], {}, out)
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.stl"]


def test_slice_result_reports_time_and_log(engine_info, tmp_path):
    stl = tmp_path / "cube.stl"
    models.write_stl(stl, models.cube(10.0))
    result = curaengine.slice_models([(str(stl), {})], {"infill_sparse_density": 30}, tmp_path / "c.gcode")
    assert result.seconds > 0 and "Gcode header after slicing" in result.log
    assert result.settings.global_values["infill_line_distance"] == pytest.approx(0.4 * 100 / 30 * 2)
