"""Never print where Cura would not: the area rebuilt from walls and skin, and Cura's lines as its witness.

* `wall_rings` joins a wall loop Cura printed in pieces (a hole is found even so);
* `skin_region` is the skin's lines and the space between them;
* `witnessed` keeps only the pieces of an area that hold Cura lines, within reach of them;
* `kept_cura_pieces` keeps Cura's lines where the new infill does not take over;
* `isolated_cura_lines` finds a dense modifier's lines cut off from the rest of its zone, far from new lines;
* end to end on synthetic Cura layers: no new infill in a hole whose wall came in three pieces, none
  on skin inside the infill, a small island keeps infill, a zero-length E move is never written;
* the ``;SETTING_3`` footer: Cura's density is read from it, lightning keeps Cura's infill.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from shapely.geometry import LineString, MultiLineString, Point, Polygon, box

from DelaunayInfill.gcode import ProcessSettings, Region, process_gcode
from DelaunayInfill.gcode.area import skin_region, wall_rings
from DelaunayInfill.gcode.footer import read_footer
from DelaunayInfill.gcode.infer import _quantile
from DelaunayInfill.gcode.read import as_cura_list
from DelaunayInfill.gcode.witness import (
    _all_near,
    _near,
    isolated_cura_lines,
    kd_tree,
    kept_cura_pieces,
    new_line_places,
    segment_polylines,
    witnessed,
)

LW = 0.4
E_PER_MM = 0.0333


# ----------------------------------------------------------------------------- synthetic Cura G-code
def _circle(cx, cy, r, n=48):
    t = np.linspace(0, 2 * np.pi, n + 1)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def _grid_lines(region, spacing: float, angle_deg: float) -> list[np.ndarray]:
    """Cura-like parallel lines of one family clipped to `region` (ends pulled in by a line width / 2)."""
    minx, miny, maxx, maxy = region.bounds
    c = np.array([(minx + maxx) / 2, (miny + maxy) / 2])
    half = math.hypot(maxx - minx, maxy - miny)
    a = math.radians(angle_deg)
    u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    inner = region.buffer(-LW / 2, join_style=2)
    out = []
    for k in np.arange(-half, half, spacing):
        line = LineString([c + v * k - u * half, c + v * k + u * half]).intersection(inner)
        for piece in getattr(line, "geoms", [line]):
            if not piece.is_empty and piece.length > LW:
                out.append(np.asarray(piece.coords))
    return out


def _gcode(layers: list[list[tuple[str, np.ndarray]]], footer: str = "") -> str:
    """Cura-style G-code: per layer, (type, polyline) features printed in order, travels between them."""
    out = [";FLAVOR:Marlin", ";TIME:100", ";Filament used: 1m", ";Layer height: 0.2",
           ";Generated with Cura_SteamEngine 4.13.0", "M82 ;absolute extrusion mode", "G92 E0", "G1 F1500 E-5",
           f";LAYER_COUNT:{len(layers)}"]
    e, depth = -5.0, 5.0
    t = 0.0
    for n, features in enumerate(layers):
        z = 0.2 * (n + 1)
        out += [f";LAYER:{n}", f"G0 F9000 Z{z:.1f}", ";MESH:part.stl"]
        current = None
        for kind, line in features:
            if kind != current:
                out.append(f";TYPE:{kind}")
                current = kind
            out.append(f"G0 F9000 X{line[0, 0]:.3f} Y{line[0, 1]:.3f}")
            if depth:
                e += depth
                depth = 0.0
                out.append(f"G1 F1500 E{e:.5f}")
            for p, q in zip(line[:-1], line[1:], strict=True):
                e += E_PER_MM * float(np.hypot(*(q - p)))
                out.append(f"G1 F1200 X{q[0]:.3f} Y{q[1]:.3f} E{e:.5f}")
        t += 10.0
        out.append(f";TIME_ELAPSED:{t:.6f}")
    out += [f"G1 F1500 E{e - 5:.5f}", "M107", ";End of Gcode"]
    return "\n".join(out) + "\n" + footer


def _fill_segments(text: str) -> dict[int, np.ndarray]:
    """Extruding FILL segments per layer, parsed on their own (absolute E), shape (k, 2, 2)."""
    layer, kind, x, y, e = None, None, math.nan, math.nan, 0.0
    out: dict[int, list] = {}
    for line in text.splitlines():
        if line.startswith(";LAYER:"):
            layer = int(line[7:])
        elif line.startswith(";TYPE:"):
            kind = line[6:]
        elif line.startswith("G92"):
            m = re.search(r"E(-?[\d.]+)", line)
            e = float(m.group(1)) if m else e
        elif line.startswith(("G0", "G1")):
            words = dict((w[0], float(w[1:])) for w in line.split(";")[0].split()[1:])
            nx, ny, ne = words.get("X", x), words.get("Y", y), words.get("E", e)
            if kind == "FILL" and layer is not None and ne > e + 1e-9 and (nx, ny) != (x, y):
                out.setdefault(layer, []).append(((x, y), (nx, ny)))
            x, y, e = nx, ny, ne
    return {k: np.array(v, dtype=float) for k, v in out.items()}


def _length_inside(segments: np.ndarray, area) -> float:
    lines = MultiLineString([s.tolist() for s in segments])
    return lines.intersection(area).length


def _ring_layer(pieces: int):
    """A 40 mm square with a 14 mm round hole; the hole's outer wall in `pieces` pieces; grid FILL between."""
    outer = box(80, 80, 120, 120)
    hole = Point(100, 100).buffer(7, 32)
    ring = outer.difference(hole)
    walls = ring.buffer(-LW / 2, join_style=2)
    features = [("WALL-OUTER", np.asarray(walls.exterior.coords))]
    circle = np.asarray(walls.interiors[0].coords)
    cuts = np.linspace(0, len(circle) - 1, pieces + 1).astype(int)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        features.append(("WALL-OUTER", circle[a:b + 1]))
    inner = ring.buffer(-1.5 * LW, join_style=2)
    features.append(("WALL-INNER", np.asarray(inner.exterior.coords)))
    features += [("WALL-INNER", np.asarray(r.coords)) for r in inner.interiors]
    fill_area = ring.buffer(-2 * LW + 0.04, join_style=2)
    for angle in (45, 135):
        features += [("FILL", line) for line in _grid_lines(fill_area, 4.0, angle)]
    return features, hole


