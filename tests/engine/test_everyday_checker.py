"""The everyday checker itself, on hand-written G-code: correct files pass, broken ones fail.

Every check of everyday_check.py is shown to fail on a deliberately broken file
(infill across a hole, infill over skin, an island left empty, half the infill
removed, infill across an infill mesh's walls), so that none of them can pass by construction; and a processed file
with different but correct infill passes, so that none of them merely compares
texts.  Those files are written here, Cura style, without CuraEngine.

The checker's own G-code reader, ``everyday_check.extract_layers``, is shown to
give the same FILL and SKIN segments per layer as ``gcode_check.parse_gcode``
on those files, on real CuraEngine slices of the star (absolute and relative E,
firmware retraction, two stars one at a time) and on the plugin's output; and
to read what parse_gcode does not follow (G91, CR LF, indented lines) right.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass

import numpy as np
import pytest
import shapely
from shapely.geometry import MultiPolygon, Polygon, box

from DelaunayInfill import curaengine, models

from . import everyday_check as ec
from . import gcode_check as gc
from .conftest import split_like_cura

LINE_WIDTH = 0.4
LAYER_HEIGHT = 0.2
WALLS = 0.8  # two walls
SPACING = 2.0  # the synthetic "Cura" infill's line distance
E_PER_MM = 0.0333  # 0.4 x 0.2 mm lines of 1.75 mm filament


# --------------------------------------------------------------------------- Cura-style G-code


def hatch(area, spacing: float, angle_deg: float, phase: float = 0.5) -> np.ndarray:
    """Parallel lines `spacing` mm apart at `angle_deg`, clipped to `area`.

    Returns
    -------
    np.ndarray
        (k, 2, 2) segments, mm, in the order of a back-and-forth sweep.
    """
    if area.is_empty:
        return np.zeros((0, 2, 2))
    cx, cy = area.centroid.x, area.centroid.y
    x0, y0, x1, y1 = area.bounds
    reach = np.hypot(x1 - x0, y1 - y0)
    direction = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))])
    normal = np.array([-direction[1], direction[0]])
    offsets = (np.arange(-reach / 2, reach / 2, spacing) // spacing + phase) * spacing
    starts = np.array([cx, cy]) + offsets[:, None] * normal - reach * direction
    ends = starts + 2 * reach * direction
    clipped = shapely.intersection(shapely.linestrings(np.stack([starts, ends], axis=1)), area)
    segments = []
    for index, part in enumerate(shapely.get_parts(clipped)):
        if part.geom_type != "LineString" or part.length < 1e-6:
            continue
        coords = np.asarray(part.coords)
        segment = np.array([coords[0], coords[-1]])
        segments.append(segment[::-1] if index % 2 else segment)
    return np.array(segments).reshape(-1, 2, 2)


def outline_segments(area) -> np.ndarray:
    """The rings of `area` as (k, 2, 2) segments: a wall path."""
    segments = []
    for polygon in shapely.get_parts(area):
        for ring in [polygon.exterior, *polygon.interiors]:
            coords = np.asarray(ring.coords)
            segments += list(np.stack([coords[:-1], coords[1:]], axis=1))
    return np.array(segments).reshape(-1, 2, 2)


def write_gcode(layers: list[list[tuple[str, np.ndarray]]]) -> str:
    """Cura 4.13 style G-code: header, one ``;LAYER:n`` per entry, absolute E.

    Parameters
    ----------
    layers : list
        Per layer, a list of (feature type, (k, 2, 2) segments) in print order.
    """
    lines = [";FLAVOR:Marlin", ";TIME:1000", ";Filament used: 1m", ";Layer height: 0.2",
             ";Generated with Cura_SteamEngine 4.13.0", "M82 ;absolute extrusion mode", "G92 E0",
             f";LAYER_COUNT:{len(layers)}"]
    e = 0.0
    at = None
    elapsed = 0.0
    for number, features in enumerate(layers):
        z = LAYER_HEIGHT * (number + 1)
        lines += [f";LAYER:{number}", f"G0 F6000 Z{z:.1f}"]
        for kind, segments in features:
            lines.append(f";TYPE:{kind}")
            for start, end in segments:
                if at is None or np.hypot(*(start - at)) > 1e-6:
                    lines.append(f"G0 F6000 X{start[0]:.3f} Y{start[1]:.3f}")
                e += E_PER_MM * float(np.hypot(*(end - start)))
                lines.append(f"G1 F1500 X{end[0]:.3f} Y{end[1]:.3f} E{e:.5f}")
                at = end
        elapsed += 10.0
        lines.append(f";TIME_ELAPSED:{elapsed:.6f}")
    lines += ["M140 S0", "M84", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- synthetic models


@dataclass
class Model:
    """A synthetic part: its section, infill area and skin area per layer (G-code XY, mm)."""

    section: object  # shapely (Multi)Polygon, the same at every height
    infill: object  # where Cura's sparse infill goes
    skin: object  # where Cura prints skin in the same layers
    layers: int = 10

    def section_at(self, z: float):
        return self.section if 0 < z < LAYER_HEIGHT * self.layers else Polygon()

    def angle(self, number: int) -> float:
        return 45.0 if number % 2 == 0 else 135.0

    def files(self, fill_of=None) -> tuple[str, str, str]:
        """(original, processed, reference) texts; `fill_of(number, cura_fill) -> new fill` makes the processed."""
        original, processed, reference = [], [], []
        walls = outline_segments(self.section.buffer(-LINE_WIDTH / 2, join_style=2))
        for number in range(self.layers):
            cura_fill = hatch(self.infill, SPACING, self.angle(number))
            dense = hatch(self.infill, LINE_WIDTH, 0.0 if number % 2 == 0 else 90.0)
            skin = hatch(self.skin, LINE_WIDTH, self.angle(number))
            common = [("WALL-OUTER", walls)] + ([("SKIN", skin)] if len(skin) else [])
            new_fill = cura_fill if fill_of is None else fill_of(number, cura_fill)
            original.append(common + [("FILL", cura_fill)])
            processed.append(common + [("FILL", new_fill)])
            reference.append(common + [("FILL", dense)])
        return write_gcode(original), write_gcode(processed), write_gcode(reference)

    def check(self, fill_of=None) -> ec.EverydayResult:
        original, processed, reference = self.files(fill_of)
        return ec.check_everyday(original, processed, reference, self.section_at, SPACING, LINE_WIDTH)


def ring(size: float = 20.0, hole: float = 6.0, layers: int = 10) -> Model:
    """A square ring centred on (110, 110): a square with a square hole."""
    section = box(110 - size / 2, 110 - size / 2, 110 + size / 2, 110 + size / 2).difference(
        box(110 - hole / 2, 110 - hole / 2, 110 + hole / 2, 110 + hole / 2))
    return Model(section, section.buffer(-WALLS, join_style=2), Polygon(), layers)


def skin_beside_infill() -> Model:
    """A 20 mm square whose left half is skin (the top of a lower step) and right half infill."""
    section = box(100, 100, 120, 120)
    inner = section.buffer(-WALLS, join_style=2)
    return Model(section, inner.intersection(box(110, 0, 200, 200)), inner.intersection(box(0, 0, 110, 200)))


def two_pillars() -> Model:
    """Two 8 mm square pillars 4 mm apart."""
    section = MultiPolygon([box(100, 100, 108, 108), box(112, 100, 120, 108)])
    return Model(section, section.buffer(-WALLS, join_style=2), Polygon())


# --------------------------------------------------------------------------- the tests


def test_identical_processed_file_passes():
    for model in (ring(), skin_beside_infill(), two_pillars()):
        result = model.check()
        assert result.ok, result.report()
        assert result.figures["outside_mm"] == 0 and result.figures["material_mm"] == 0
        assert result.figures["coverage"] == 1.0 and result.figures["on_skin_mm"] == 0
        assert result.figures["islands"] == (2 * model.layers if model.section.geom_type == "MultiPolygon"
                                             else model.layers)


def test_different_but_correct_infill_passes():
    """Lines in other directions and phases, inside the infill area: the checker does not compare texts."""
    model = ring()
    result = model.check(lambda number, fill: hatch(model.infill, SPACING, 20.0 + 37 * number, phase=0.3))
    assert result.ok, result.report()
    assert result.figures["coverage"] >= ec.MIN_COVERAGE


def test_infill_across_the_hole_fails_the_material_check():
    model = ring()
    outer = box(100, 100, 120, 120).buffer(-WALLS, join_style=2)  # the ring's area with the hole filled
    result = model.check(lambda number, fill: hatch(outer, SPACING, model.angle(number)))
    assert not result.ok
    material = [p for p in result.problems if p.startswith("material")]
    assert material, result.report()
    assert any("layer 3 " in p for p in material)
    # the hole is 6 mm wide, grown by half a line width on each side: ~5.6 mm per crossing line
    assert result.figures["material_mm"] > 10 * model.layers
    assert result.figures["worst_material_layer"][1] >= ec.MAX_MATERIAL_MM_LAYER
    assert result.figures["on_skin_mm"] == 0


def test_infill_in_mid_air_fails_the_material_check():
    model = ring()
    shifted = np.array([[[0.0, 30.0]]])  # one layer's infill moved 30 mm off the part
    result = model.check(lambda number, fill: fill + shifted if number == 6 else fill)
    assert any(p.startswith("material: layer 6 ") for p in result.problems), result.report()
    assert any(p.startswith("containment: layer 6 ") for p in result.problems), result.report()


def test_infill_over_skin_fails_containment_and_reports_on_skin():
    model = skin_beside_infill()
    whole = model.section.buffer(-WALLS, join_style=2)
    result = model.check(lambda number, fill: hatch(whole, SPACING, model.angle(number)))
    assert not result.ok
    assert any(p.startswith("containment") for p in result.problems), result.report()
    # about half of the new infill lies over the skin half
    assert result.figures["on_skin_mm"] > 0.3 * result.figures["new_fill_mm"]
    assert result.figures["on_skin_mm"] <= result.figures["outside_mm"] + 1e-6
    # there is material under the skin: the material check has nothing to say
    assert result.figures["material_mm"] == 0
    assert not any(p.startswith("material") for p in result.problems)


def test_cura_s_own_lines_kept_are_not_counted_outside_but_a_new_line_there_is():
    """A line Cura itself printed in that layer (Cura's single lines of combined infill, which the dense
    reference slice need not print in the same places) is where Cura prints; the same line moved is not."""
    model = ring()
    walls = outline_segments(model.section.buffer(-LINE_WIDTH / 2, join_style=2))
    # a Cura FILL line in the walls' zone of layer 5: inside the part, outside the reference's infill area
    extra = np.array([[[100.1, 102.0], [100.1, 118.0]]])

    def files(new_extra):
        original, processed, reference = [], [], []
        for number in range(model.layers):
            cura_fill = hatch(model.infill, SPACING, model.angle(number))
            dense = hatch(model.infill, LINE_WIDTH, 0.0 if number % 2 == 0 else 90.0)
            own = np.concatenate([cura_fill, extra]) if number == 5 else cura_fill
            new = np.concatenate([cura_fill, new_extra]) if number == 5 else cura_fill
            original.append([("WALL-OUTER", walls), ("FILL", own)])
            processed.append([("WALL-OUTER", walls), ("FILL", new)])
            reference.append([("WALL-OUTER", walls), ("FILL", dense)])
        return write_gcode(original), write_gcode(processed), write_gcode(reference)

    kept = ec.check_everyday(*files(extra[:, ::-1]), model.section_at, SPACING, LINE_WIDTH)  # (either way round)
    assert kept.figures["outside_mm"] == 0, kept.report()
    moved = ec.check_everyday(*files(extra + np.array([0.1, 0.0])), model.section_at, SPACING, LINE_WIDTH)
    assert moved.figures["outside_mm"] > 10.0, moved.report()


def test_an_island_without_infill_fails_the_island_check():
    model = two_pillars()
    right_pillar = box(110, 0, 200, 200)

    def drop_right_pillar_on_layer_5(number, fill):
        if number != 5:
            return fill
        middle = fill.mean(axis=1)
        return fill[~shapely.contains_xy(right_pillar, middle[:, 0], middle[:, 1])]

    result = model.check(drop_right_pillar_on_layer_5)
    assert not result.ok
    assert result.figures["lost_islands"] == 1, result.report()
    lost = result.lost_islands[0]
    assert lost.layer == "5" and abs(lost.centroid[0] - 116) < 0.5 and abs(lost.centroid[1] - 104) < 0.5
    assert 30 < lost.area < 60 and lost.new_mm == 0
    assert any(p.startswith("islands: layer 5:") for p in result.problems)


def test_an_island_of_cura_stubs_only_has_nothing_to_lose():
    """Cura's FILL runs shorter than a line width (stubs in a sliver between walls and skin) print as
    blobs: they do not make an island count; a run of short segments a line width long does."""
    joined = np.array([[[0.0, 0.0], [0.2, 0.0]], [[0.2, 0.0], [0.4, 0.0]], [[0.4, 0.0], [0.6, 0.0]]])
    stubs = np.array([[[5.0, 5.0], [5.16, 5.16]], [[6.0, 5.0], [5.84, 5.16]]])
    line = np.array([[[0.0, 3.0], [1.0, 3.0]]])
    kept = ec._without_stubs(np.concatenate([joined, stubs, line]), LINE_WIDTH)
    assert kept.tolist() == np.concatenate([joined, line]).tolist()
    assert len(ec._without_stubs(stubs, LINE_WIDTH)) == 0


def test_coverage_drops_when_half_the_infill_is_removed():
    model = ring()
    full = model.check()
    half = model.check(lambda number, fill: fill[fill.mean(axis=1)[:, 0] > 110])
    assert full.figures["coverage"] == 1.0
    assert half.figures["coverage"] < 0.7, half.report()
    assert any(p.startswith("coverage") for p in half.problems)
    # the removed half is a place without infill, not infill in a wrong place
    assert half.figures["outside_mm"] == 0 and half.figures["material_mm"] == 0


def _nested_mesh_files(host_fill_of) -> tuple[str, str, str]:
    """A 24 mm square with an 8 mm infill mesh inside it that has walls of its own (Cura's infill_mesh).

    Cura's host infill stops at the inner mesh's outer wall; `host_fill_of(number, host_area, inner_part)`
    gives the processed file's host infill.
    """
    section = box(98, 98, 122, 122)
    inner = box(104, 104, 112, 112)
    host_area = section.buffer(-WALLS, join_style=2)
    walls = outline_segments(section.buffer(-LINE_WIDTH / 2, join_style=2))
    inner_walls = [("WALL-OUTER", outline_segments(inner.buffer(-LINE_WIDTH / 2, join_style=2))),
                   ("WALL-INNER", outline_segments(inner.buffer(-1.5 * LINE_WIDTH, join_style=2)))]
    inner_area = inner.buffer(-WALLS, join_style=2)
    original, processed, reference = [], [], []
    for number in range(6):
        angle = 45.0 if number % 2 == 0 else 135.0
        host = hatch(host_area.difference(inner), SPACING, angle)
        dense = [hatch(host_area.difference(inner), LINE_WIDTH, 0.0), hatch(inner_area, LINE_WIDTH, 0.0)]
        inner_fill = hatch(inner_area, 1.0, angle)
        common = [("WALL-OUTER", walls)]
        original.append(common + [("FILL", host)] + inner_walls + [("FILL", inner_fill)])
        processed.append(common + [("FILL", host_fill_of(number, host_area, inner))] + inner_walls
                         + [("FILL", inner_fill)])
        reference.append(common + [("FILL", dense[0])] + inner_walls + [("FILL", dense[1])])
    return write_gcode(original), write_gcode(processed), write_gcode(reference)


def _check_nested(host_fill_of) -> ec.EverydayResult:
    section = box(98, 98, 122, 122)
    files = _nested_mesh_files(host_fill_of)
    return ec.check_everyday(*files, lambda z: section if 0 < z < 6 * LAYER_HEIGHT else Polygon(), SPACING, LINE_WIDTH)


def test_host_infill_across_an_infill_mesh_with_walls_fails_the_walls_check():
    """The infill mesh's region is inside the reference area (its own dense lines): containment sees
    only the gap its walls leave there; check 6 sees the host's infill printed across them."""
    good = _check_nested(lambda number, area, inner: hatch(area.difference(inner), SPACING, 20.0 + 30 * number))
    assert good.ok, good.report()
    assert good.figures["on_wall_mm"] <= 0.5 * good.figures["layers_checked"]
    bad = _check_nested(lambda number, area, inner: hatch(area, SPACING, 45.0 if number % 2 == 0 else 135.0))
    assert not bad.ok
    walls = [p for p in bad.problems if p.startswith("walls")]
    assert len(walls) == 6, bad.report()
    # (containment sees only the walls' gap in the reference area: less than the walls check)
    assert bad.figures["outside_mm"] < bad.figures["on_wall_mm"], bad.report()
    # about 8 host lines cross the inner mesh's two walls twice each, diagonally
    assert bad.figures["on_wall_mm"] > 6 * 8 * 2 * 0.2


def test_small_deviations_are_tolerated():
    """Infill shifted by a quarter line width stays within the allowances."""
    model = ring()
    result = model.check(lambda number, fill: hatch(model.infill.buffer(-0.1), SPACING, model.angle(number)) + 0.1)
    assert result.ok, result.report()


def test_report_and_layer_table_show_layer_numbers():
    model = ring()
    result = model.check(lambda number, fill: fill + np.array([[[0.0, 30.0]]]) if number == 4 else fill)
    report = result.report()
    assert "FAILED" in report and "layer 4 " in report
    table = ec.layer_table(result, count=3)
    lines = table.splitlines()
    assert lines[0].split()[:3] == ["layer", "z", "mm"] and len(lines) == 2 + 3
    assert lines[2].split()[0] == "4"  # the worst layer comes first


def _skin_lines(text: str) -> set[int]:
    """The line numbers (1-based, as parse_gcode counts them) inside a ``;TYPE:SKIN`` block, line by line."""
    inside, out = False, set()
    for number, line in enumerate(text.split("\n"), 1):
        line = line.strip()
        if line.startswith(";TYPE:"):
            inside = line[len(";TYPE:"):] in ec.SKIN_TYPES
        elif line.startswith((";LAYER:", ";MESH:NONMESH", ";TIME_ELAPSED:")):
            inside = False
        elif inside:
            out.add(number)
    return out


def layers_by_parse_gcode(text: str) -> dict[tuple[int, int], ec.LayerMoves]:
    """What ``extract_layers`` must give, from gcode_check.parse_gcode (slow, line by line)."""
    parsed = gc.parse_gcode(text)
    moves = parsed.moves
    travel = np.hypot(moves[:, gc.C_X1] - moves[:, gc.C_X0], moves[:, gc.C_Y1] - moves[:, gc.C_Y0])
    extruding = (moves[:, gc.C_DE] > 1e-9) & (travel > 1e-9)
    skin_lines = _skin_lines(text)
    in_skin = np.array([int(number) in skin_lines for number in moves[:, gc.C_LINE]], dtype=bool)
    segments = moves[:, [gc.C_X0, gc.C_Y0, gc.C_X1, gc.C_Y1]].reshape(-1, 2, 2)
    seen: dict[int, int] = {}
    out = {}
    for seq, layer in enumerate(parsed.layers):
        number = layer["number"] if layer["number"] is not None else -10_000 - seq
        occurrence = seen.get(number, 0)
        seen[number] = occurrence + 1
        here = extruding & (moves[:, gc.C_LAYER] == seq)
        out[(number, occurrence)] = ec.LayerMoves(
            z=float(layer["z"]),
            fill=segments[here & (moves[:, gc.C_FILL] == 1)],
            skin=segments[here & (moves[:, gc.C_FILL] == 0) & in_skin])
    return out


def assert_same_layers(text: str) -> dict[tuple[int, int], ec.LayerMoves]:
    """extract_layers(text) equals layers_by_parse_gcode(text), bit for bit; returns it."""
    got, expected = ec.extract_layers(text), layers_by_parse_gcode(text)
    assert list(got) == list(expected)
    for key, want in expected.items():
        layer = got[key]
        assert layer.fill.shape == want.fill.shape and np.array_equal(layer.fill, want.fill), f"FILL of layer {key}"
        assert layer.skin.shape == want.skin.shape and np.array_equal(layer.skin, want.skin), f"SKIN of layer {key}"
        assert layer.z == want.z or (math.isnan(layer.z) and math.isnan(want.z)), f"z of layer {key}"
    return got


def test_the_reader_matches_parse_gcode_on_the_synthetic_files():
    model = skin_beside_infill()
    texts = [*ring().files(), *model.files(), *two_pillars().files(lambda number, fill: fill[::2])]
    for text in texts:
        layers = assert_same_layers(text)
        assert len(layers) == 10 and all(len(layer.fill) for layer in layers.values())
    assert all(len(layer.skin) for layer in ec.extract_layers(model.files()[0]).values())


STAR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                    "DelaunayInfill", "data", "star.stl")

