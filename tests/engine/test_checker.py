"""The independent checker itself: Cura's own G-code passes, broken G-code fails.

Every check of gcode_check.py is shown to fail on a deliberately broken file,
so that none of them can pass by construction.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from . import gcode_check as gc
from .conftest import MATRIX


def _load(sliced):
    with open(sliced.gcode, encoding="utf-8") as f:
        return f.read()


def _settings(sliced):
    return gc.SliceSettings.from_resolved(sliced.resolved)


def _min_density(case):
    return min([case.density] + [r.target for r in case.regions()])


def test_cura_gcode_passes_every_check_against_itself(sliced):
    """Cura's own output is trivially unchanged and must satisfy checks 1-4 (it is the reference)."""
    text = _load(sliced)
    parsed = gc.parse_gcode(text)
    case, settings, geometry = sliced.case, _settings(sliced), sliced.case.geometry()
    assert parsed.layer_count() > 0 and len(parsed.fill_moves(extruding=True)) > 0
    results = [
        gc.check_unchanged(parsed, parsed),
        gc.check_infill_area(parsed, parsed, geometry, settings, min_density=_min_density(case)),
        gc.check_extrusion(parsed, parsed, geometry),
        # (Cura's infill-mesh lines stop short of their mesh's border: its regions measure right inside)
        gc.check_region_densities(parsed, geometry, settings, case.regions(), whole=False),
    ]
    for result in results:
        assert result.ok, result.report()
    # the independent area model agrees with Cura: its grid measures within 1.5 points of the setting
    for name, (target, measured) in results[3].figures.items():
        assert measured is None or abs(measured - target) <= 1.5, (name, target, measured)


# ---------------------------------------------------------------- mutations


def _fill_lines_by_layer(text: str) -> dict[int, list[int]]:
    """0-based line indices of FILL-context extrusion moves, per layer sequence number."""
    parsed = gc.parse_gcode(text)
    fill = parsed.fill_moves(extruding=True)
    out: dict[int, list[int]] = {}
    for row in fill:
        out.setdefault(int(row[gc.C_LAYER]), []).append(int(row[gc.C_LINE]) - 1)
    return out