# ----------------------------------------------------------------------------- pieces
def test_wall_rings_joins_a_loop_printed_in_pieces():
    circle = _circle(0, 0, 5)
    pieces = [circle[0:17], circle[16:33][::-1], circle[32:49]]  # one piece printed backwards
    rings = wall_rings(pieces, 0.8)
    assert len(rings) == 1
    assert abs(Polygon(rings[0]).area - Polygon(circle).area) < 0.05 * Polygon(circle).area
    # a gap wider than the tolerance closes no loop
    assert wall_rings([circle[0:20], circle[24:49]], 0.4) == []


def test_skin_region_is_the_lines_and_the_space_between_them():
    lines = [np.array([[0.0, y], [10.0, y]]) for y in np.arange(0.0, 10.01, 0.6)]  # 0.6 mm apart
    region = skin_region(lines, LW)
    assert region.contains(box(0.5, 0.5, 9.5, 9.5))
    apart = [np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[0.0, 3.0], [10.0, 3.0]])]
    assert not skin_region(apart, LW).contains(Point(5, 1.5))  # lines 3 mm apart are not one skin


def test_witnessed_keeps_only_what_cura_lines_confirm():
    part = box(0, 0, 40, 40)
    island = box(50, 0, 54, 4)
    area = part.union(island)
    runs = [np.array([[1.0, y], [39.0, y]]) for y in np.arange(1.0, 20.0, 4.0)]  # only the lower half
    out = witnessed(area, runs, LW, 4.0)
    assert out.intersection(island).area == 0.0  # no Cura line in it
    assert out.intersection(box(0, 30, 40, 40)).area == 0.0  # farther than 4 mm from every line
    assert out.intersection(box(2, 2, 38, 18)).area > 0.99 * 36 * 16


