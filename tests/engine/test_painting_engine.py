"""Painted density regions (issue 14) through the console script, on models sliced by CuraEngine 4.13.

A box, a bushing and a dome (manifold3d) are sliced at 20 % with Cura's defaults, together with a
dense-lines reference slice that tiles Cura's infill area (``everyday.reference_settings``).  Faces
are painted (the box's top, one of its sides, the bushing's bore, the dome's curved face) and the G-code is processed
with ``delaunay-infill process --paint MODEL.stl:FACES.json:60:DEPTH --modifier-offset 110,110``.

Measured independently of the package: the G-code is read by ``everyday_check.extract_layers``, the
infill area of a layer is the reference's lines grown by half a line width, and the painted region
is said analytically for each model (the top DEPTH mm of the box; the slab DEPTH mm deep behind the
painted side; the ring of radius 7 to 7 + DEPTH
round the bore; the dome's shell of radius 20 - DEPTH to 20, at each layer's mid-height).  Density
is new infill line length x line width / area, inside each piece shrunk by a line width (so that
lines on a border count once), over all layers, as ``gcode_check.measure_region_densities`` does.
Everything must stay inside the infill area (``everyday_check.check_everyday``).
"""

from __future__ import annotations

import json
import math
import os
import subprocess

import numpy as np
import pytest
import shapely
from shapely.affinity import translate
from shapely.geometry import Point, Polygon, box

from DelaunayInfill import curaengine

from .conftest import cli_command
from .everyday import block, bushing, dome, mesh_triangles, reference_settings, section, write_model_stl
from .everyday_check import REFERENCE_MERGE_MM, check_everyday, extract_layers, lines_buffer

BED = (110.0, 110.0)  # model (0, 0) in G-code coordinates (CuraEngine centres it on the 220 mm bed)
BASE, PAINTED = 20, 60  # %


def _normals(tri: np.ndarray) -> np.ndarray:
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _box_top(tri):
    return np.flatnonzero((_normals(tri)[:, 2] > 0.99) & (tri[:, :, 2].min(axis=1) > 19.99))


def _box_side(tri):
    return np.flatnonzero((_normals(tri)[:, 0] > 0.99) & (tri[:, :, 0].min(axis=1) > 19.99))


def _bore(tri):
    radius = np.hypot(*tri[:, :, :2].mean(axis=1).T)
    return np.flatnonzero((np.abs(_normals(tri)[:, 2]) < 0.01) & (radius < 7.5))


def _dome_face(tri):
    return np.flatnonzero(_normals(tri)[:, 2] > -0.5)


def _box_truth(depth):
    return lambda z: box(-1e3, -1e3, 1e3, 1e3) if z >= 20.0 - depth else Polygon()


def _side_truth(depth):
    return lambda z: box(20.0 - depth, -1e3, 1e3, 1e3)


def _bore_truth(depth):
    return lambda z: Point(0, 0).buffer(7.0 + depth, 256)


def _dome_truth(depth):
    def truth(z):
        inner = (20.0 - depth) ** 2 - z * z
        outer = Point(0, 0).buffer(30.0, 16)
        return outer if inner <= 0 else outer.difference(Point(0, 0).buffer(math.sqrt(inner), 256))
    return truth


CASES = {
    # name: (solid builder, painted faces, depth mm, the painted region at a height, model coordinates)
    "box": (lambda: block(40, 40, 20), _box_top, 6.0, _box_truth),
    "box_side": (lambda: block(40, 40, 20), _box_side, 6.0, _side_truth),
    "bushing": (bushing, _bore, 6.0, _bore_truth),
    "dome": (dome, _dome_face, 4.0, _dome_truth),
}


def _slice(folder: str, name: str, solid) -> dict:
    """Sparse (20 %) and reference slices of `solid`, as everyday.slice_everyday makes them."""
    stl = os.path.join(folder, f"{name}.stl")
    write_model_stl(stl, solid, f"{name}.stl")
    meshes = [(f"{name}.stl", {})]
    settings = {"infill_sparse_density": BASE}
    resolved = curaengine.resolve_settings(settings, meshes)
    line_width = float({**resolved.global_values, **resolved.extruder_values}["infill_line_width"])
    sparse = curaengine.slice_models(meshes, settings, os.path.join(folder, "cura.gcode"), cwd=folder)
    reference = curaengine.slice_models(meshes, reference_settings(settings, line_width),
                                        os.path.join(folder, "reference.gcode"), cwd=folder)
    return {"stl": stl, "gcode": sparse.path, "reference": reference.path, "line_width": line_width}


