"""Engine tier: G-code flavours and print modes sliced by the real CuraEngine 4.13, then processed.

Each case slices the star or the H-bracket with one setting changed, processes
the file and checks it with DelaunayInfill.gcode.verify.  Without CuraEngine
these tests fail (they never skip).
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from DelaunayInfill.curaengine import infill_modifier_settings, slice_models
from DelaunayInfill.gcode import MeshSettings, ProcessSettings, Region, process_file, process_gcode
from DelaunayInfill.gcode.read import as_cura_list
from DelaunayInfill.gcode.verify import verify_files
from DelaunayInfill.models import box, write_stl, write_test_models

pytestmark = pytest.mark.engine

CASES = {
    "relative_e": ("star", {"relative_extrusion": True}),
    "ultigcode_volumetric": ("star", {"machine_gcode_flavor": "UltiGCode", "retraction_combing": "off"}),
    "griffin": ("star", {"machine_gcode_flavor": "Griffin"}),
    "z_hop": ("star", {"retraction_hop_enabled": True, "retraction_hop": 0.4, "retraction_combing": "off"}),
    "firmware_retraction": ("star", {"machine_firmware_retract": True, "retraction_combing": "off"}),
    "raft": ("cube", {"adhesion_type": "raft"}),
    "infill_every_2nd_layer": ("star", {"infill_sparse_thickness": 0.4}),
    "lines_30": ("hbracket", {"infill_pattern": "lines", "infill_sparse_density": 30}),
    "gyroid": ("star", {"infill_pattern": "gyroid"}),
    "one_wall": ("hbracket", {"wall_line_count": 1}),
    "infill_before_walls_off": ("star", {"infill_before_walls": False}),
}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    paths = write_test_models(folder)
    paths["cube2"] = os.path.join(folder, "cube2.stl")
    write_stl(paths["cube2"], box(20, 20, 10, -45, 0, 0))
    paths["box"] = os.path.join(folder, "box.stl")
    write_stl(paths["box"], box(30, 44, 24, 15, 0, 0))
    return paths


def _run(tmp_path, models_and_settings, settings, min_density=0.1):
    src = tmp_path / "cura.gcode"
    slice_models(models_and_settings, settings, src)
    out = tmp_path / "out.gcode"
    report = process_file(src, out, ProcessSettings(seed=1))
    assert not report.failed_layers, report.failure_messages
    assert report.layers_processed > 0
    check = verify_files(src, out, min_density=min_density)
    assert check.ok, check.problems
    return src, out, report


@pytest.mark.parametrize("name", sorted(CASES))
def test_flavours_and_modes(name, models, tmp_path):
    model, settings = CASES[name]
    src, out, report = _run(tmp_path, [(models[model], {})], settings)
    base = report.regions[0]
    assert abs(base.measured - base.target) <= 0.02, report.format_table()
    text = out.read_text()
    if name == "ultigcode_volumetric":
        assert report.volumetric
        assert "G10" in text and "G11" in text
    if name == "firmware_retraction":
        new_fill = re.findall(r";TYPE:FILL\n(?:(?!;TYPE:).*\n)*", text)
        assert any("G10" in block for block in new_fill), "the new infill retracts with G10 like Cura"
        assert not any(re.search(r"^G1 F\d+ E", block, re.M) for block in new_fill)
    if name == "z_hop":
        assert report.infill_retractions > 0
    if name == "relative_e":
        assert "M83" in text and "G92 E" not in "".join(re.findall(r";TYPE:FILL\n(?:(?!;TYPE:).*\n)*", text))


def test_two_objects_and_one_at_a_time(models, tmp_path):
    for mode in ("all_at_once", "one_at_a_time"):
        folder = tmp_path / mode
        folder.mkdir()
        _, out, report = _run(folder, [(models["star"], {}), (models["cube2"], {})], {"print_sequence": mode})
        numbers = [int(n) for n in re.findall(r"^;LAYER:(-?\d+)", out.read_text(), re.M)]
        if mode == "one_at_a_time":
            assert numbers.count(0) == 2, "layer numbers restart per object"
            assert report.layers_processed >= 80
        else:
            assert report.blocks_replaced >= 2 * report.layers_processed, "both objects' infill replaced"


def test_infill_mesh_modifier_region(models, tmp_path):
    _, _, report = _run(tmp_path, [(models["hbracket"], {}), (models["box"], infill_modifier_settings(60))], {}, 0.2)
    names = [r.name for r in report.regions]
    assert len(names) == 2 and names[1].startswith("mesh ") and names[1].endswith("box.stl")
    for region in report.regions:
        assert abs(region.measured - region.target) <= 0.02, report.format_table()
    assert report.regions[1].target == pytest.approx(0.6, abs=0.01)


def _region_scene(folder):
    """The GUI test's slab with three infill_mesh regions (sphere 60 %, cylinder 10 %, box 40 %).

    Model coordinates (CuraEngine centres (0, 0) on the bed); returns the
    models to slice and each region's triangles in model coordinates.
    """
    from DelaunayInfill.cura.region_shapes import scene_to_gcode, shape_triangles

    def placed(shape, size, centre):
        tri = scene_to_gcode(shape_triangles(shape, size), 0, 0, center_is_zero=True)
        pts = tri.reshape(-1, 3)
        return tri - (pts.min(axis=0) + pts.max(axis=0)) / 2 + np.asarray(centre, dtype=float)

    shapes = {
        "pms_box.stl": (box(14, 8, 14, 0, 13), 40),
        "region_sphere.stl": (placed("sphere", 18, (-22, 0, 6)), 60),
        "region_cylinder.stl": (placed("cylinder", 16, (20.9135, -0.4717, 12.155)), 10),
    }
    write_stl(os.path.join(folder, "slab.stl"), box(80, 40, 12))
    models = [("slab.stl", {})]
    for name, (tri, pct) in shapes.items():
        write_stl(os.path.join(folder, name), tri)
        models.append((name, infill_modifier_settings(pct)))
    return models, {name: (tri, pct) for name, (tri, pct) in shapes.items()}


def test_region_meshes_never_print_cura_s_infill_under_the_new(tmp_path):
    """Issue 3: a sparse region's own FILL blocks got no new path and kept Cura's lines (printed twice).

    Settings as the Cura plugin passes them: every region is an infill_mesh with
    its density and also a Region with the mesh's triangles.
    """
    models, shapes = _region_scene(tmp_path)
    src = tmp_path / "cura.gcode"
    slice_models(models, {"infill_sparse_density": 20}, src, cwd=tmp_path)
    text = src.read_text()
    layer = re.search(r"(?ms)^;LAYER:6\n.*?^;TIME_ELAPSED", text).group(0)
    xs = [float(v) for v in re.findall(r"^G1 [^\n]*X([\d.]+)", layer, re.M)]
    ys = [float(v) for v in re.findall(r"^G1 [^\n]*Y([\d.]+)", layer, re.M)]
    bed_centre = np.array([(min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2, 0.0])  # the slab's centre
    meshes = {"slab.stl": MeshSettings(density=0.2)}
    regions = []
    for name, (tri, pct) in shapes.items():
        meshes[name] = MeshSettings(density=pct / 100, region_density=pct / 100)
        regions.append(Region(pct / 100, triangles=tri + bed_centre, name=name))
    settings = ProcessSettings(density=0.2, line_width=0.4, infill_overlap=0.12, speed=50.0, meshes=meshes,
                               process_unlisted_meshes=False, seed=0, filament_diameter=1.75, retraction_amount=5.0,
                               retraction_retract_speed=45.0, retraction_prime_speed=45.0, retraction_hop=0.0,
                               retraction_min_travel=1.5, travel_speed=150.0, acceleration=500.0)
    out, report = process_gcode(as_cura_list(text), settings, regions=regions)
    assert not report.failed_layers, report.failure_messages
    new_text = "".join(out)

    def fill_blocks(t, mesh):
        blocks = []
        for chunk in re.split(r"(?m)^(?=;LAYER:)", t):
            for part in re.split(r"(?m)^(?=;MESH:)", chunk)[1:]:
                if part.startswith(f";MESH:{mesh}\n"):
                    blocks += re.findall(r"(?ms)^;TYPE:FILL\n(.*?)(?=^;TYPE:|^;MESH:|\Z)", part)
        return blocks

    cura_blocks = fill_blocks(text, "region_cylinder.stl")
    assert len(cura_blocks) > 20
    kept = set(cura_blocks) & set(fill_blocks(new_text, "region_cylinder.stl"))
    assert not kept, f"{len(kept)} of {len(cura_blocks)} FILL blocks of the 10 % region still print Cura's lines"
    for r in report.regions:
        if r.name.startswith("region_cylinder"):
            assert abs(r.measured - 0.10) <= 0.02, report.format_table()