#: the real slices of the star: name -> (user settings, two stars one at a time)
STAR_SLICES = {
    "absolute_e": ({}, False),
    "relative_e": ({"relative_extrusion": True}, False),
    "firmware_retraction": ({"machine_firmware_retract": True}, False),
    "one_at_a_time": ({"print_sequence": "one_at_a_time"}, True),
}


@pytest.fixture(scope="module")
def star_slices(engine_info, tmp_path_factory) -> dict[str, str]:
    """Name -> G-code text of the star sliced by CuraEngine with each of :data:`STAR_SLICES`."""
    folder = tmp_path_factory.mktemp("reader")
    star = models.read_stl(STAR)
    models.write_stl(folder / "left.stl", star + np.array([-30.0, 0.0, 0.0]), name="left.stl")
    models.write_stl(folder / "right.stl", star + np.array([30.0, 0.0, 0.0]), name="right.stl")
    shutil.copyfile(STAR, folder / "star.stl")
    texts = {}
    for name, (settings, two) in STAR_SLICES.items():
        meshes = [("left.stl", {}), ("right.stl", {})] if two else [("star.stl", {})]
        result = curaengine.slice_models(meshes, settings, folder / f"{name}.gcode", cwd=folder)
        with open(result.path, encoding="utf-8") as f:
            texts[name] = f.read()
    return texts


