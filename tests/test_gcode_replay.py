"""Repeated layers (gcode/replay.py): written from an earlier layer, the same G-code as processing them.

Every test processes the same input twice, with ``repeat_layers`` on (the default) and off (every
layer processed on its own), and compares the texts with a plain line comparison
(`gcode_compare.differences`): all equal but E numbers, which may differ by Cura's rounding.
"""

from __future__ import annotations

import gzip
import math
import os
import re

import numpy as np
import pytest
from gcode_compare import differences
from shapely.geometry import Polygon

from DelaunayInfill.gcode import ProcessSettings, Region, process_gcode
from DelaunayInfill.gcode.read import as_cura_list
from DelaunayInfill.gcode.replay import BlockEdit, layer_words
from DelaunayInfill.gcode.verify import verify

DATA = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data")
E_ROUNDING = 3e-5  # E units: Cura's E words carry 5 decimals (equal moves may differ by two of those)
_COUNTERS = ("layers_total", "layers_processed", "layers_kept", "blocks_replaced", "blocks_kept", "infill_retractions")
_FIGURES = ("filament_before_mm", "filament_after_mm", "time_after_s", "infill_before_mm", "infill_after_mm",
            "infill_travel_mm")


def bundled(name: str) -> list[str]:
    with gzip.open(os.path.join(DATA, name), "rt", encoding="utf-8", newline="") as f:
        return as_cura_list(f.read())


def both_ways(layers, regions=(), **settings):
    """(output, report) with repeated layers written from earlier ones, and with every layer processed."""
    on = process_gcode(layers, ProcessSettings(seed=3, **settings), regions=regions)
    off = process_gcode(layers, ProcessSettings(seed=3, repeat_layers=False, **settings), regions=regions)
    return on, off


def assert_same_result(on, off):
    (out_on, rep_on), (out_off, rep_off) = on, off
    assert differences("".join(out_on), "".join(out_off), E_ROUNDING) == []
    assert rep_off.layers_repeated == 0
    for name in _COUNTERS:
        assert getattr(rep_on, name) == getattr(rep_off, name), name
    for name in _FIGURES:
        assert math.isclose(getattr(rep_on, name), getattr(rep_off, name), rel_tol=1e-6, abs_tol=1e-3), name
    assert [(r.name, round(r.measured, 6), round(r.area_mm2, 3)) for r in rep_on.regions] == \
        [(r.name, round(r.measured, 6), round(r.area_mm2, 3)) for r in rep_off.regions]


@pytest.mark.parametrize("name", ["star.gcode.gz", "hbracket_modifier.gcode.gz"])
def test_repeated_layers_are_written_as_processing_them_would(name):
    layers = bundled(name)
    on, off = both_ways(layers)
    assert_same_result(on, off)
    out, report = on
    # a prism: every middle layer repeats the one below it
    assert report.layers_repeated >= 0.6 * report.layers_total, report.format_table()
    check = verify(layers, out, min_density=0.1)
    assert check.ok, check.problems


def _rewrite_e(text: str, layer: int, factor: float) -> str:
    """`text` with every extrusion of `layer` `factor` times as long; later E words follow (absolute E)."""
    out, register, new_register, current = [], 0.0, 0.0, None
    for line in text.split("\n"):
        if line.startswith(";LAYER:"):
            current = int(line[7:])
        m = re.search(r" E(-?[\d.]+)", line)
        if m and line.startswith(("G0 ", "G1 ")):
            value = float(m.group(1))
            delta = value - register
            register = value
            if current == layer and delta > 0 and (" X" in line or " Y" in line):
                delta *= factor
            new_register += delta
            line = line[: m.start(1)] + f"{new_register:.5f}" + line[m.end(1):]
        elif m and line.startswith("G92"):
            register = new_register = float(m.group(1))
        out.append(line)
    return "\n".join(out)