def _middle_fill_layer(text: str) -> tuple[int, list[int]]:
    by_layer = _fill_lines_by_layer(text)
    keys = sorted(by_layer)
    key = keys[len(keys) // 2]
    return key, by_layer[key]


def _set_word(line: str, word: str, value: float) -> str:
    return re.sub(rf"{word}-?[\d.]+", f"{word}{value:.5f}", line, count=1)


def _get_word(line: str, word: str) -> float:
    return float(re.search(rf"{word}(-?[\d.]+)", line).group(1))


@pytest.fixture(scope="module")
def hbracket(slices):
    return slices.get(MATRIX["hbracket"])


@pytest.fixture(scope="module")
def hbracket_relative(slices):
    return slices.get(MATRIX["relative_e"])


@pytest.fixture(scope="module")
def modifiers(slices):
    return slices.get(MATRIX["star_modifiers"])


def _checks(orig_text, new_text, sliced):
    orig, new = gc.parse_gcode(orig_text), gc.parse_gcode(new_text)
    case, settings, geometry = sliced.case, _settings(sliced), sliced.case.geometry()
    return {
        1: gc.check_unchanged(orig, new),
        2: gc.check_infill_area(orig, new, geometry, settings, min_density=_min_density(case)),
        3: gc.check_extrusion(orig, new, geometry),
        4: gc.check_region_densities(new, geometry, settings, case.regions()),
    }


def test_check1_fails_when_a_wall_moves(hbracket):
    text = _load(hbracket)
    lines = text.split("\n")
    i = next(i for i, line in enumerate(lines) if i > len(lines) // 2 and line == ";TYPE:WALL-OUTER")
    j = next(k for k in range(i, len(lines)) if lines[k].startswith("G1 ") and " X" in lines[k])
    lines[j] = _set_word(lines[j], "X", _get_word(lines[j], "X") + 0.1)
    result = _checks(text, "\n".join(lines), hbracket)[1]
    assert not result.ok and "became" in result.failures[0]


def test_check1_fails_when_a_header_command_is_dropped(hbracket):
    text = _load(hbracket)
    broken = text.replace("M190 S60\n", "", 1)
    assert broken != text
    assert not _checks(text, broken, hbracket)[1].ok


def test_check1_ignores_only_time_figures(hbracket):
    text = _load(hbracket)
    changed = re.sub(r";TIME_ELAPSED:[\d.]+", ";TIME_ELAPSED:1.5", text)
    changed = changed.replace(";TIME:6666", ";TIME:1234").replace(";Filament used: 0m", ";Filament used: 1.2m")
    assert _checks(text, changed, hbracket)[1].ok


def test_check1_fails_when_the_position_is_not_handed_back(hbracket):
    """Drop the last move of a FILL block: the next original line starts elsewhere."""
    text = _load(hbracket)
    lines = text.split("\n")
    i = next(i for i, line in enumerate(lines) if i > len(lines) // 2 and line == ";TYPE:WALL-INNER")
    k = i - 1
    while not lines[k].startswith("G"):
        k -= 1
    del lines[k]
    result = _checks(text, "\n".join(lines), hbracket)[1]
    assert not result.ok and "state before" in " ".join(result.failures)


def test_check1_fails_when_the_filament_is_left_retracted(hbracket):
    text = _load(hbracket)
    lines = text.split("\n")
    i = next(i for i, line in enumerate(lines) if i > len(lines) // 2 and line == ";TYPE:WALL-INNER")
    e = max(_get_word(lines[k], "E") for k in range(i - 40, i) if " E" in lines[k])
    lines.insert(i, f"G92 E{e:.5f}")
    lines.insert(i, f"G1 F2700 E{e - 5:.5f}")  # retract and "forget" it with G92
    result = _checks(text, "\n".join(lines), hbracket)
    assert not result[1].ok and "retracted" in " ".join(result[1].failures)
    assert not result[3].ok and "retracted" in " ".join(result[3].failures)


def test_check2_fails_when_infill_leaves_the_part(hbracket_relative):
    text = _load(hbracket_relative)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    for k in fill:  # relative E: shifting every fill move keeps E/mm and continuity
        lines[k] = _set_word(_set_word(lines[k], "X", _get_word(lines[k], "X") + 3.0), "Y", _get_word(lines[k], "Y"))
    result = _checks(text, "\n".join(lines), hbracket_relative)[2]
    assert not result.ok and "outside" in " ".join(result.failures)


def test_check2_fails_when_a_layer_loses_its_infill(hbracket_relative):
    text = _load(hbracket_relative)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    for k in fill:
        lines[k] = re.sub(r"^G1", "G0", re.sub(r" E-?[\d.]+", "", lines[k]))
    result = _checks(text, "\n".join(lines), hbracket_relative)[2]
    assert not result.ok and "has none now" in " ".join(result.failures)


def test_check2_fails_when_part_of_a_layer_loses_its_infill(hbracket_relative):
    """Remove the infill of one leg of the H only: coverage drops."""
    text = _load(hbracket_relative)
    lines = text.split("\n")
    parsed = gc.parse_gcode(text)
    fill = parsed.fill_moves(extruding=True)
    left_leg = fill[(fill[:, gc.C_X1] < 95) & (fill[:, gc.C_X0] < 95)]
    assert len(left_leg) > 20
    for k in left_leg[:, gc.C_LINE].astype(int) - 1:
        lines[k] = re.sub(r"^G1", "G0", re.sub(r" E-?[\d.]+", "", lines[k]))
    result = _checks(text, "\n".join(lines), hbracket_relative)[2]
    assert not result.ok and "places with Cura infill" in " ".join(result.failures)
    assert result.figures["coverage"] < 0.9


def test_check3_fails_on_wrong_extrusion_per_mm(hbracket_relative):
    text = _load(hbracket_relative)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    for k in fill:
        lines[k] = _set_word(lines[k], "E", _get_word(lines[k], "E") * 0.9)
    result = _checks(text, "\n".join(lines), hbracket_relative)
    assert result[1].ok  # nothing outside FILL changed
    assert not result[3].ok and "E/mm" in " ".join(result[3].failures)


def test_check3_fails_on_an_e_jump(hbracket):
    """Absolute E: add 20 mm to every E from the middle of the file on (a jump, no G92)."""
    text = _load(hbracket)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    start = fill[len(fill) // 2]
    lines[start] = _set_word(lines[start], "E", _get_word(lines[start], "E") + 20.0)
    for k in range(start + 1, len(lines)):
        if re.match(r"G[01] .*E-?[\d.]+", lines[k]) and not lines[k].startswith("G92"):
            lines[k] = _set_word(lines[k], "E", _get_word(lines[k], "E") + 20.0)
        if lines[k].startswith("G92"):
            break
    result = _checks(text, "\n".join(lines), hbracket)[3]
    assert not result.ok and "E jump" in " ".join(result.failures)


def test_check3_fails_on_unretracted_travel_outside_the_part(hbracket):
    text = _load(hbracket)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    k = fill[3]
    x, y = _get_word(lines[k], "X"), _get_word(lines[k], "Y")
    lines[k + 1:k + 1] = ["G0 F7200 X10 Y10", f"G0 X{x} Y{y}"]
    result = _checks(text, "\n".join(lines), hbracket)[3]
    assert not result.ok and "without retraction" in " ".join(result.failures)


def test_check4_fails_when_a_region_is_too_sparse(modifiers):
    """Thin out the dense box's infill (every other line becomes travel): its density drops ~25 points."""
    text = _load(modifiers)
    lines = text.split("\n")
    parsed = gc.parse_gcode(text)
    dense = parsed.meshes.index("box_dense.stl")
    fill = parsed.fill_moves(extruding=True)
    rows = fill[fill[:, gc.C_MESH] == dense]
    assert len(rows) > 100
    for k in rows[::2, gc.C_LINE].astype(int) - 1:
        lines[k] = re.sub(r"^G1", "G0", re.sub(r" E-?[\d.]+", "", lines[k]))
    result = gc.check_region_densities(gc.parse_gcode("\n".join(lines)), modifiers.case.geometry(),
                                       _settings(modifiers), modifiers.case.regions())
    assert not result.ok and "box_dense.stl" in " ".join(result.failures)
    measured = result.figures["box_dense.stl"][1]
    assert 15 < measured < 40


def test_check5_fails_without_the_marker(hbracket):
    parsed = gc.parse_gcode(_load(hbracket))
    assert not gc.check_marker(parsed).ok
    marked = gc.parse_gcode(";DELAUNAYINFILL_PROCESSED version=0.1.0\n" + _load(hbracket))
    assert gc.check_marker(marked).ok


def test_region_density_measure_is_independent_of_line_direction():
    """A hand-made 19.2 x 19.2 mm square at 25 % (12 lines 1.6 mm apart, 0.4 wide) measures 25 %."""
    geometry = gc.SliceGeometry([gc.Part(np.array([(-10.4, -10.4), (10.4, -10.4), (10.4, 10.4), (-10.4, 10.4)]),
                                         0.0, 10.0, mesh="sq")], (0.0, 0.0))
    settings = gc.SliceSettings(line_width=0.4, wall_inset=0.8, infill_overlap=0.0, top_layers=0,
                                bottom_layers=0, density=0.25)
    out = [";LAYER:0", ";MESH:sq", ";TYPE:WALL-OUTER", "G0 X-10 Y-10 Z5.2", "G1 X10 Y-10 E1", ";TYPE:FILL"]
    e = 1.0
    for y in np.arange(-8.8, 9.0, 1.6):
        e += 1
        out += [f"G0 X-9.6 Y{y:.3f}", f"G1 X9.6 Y{y:.3f} E{e}"]
    parsed = gc.parse_gcode("\n".join(out))
    measured = gc.measure_region_densities(parsed, geometry, settings, [])["base"][0]
    assert measured == pytest.approx(0.25, abs=0.01)
    # inside, a line width in from the border: the 12 lines over 18.4 mm
    inside = gc.measure_region_densities(parsed, geometry, settings, [], whole=False)["base"][0]
    assert inside == pytest.approx(12 * 0.4 / 18.4, abs=0.005)


def test_check3_fails_on_a_retraction_for_a_travel_inside_the_part(hbracket):
    """Cura combs inside the part without retracting; a retraction there is needless."""
    text = _load(hbracket)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    k = next(k for k in fill if lines[k + 1].startswith("G0 ") and "E" not in lines[k + 1])
    e = _get_word(lines[k], "E")
    lines[k + 1:k + 1] = [f"G1 F1500 E{e - 5:.5f}"]
    lines[k + 3:k + 3] = [f"G1 F1500 E{e:.5f}"] if lines[k + 2].startswith("G0") else []
    broken = "\n".join(lines)
    result = _checks(text, broken, hbracket)[3]
    assert not result.ok and "stays inside the part" in " ".join(result.failures)
    assert result.figures["needless_retractions"] == 1


def test_check3_fails_on_a_retraction_unlike_cura(hbracket):
    """A retraction of 3 mm at F2400 where Cura retracts 5 mm at F1500."""
    text = _load(hbracket)
    lines = text.split("\n")
    _, fill = _middle_fill_layer(text)
    k = next(k for k in fill if lines[k + 1].startswith("G0 ") and "E" not in lines[k + 1])
    e = _get_word(lines[k], "E")
    lines[k + 1:k + 2] = [f"G1 F2400 E{e - 3:.5f}", "G0 F7200 X10 Y10", lines[k + 1], f"G1 F2400 E{e:.5f}"]
    result = _checks(text, "\n".join(lines), hbracket)[3]
    failures = " ".join(result.failures)
    assert not result.ok and "retraction of 3.0000 at F2400" in failures and "unretraction" in failures


def test_check_all_runs_the_five_checks(hbracket):
    text = _load(hbracket)
    results = gc.check_all(text, text, hbracket.case.geometry(), _settings(hbracket))
    assert [r.name[0] for r in results] == ["1", "2", "3", "4", "5"]
    assert all(r.ok for r in results[:4]) and not results[4].ok  # Cura's own file has no marker