@pytest.mark.parametrize("name", sorted(STAR_SLICES))
def test_the_reader_matches_parse_gcode_on_real_slices(star_slices, name):
    text = star_slices[name]
    # the slice is what it is meant to be
    assert ("M83 ;relative extrusion mode" in text) == (name == "relative_e")
    assert ("\nG10\n" in text and "\nG11\n" in text) == (name == "firmware_retraction")
    layers = assert_same_layers(text)
    assert len(layers) == (100 if name == "one_at_a_time" else 50)
    if name == "one_at_a_time":
        assert {occurrence for _, occurrence in layers} == {0, 1}
    assert sum(len(layer.fill) for layer in layers.values()) > 1000
    assert sum(len(layer.skin) for layer in layers.values()) > 1000
    assert [round(layers[(n, 0)].z, 3) for n in (0, 1, 49)] == [0.2, 0.4, 10.0]


def test_the_reader_matches_parse_gcode_on_the_plugins_output(star_slices):
    from DelaunayInfill import process_gcode

    original = star_slices["absolute_e"]
    chunks, _report = process_gcode(split_like_cura(original))
    processed = "".join(chunks)
    assert processed != original
    layers = assert_same_layers(processed)
    before = ec.extract_layers(original)
    changed = [key for key in layers if not np.array_equal(layers[key].fill, before[key].fill)]
    assert len(changed) > 10  # the plugin rewrote the infill
    assert all(np.array_equal(layers[key].skin, before[key].skin) for key in layers)


