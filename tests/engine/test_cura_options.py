"""Cura options the everyday corpus does not set, through real CuraEngine slices.

* **Infill Layer Thickness** (``infill_sparse_thickness`` = 2 layers): Cura prints the infill of two
  layers as one line twice as high in the upper layer, and single lines only where the sections
  differ.  The pass keeps Cura's infill and says so, from the settings footer, and without it from the
  G-code's own extrusion; the everyday checker finds nothing printed where Cura does not print.
* **Infill Wall Line Count** (walls round the infill area, printed as closed FILL loops): they stay as
  Cura printed them and the new infill fills what they enclose (the pass dropped them before: 9-15 %
  less filament than Cura's).
* **Infill as Support** (infill only under the top surfaces it holds up): its lines do not show how far
  that reaches; with the footer the pass keeps Cura's infill and says so (a dome: 22 % of the new
  infill was outside Cura's area before).
* **Infill patterns whose lines pair up** (octet, quarter cubic, cross, cross 3D): one layer's lines
  come in pairs whose gap changes from layer to layer, so their spacing does not tell the density.
  With the footer the pass prints its density; without it, what the lines' length says.
* **A 0.6 mm nozzle** (line width 0.6 mm, 0.3 mm layers, Cura's 0.8 mm wall thickness: one wall): no
  inner wall tells the line width; the skin's lines do (the CLI took 0.4 mm: 20 % printed as 24 %,
  filament +11-15 %, up to 1.9 mm of infill on skin).
* **Two extruders**: two models each on its own extruder with a prime tower (both engines), and one
  model's infill on the second extruder (CuraEngine 4.13: the 5.0 command line crashes on
  ``infill_extruder_nr``, exit -11).  Each extruder's infill is replaced at its own E per mm, every
  other move of each extruder is Cura's.
* **Infill meshes and cutting meshes** (a box over the dome; with no walls, one wall or two): the dome's
  new infill stays off the box's walls and skin and out of a box with walls; the box prints its own
  density (reported as its own region), the dome the print's.

    python3 -m pytest tests/engine/test_cura_options.py -q -c tests/pytest.ini
"""

from __future__ import annotations

import numpy as np
import pytest

from DelaunayInfill import process_gcode
from DelaunayInfill.curaengine import CuraEngineError
from DelaunayInfill.gcode.read import as_cura_list

from .engines import ENGINES
from .everyday import EverydayCase, EverydaySliceCache
from .everyday_check import check_everyday, extract_layers
from .gcode_check import check_unchanged, parse_gcode

DENSITY = 20.0
PAIRED_PATTERNS = ("tetrahedral", "quarter_cubic", "cross", "cross_3d")


def _case(model: str, settings: dict, exercises: str) -> EverydayCase:
    return EverydayCase(model, ((model, (0.0, 0.0)),), settings, exercises)


@pytest.fixture(scope="module")
def option_slices(engine_info, tmp_path_factory) -> EverydaySliceCache:
    return EverydaySliceCache(tmp_path_factory.mktemp("cura-options"))


def _slice(cache, case, version):
    try:
        return cache.get(case, DENSITY, version)
    except CuraEngineError as exc:
        pytest.fail(f"CuraEngine {version} cannot slice {case.name} ({case.exercises}): {exc}", pytrace=False)


def _without_footer(text: str) -> str:
    """The G-code as the CuraEngine command line writes it: no ;SETTING_3 footer."""
    return "".join(line for line in text.splitlines(keepends=True) if not line.startswith(";SETTING_3"))


def _process(sliced, footer: bool):
    with open(sliced.cura_gcode, encoding="utf-8") as f:
        original = f.read()
    if not footer:
        original = _without_footer(original)
    with open(sliced.reference_gcode, encoding="utf-8") as f:
        reference = f.read()
    layers, report = process_gcode(as_cura_list(original))
    processed = "".join(layers)
    result = check_everyday(original, processed, reference, sliced.section_at, spacing=sliced.spacing,
                            line_width=sliced.line_width)
    return original, processed, report, result


