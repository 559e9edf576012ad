"""An independent checker for processed Cura G-code (checks 1-5 of the engine tier).

It shares no code with ``DelaunayInfill.gcode``: its own line parser and machine
model, and its own notion of the part's infill area, built from the model
geometry that was sliced (not from the G-code's walls).

Usage::

    orig = parse_gcode(original_text)
    new = parse_gcode(processed_text)
    result = check_unchanged(orig, new)          # 1 (+ state handed back, part of 3)
    result = check_infill_area(orig, new, geometry, settings)      # 2
    result = check_extrusion(orig, new, geometry, settings)        # 3
    result = check_region_densities(new, geometry, settings, regions)   # 4
    assert result.ok, result.report()

A :class:`CheckResult` holds the failures and the measured figures.  Every check
is also run on deliberately broken files by the tier's self-tests, so that a
check that cannot fail is noticed.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from shapely.geometry import MultiLineString, Point, Polygon
from shapely.ops import unary_union
from shapely.prepared import prep

# --------------------------------------------------------------------------- parsing

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_IGNORED_HEADER = re.compile(r"^;(TIME|Filament used|PRINT\.TIME|PRINT_TIME|EXTRUDER_TRAIN\.\d+\.MATERIAL\.VOLUME_USED)\b")
_STRUCTURE = re.compile(r"^;(TYPE|MESH|LAYER|TIME_ELAPSED):(.*)$")
MARKER_PREFIX = ";DELAUNAYINFILL"

# Move columns (float array, one row per G0/G1 with an X, Y, Z or E word)
C_LINE, C_LAYER, C_X0, C_Y0, C_X1, C_Y1, C_Z, C_DE, C_F, C_G0, C_FILL, C_RETRACTED, C_MESH = range(13)


@dataclass
class State:
    """Machine state as the firmware sees it (absolute coordinates, E register)."""

    x: float = math.nan
    y: float = math.nan
    z: float = math.nan
    e: float = 0.0
    f: float = math.nan
    relative_e: bool = False
    tool: int = 0
    depth: float = 0.0  # how far the filament is retracted, E units
    fw_retracted: bool = False

    def key(self):
        return (self.x, self.y, self.z, self.f, self.tool, round(self.depth, 4), self.fw_retracted)


@dataclass
class Event:
    """One non-FILL line, in the form check 1 compares."""

    line_no: int
    text: str
    kind: str  # "move", "line"
    value: tuple
    state_before: State
    fill_before: bool  # a FILL block ended just before this event


@dataclass
class Parsed:
    """A parsed G-code file."""

    header: list[str]
    events: list[Event]
    moves: np.ndarray  # (m, 13) float, see C_* columns
    layers: list[dict]  # per ;LAYER: in file order: number, z, first/last line
    meshes: list[str]
    marker_lines: list[str]
    relative_e: bool
    g92_count: int
    lines: int

    def layer_count(self) -> int:
        return len(self.layers)

    def fill_moves(self, extruding: bool | None = None) -> np.ndarray:
        m = self.moves[self.moves[:, C_FILL] == 1]
        if extruding is None:
            return m
        ext = (m[:, C_DE] > 1e-9) & (np.hypot(m[:, C_X1] - m[:, C_X0], m[:, C_Y1] - m[:, C_Y0]) > 0)
        return m[ext] if extruding else m[~ext]


def parse_gcode(text: str) -> Parsed:
    """Parse Cura-style G-code.

    FILL context starts at ``;TYPE:FILL`` and ends at any other ``;TYPE:``,
    ``;LAYER:``, ``;MESH:NONMESH``, ``;TIME_ELAPSED:`` or a tool change.  Every
    other line becomes an :class:`Event` (G92 lines excepted: their effect is in
    the E deltas of the moves).
    """
    st = State()
    in_fill = False
    fill_just_ended = False
    layer_seq = -1
    layers: list[dict] = []
    header: list[str] = []
    events: list[Event] = []
    rows: list[list[float]] = []
    meshes: list[str] = []
    mesh_index = -1
    markers: list[str] = []
    g92 = 0
    lines = text.split("\n")
    for no, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith(MARKER_PREFIX):
            markers.append(line)
            continue
        if layer_seq < 0 and not line.startswith(";LAYER:"):
            header.append(line)
        m = _STRUCTURE.match(line)
        if m:
            tag, val = m.groups()
            if tag == "TYPE":
                if in_fill and val != "FILL":
                    fill_just_ended = True
                in_fill = val == "FILL"
                if in_fill:
                    continue
            elif tag == "LAYER":
                if in_fill:
                    fill_just_ended = True
                in_fill = False
                layer_seq += 1
                try:
                    number = int(val)
                except ValueError:
                    number = None
                layers.append({"number": number, "z": math.nan, "first_line": no, "meshes": set()})
            elif tag == "MESH":
                if val not in meshes:
                    meshes.append(val)
                mesh_index = meshes.index(val)
                if in_fill and val != "NONMESH":
                    continue  # mesh switches inside infill belong to the infill
                if in_fill:
                    fill_just_ended = True
                in_fill = False
                continue  # the current mesh is part of every move event instead
            elif tag == "TIME_ELAPSED":
                if in_fill:
                    fill_just_ended = True
                in_fill = False
                events.append(Event(no, line, "line", ("TIME_ELAPSED",), _copy(st), fill_just_ended))
                fill_just_ended = False
                continue
        code = line.split(";", 1)[0].strip()
        words = _WORD.findall(code)
        cmd = (words[0][0].upper() + str(int(float(words[0][1])))) if words else ""
        params = {k.upper(): float(v) for k, v in words[1:]}
        if cmd in ("G0", "G1") and any(k in params for k in "XYZE"):
            before = _copy(st)
            x1 = params.get("X", st.x)
            y1 = params.get("Y", st.y)
            z1 = params.get("Z", st.z)
            if "E" in params:
                de = params["E"] if st.relative_e else params["E"] - st.e
                st.e = st.e + de if st.relative_e else params["E"]
            else:
                de = 0.0
            pure_e = "E" in params and not any(k in params for k in "XY")
            if pure_e:
                st.depth = max(0.0, st.depth - de)
            if "F" in params:
                st.f = params["F"]
            rows.append([no, layer_seq, st.x, st.y, x1, y1, z1, de, st.f, cmd == "G0", in_fill,
                         float(before.depth > 1e-6 or before.fw_retracted), mesh_index])
            if de > 1e-9 and not pure_e and layer_seq >= 0:
                if math.isnan(layers[layer_seq]["z"]):
                    layers[layer_seq]["z"] = z1
                if mesh_index >= 0:
                    layers[layer_seq]["meshes"].add(meshes[mesh_index])
            st.x, st.y, st.z = x1, y1, z1
            if not in_fill:
                given = tuple(sorted((k, round(v, 4)) for k, v in params.items() if k != "E"))
                value = (cmd, given, round(de, 4), "E" in params, mesh_index)
                events.append(Event(no, line, "move", value, before, fill_just_ended))
                fill_just_ended = False
            continue
        if cmd == "G0" or cmd == "G1":
            if "F" in params:
                st.f = params["F"]
        elif cmd == "G92":
            g92 += 1
            if "E" in params:
                st.e = params["E"]
            for axis in "XYZ":
                if axis in params:
                    setattr(st, axis.lower(), params[axis])
            continue
        elif cmd == "M82":
            st.relative_e = False
        elif cmd == "M83":
            st.relative_e = True
        elif cmd == "G10":
            st.fw_retracted = True
        elif cmd == "G11":
            st.fw_retracted = False
        elif cmd.startswith("T"):
            st.tool = int(cmd[1:])
            if in_fill:
                fill_just_ended = True
            in_fill = False
        if in_fill:
            continue
        value = ("HEADER",) if _IGNORED_HEADER.match(line) else (line,)
        events.append(Event(no, line, "line", value, _copy(st), fill_just_ended))
        fill_just_ended = False
    moves = np.array(rows, dtype=float) if rows else np.zeros((0, 13))
    return Parsed(header, events, moves, layers, meshes, markers, st.relative_e, g92, len(lines))


def _copy(st: State) -> State:
    return State(**st.__dict__)


# --------------------------------------------------------------------------- results


@dataclass
class CheckResult:
    name: str
    failures: list[str] = field(default_factory=list)
    figures: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.failures

    def fail(self, message: str) -> None:
        if len(self.failures) < 50:
            self.failures.append(message)

    def report(self) -> str:
        head = f"{self.name}: {'ok' if self.ok else 'FAILED'} {self.figures}"
        return "\n  ".join([head, *self.failures[:20]])


# --------------------------------------------------------------------------- check 1


def _same_state(a: State, b: State, next_value: tuple | None, tol: float = 1e-3) -> list[str]:
    problems = []
    for axis in ("x", "y", "z"):
        va, vb = getattr(a, axis), getattr(b, axis)
        if not (math.isnan(va) and math.isnan(vb)) and not abs(va - vb) <= tol:
            problems.append(f"{axis.upper()} {vb} instead of {va}")
    if next_value is not None and next_value[0] in ("G0", "G1"):
        gives_f = any(k == "F" for k, _ in next_value[1])
        if not gives_f and not abs(a.f - b.f) <= 1e-6:
            problems.append(f"feedrate F{b.f} instead of F{a.f} (next move gives no F)")
    if a.tool != b.tool:
        problems.append(f"extruder T{b.tool} instead of T{a.tool}")
    if abs(a.depth - b.depth) > 1e-3:
        problems.append(f"filament retracted by {b.depth:.5f} instead of {a.depth:.5f}")
    if a.fw_retracted != b.fw_retracted:
        problems.append(f"firmware retraction {'on' if b.fw_retracted else 'off'} instead of {'on' if a.fw_retracted else 'off'}")
    if a.relative_e != b.relative_e:
        problems.append("extrusion mode (M82/M83) differs")
    return problems


def check_unchanged(orig: Parsed, new: Parsed) -> CheckResult:
    """Check 1 (and the state hand-back of check 3).

    Every non-FILL line is the same, move for move (same target coordinates,
    feedrate and E delta, same mesh and feature context), apart from the
    header's time/filament figures and ``;TIME_ELAPSED`` values; before every
    such line the machine state (position, feedrate where the line relies on
    it, extruder, retraction) equals the original's.
    """
    res = CheckResult("1 non-FILL unchanged")
    res.figures["events"] = len(orig.events)
    res.figures["layers"] = (orig.layer_count(), new.layer_count())
    if orig.layer_count() != new.layer_count():
        res.fail(f"layer count changed: {orig.layer_count()} -> {new.layer_count()}")
    if len(orig.events) != len(new.events):
        res.fail(f"number of non-FILL lines changed: {len(orig.events)} -> {len(new.events)}")
    handbacks = 0
    for a, b in zip(orig.events, new.events, strict=False):
        if a.value != b.value:
            res.fail(f"line {a.line_no} {a.text!r} became line {b.line_no} {b.text!r}")
            break  # later lines are misaligned; the first difference is what matters
        problems = _same_state(a.state_before, b.state_before, a.value if a.kind == "move" else None)
        if a.kind == "line" and a.value and a.value[0] in ("HEADER", "TIME_ELAPSED"):
            problems = [p for p in problems if not p.startswith("feedrate")]
        if problems and (a.fill_before or b.fill_before or a.kind == "move"):
            res.fail(f"state before original line {a.line_no} {a.text!r} (new line {b.line_no}): " + "; ".join(problems))
        handbacks += a.fill_before
    res.figures["fill_handbacks"] = handbacks
    return res


# --------------------------------------------------------------------------- geometry


@dataclass
class Part:
    """A vertical prism of the sliced geometry, in model coordinates."""

    outline: np.ndarray  # (n, 2) mm
    z0: float
    z1: float
    offset: tuple = (0.0, 0.0)  # model XY offset (second object...), mm
    mesh: str = ""  # the ;MESH: name it prints under


@dataclass
class SliceGeometry:
    """What was sliced, and where the engine put it.

    ``bed_offset`` is CuraEngine's shift (machine_width / 2, machine_depth / 2).
    """

    parts: list[Part]
    bed_offset: tuple = (110.0, 110.0)

    def polygon(self, part: Part) -> Polygon:
        dx = part.offset[0] + self.bed_offset[0]
        dy = part.offset[1] + self.bed_offset[1]
        return Polygon(np.asarray(part.outline) + [dx, dy])

    def section(self, z: float, meshes=None) -> Polygon:
        """The model's cross-section at height z (of the given mesh names only, when given)."""
        polys = [self.polygon(p) for p in self.parts if p.z0 < z < p.z1 and (meshes is None or p.mesh in meshes)]
        return unary_union(polys) if polys else Polygon()

    def to_gcode_xy(self, polygon_model: Polygon) -> Polygon:
        from shapely.affinity import translate

        return translate(polygon_model, *self.bed_offset)


