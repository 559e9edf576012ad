"""Layer-view paths from processed G-code (DelaunayInfill/cura/preview.py, pure part)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from DelaunayInfill.cura.preview import (
    INFILL,
    LINE_TYPE_IDS,
    TRAVEL,
    TRAVEL_RETRACTED,
    cura_points,
    layer_index_map,
    parse_gcode_paths,
)

HEADER = ";FLAVOR:Marlin\n;TIME:100\n;Filament used: 0.1m\n;Layer height: 0.2\n"
START = ";Generated with Cura_SteamEngine 4.13.0\nM82 ;absolute extrusion mode\nG28\nG92 E0\nG1 F1500 E-5\n;LAYER_COUNT:2\n"

# E per mm for a 0.4 x 0.2 line with 1.75 mm filament
E_PER_MM = 0.4 * 0.2 / (math.pi * 0.875**2)


def _layer(n, z, e0):
    e1 = e0 + 10 * E_PER_MM
    e2 = e1 + 10 * E_PER_MM
    return (
        f";LAYER:{n}\n"
        f"G0 F6000 X10 Y10 Z{z}\n"
        ";TYPE:WALL-OUTER\n"
        f"G1 F1500 E{e0:.5f}\n"  # unretract (E-only)
        f"G1 F1200 X20 Y10 E{e1:.5f}\n"
        ";TYPE:FILL\n"
        f"G1 X20 Y20 E{e2:.5f}\n"
        f"G1 F1500 E{e2 - 5:.5f}\n"  # retract
        "G0 F6000 X30 Y30\n"
        f";TIME_ELAPSED:{10 * (n + 1)}\n"
    ), e2 - 5


def _gcode():
    layer0, e = _layer(0, 0.2, 0.0)
    layer1, e = _layer(1, 0.4, e + 5)
    return [HEADER, START, layer0, layer1, "M107\nM82 ;absolute extrusion mode\n;End of Gcode\n"]


def test_moves_become_typed_segments_per_layer():
    paths = parse_gcode_paths(_gcode())
    assert [p.number for p in paths] == [0, 1]
    first = paths[0]
    assert first.z == pytest.approx(0.2)
    assert first.thickness == pytest.approx(0.2)
    assert paths[1].thickness == pytest.approx(0.2)
    assert first.points.shape == (first.segment_count + 1, 3)
    assert list(first.types) == [TRAVEL_RETRACTED, LINE_TYPE_IDS["WALL-OUTER"], INFILL, TRAVEL_RETRACTED]
    assert first.length_of(INFILL) == pytest.approx(10.0)
    assert first.length_of(LINE_TYPE_IDS["WALL-OUTER"]) == pytest.approx(10.0)
    extrusions = first.types < TRAVEL
    np.testing.assert_allclose(first.widths[extrusions], 0.4, rtol=1e-3)
    np.testing.assert_allclose(first.thicknesses[extrusions], 0.2)
    assert (first.thicknesses[~extrusions] == 0).all()
    np.testing.assert_allclose(first.feedrates, [100, 20, 20, 100])


def test_chunk_boundaries_do_not_matter():
    chunks = _gcode()
    whole = parse_gcode_paths(["".join(chunks)])
    split = parse_gcode_paths(chunks)
    assert len(whole) == len(split)
    for a, b in zip(whole, split):
        np.testing.assert_array_equal(a.types, b.types)
        np.testing.assert_allclose(a.points, b.points)


def test_relative_extrusion_and_travel_without_retraction():
    gcode = [
        HEADER,
        "M83 ;relative extrusion mode\n;LAYER_COUNT:1\n",
        ";LAYER:0\nG0 X0 Y0 Z0.3\n;TYPE:FILL\nG1 X5 Y0 E0.2\nG0 X5 Y5\nG1 X0 Y5 E0.2\n",
    ]
    (layer,) = parse_gcode_paths(gcode)
    assert list(layer.types) == [TRAVEL, INFILL, TRAVEL, INFILL]
    assert layer.length_of(INFILL) == pytest.approx(10.0)


def test_g92_resets_do_not_count_as_extrusion():
    gcode = [
        HEADER,
        "M82\n;LAYER_COUNT:1\n",
        ";LAYER:0\nG0 X0 Y0 Z0.2\n;TYPE:FILL\nG1 X10 Y0 E5\nG92 E0\nG1 X20 Y0 E0.1\nG1 X30 Y0 E0.1\n",
    ]
    (layer,) = parse_gcode_paths(gcode)
    # the move after G92 extrudes 0.1, the next one extrudes nothing (a travel)
    assert list(layer.types) == [TRAVEL, INFILL, INFILL, TRAVEL]


def test_volumetric_flavour_widths_use_mm3():
    gcode = [";FLAVOR:UltiGCode\n;TIME:1\n", "M82\n", ";LAYER:0\nG0 X0 Y0 Z0.2\n;TYPE:FILL\nG1 X10 Y0 E0.8\n"]
    (layer,) = parse_gcode_paths(gcode)
    assert layer.widths[-1] == pytest.approx(0.8 / (10 * 0.2))


def test_raft_layers_come_first_in_preview_numbering():
    assert layer_index_map([-3, -2, -1, 0, 1]) == {-3: 0, -2: 1, -1: 2, 0: 3, 1: 4}
    assert layer_index_map([0, 1, 2]) == {0: 0, 1: 1, 2: 2}
    assert layer_index_map([2, 3]) == {2: 0, 3: 1}
    assert layer_index_map([]) == {}


def test_cura_points_are_y_up_z_towards_the_front():
    np.testing.assert_allclose(cura_points(np.array([[1.0, 2.0, 3.0]])), [[1, 3, -2]])


def _naive_fill_length(text):
    """Line-by-line reference: FILL extrusion length in XY."""
    x = y = 0.0
    e = 0.0
    kind = None
    relative = False
    total = 0.0
    for line in text.splitlines():
        if line.startswith(";TYPE:"):
            kind = line[6:]
            continue
        code = line.split(";")[0].split()
        if not code:
            continue
        if code[0] in ("M82", "M83"):
            relative = code[0] == "M83"
            continue
        words = {w[0]: float(w[1:]) for w in code[1:]}
        if code[0] == "G92":
            e = words.get("E", e)
        elif code[0] in ("G0", "G1"):
            nx, ny = words.get("X", x), words.get("Y", y)
            if "E" in words:
                de = words["E"] if relative else words["E"] - e
                if not relative:
                    e = words["E"]
            else:
                de = 0.0
            if de > 1e-9 and kind == "FILL" and (nx, ny) != (x, y):
                total += math.hypot(nx - x, ny - y)
            x, y = nx, ny
    return total


@given(
    st.lists(
        st.tuples(
            st.sampled_from(["FILL", "SKIN", "WALL-INNER", None]),
            st.floats(0, 50),
            st.floats(0, 50),
            st.floats(-0.5, 1.0),
            st.booleans(),
        ),
        min_size=1,
        max_size=40,
    ),
    st.booleans(),
)
@settings(max_examples=60, deadline=None)
def test_fill_length_matches_a_line_by_line_reading(moves, relative):
    lines = [";LAYER:0", "G0 X0 Y0 Z0.2"]
    e = 0.0
    for kind, x, y, de, reset in moves:
        if kind:
            lines.append(f";TYPE:{kind}")
        if reset and not relative:
            lines.append("G92 E0")
            e = 0.0
        e_word = de if relative else e + de
        e = e if relative else e + de
        lines.append(f"G1 X{x:.3f} Y{y:.3f} E{e_word:.5f}")
    mode = "M83" if relative else "M82"
    text = "\n".join(lines) + "\n"
    paths = parse_gcode_paths([HEADER, mode + "\n", text])
    ours = sum(p.length_of(INFILL) for p in paths)
    # points are float32, as Cura's layer view stores them
    assert ours == pytest.approx(_naive_fill_length(mode + "\n" + text), rel=1e-5, abs=1e-3)


def test_end_gcode_after_the_last_layer_is_not_drawn():
    """Moves after ;TIME_ELAPSED: (the end G-code, often in G91) belong to no layer, as in Cura's view."""
    layer0, _ = _layer(0, 0.2, 0.0)
    end = "G91\nG1 E-2 Z0.2 F2400\nG1 X5 Y5 F3000\nG1 Z10\nG90\nG1 X0 Y235\nM84\n"
    with_end = parse_gcode_paths([HEADER, START, layer0 + end])
    without = parse_gcode_paths([HEADER, START, layer0])
    assert len(with_end) == len(without) == 1
    np.testing.assert_array_equal(with_end[0].types, without[0].types)
    np.testing.assert_allclose(with_end[0].points, without[0].points)


def test_g91_moves_do_not_move_the_tracked_position():
    gcode = [
        HEADER,
        "M82\n",
        ";LAYER:0\nG0 X10 Y10 Z0.2\nG91\nG1 X5 Y5\nG90\n;TYPE:FILL\nG1 X20 Y10 E1\n",
    ]
    (layer,) = parse_gcode_paths(gcode)
    assert layer.length_of(INFILL) == pytest.approx(10.0)