THICKNESS_CASES = {
    # name: (case, whether its top layers' infill lies inside the layers below: replaced)
    "prism": (_case("through_hole", {"infill_sparse_thickness": 0.4}, "a prism with holes"), True),
    "shrinking": (_case("dome", {"infill_sparse_thickness": 0.4}, "a dome: each section inside the one below"), True),
    "growing": (_case("cone_up", {"infill_sparse_thickness": 0.4, "wall_line_count": 2},
                      "a cone growing upwards: each section over the one below"), False),
}


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("footer", [True, False], ids=["footer", "no-footer"])
@pytest.mark.parametrize("name", sorted(THICKNESS_CASES))
def test_infill_layer_thickness(option_slices, name, footer, version):
    """Infill every 2 layers: a top layer whose infill area the layer below holds gets the new infill as
    high as Cura's line; the others keep Cura's. Nowhere new infill where Cura has none (the checker)."""
    case, replaced = THICKNESS_CASES[name]
    sliced = _slice(option_slices, case, version)
    _, _, report, result = _process(sliced, footer=footer)
    assert result.ok, result.report()
    if not footer:  # found in the extrusion: from the first layer printed two layers high
        assert any("2 layers high (Cura's Infill Layer Thickness)" in w for w in report.warnings), report.warnings
    if replaced:
        assert report.layers_processed >= 10, report.format_table()
        assert abs(report.regions[0].measured - DENSITY / 100) < 0.02, report.format_table()
        # the filament of lines two layers high: what Cura's put out, about
        assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.05, report.format_table()
    else:
        assert any("Infill Layer Thickness prints it 2 layers high" in w and "grows" in w
                   for w in report.warnings), report.warnings
        assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.01, report.format_table()


WALL_CASES = [_case("cup", {"infill_pattern": "cubic", "wall_line_count": 4}, "4 walls"),
              _case("side_text", {"wall_line_count": 6}, "6 walls")]


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("case", WALL_CASES, ids=lambda c: c.exercises.replace(" ", "-"))
def test_many_walls_give_the_line_width_and_the_density(option_slices, case, version):
    """The inner walls lie one, two, ... widths in: the line width is the first one's distance (the
    median of all of them read 0.8 mm for 4 walls and 1.2 mm for 6, and the reports 40 % and 60 %)."""
    sliced = _slice(option_slices, case, version)
    _, _, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert report.line_width_found == pytest.approx(0.4, abs=0.01)
    assert report.regions[0].target == pytest.approx(DENSITY / 100)
    assert 0.16 <= report.regions[0].measured <= 0.21, report.format_table()


INFILL_WALL_CASES = [_case("dome", {"infill_wall_line_count": 2, "infill_pattern": "triangles"}, "2 infill walls"),
                     _case("stairs", {"infill_wall_line_count": 1}, "1 infill wall")]


def _closed_runs_length(segments) -> float:
    """Length of the closed runs (last end back at the first start) among segments in file order, mm."""
    total, start = 0.0, 0
    for i in range(len(segments)):
        last = i + 1 == len(segments) or float(np.abs(segments[i + 1, 0] - segments[i, 1]).max()) > 1e-6
        if last:
            run = segments[start:i + 1]
            if len(run) >= 3 and float(np.hypot(*(run[-1, 1] - run[0, 0]))) < 0.05:
                total += float(np.hypot(*(run[:, 1] - run[:, 0]).T).sum())
            start = i + 1
    return total


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("case", INFILL_WALL_CASES, ids=lambda c: c.exercises.replace(" ", "-"))
def test_infill_walls_stay_as_cura_printed_them(option_slices, case, version):
    sliced = _slice(option_slices, case, version)
    original, processed, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert report.layers_processed >= 10
    assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.02, report.format_table()
    before, after = extract_layers(original), extract_layers(processed)
    walls = kept = 0.0
    for key, layer in before.items():
        loops = _closed_runs_length(layer.fill)
        walls += loops
        if loops and key in after:
            # Cura's loop segments found again, move for move (either way round: a loop may be printed
            # backwards on the route), in the processed layer
            def ends(segment):
                a, b = tuple(np.round(segment[0], 3)), tuple(np.round(segment[1], 3))
                return min(a, b), max(a, b)

            theirs = {ends(s) for s in layer.fill}
            mine = [s for s in after[key].fill if ends(s) in theirs]
            kept += min(loops, float(sum(np.hypot(*(s[1] - s[0])) for s in mine)))
    assert walls > 1000.0 and kept >= 0.98 * walls, (kept, walls)


FUZZY_CASE = _case("lofted_hull", {"magic_fuzzy_skin_enabled": True}, "fuzzy skin")