@dataclass
class SliceSettings:
    """The settings the checks need (all mm)."""

    line_width: float = 0.4
    wall_inset: float = 0.8  # outer wall + inner walls
    infill_overlap: float = 0.04
    layer_height: float = 0.2
    layer_height_0: float = 0.2
    top_layers: int = 4
    bottom_layers: int = 4
    density: float = 0.2  # base density, fraction

    @classmethod
    def from_resolved(cls, values: dict) -> SliceSettings:
        walls = int(values["wall_line_count"])
        inset = 0.0 if walls == 0 else values["wall_line_width_0"] + (walls - 1) * values["wall_line_width_x"]
        return cls(
            line_width=float(values["infill_line_width"]),
            wall_inset=float(inset),
            infill_overlap=float(values["infill_overlap_mm"]),
            layer_height=float(values["layer_height"]),
            layer_height_0=float(values["layer_height_0"]),
            top_layers=int(values["top_layers"]),
            bottom_layers=int(values["bottom_layers"]),
            density=float(values["infill_sparse_density"]) / 100.0,
        )


def infill_area(geometry: SliceGeometry, settings: SliceSettings, z_top: float, meshes=None) -> Polygon:
    """The sparse-infill area of the layer whose top is at `z_top`, from the model alone.

    The model's section at mid-layer, intersected with the sections of the
    layers within the top/bottom skin range (elsewhere there is skin), shrunk
    by the walls and grown by the infill overlap.
    """
    h = settings.layer_height
    z_mid = z_top - h / 2 if z_top > settings.layer_height_0 + 1e-6 else settings.layer_height_0 / 2
    area = geometry.section(z_mid, meshes)
    for k in range(1, settings.bottom_layers + 1):
        if area.is_empty:
            break
        below = z_mid - k * h
        area = area.intersection(geometry.section(below, meshes)) if below > 0 else Polygon()
    for k in range(1, settings.top_layers + 1):
        if area.is_empty:
            break
        area = area.intersection(geometry.section(z_mid + k * h, meshes))
    if area.is_empty:
        return area
    return area.buffer(-(settings.wall_inset - settings.infill_overlap), join_style=2)