def _measure(processed: str, reference: str, truth, line_width: float) -> dict:
    """{"painted": (density, area), "rest": (density, area)} over all layers, fractions and mm²."""
    new, ref = extract_layers(processed), extract_layers(reference)
    keys = [k for k in new if not math.isnan(new[k].z)]
    zs = [new[k].z for k in keys]
    totals = {"painted": [0.0, 0.0], "rest": [0.0, 0.0]}
    for i, key in enumerate(keys):
        layer = new[key]
        if key not in ref or len(ref[key].fill) == 0 or len(layer.fill) == 0:
            continue
        height = zs[i] - zs[i - 1] if i > 0 else zs[i]
        mid = zs[i] - height / 2
        # Cura's infill area: the dense reference lines' footprint, less the half width their ends reach
        # past it (Cura's lines end on the area's edge)
        area = lines_buffer(ref[key].fill, line_width / 2 + REFERENCE_MERGE_MM).buffer(-line_width / 2, join_style=2)
        painted = translate(truth(mid), *BED)
        lines = shapely.multilinestrings(shapely.linestrings(layer.fill))
        # each piece whole, the bands along the painted region's border included (issue 15)
        for name, piece in (("painted", area.intersection(painted)), ("rest", area.difference(painted))):
            if piece.is_empty or piece.area < 1.0:
                continue
            totals[name][0] += lines.intersection(piece).length
            totals[name][1] += piece.area
    return {k: (v[0] * line_width / v[1] if v[1] else math.nan, v[1]) for k, v in totals.items()}


@pytest.mark.parametrize("name", sorted(CASES))
def test_painted_region_density(engine_info, tmp_path, name):
    build, select, depth, truth_of = CASES[name]
    solid = build()
    folder = str(tmp_path)
    done = _slice(folder, name, solid)
    faces = select(mesh_triangles(solid))
    assert len(faces) > 0
    faces_path = os.path.join(folder, "faces.json")
    with open(faces_path, "w", encoding="utf-8") as f:
        json.dump({"faces": [int(i) for i in faces]}, f)
    out = os.path.join(folder, "painted.gcode")
    proc = subprocess.run([*cli_command(), "process", done["gcode"], "-o", out,
                           "--paint", f"{done['stl']}:{faces_path}:{PAINTED}:{depth:g}",
                           "--modifier-offset", f"{BED[0]:g},{BED[1]:g}"],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"{proc.stdout}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    with open(out, encoding="utf-8") as f:
        processed = f.read()
    with open(done["gcode"], encoding="utf-8") as f:
        original = f.read()
    with open(done["reference"], encoding="utf-8") as f:
        reference = f.read()
    lw = done["line_width"]
    measured = _measure(processed, reference, truth_of(depth), lw)
    print(f"\n[painting] {name}: painted {100 * measured['painted'][0]:.2f} % over {measured['painted'][1]:.0f} mm2, "
          f"rest {100 * measured['rest'][0]:.2f} % over {measured['rest'][1]:.0f} mm2\n{proc.stdout}")
    assert measured["painted"][1] > 200.0 and measured["rest"][1] > 200.0, measured
    assert abs(measured["painted"][0] - PAINTED / 100) <= 0.03, (measured, proc.stdout)
    assert abs(measured["rest"][0] - BASE / 100) <= 0.02, (measured, proc.stdout)
    # nothing printed outside Cura's infill area (nor outside the model)
    result = check_everyday(original, processed, reference,
                            lambda z: translate(section(solid, round(z, 4)), *BED),
                            spacing=2.0 * lw / (BASE / 100), line_width=lw)
    figures = result.figures
    assert figures["outside_fraction"] <= 0.003, result.report()
    assert figures["material_mm"] <= 2.0, result.report()