HANDWRITTEN = """;FLAVOR:Marlin
;Generated with Cura_SteamEngine 4.13.0
M82
G92 E0
;LAYER:0
G0 F9000 X10 Y10 Z0.2
;TYPE:FILL
G1 X20 Y10 E1 F1200
G1 E2 X20.5 Y20
G1 F1800 E1.5
G0 X30 Y30
G1 E2
G1 X40 Y30 E1.9
G1 X40 Y40 E3 ; X99 Y99 E99
G1 X+40.5 Y.5 E4
;MESH:other.stl
G1 X-1.25 Y0 E5
;TYPE:SKIN
G0 X5 Y5
G10
G11
G1 X6 Y5 E6
G92 E0
G1 X7 Y5 E1
M83
G1 X8 Y5 E0.5
G1 X9 Y5 E0
G1 X10 Y5 E-1
G1 X11 Y5 E0.5
;TIME_ELAPSED:1.0
;LAYER:1
M82
G92 E0
G0 X0 Y0 Z0.4
;TYPE:FILL
G01 X1 Y0 E1
G1 X2 Y0 E2
G10.5 X3 Y0 E3
;TYPE:WALL-OUTER
G1 X4 Y0 E4
;TYPE:FILL
T1
G1 X5 Y0 E5
;TIME_ELAPSED:2.0
T0
;LAYER:0
G0 X4 Y0 Z0.2
;TYPE:FILL
G1 X5 Y0 E6
;TIME_ELAPSED:3.0
G91
G1 X5 Y5 E1
G90
G1 X10 Y5
"""