def _segments_by_layer(moves: np.ndarray) -> dict[int, np.ndarray]:
    out: dict[int, list] = {}
    if len(moves) == 0:
        return {}
    order = np.argsort(moves[:, C_LAYER], kind="stable")
    moves = moves[order]
    keys, starts = np.unique(moves[:, C_LAYER], return_index=True)
    for key, chunk in zip(keys, np.split(moves, starts[1:]), strict=True):
        out[int(key)] = chunk[:, [C_X0, C_Y0, C_X1, C_Y1]].reshape(-1, 2, 2)
    return out


def _lines(segments: np.ndarray) -> MultiLineString:
    segments = segments[np.hypot(*(segments[:, 1] - segments[:, 0]).T) > 1e-9]
    return MultiLineString([tuple(map(tuple, s)) for s in segments])


def _sample_points(segments: np.ndarray, step: float) -> np.ndarray:
    """Points every `step` mm along segments (k, 2, 2) -> (n, 2): the midpoints of equal pieces."""
    from .everyday_check import sample_segments

    return sample_segments(segments, step)[0]


def check_infill_area(orig: Parsed, new: Parsed, geometry: SliceGeometry, settings: SliceSettings,
                      *, min_density: float | None = None, max_outside: float = 0.01,
                      min_coverage: float = 0.99) -> CheckResult:
    """Check 2: new infill inside the infill area; every place that had infill still has some.

    Outside: infill length farther than one line width outside :func:`infill_area`
    must be at most `max_outside` of the total.  Coverage: points every 1 mm
    along Cura's FILL must lie within ``2.5 * line_width / density`` of the new
    infill (about the largest empty circle of a Poisson-disk Delaunay pattern
    at that density), for `min_coverage` of them; a layer that had infill must
    still have some.
    """
    res = CheckResult("2 infill inside the part and everywhere")
    w = settings.line_width
    reach = 2.5 * w / (min_density or settings.density)
    new_fill = _segments_by_layer(new.fill_moves(extruding=True))
    old_fill = _segments_by_layer(orig.fill_moves(extruding=True))
    total = outside = 0.0
    covered = sampled = 0
    for seq, layer in enumerate(new.layers):
        segs = new_fill.get(seq)
        if segs is not None and len(segs):
            allowed = infill_area(geometry, settings, layer["z"]).buffer(w)
            lines = _lines(segs)
            total += lines.length
            out_len = lines.difference(allowed).length if not allowed.is_empty else lines.length
            outside += out_len
            if out_len > 0.05 * lines.length + 1.0:
                res.fail(f"layer {layer['number']} (z {layer['z']}): {out_len:.1f} of {lines.length:.1f} mm infill outside the infill area")
        old = old_fill.get(seq)
        if old is None or not len(old):
            continue
        if segs is None or not len(segs):
            res.fail(f"layer {layer['number']}: had {len(old)} infill lines, has none now")
            continue
        # distance from Cura's infill to the nearest new infill, via points every 0.25 mm along it
        tree = cKDTree(_sample_points(segs, 0.25))
        distance, _ = tree.query(_sample_points(old, 1.0))
        covered += int((distance <= reach + 0.125).sum())
        sampled += len(distance)
    res.figures["infill_mm"] = round(total, 1)
    res.figures["outside_fraction"] = round(outside / total, 5) if total else 0.0
    res.figures["coverage"] = round(covered / sampled, 4) if sampled else 1.0
    if total == 0:
        res.fail("no infill at all")
    elif outside / total > max_outside:
        res.fail(f"{100 * outside / total:.2f} % of the infill length lies outside the infill area (limit {100 * max_outside:g} %)")
    if sampled and covered / sampled < min_coverage:
        res.fail(f"only {100 * covered / sampled:.1f} % of the places with Cura infill have new infill within {reach:.1f} mm")
    return res