def test_a_layer_with_other_extrusion_is_processed_on_its_own():
    """Same moves, 10 % more E per mm in layer 25: that layer is not taken from the one below."""
    layers = as_cura_list(_rewrite_e("".join(bundled("star.gcode.gz")), 25, 1.10))
    on, off = both_ways(layers)
    assert_same_result(on, off)
    plain, _ = both_ways(bundled("star.gcode.gz"))
    assert on[1].layers_repeated < plain[1].layers_repeated
    check = verify(layers, on[0], min_density=0.1)
    assert check.ok, check.problems  # E per mm of the new infill is layer 25's own (checked per block)


def _z_at_layer_start(text: str) -> str:
    """CuraEngine 4 moves to the next layer's height at the end of a layer: move that Z word to the
    start of the next layer instead (each layer's Z is then a word inside its own chunk)."""
    chunks = re.split(r"(?m)^(?=;LAYER:)", text)
    carry = None
    for i, chunk in enumerate(chunks):
        lines = chunk.split("\n")
        if carry is not None and lines[0].startswith(";LAYER:"):
            lines.insert(1, f"G0 Z{carry}")
            carry = None
        if lines[0].startswith(";LAYER:"):
            last = max((j for j, line in enumerate(lines) if re.search(r" Z[\d.]+", line)), default=None)
            if last is not None and i + 1 < len(chunks) and chunks[i + 1].startswith(";LAYER:"):
                carry = re.search(r" Z([\d.]+)", lines[last]).group(1)
                lines[last] = re.sub(r" Z[\d.]+", "", lines[last])
        chunks[i] = "\n".join(lines)
    return "".join(chunks)


def test_a_layer_step_that_changes_is_not_taken_from_a_layer_with_another():
    """Layers 25 and up 0.1 mm higher (one 0.3 mm step), each layer's Z inside its own chunk: the Z
    words of a repeat must move by the same step as the Z before it."""
    text = _z_at_layer_start("".join(bundled("star.gcode.gz")))
    out, current = [], None
    for line in text.split("\n"):
        if line.startswith(";LAYER:"):
            current = int(line[7:])
        if current is not None and current >= 25:
            line = re.sub(r" Z(\d*\.?\d+)", lambda m: f" Z{float(m.group(1)) + 0.1:.3f}".rstrip("0"), line)
        out.append(line)
    layers = as_cura_list("\n".join(out))
    # retracted travels hop (Z words inside the new blocks, at each layer's own height)
    on, off = both_ways(layers, combing=False, retraction_hop=0.4)
    assert_same_result(on, off)
    assert on[1].layers_repeated > 20 and on[1].infill_retractions > 0
    hops = re.findall(r"(?m)^G0 (?:F\d+ )?Z(\d*\.?\d+)$", "".join(on[0]))
    assert len(hops) > 2 * on[1].layers_processed
    assert verify(layers, on[0], min_density=0.1).ok


