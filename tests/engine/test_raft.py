"""Rafts lift the model: the plugin's regions must be lifted by the same amount.

CuraEngine prints model layer k >= 1 of a raft print at scene height + raft
thickness + air gap - ``layer_0_z_overlap``.  The plugin's regions come from
Cura's scene (heights above the plate), so the adapter lifts them by
``raft_z_offset``.  Checked here against real CuraEngine 4.13 G-code, with
this file's own parser (gcode_check).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from DelaunayInfill import curaengine, models, process_gcode
from DelaunayInfill.cura.adapter import build_settings, raft_z_offset
from DelaunayInfill.cura.snapshot import MeshSnapshot, SceneSnapshot

from . import gcode_check as gc
from .conftest import split_like_cura

RAFTS = {
    "defaults": {},
    "thick raft, small overlap": {"raft_airgap": 0.5, "layer_0_z_overlap": 0.1, "raft_base_thickness": 0.4,
                                  "raft_surface_layers": 3},
    "thicker first layer": {"layer_height_0": 0.3},
}
BED_CENTRE = (110.0, 110.0)  # fdmprinter's 220 x 220 bed: the CLI centres (0, 0) there


def _snapshot(resolved: dict, meshes=()) -> SceneSnapshot:
    """A snapshot carrying the engine's own resolved values (global and extruder alike)."""
    return SceneSnapshot(
        global_values={**resolved, "machine_width": 220, "machine_depth": 220},
        extruder_values={0: dict(resolved)},
        meshes=list(meshes),
    )


def _layer_heights(text: str) -> dict[int, float]:
    """``;LAYER:n`` -> Z of that layer's printing moves (the last Z set before its first extrusion)."""
    heights = {}
    z = None
    layer = None
    for line in text.splitlines():
        if line.startswith(";LAYER:"):
            layer = int(line[7:])
            continue
        m = re.match(r"G[01] .*Z(-?[\d.]+)", line)
        if m:
            z = float(m.group(1))
        if layer is not None and layer not in heights and re.match(r"G1 .*X.*E", line):
            heights[layer] = z
    return heights


@pytest.mark.parametrize("name", sorted(RAFTS))
def test_raft_offset_matches_the_engine(engine_info, tmp_path, name):
    stl = tmp_path / "cube.stl"
    models.write_stl(stl, models.cube(10.0), name="cube.stl")
    settings = {"adhesion_type": "raft", **RAFTS[name]}
    result = curaengine.slice_models([("cube.stl", {})], settings, tmp_path / "raft.gcode", cwd=tmp_path)
    resolved = result.settings.global_values
    heights = _layer_heights(open(result.path, encoding="utf-8").read())
    assert min(heights) < 0, "a raft print has raft layers (negative numbers)"
    lift = raft_z_offset(_snapshot(resolved))
    assert lift > 0.5
    lh0, lh = resolved["layer_height_0"], resolved["layer_height"]
    for k in (1, 2, 10, 40):
        assert heights[k] == pytest.approx(lift + lh0 + k * lh, abs=1e-3), f"layer {k}"
    assert raft_z_offset(_snapshot({**resolved, "adhesion_type": "skirt"})) == 0.0


def test_a_region_lands_at_its_scene_height_on_a_raft(engine_info, tmp_path):
    """A 60 % box from 4 to 7 mm above the plate (scene) densifies exactly the layers at those heights."""
    stl = tmp_path / "cube.stl"
    models.write_stl(stl, models.cube(20.0), name="cube.stl")
    result = curaengine.slice_models([("cube.stl", {})], {"adhesion_type": "raft", "infill_sparse_density": 15},
                                     tmp_path / "raft.gcode", cwd=tmp_path)
    resolved = result.settings.global_values
    text = open(result.path, encoding="utf-8").read()
    box = models.box(30.0, 30.0, 3.0, cx=BED_CENTRE[0], cy=BED_CENTRE[1], z0=4.0)  # scene heights
    region = MeshSnapshot(name="DelaunayRegion_1", values={"infill_sparse_density": 60, "infill_mesh": True},
                          enabled=True, is_region=True, triangles=box)
    model = MeshSnapshot(name="cube.stl", enabled=True,
                         values={"infill_sparse_density": 15, "infill_line_width": resolved["infill_line_width"]})
    settings, regions = build_settings(_snapshot(resolved, [model, region]))
    layers, report = process_gcode(split_like_cura(text), settings, regions=regions)
    assert report.failed_layers == []
    # the lift as the G-code shows it (not the code under test): layer 5's height minus its scene height
    lift = _layer_heights(text)[5] - resolved["layer_height_0"] - 5 * resolved["layer_height"]
    assert lift > 0.5

    parsed = gc.parse_gcode("".join(layers))
    fill = parsed.fill_moves(extruding=True)
    length = np.hypot(fill[:, gc.C_X1] - fill[:, gc.C_X0], fill[:, gc.C_Y1] - fill[:, gc.C_Y0])
    layer_ids, inverse = np.unique(fill[:, gc.C_LAYER], return_inverse=True)
    per_layer = np.bincount(inverse, weights=length)
    z_of = {int(k): float(np.median(fill[fill[:, gc.C_LAYER] == k][:, gc.C_Z])) for k in layer_ids}
    scene_mid = np.array([z_of[int(k)] - lift - resolved["layer_height"] / 2 for k in layer_ids])
    inside = (scene_mid > 4.0 + 0.2) & (scene_mid < 7.0 - 0.2)
    outside = ((scene_mid < 4.0 - 0.4) | (scene_mid > 7.0 + 0.4)) & (per_layer > 0)
    assert inside.sum() >= 10 and outside.sum() >= 10
    # 60 % against 15 %: the region's layers carry about four times the infill
    assert per_layer[inside].min() > 2.5 * np.median(per_layer[outside])
    assert per_layer[outside].max() < 1.5 * np.median(per_layer[outside])