# --------------------------------------------------------------------------- check 3


def _e_per_mm(moves: np.ndarray) -> tuple[float, np.ndarray]:
    length = np.hypot(moves[:, C_X1] - moves[:, C_X0], moves[:, C_Y1] - moves[:, C_Y0])
    return float(moves[:, C_DE].sum() / length.sum()) if length.sum() else math.nan, moves[:, C_DE] / np.maximum(length, 1e-12)


def check_extrusion(orig: Parsed, new: Parsed, geometry: SliceGeometry, *, rel_tol: float = 0.01) -> CheckResult:
    """Check 3: E per mm, E continuity, no extrusion while retracted, retraction on travel.

    * per layer, the new FILL's E per mm equals Cura's (total E / length,
      within `rel_tol`), and each new FILL move longer than 1 mm is within 3 %;
    * no move anywhere extrudes more per mm than the most Cura extruded per mm
      anywhere (+1 %), and no E-only move is larger than Cura's largest: no jumps;
    * nothing extrudes while the filament is retracted;
    * a new infill travel that leaves the part is made retracted when Cura
      retracts on travel at all.
    """
    res = CheckResult("3 extrusion and travel")
    old_fill = orig.fill_moves(extruding=True)
    new_fill = new.fill_moves(extruding=True)
    worst = 0.0
    for seq in np.unique(new_fill[:, C_LAYER]).astype(int) if len(new_fill) else []:
        a = old_fill[old_fill[:, C_LAYER] == seq]
        b = new_fill[new_fill[:, C_LAYER] == seq]
        if not len(a):
            res.fail(f"layer seq {seq}: new infill where Cura had none")
            continue
        ra, _ = _e_per_mm(a)
        rb, per_move = _e_per_mm(b)
        worst = max(worst, abs(rb / ra - 1))
        if abs(rb / ra - 1) > rel_tol:
            res.fail(f"layer {new.layers[seq]['number']}: infill E/mm {rb:.5f} vs Cura's {ra:.5f}")
        long = np.hypot(b[:, C_X1] - b[:, C_X0], b[:, C_Y1] - b[:, C_Y0]) > 1.0
        bad = long & (np.abs(per_move / ra - 1) > 0.03)
        if bad.any():
            res.fail(f"layer {new.layers[seq]['number']}: {int(bad.sum())} infill moves with E/mm off by > 3 % (line {int(b[bad][0, C_LINE])})")
    res.figures["worst_layer_e_per_mm_dev"] = round(worst, 5)

    def extrusion_limits(p: Parsed):
        m = p.moves
        xy = np.hypot(m[:, C_X1] - m[:, C_X0], m[:, C_Y1] - m[:, C_Y0])
        moving = xy > 1e-6
        rate = np.where(moving, m[:, C_DE] / np.maximum(xy, 1e-12), 0.0)
        pure = ~moving & (m[:, C_DE] != 0)
        return rate, pure, xy

    rate_o, pure_o, _ = extrusion_limits(orig)
    rate_n, pure_n, xy_n = extrusion_limits(new)
    max_rate = float(rate_o.max()) if len(rate_o) else 0.0
    max_pure = float(np.abs(orig.moves[pure_o, C_DE]).max()) if pure_o.any() else 0.0
    # allowance for the G-code's rounding (3 decimals for XY, 5 for E) on very short moves
    allowed = max_rate * 1.01 * (xy_n + 0.002) + 2e-5
    jumps = np.flatnonzero(~pure_n & (new.moves[:, C_DE] > allowed))
    for i in jumps[:3]:
        res.fail(f"E jump: line {int(new.moves[i, C_LINE])} extrudes {rate_n[i]:.4f}/mm (Cura's maximum {max_rate:.4f}/mm)")
    big = np.flatnonzero(pure_n & (np.abs(new.moves[:, C_DE]) > max_pure + 1e-4))
    for i in big[:3]:
        res.fail(f"E jump: line {int(new.moves[i, C_LINE])} moves the filament by {new.moves[i, C_DE]:.4f} (Cura's largest {max_pure:.4f})")
    extruding_retracted = (new.moves[:, C_DE] > 1e-9) & ~pure_n & (new.moves[:, C_RETRACTED] == 1)
    for i in np.flatnonzero(extruding_retracted)[:3]:
        res.fail(f"line {int(new.moves[i, C_LINE])} extrudes while the filament is retracted")
    res.figures["e_jumps"] = len(jumps) + len(big)

    # travel inside the new infill: retracted where it leaves the part
    cura_retracts = pure_o.any() and (orig.moves[pure_o, C_DE] < 0).any()
    travel = new.fill_moves(extruding=False)
    travel = travel[np.hypot(travel[:, C_X1] - travel[:, C_X0], travel[:, C_Y1] - travel[:, C_Y0]) > 1e-6]
    res.figures["fill_travels"] = len(travel)
    leaving = 0
    unretracted_leaving = 0
    leaving_one_island = 0  # a travel that leaves the part between two places of the same island
    for seq in np.unique(travel[:, C_LAYER]).astype(int) if len(travel) else []:
        t = travel[travel[:, C_LAYER] == seq]
        z_top = new.layers[seq]["z"]
        part = geometry.section(z_top - 0.1 if not math.isnan(z_top) else 0.1)
        grown = part.buffer(0.05)
        prepared = prep(grown)
        islands = [prep(g) for g in getattr(grown, "geoms", [grown])]
        for row in t:
            seg = ((row[C_X0], row[C_Y0]), (row[C_X1], row[C_Y1]))
            if not prepared.contains(MultiLineString([seg])):
                leaving += 1
                ends = [Point(seg[0]), Point(seg[1])]
                if any(island.contains(ends[0]) and island.contains(ends[1]) for island in islands):
                    leaving_one_island += 1
                if row[C_RETRACTED] == 0:
                    unretracted_leaving += 1
                    if cura_retracts and unretracted_leaving <= 3:
                        res.fail(f"line {int(row[C_LINE])}: travel leaves the part without retraction")
    res.figures["fill_travels_leaving_part"] = leaving
    res.figures["unretracted_leaving"] = unretracted_leaving
    res.figures["fill_travels_leaving_one_island"] = leaving_one_island
    # retractions inside the new infill are Cura's: same amount, same speeds
    fill_o, fill_n = orig.moves[:, C_FILL] == 1, new.moves[:, C_FILL] == 1
    old_ret = orig.moves[pure_o & (orig.moves[:, C_DE] < 0)]
    old_pri = orig.moves[pure_o & (orig.moves[:, C_DE] > 0) & (orig.moves[:, C_RETRACTED] == 1)]
    new_ret = new.moves[pure_n & fill_n & (new.moves[:, C_DE] < 0)]
    new_pri = new.moves[pure_n & fill_n & (new.moves[:, C_DE] > 0) & (new.moves[:, C_RETRACTED] == 1)]
    res.figures["fill_retractions"] = (int((pure_o & fill_o & (orig.moves[:, C_DE] < 0)).sum()), len(new_ret))
    if len(new_ret) and not len(old_ret):
        res.fail("the new infill retracts, Cura never does in this file")
    for moves, ref, what in ((new_ret, old_ret, "retraction"), (new_pri, old_pri, "unretraction")):
        if not len(moves) or not len(ref):
            continue
        amounts, speeds = np.unique(np.round(np.abs(ref[:, C_DE]), 4)), np.unique(ref[:, C_F])
        bad_amount = ~np.isin(np.round(np.abs(moves[:, C_DE]), 4), amounts)
        bad_speed = ~np.isin(moves[:, C_F], speeds)
        for row in moves[bad_amount | bad_speed][:2]:
            res.fail(f"line {int(row[C_LINE])}: {what} of {abs(row[C_DE]):.4f} at F{row[C_F]:g}; Cura uses "
                     f"{', '.join(f'{a:g}' for a in amounts)} at F{', F'.join(f'{v:g}' for v in speeds)}")
    needless = needless_retractions(new, geometry)
    res.figures["needless_retractions"] = len(needless)
    # only where Cura itself combs without retracting (combing off: Cura retracts on every travel)
    if not needless_retractions(orig, geometry):
        for line in needless[:3]:
            res.fail(f"line {line}: retraction for a travel that stays inside the part")
    return res