def _sphere(centre, radius: float, rings: int = 12, sectors: int = 24) -> np.ndarray:
    """A closed UV sphere, shape (n, 3, 3) mm."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2 * np.pi, sectors + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pts = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1) * radius + np.asarray(centre)
    a, b, c, d = pts[:-1, :-1], pts[1:, :-1], pts[1:, 1:], pts[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], axis=2).reshape(-1, 3, 3), np.stack([a, c, d], axis=2).reshape(-1, 3, 3)])
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    return tris[area > 1e-12]


def test_user_regions_that_change_with_height_are_processed_at_every_height():
    layers = bundled("star.gcode.gz")
    sphere = Region(0.6, triangles=_sphere((110.0, 110.0, 5.0), 7.0), name="sphere")
    on, off = both_ways(layers, regions=[sphere])
    assert_same_result(on, off)
    plain, _ = both_ways(layers)
    # the sphere's section changes at every layer it spans: only layers above or below it repeat
    assert on[1].layers_repeated < plain[1].layers_repeated - 20

    square = Region(0.5, polygon=Polygon([(100, 100), (120, 100), (120, 120), (100, 120)]), name="square")
    on, off = both_ways(layers, regions=[square])
    assert_same_result(on, off)
    assert on[1].layers_repeated >= plain[1].layers_repeated - 2  # a prism region repeats like the part


def test_layer_words_ignore_only_z_e_and_the_counters():
    a = ";LAYER:7\nG0 F9000 X10 Y10 Z1.4\nG1 X20 Y10 E12.5\n;TIME_ELAPSED:120.5\n"
    b = ";LAYER:8\nG0 F9000 X10 Y10 Z1.6\nG1 X20 Y10 E13.75\n;TIME_ELAPSED:131.25\n"
    c = ";LAYER:8\nG0 F9000 X10 Y10 Z1.6\nG1 X20 Y11 E13.75\n;TIME_ELAPSED:131.25\n"
    wa, wb, wc = layer_words(a), layer_words(b), layer_words(c)
    assert wa.key == wb.key != wc.key
    assert wb.values.tolist() == [1.6, 13.75] and wb.is_e.tolist() == [False, True]
    assert layer_words(";LAYER:8\nG1 X20 Y10 E1.2.3\n") is None


def test_block_edit_moves_e_and_z_words_and_sets_the_register_after_it():
    lines = ["M106 S127 ;fan 50%", "G0 F300 Z0.8", "G1 F3000 X10.000 Y10.000 E100.12340", "G1 F1500 E99.32345",
             "G92 E98.5", "G1 F9000"]
    edit = BlockEdit(3, 9, lines, e_before=100.0, e_word_before=1, e_word_after=4)
    assert edit.render(0, 0.0, 98.5) == "\n".join(lines)
    assert edit.render(250_000, 0.2, 101.0).split("\n") == [
        "M106 S127 ;fan 50%", "G0 F300 Z1", "G1 F3000 X10.000 Y10.000 E102.62340", "G1 F1500 E101.82345", "G92 E101",
        "G1 F9000"]
    assert BlockEdit(3, 4, ["G0 X1 Y2"], 0.0, 0, 0).render(5, 0.2, 1.0) == "G0 X1 Y2"


def test_the_comparison_allows_only_rounding_in_e_and_the_header_figures():
    """The yardstick of the tests above: E words within the tolerance, the header's filament sum
    within its six-decimal rounding; anything else is a difference."""
    head = ";FLAVOR:Marlin\n;Filament used: 0.046470m\n"
    move = "G1 X20 Y10 E13.75000\n"
    assert differences(head + move, head + "G1 X20 Y10 E13.75002\n", E_ROUNDING) == []
    assert differences(head + move, ";FLAVOR:Marlin\n;Filament used: 0.046469m\n" + move, E_ROUNDING) == []
    assert differences(head + move, ";FLAVOR:Marlin\n;Filament used: 0.046500m\n" + move, E_ROUNDING) != []
    assert differences(head + move, ";FLAVOR:Marlin\n;Filament used: 0.046470mm\n" + move, E_ROUNDING) != []
    assert differences(head + move, head + "G1 X20 Y10 E13.76000\n", E_ROUNDING) != []
    assert differences(head + move, head + "G1 X20 Y11 E13.75000\n", E_ROUNDING) != []


def test_a_mesh_prism_region_repeats_like_the_part():
    """A box STL's triangulated sides cut the plane at other points at every height: its sections are
    still the same polygon (collinear vertices dropped), so the layers repeat, as processing every layer
    would write them."""
    from DelaunayInfill.models import box

    layers = bundled("star.gcode.gz")
    dense = Region(0.6, triangles=box(12, 12, 30, 110, 112), name="dense.stl")
    assert dense.at(1.1).wkb == dense.at(1.3).wkb and len(dense.at(1.1).geoms[0].exterior.coords) == 5
    on, off = both_ways(layers, regions=[dense])
    assert_same_result(on, off)
    plain, _ = both_ways(layers)
    assert on[1].layers_repeated >= plain[1].layers_repeated - 2