def test_the_reader_follows_cura_syntax():
    layers = ec.extract_layers(HANDWRITTEN)
    assert list(layers) == [(0, 0), (1, 0), (0, 1)]
    first = layers[(0, 0)]
    assert first.z == 0.2
    np.testing.assert_array_equal(first.fill, [
        [[10, 10], [20, 10]],  # F after E
        [[20, 10], [20.5, 20]],  # E before X and Y
        # (a retraction, a travel and an unretraction at (30, 30): not extrusion)
        # (X40 Y30 E0.5: E does not increase after the unretraction to 0.5)
        [[40, 30], [40, 40]],  # the comment's words do not count
        [[40, 40], [40.5, 0.5]],  # "+40.5" and ".5" read as numbers
        [[40.5, 0.5], [-1.25, 0]],  # a ;MESH: inside FILL stays FILL
    ])
    np.testing.assert_array_equal(first.skin, [
        [[5, 5], [6, 5]],  # after G10 / G11 (firmware retraction: no E)
        [[6, 5], [7, 5]],  # after G92 E0
        [[7, 5], [8, 5]],  # relative E
        [[10, 5], [11, 5]],  # relative E0 and E-1 do not extrude
    ])
    second = layers[(1, 0)]
    assert second.z == 0.4 and len(second.skin) == 0
    # G01 and G0 are moves, G10.5 is not; a ;TYPE: other than FILL, and a tool change, end FILL
    np.testing.assert_array_equal(second.fill, [[[0, 0], [1, 0]], [[1, 0], [2, 0]]])
    # the layer number again: its second occurrence; after ;TIME_ELAPSED: nothing is FILL, and the
    # end G-code's G91 moves are relative (X5 Y5 from (5, 0) ends at (10, 5), then absolute again)
    again = layers[(0, 1)]
    np.testing.assert_array_equal(again.fill, [[[4, 0], [5, 0]]])
    assert again.z == 0.2