def test_witnessed_takes_segments_as_well_as_runs():
    area = box(0, 0, 40, 40)
    runs = [np.array([[1.0, y], [20.0, y], [39.0, y + 0.5]]) for y in np.arange(1.0, 20.0, 4.0)]
    segments = np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in runs])
    assert witnessed(area, segments, LW, 4.0).equals(witnessed(area, runs, LW, 4.0))
    assert [r.tolist() for r in segment_polylines(segments)] == [r.tolist() for r in runs]


def test_grouped_reach_queries_answer_as_one_query_per_point():
    """`_all_near` and `_near` answer groups of points at once: the same answers as querying each point."""
    rng = np.random.default_rng(3)
    lines = np.concatenate([np.c_[np.linspace(0, 30, 80), np.full(80, y)] for y in (2.0, 9.0, 17.0, 29.0)])
    tree = kd_tree(lines)
    for limit in (1.0, 3.0, 6.0, 9.0):
        points = rng.uniform(-2, 32, (500, 2))
        group = np.arange(len(points)) // 7
        exact = bool((tree.query(points)[0] <= limit).all())
        assert _all_near(tree, points, group, limit) == exact
        near_ones = points[tree.query(points)[0] <= limit]
        assert _all_near(tree, near_ones, np.arange(len(near_ones)) // 5, limit)
    # Cura's segments stepped at half a line width, as kept_cura_pieces asks
    cura = np.array([[[0.0, 5.0], [30.0, 5.0]], [[0.0, 25.0], [30.0, 25.0]], [[5.0, -10.0], [5.0, 40.0]]])
    d = cura[:, 1] - cura[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.ceil(length / (LW / 2)).astype(np.int64)
    seg = np.repeat(np.arange(len(cura)), n)
    k = np.arange(seg.size) - (np.cumsum(n) - n)[seg]
    mid = cura[seg, 0] + d[seg] * ((k + 0.5) / n[seg])[:, None]
    rows = np.flatnonzero(rng.uniform(size=len(mid)) < 0.9)
    for reach in (0.5, 2.0, 5.0):
        expected = tree.query(mid[rows])[0] <= reach
        assert (_near(tree, mid, rows, reach, (seg, k, length / n)) == expected).all()


def test_quantile_is_numpy_s():
    rng = np.random.default_rng(4)
    for size in (1, 2, 3, 10, 57):
        values = rng.uniform(0, 5, size)
        for q in (0.0, 0.1, 0.5, 0.9, 1.0):
            assert _quantile(values, q) == float(np.quantile(values, q))


def test_kept_cura_pieces_where_no_new_line_takes_over():
    area = box(0, 0, 20, 20)
    cura = np.array([[[1.0, 1.0], [19.0, 1.0]], [[1.0, 10.0], [19.0, 10.0]], [[30.0, 5.0], [35.0, 5.0]]])
    new = [np.array([[1.0, 11.0], [19.0, 11.0]])]
    kept = kept_cura_pieces(cura, area, new, LW, reach=3.0)
    kept_lines = MultiLineString([k.tolist() for k in kept])
    assert abs(kept_lines.intersection(box(0, 0.5, 20, 1.5)).length - 18.0) < 0.5  # no new line near
    assert kept_lines.intersection(box(0, 9, 20, 10.5)).length < 0.5  # taken over by the new line
    assert abs(kept_lines.intersection(box(29, 4, 36, 6)).length - 5.0) < 0.5  # outside the area
    # a 0 % region needs no infill
    assert kept_cura_pieces(cura[:1], area, [], LW, 3.0, no_infill=box(0, 0, 20, 5)) == []


def test_a_dense_modifier_s_lines_cut_off_from_its_zone_and_far_from_new_lines_are_isolated():
    """Random regions 75: a 60 % modifier's corner beyond a skin band (two short Cura lines, 0.9 mm) with the
    nearest new line 2.3 mm away; the host's sparse reach took that for covered."""
    spacing = LW / 0.6
    zone = [[[x, 0.0], [x, 10.0]] for x in np.arange(0.0, 10.0, 2 * spacing)]  # the modifier's main zone
    corner = [[[16.0, 5.0], [16.4, 5.1]], [[16.5, 5.0], [16.6, 4.5]]]  # beyond the skin, 6 mm on
    cura = np.array(zone + corner)
    new = [np.array([[0.5, 0.0], [0.5, 10.0], [9.5, 10.0]]), np.array([[18.6, 2.0], [18.6, 8.0]])]
    alone = isolated_cura_lines(cura, new_line_places(new, LW), LW, link=2 * spacing, reach=2.5 * spacing)
    assert alone.tolist() == [False] * len(zone) + [True, True]
    # a new line within reach takes the corner over; so does joining the zone (the band beside a region:
    # Cura's lines there are one group with the zone's, which new lines reach)
    near = [new[0], np.array([[17.5, 2.0], [17.5, 8.0]])]
    assert not isolated_cura_lines(cura, new_line_places(near, LW), LW, link=2 * spacing, reach=2.5 * spacing).any()
    assert not isolated_cura_lines(cura, new_line_places(new, LW), LW, link=8.0, reach=2.5 * spacing).any()
    # a stub of new infill takes nothing over; no Cura lines, nothing isolated
    stub = [new[0], np.array([[16.2, 5.3], [16.4, 5.3]])]
    assert isolated_cura_lines(cura, new_line_places(stub, LW), LW, link=2 * spacing, reach=2.5 * spacing)[-2:].all()
    assert isolated_cura_lines(np.zeros((0, 2, 2)), new_line_places(new, LW), LW, link=1.0, reach=1.0).size == 0
    assert new_line_places(stub[1:], LW) is None and isolated_cura_lines(cura, None, LW, 1.0, 1.0).all()


def test_a_stub_of_new_infill_does_not_take_over_a_small_island():
    island = box(0, 0, 2.5, 2.5)  # a letter's stroke: the pattern leaves a 0.3 mm stub in it
    cura = np.array([[[0.3, 1.2], [2.2, 1.2]], [[1.2, 0.3], [1.2, 2.2]]])
    stub = [np.array([[1.0, 1.0], [1.3, 1.0]])]
    kept = kept_cura_pieces(cura, island, stub, LW, reach=5.0)
    assert abs(sum(LineString(k).length for k in kept) - 3.8) < 0.1
    # nor in a large piece; a real line there takes over what it reaches
    big = box(0, 0, 30, 30)
    assert len(kept_cura_pieces(cura, big, stub, LW, reach=5.0)) > 0
    assert kept_cura_pieces(cura, big, [np.array([[1.0, 1.0], [2.0, 1.0]])], LW, reach=5.0) == []


def test_cura_lines_in_a_finger_narrower_than_two_line_widths_stay():
    """A 0.6 mm finger of a small piece (under reach squared) beside a hole (random shape 25): the
    pattern crosses it only as stubs, so a new line 3 mm away does not take over Cura's stub at its
    tip; one along it does."""
    body = box(0, 0, 10, 10)
    finger = box(4.7, 10, 5.3, 14)  # 0.6 mm wide, 4 mm long, on the body's top edge
    area = body.union(finger)
    tip = np.array([[[5.0, 12.8], [5.0, 13.7]]])  # Cura's 0.9 mm line at the finger's tip
    across = [np.array([[0.5, 9.5], [9.5, 9.5]])]  # the pattern's nearest line: in the body, 3.3 mm away
    kept = kept_cura_pieces(tip, area, across, LW, reach=12.0)
    assert abs(sum(LineString(k).length for k in kept) - 0.9) < 0.05
    # a new line along the finger takes it over
    along = [*across, np.array([[5.0, 10.2], [5.0, 13.9]])]
    assert kept_cura_pieces(tip, area, along, LW, reach=12.0) == []
    # in the body (wider than two line widths) the line 3.3 mm away takes a Cura line over, as before
    inside = np.array([[[5.0, 6.0], [5.0, 7.0]]])
    assert kept_cura_pieces(inside, area, across, LW, reach=12.0) == []


# ----------------------------------------------------------------------------- end to end
def test_no_new_infill_in_a_hole_whose_wall_came_in_three_pieces():
    features, hole = _ring_layer(3)
    text = _gcode([features] * 3)
    out, report = process_gcode(as_cura_list(text))
    assert report.layers_processed == 3, report.format_table()
    new = _fill_segments("".join(out))
    for layer, segs in new.items():
        assert _length_inside(segs, hole.buffer(-LW / 2)) < 1e-6, f"layer {layer} prints in the hole"
    assert sum(len(s) for s in new.values()) > 0


def test_no_new_infill_on_skin_inside_the_infill():
    part = box(80, 80, 130, 110)
    letter = box(95, 88, 103, 102)  # a skin patch (the floor of an engraved letter) inside the infill
    features = [("WALL-OUTER", np.asarray(part.buffer(-LW / 2, join_style=2).exterior.coords)),
                ("WALL-INNER", np.asarray(part.buffer(-1.5 * LW, join_style=2).exterior.coords))]
    skin_area = letter.buffer(-LW / 2, join_style=2)
    x0, y0, x1, y1 = skin_area.bounds
    features += [("SKIN", np.array([[x0, y], [x1, y]])) for y in np.linspace(y0, y1, int(math.ceil((y1 - y0) / LW)) + 1)]
    fill_area = part.buffer(-2 * LW + 0.04, join_style=2).difference(letter.buffer(LW / 2, join_style=2))
    for angle in (45, 135):
        features += [("FILL", line) for line in _grid_lines(fill_area, 4.0, angle)]
    out, report = process_gcode(as_cura_list(_gcode([features] * 2)))
    assert report.layers_processed == 2
    for layer, segs in _fill_segments("".join(out)).items():
        assert _length_inside(segs, letter.buffer(-LW / 2)) < 0.05, f"layer {layer} prints on the skin"


def test_a_small_island_keeps_infill():
    part = box(80, 80, 120, 120)
    pillar = box(130, 100, 133.2, 103.2)  # 3.2 mm across: room for one short Cura line
    features = []
    for poly in (part, pillar):
        features += [("WALL-OUTER", np.asarray(poly.buffer(-LW / 2, join_style=2).exterior.coords)),
                     ("WALL-INNER", np.asarray(poly.buffer(-1.5 * LW, join_style=2).exterior.coords))]
    for angle in (45, 135):
        features += [("FILL", line) for line in _grid_lines(part.buffer(-2 * LW + 0.04, join_style=2), 4.0, angle)]
    features.append(("FILL", np.array([[130.9, 101.6], [132.3, 101.6]])))
    out, report = process_gcode(as_cura_list(_gcode([features] * 2)))
    new = _fill_segments("".join(out))
    for layer, segs in new.items():
        assert _length_inside(segs, pillar) > 1.0, f"layer {layer}: the pillar lost its infill"


@pytest.mark.parametrize("seed", [2, 4, 5])
def test_a_pocket_behind_a_neck_a_0_percent_region_leaves_keeps_its_infill(seed):
    """Random regions 81 (CuraEngine 5.0): a 0 % region's border passes within 0.3 mm of another part of
    itself, and the pocket beyond that neck has Cura's line.  Through the neck the pocket was part of the
    rest, whose new lines within reach "took over" its line: on these seeds the pocket printed nothing."""
    part = box(80, 80, 120, 120)
    pocket = box(96.5, 99.0, 99.0, 101.5)
    neck = box(98.9, 100.1, 100.2, 100.4)  # 0.3 mm wide, to the rest of the area at x > 100
    empty = box(70, 70, 100, 130).difference(pocket).difference(neck)
    features = [("WALL-OUTER", np.asarray(part.buffer(-LW / 2, join_style=2).exterior.coords)),
                ("WALL-INNER", np.asarray(part.buffer(-1.5 * LW, join_style=2).exterior.coords))]
    fill_area = part.buffer(-2 * LW + 0.04, join_style=2).difference(empty.buffer(LW / 2))
    for angle in (45, 135):  # Cura's 10 % grid beside the region, and its line in the pocket
        features += [("FILL", line) for line in _grid_lines(fill_area, 8.0, angle)]
    features.append(("FILL", np.array([[97.0, 100.2], [98.6, 100.2]])))
    out, report = process_gcode(as_cura_list(_gcode([features] * 2)), ProcessSettings(seed=seed),
                                regions=[Region(0.0, polygon=empty)])
    assert report.layers_processed == 2, report.format_table()
    new = _fill_segments("".join(out))
    assert sorted(new) == [0, 1]
    for layer, segs in new.items():
        assert _length_inside(segs, pocket) > 1.0, f"layer {layer}: the pocket lost its infill"
        assert _length_inside(segs, empty.buffer(-LW)) < 0.05, f"layer {layer} prints in the 0 % region"


def test_a_part_whose_walls_do_not_close_keeps_cura_infill_and_is_reported():
    good, broken = box(80, 80, 110, 110), box(120, 80, 150, 110)
    features = []
    for poly in (good, broken):
        outer = np.asarray(poly.buffer(-LW / 2, join_style=2).exterior.coords)
        if poly is broken:
            outer = np.vstack([outer[:4], outer[3] + (outer[4] - outer[3]) * 0.8])  # a 6 mm gap: no loop
        features += [("WALL-OUTER", outer),
                     ("WALL-INNER", np.asarray(poly.buffer(-1.5 * LW, join_style=2).exterior.coords))]
    for poly in (good, broken):
        for angle in (45, 135):
            features += [("FILL", line) for line in _grid_lines(poly.buffer(-2 * LW + 0.04, join_style=2), 4.0, angle)]
    text = _gcode([features] * 2)
    out, report = process_gcode(as_cura_list(text))
    before, after = _fill_segments(text), _fill_segments("".join(out))
    for layer in before:
        cura_there = MultiLineString([s.tolist() for s in before[layer]]).intersection(broken)
        new_there = MultiLineString([s.tolist() for s in after[layer]]).intersection(broken)
        assert abs(new_there.length - cura_there.length) < 0.01 * cura_there.length  # Cura's lines, all of them
        assert new_there.buffer(0.01).covers(cura_there)
        assert _length_inside(after[layer], good) > 0 and report.layers_processed == 2
    assert report.cura_infill_kept_mm > 0.9 * sum(
        MultiLineString([s.tolist() for s in b]).intersection(broken).length for b in before.values())
    assert "Cura's lines kept" in report.format_table()


def test_no_zero_length_e_move_in_a_replaced_block():
    features, _ = _ring_layer(1)
    out = "".join(process_gcode(as_cura_list(_gcode([features] * 3)))[0])
    e_prev = None
    for line in out.splitlines():
        m = re.match(r"G1 (?:F[\d.]+ )?E(-?[\d.]+)$", line)
        if m:
            assert e_prev is None or m.group(1) != e_prev, f"an E move that moves nothing: {line}"
        m_any = re.search(r" E(-?[\d.]+)", line)
        if line.startswith(("G0", "G1")) and m_any:
            e_prev = m_any.group(1)
        elif line.startswith("G92"):
            e_prev = None


# ----------------------------------------------------------------------------- the settings footer
def _footer(values: dict[str, str]) -> str:
    ini = "[general]\nversion = 4\nname = test\n\n[metadata]\ntype = quality_changes\n\n[values]\n" + "".join(
        f"{k} = {v}\n" for k, v in values.items())
    text = json.dumps({"global_quality": "[general]\nversion = 4\n\n[values]\nlayer_height = 0.2\n",
                       "extruder_quality": [ini]})
    escaped = text.replace("\\", "\\\\").replace("\n", "\\n")
    return "".join(f";SETTING_3 {escaped[i:i + 69]}\n" for i in range(0, len(escaped), 69))


def test_footer_settings_are_read_as_cura_wrote_them():
    footer = read_footer("G1 X0\n;End of Gcode\n" + _footer({"infill_sparse_density": "15", "infill_pattern": "grid"}))
    assert footer.infill_density() == 0.15
    assert footer.infill_pattern() == "grid"
    assert footer.value("layer_height") == "0.2"  # the global value where the extruder has none
    assert not read_footer(";SETTING_3 {broken").found
    doubled = read_footer(_footer({"infill_sparse_density": "15", "infill_multiplier": "2"}))
    assert doubled.infill_density() == 0.3  # each line printed twice: twice the material


def test_density_from_the_footer_not_from_the_lines():
    features, _ = _ring_layer(1)  # grid lines 4 mm apart: 20 % from the lines
    text = _gcode([features] * 3, _footer({"infill_sparse_density": "22"}))
    _, report = process_gcode(as_cura_list(text))
    assert report.regions[0].target == 0.22, report.format_table()
    _, report = process_gcode(as_cura_list(_gcode([features] * 3)))
    assert abs(report.regions[0].target - 0.2) < 0.01


def test_lightning_keeps_cura_infill_and_says_so():
    features, _ = _ring_layer(1)
    text = _gcode([features] * 3, _footer({"infill_sparse_density": "10", "infill_pattern": "lightning"}))
    out, report = process_gcode(as_cura_list(text))
    assert report.layers_processed == 0
    assert any("lightning" in w for w in report.warnings)
    assert _fill_segments("".join(out)).keys() == _fill_segments(text).keys()
    assert all(np.allclose(a, b) for a, b in zip(_fill_segments("".join(out)).values(), _fill_segments(text).values()))
    # the plugin says so from Cura's settings (no footer in Cura's own G-code before it is saved)
    _, report = process_gcode(as_cura_list(_gcode([features] * 3)), ProcessSettings(density=0.1, infill_pattern="lightning"))
    assert report.layers_processed == 0 and any("lightning" in w for w in report.warnings)
    _, report = process_gcode(as_cura_list(_gcode([features] * 3)), ProcessSettings(density=0.1, infill_pattern="grid"))
    assert report.layers_processed == 3


def test_gradual_infill_is_named_as_replaced_by_uniform_infill():
    """Cura's gradual infill thins the infill below the top; the pass prints its full density everywhere,
    and says so (from the footer of a saved file, or from Cura's settings in the plugin)."""
    features, _ = _ring_layer(1)
    text = _gcode([features] * 3, _footer({"infill_sparse_density": "20", "gradual_infill_steps": "2"}))
    _, report = process_gcode(as_cura_list(text))
    assert report.layers_processed == 3
    assert any("gradual infill (2 steps)" in w and "Gradual Infill Steps to 0" in w for w in report.warnings)
    _, report = process_gcode(as_cura_list(_gcode([features] * 3, _footer({"gradual_infill_steps": "0"}))))
    assert not any("gradual" in w for w in report.warnings)
    _, report = process_gcode(as_cura_list(_gcode([features] * 3)), ProcessSettings(gradual_infill_steps=1))
    assert any("gradual infill (1 step)" in w for w in report.warnings)