@pytest.mark.parametrize("version", ENGINES)
def test_fuzzy_skin_gives_the_line_width_and_keeps_off_the_skin(option_slices, version):
    """Fuzzy skin jitters the outer wall by up to 0.3 mm: the line width is still the first inner wall's
    distance (read from the inner walls out it came to 0.23 mm, the skin's closing shrank with it and
    the new infill reached 24-77 mm onto the skin at 10 %)."""
    try:
        sliced = option_slices.get(FUZZY_CASE, 10.0, version)
    except CuraEngineError as exc:
        pytest.fail(f"CuraEngine {version} cannot slice the fuzzy hull: {exc}", pytrace=False)
    _, _, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert report.line_width_found == pytest.approx(0.4, abs=0.01)


SUPPORT_CASE = _case("dome", {"infill_support_enabled": True, "infill_support_angle": 40}, "infill as support")


@pytest.mark.parametrize("version", ENGINES)
def test_infill_as_support_keeps_cura_s_infill(option_slices, version):
    sliced = _slice(option_slices, SUPPORT_CASE, version)
    original, processed, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert report.layers_processed == 0
    assert any("Infill as Support" in w for w in report.warnings), report.warnings
    assert [line for line in processed.splitlines() if not line.startswith(";DELAUNAYINFILL_PROCESSED")] \
        == original.splitlines()


PATTERN_CASES = [_case("dome", {"infill_pattern": p}, f"{p} infill") for p in PAIRED_PATTERNS]


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("footer", [True, False], ids=["footer", "no-footer"])
@pytest.mark.parametrize("case", PATTERN_CASES, ids=lambda c: c.settings["infill_pattern"])
def test_paired_line_patterns_print_their_density(option_slices, case, footer, version):
    """With the footer: its density (the pass added 76-86 % filament before); without: what the lines'
    length over the area says."""
    sliced = _slice(option_slices, case, version)
    _, _, report, result = _process(sliced, footer=footer)
    assert result.ok, result.report()
    base = report.regions[0]
    if footer:
        assert abs(base.target - DENSITY / 100) < 1e-6, (base.target, case.exercises)
        assert abs(base.measured - DENSITY / 100) < 0.01, (base.measured, case.exercises)
        # (Cura's cross patterns print a little under their density: up to 10 % more filament)
        assert report.filament_after_mm < 1.12 * report.filament_before_mm, case.exercises
    else:
        assert 0.15 <= base.measured <= 0.22, (base.measured, case.exercises)
        assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.06, case.exercises


NOZZLE_CASE = _case("dome", {"machine_nozzle_size": 0.6, "line_width": 0.6, "layer_height": 0.3,
                             "layer_height_0": 0.3}, "0.6 mm nozzle, one wall")


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("footer", [True, False], ids=["footer", "no-footer"])
def test_one_wall_of_a_wide_nozzle_gives_the_line_width_by_the_skin(option_slices, footer, version):
    sliced = _slice(option_slices, NOZZLE_CASE, version)
    original, _, report, result = _process(sliced, footer=footer)
    assert result.ok, result.report()
    assert extract_layers(original), "no layers read"
    assert report.line_width_found == pytest.approx(0.6, abs=0.01), report.warnings
    assert not any("line width not found" in w for w in report.warnings), report.warnings
    assert report.layers_processed >= 10
    assert abs(report.regions[0].measured - DENSITY / 100) < 0.015, report.format_table()
    assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.03, report.format_table()


def _extrusion_by_tool(text: str) -> dict:
    """Net E per (extruder, feature type) of a G-code text, read line by line (absolute E, G92, T<n>)."""
    import re

    tool, e, kind, totals = 0, 0.0, None, {}
    number = re.compile(r"E(-?\d*\.?\d+)")
    for line in text.splitlines():
        if line.startswith(";TYPE:"):
            kind = line[6:].strip()
        elif line.startswith(";LAYER:"):
            kind = None
        elif re.match(r"T\d+\s*$", line):
            tool, kind = int(line[1:]), None  # (the switch's own retract and prime belong to no feature)
        elif line.startswith(("G0", "G1", "G92")):
            found = number.search(line.split(";")[0])
            if found:
                value = float(found.group(1))
                if not line.startswith("G92"):
                    totals[tool, kind] = totals.get((tool, kind), 0.0) + value - e
                e = value
    return totals