def needless_retractions(parsed: Parsed, geometry: SliceGeometry, inset: float = 0.4) -> list[int]:
    """Line numbers of FILL retractions whose travel (up to the unretract) stays well inside the part.

    "Well inside": at least `inset` mm (a line width) from the part's outline,
    so travels grazing a corner may retract, as Cura's combing boundary also
    keeps off the outer wall.  Such a travel needs no retraction.
    """
    m = parsed.moves
    xy = np.hypot(m[:, C_X1] - m[:, C_X0], m[:, C_Y1] - m[:, C_Y0])
    pure = xy < 1e-9
    out = []
    parts: dict[int, object] = {}
    for i in np.flatnonzero((m[:, C_FILL] == 1) & pure & (m[:, C_DE] < 0)):
        j, travel = i + 1, []
        while j < len(m) and m[j, C_FILL] == 1 and not (pure[j] and m[j, C_DE] > 0):
            if xy[j] > 0:
                travel.append(((m[j, C_X0], m[j, C_Y0]), (m[j, C_X1], m[j, C_Y1])))
            j += 1
        if j == len(m) or m[j, C_FILL] != 1 or not travel:
            continue  # retraction handed over to the next original line
        seq = int(m[i, C_LAYER])
        if seq not in parts:
            z_top = parsed.layers[seq]["z"]
            parts[seq] = prep(geometry.section(z_top - 0.1).buffer(-inset))
        if parts[seq].contains(MultiLineString(travel)):
            out.append(int(m[i, C_LINE]))
    return out