def test_the_reader_follows_g91_relative_positioning():
    text = "G28\n;LAYER:0\nG0 X10 Y10 Z0.2\n;TYPE:FILL\nG91\nG1 X5 E1\nG1 Y5 E1\nG90\nM83\nG1 X20 Y20 E1\n" \
           "G1 X30 E-1\nM82\nG1 X40 E5\n"
    np.testing.assert_array_equal(ec.extract_layers(text)[(0, 0)].fill, [
        [[10, 10], [15, 10]], [[15, 10], [15, 15]],  # relative X, Y and E
        [[15, 15], [20, 20]],  # absolute XY, relative E (M83 after G90)
        # (relative E-1: a retraction; then absolute E5 from a register of 1 + 1 + 1 - 1 = 2)
        [[30, 20], [40, 20]],
    ])


def test_the_reader_takes_crlf_and_indented_lines():
    text = ";LAYER:0\n  G0 X0 Y0 Z0.2\n\t;TYPE:FILL\n G1 X1 Y0 E1\n"
    expected = [[[0, 0], [1, 0]]]
    np.testing.assert_array_equal(ec.extract_layers(text)[(0, 0)].fill, expected)
    np.testing.assert_array_equal(ec.extract_layers(text.replace("\n", "\r\n"))[(0, 0)].fill, expected)
    assert ec.extract_layers("") == {}