DUAL_CASES = {
    "two-models-two-extruders": (EverydayCase(
        "dome", (("dome", (-18.0, 0.0)), ("through_hole", (18.0, 0.0))),
        {"machine_extruder_count": 2, "prime_tower_enable": True}, "a model on each extruder, a prime tower",
        ({"extruder_nr": 0}, {"extruder_nr": 1})), ENGINES),
    "infill-on-the-second-extruder": (EverydayCase(
        "dome", (("dome", (0.0, 0.0)),), {"machine_extruder_count": 2, "infill_extruder_nr": 1},
        "walls and skin on extruder 0, infill on extruder 1", ({"extruder_nr": 0},)), ("4.13",)),
}


@pytest.mark.parametrize("name,version", [(n, v) for n, (_, versions) in DUAL_CASES.items() for v in versions])
def test_two_extruders_each_keep_their_own_extrusion(option_slices, name, version):
    case = DUAL_CASES[name][0]
    sliced = _slice(option_slices, case, version)
    original, processed, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert report.layers_processed >= 20, report.format_table()
    unchanged = check_unchanged(parse_gcode(original), parse_gcode(processed))
    assert unchanged.ok, unchanged.report()
    before, after = _extrusion_by_tool(original), _extrusion_by_tool(processed)
    fill_tools = {tool for tool, kind in before if kind == "FILL" and before[tool, kind] > 10.0}
    assert fill_tools == ({0, 1} if len(case.models) == 2 else {1}), before
    for key in set(before) | set(after):
        if key[1] == "FILL":
            assert after.get(key, 0.0) == pytest.approx(before[key], rel=0.03), (key, before, after)
        else:
            assert after.get(key, 0.0) == pytest.approx(before.get(key, 0.0), abs=1e-3), (key, before, after)
    for region in report.regions:
        assert abs(region.measured - region.target) < 0.015, report.format_table()


def _modifier_case(offset: tuple, values: dict, exercises: str) -> EverydayCase:
    return EverydayCase("dome", (("dome", (0.0, 0.0)), ("modifier_box", offset)), {}, exercises, ({}, values))


MODIFIER_CASES = {
    # name: (case, the modifier's density, %)
    "infill-mesh": (_modifier_case((0.0, 0.0), {"infill_mesh": True, "infill_sparse_density": 60},
                                   "an infill mesh over the dome's middle, with the print's 2 walls and skin"), 60.0),
    "infill-mesh-one-wall": (_modifier_case((5.0, 5.0), {"infill_mesh": True, "infill_sparse_density": 40,
                                                         "wall_line_count": 1},
                                            "an infill mesh with a wall of its own, off centre"), 40.0),
    "infill-mesh-no-walls": (_modifier_case((4.0, -3.0), {"infill_mesh": True, "infill_sparse_density": 50,
                                                          "wall_line_count": 0},
                                            "an infill mesh, wall count 0"), 50.0),
    "cutting-mesh": (_modifier_case((0.0, 0.0), {"cutting_mesh": True, "infill_sparse_density": 60,
                                                 "wall_line_count": 1},
                                    "a cutting mesh with a wall, denser"), 60.0),
    "cutting-mesh-two-walls": (_modifier_case((6.0, 0.0), {"cutting_mesh": True, "infill_sparse_density": 10,
                                                           "wall_line_count": 2},
                                              "a cutting mesh with two walls, sparser, over the dome's edge"), 10.0),
}


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("name", sorted(MODIFIER_CASES))
def test_infill_and_cutting_meshes_keep_their_walls_and_density(option_slices, name, version):
    """A modifier box over the dome: its walls and skin, where it has them, stay clear of the dome's new
    infill (before: 1.0-1.2 % of the new infill outside Cura's area, up to 349 mm on skin and the box's
    inside filled twice); the box gets its own density, the dome outside it the print's."""
    case, box_density = MODIFIER_CASES[name]
    sliced = _slice(option_slices, case, version)
    _, _, report, result = _process(sliced, footer=True)
    assert result.ok, result.report()
    assert result.figures["on_wall_mm"] <= 2.0, result.report()
    assert report.layers_processed >= 20, report.format_table()
    regions = {region.name: region for region in report.regions}
    base, box = regions["base"], regions["mesh modifier_box.stl"]
    assert base.target == pytest.approx(DENSITY / 100) and abs(base.measured - base.target) < 0.015, \
        report.format_table()
    # (a cutting mesh's density is not in the footer: its few lines tell it, as Cura prints it: 10 % as 11 %)
    assert abs(box.target - box_density / 100) < 0.02 and abs(box.measured - box.target) < 0.03, \
        report.format_table()
    assert abs(report.filament_after_mm / report.filament_before_mm - 1.0) < 0.03, report.format_table()