# --------------------------------------------------------------------------- check 4


@dataclass
class DensityRegion:
    name: str
    polygon: Polygon  # G-code XY
    target: float  # fraction
    #: a wall-less infill mesh sliced by CuraEngine 4.13: its part of the host's infill area is inset by
    #: half an inner wall's width (``generateInfill``'s inner-wall offset, kept with no walls), which no
    #: infill of it, Cura's or the pass's, reaches; CuraEngine 5 does not inset
    cura4_inset: bool = False


def measure_region_densities(parsed: Parsed, geometry: SliceGeometry, settings: SliceSettings,
                             regions: list[DensityRegion], *, whole: bool = True) -> dict[str, tuple[float, float]]:
    """Measured density per region: infill length x line width / infill area, over all FILL layers.

    Regions later in the list win where they overlap; "base" is the rest.  `whole`: each region
    whole, the band along its borders included (issue 15); else its interior, a line width in from
    its borders (Cura's infill-mesh lines stop short of their mesh's border).  A region with
    `cura4_inset` is measured without its half line width along the infill area's border.
    Returns name -> (measured fraction, area mm^2 summed over layers).
    """
    fill = _segments_by_layer(parsed.fill_moves(extruding=True))
    totals = {r.name: [0.0, 0.0] for r in regions}
    totals["base"] = [0.0, 0.0]
    for seq, segs in fill.items():
        z = parsed.layers[seq]["z"]
        # one-at-a-time: a layer prints only some objects; measure over those (known by their walls)
        area = infill_area(geometry, settings, z, parsed.layers[seq]["meshes"])
        if area.is_empty:
            continue
        lines = _lines(segs)
        claimed = Polygon()
        pieces = []
        inset_area = None
        for r in reversed(regions):  # later regions win
            piece = area.intersection(r.polygon).difference(claimed)
            if r.cura4_inset:
                if inset_area is None:
                    inset_area = area.buffer(-settings.line_width / 2, join_style=2)
                piece = piece.intersection(inset_area)
            claimed = claimed.union(r.polygon)
            pieces.append((r.name, piece))
        pieces.append(("base", area.difference(claimed)))
        for name, piece in pieces:
            if piece.is_empty or piece.area < 1.0:
                continue
            # Whole: a line on a border is cut there, each side counts its own part.  Interior: lines on
            # the border count once.
            inner = piece if whole else piece.buffer(-settings.line_width, join_style=2)
            if inner.is_empty:
                continue
            totals[name][0] += lines.intersection(inner).length
            totals[name][1] += inner.area
    return {k: (v[0] * settings.line_width / v[1] if v[1] else math.nan, v[1]) for k, v in totals.items()}


