"""Both CuraEngines of the tier (4.13 on the host, 5.0 in the trixie chroot) slice the star for real."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import numpy as np
import pytest
from shapely.geometry import Polygon

from DelaunayInfill import curaengine, models

from . import gcode_check as gc
from .engines import ENGINES, Engine, chroot_root, engine, engine_version

STAR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                    "DelaunayInfill", "data", "star.stl")


def _engine_or_fail(version: str) -> Engine:
    # the tier fails, never skips, when an engine cannot run
    try:
        return engine(version)
    except curaengine.CuraEngineError as exc:
        pytest.fail(f"CuraEngine {version} cannot run: {exc}", pytrace=False)


@pytest.fixture(scope="module", params=ENGINES)
def star_slice(request, engine_info, tmp_path_factory):
    """(engine, G-code text, SliceResult) of the star at 20 %, sliced once per engine."""
    e = _engine_or_fail(request.param)
    folder = tmp_path_factory.mktemp(f"star-{request.param}")
    shutil.copyfile(STAR, folder / "star.stl")
    result = curaengine.slice_models([("star.stl", {})], {"infill_sparse_density": 20}, folder / "star.gcode",
                                     engine=e.executable, resources=e.resources, cwd=folder)
    with open(result.path, encoding="utf-8") as f:
        return e, f.read(), result


def test_the_star_slices_to_real_gcode(star_slice):
    e, text, result = star_slice
    assert result.settings.warnings == []
    assert text.startswith(";FLAVOR:Marlin\n")
    assert f";Generated with Cura_SteamEngine {e.version}.0\n" in text
    layers = [int(n) for n in re.findall(r"^;LAYER:(-?\d+)$", text, re.M)]
    assert layers == list(range(50))  # 10 mm at 0.2 mm
    assert ";LAYER_COUNT:50\n" in text
    elapsed = [float(t) for t in re.findall(r"^;TIME_ELAPSED:([\d.]+)$", text, re.M)]
    assert len(elapsed) == 50 and elapsed == sorted(elapsed) and elapsed[-1] > 60
    meshes = set(re.findall(r"^;MESH:(.*)$", text, re.M))
    assert meshes == {"star.stl", "NONMESH"}  # the -l argument as given
    types = set(re.findall(r"^;TYPE:(.*)$", text, re.M))
    assert {"FILL", "SKIN", "WALL-INNER", "WALL-OUTER", "SKIRT"} <= types


def test_the_star_has_20_percent_infill_of_the_right_line(star_slice):
    """The resolved settings reach both engines: FILL on every layer between the skins, 0.4 x 0.2 mm lines."""
    _, text, _ = star_slice
    parsed = gc.parse_gcode(text)
    fill = parsed.fill_moves(extruding=True)
    layers = np.unique(fill[:, gc.C_LAYER])
    assert list(layers) == list(range(4, 46))  # 4 bottom and 4 top skin layers
    length = np.hypot(fill[:, gc.C_X1] - fill[:, gc.C_X0], fill[:, gc.C_Y1] - fill[:, gc.C_Y0])
    assert fill[:, gc.C_DE].sum() / length.sum() == pytest.approx(0.4 * 0.2 / (np.pi * 0.875**2), rel=0.02)
    # density = line length x line width / infill area (the star inset by its two walls)
    area = Polygon(models.star_outline()).buffer(-0.8, join_style=2).area
    assert length.sum() / len(layers) * 0.4 / area == pytest.approx(0.20, abs=0.02)


def test_wall_order_differs_between_the_engines(star_slice):
    """4.13 prints the inner wall first; 5.0 (inset_direction = outside_in) the outer wall first."""
    e, text, _ = star_slice
    first = {"4.13": "WALL-INNER", "5.0": "WALL-OUTER"}[e.version]
    blocks = re.split(r"^;LAYER:\d+$", text, flags=re.M)[1:]
    walls = [next(t for t in re.findall(r"^;TYPE:(.*)$", block, re.M) if t.startswith("WALL")) for block in blocks]
    assert set(walls) == {first}


def test_cura5_runs_inside_the_chroot(tmp_path):
    e = _engine_or_fail("5.0")
    root = chroot_root()
    assert e.resources == os.path.join(root, "usr/share/cura/resources")
    assert "/usr/sbin/chroot" in open(e.executable, encoding="utf-8").read()
    assert "version 5.0.0" in engine_version(e.executable)
    assert "version 4.13" in engine_version(None)  # the host's engine is another one
    # a model that exists only in the chroot's own file system (not under the shared /tmp), given by
    # its host path: the wrapper gives the engine the inside path, and ;MESH: shows what it was given
    inside = f"/var/tmp/delaunay-test-{os.getpid()}"
    folder = root + inside
    os.makedirs(folder, exist_ok=True)
    try:
        shutil.copyfile(STAR, os.path.join(folder, "star.stl"))
        result = curaengine.slice_models([(os.path.join(folder, "star.stl"), {})], {}, tmp_path / "star.gcode",
                                         engine=e.executable, resources=e.resources)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    text = open(result.path, encoding="utf-8").read()
    assert f";MESH:{inside}/star.stl\n" in text
    assert ";Generated with Cura_SteamEngine 5.0.0\n" in text


def test_cura5_wrapper_reports_a_missing_model_like_the_engine(tmp_path):
    """Relative paths are resolved in the caller's folder (chroot alone would run the engine in /)."""
    e = _engine_or_fail("5.0")
    proc = subprocess.run([e.executable, "slice", "-j", os.path.join(e.resources, "definitions", "fdmprinter.def.json"),
                           "-l", "no-such.stl", "-o", str(tmp_path / "x.gcode")],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode != 0
    assert "no-such.stl" in proc.stderr


def test_cura5_definitions_resolve_the_arachne_settings():
    """Cura 5.0's fdmprinter formulas evaluate on the host without a warning, Arachne's wall settings included."""
    e = _engine_or_fail("5.0")
    resolved = curaengine.resolve_settings({}, [("star.stl", curaengine.infill_modifier_settings(60))],
                                           resources=e.resources)
    assert resolved.warnings == []
    values = resolved.global_values
    assert values["min_wall_line_width"] == pytest.approx(0.34)  # machine_nozzle_size * .85
    assert values["wall_split_middle_threshold"] == pytest.approx(70)
    assert values["wall_add_middle_threshold"] == pytest.approx(85)
    assert values["inset_direction"] == "outside_in"
    assert values["infill_line_distance"] == pytest.approx(4.0) and values["top_layers"] == 4
    assert "outer_inset_first" not in values  # a 4.13 setting 5.0 dropped
    assert resolved.meshes[0][1]["infill_line_distance"] == pytest.approx(4 / 3, abs=1e-3)