def test_the_reader_reads_numbers_exactly():
    rng = np.random.default_rng(7)
    values = [round(float(v), int(d)) for v, d in zip(rng.uniform(-300, 300, 2000), rng.integers(0, 6, 2000))]
    values += [0.0, -0.0, 1e-5, 1999.99999]
    words = [f"{v:.6f}".rstrip("0") for v in values] + ["12345678901.5", "7", "-.25", "+3."]
    text = ";LAYER:0\nG0 X0 Y0 Z0.2\n;TYPE:FILL\n" + "".join(
        f"G1 X{word} Y{index} E{index + 1}\n" for index, word in enumerate(words))
    fill = ec.extract_layers(text)[(0, 0)].fill
    assert np.array_equal(fill[:, 1, 0], [float(word) for word in words])


def test_a_piece_of_one_of_cura_s_lines_is_cura_s_and_nothing_beside_or_beyond_it_is():
    """The pass keeps the stretch of a Cura line its new infill does not take over: that piece is where
    Cura prints (random shape 46 on CuraEngine 5.0: a kept piece along a wall, beside skin, outside the
    dense reference's lines, counted 4.2 % of a layer outside); a line 0.05 mm beside it, or reaching
    0.1 mm past its end, is not."""
    cura = np.array([[[100.0, 100.0], [110.0, 105.0]], [[100.0, 110.0], [100.0, 120.0]]])
    on_first = np.array([[100.0, 100.0], [110.0, 105.0]])[0] + np.outer([0.2, 0.7], [10.0, 5.0])
    pieces = np.array([
        on_first,                                      # a piece of the first
        on_first[::-1],                                # the same, the other way round
        on_first + [0.0, 0.05],                        # 0.05 mm beside it
        [[100.0, 112.0], [100.0, 120.1]],              # past the second's end
        [[100.0, 112.0], [100.0, 119.0]],              # a piece of the second
    ])
    assert ec._on_cura_segments(pieces, cura, np.ones(len(pieces), dtype=bool)).tolist() == [True, True, False, False, True]
    assert not ec._on_cura_segments(pieces, cura, np.zeros(len(pieces), dtype=bool)).any()  # only the flagged