def check_region_densities(parsed: Parsed, geometry: SliceGeometry, settings: SliceSettings,
                           regions: list[DensityRegion], *, tolerance: float = 0.02, whole: bool = True) -> CheckResult:
    """Check 4: measured density per region within `tolerance` (fraction: 0.02 = 2 points) of its target.

    `whole`: see `measure_region_densities`.
    """
    res = CheckResult("4 region densities")
    measured = measure_region_densities(parsed, geometry, settings, regions, whole=whole)
    targets = {r.name: r.target for r in regions}
    targets["base"] = settings.density
    for name, (value, area) in measured.items():
        res.figures[name] = (round(100 * targets[name], 1), round(100 * value, 2) if not math.isnan(value) else None)
        if math.isnan(value):
            if area == 0 and name != "base":
                res.fail(f"region {name}: no infill area found")
            continue
        if abs(value - targets[name]) > tolerance:
            res.fail(f"region {name}: measured {100 * value:.1f} % vs target {100 * targets[name]:.1f} %")
    return res


# --------------------------------------------------------------------------- check 5


def check_marker(parsed: Parsed) -> CheckResult:
    """Check 5 (first half): the processed marker sits in the header, once."""
    res = CheckResult("5 processed marker")
    header_markers = [m for m in parsed.marker_lines if m.startswith(";DELAUNAYINFILL_PROCESSED")]
    res.figures["markers"] = len(header_markers)
    if len(header_markers) != 1:
        res.fail(f"expected one ;DELAUNAYINFILL_PROCESSED line, found {len(header_markers)}")
    return res


def filament_and_time(parsed: Parsed) -> dict:
    """Total filament (E, net of retractions), infill travel and retraction counts."""
    m = parsed.moves
    fill = m[m[:, C_FILL] == 1]
    travel = fill[(fill[:, C_DE] <= 1e-9)]
    xy = np.hypot(travel[:, C_X1] - travel[:, C_X0], travel[:, C_Y1] - travel[:, C_Y0])
    pure = (np.hypot(fill[:, C_X1] - fill[:, C_X0], fill[:, C_Y1] - fill[:, C_Y0]) < 1e-9) & (fill[:, C_DE] < 0)
    return {
        "filament_mm": float(m[:, C_DE].sum()),
        "infill_travel_mm": float(xy.sum()),
        "infill_retractions": int(pure.sum()),
    }


def check_all(original: str, processed: str, geometry: SliceGeometry, settings: SliceSettings,
              regions: list[DensityRegion] = ()) -> list[CheckResult]:
    """Checks 1-5 on G-code texts (for other tiers, e.g. the GUI tier's saved G-code)."""
    orig, new = parse_gcode(original), parse_gcode(processed)
    min_density = min([settings.density] + [r.target for r in regions])
    return [
        check_unchanged(orig, new),
        check_infill_area(orig, new, geometry, settings, min_density=min_density),
        check_extrusion(orig, new, geometry),
        check_region_densities(new, geometry, settings, list(regions)),
        check_marker(new),
    ]
