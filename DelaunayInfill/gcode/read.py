"""Reading Cura G-code: chunks, header facts, and one layer's moves and FILL blocks.

A layer is parsed line by line once (a compiled regex per motion line); the
result is numpy arrays of moves plus the list of ``;TYPE:FILL`` blocks, each
with the machine state before and after it.  The machine state is carried
from chunk to chunk, so the parser sees the file as one stream.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "GCodeError",
    "MachineState",
    "FillBlock",
    "LayerParse",
    "HeaderInfo",
    "read_header",
    "check_cura_gcode",
    "iter_chunks",
    "iter_file_chunks",
    "parse_layer",
    "as_cura_list",
    "MARKER",
]

MARKER = ";DELAUNAYINFILL_PROCESSED"

# Feature names Cura writes after ;TYPE:, mapped to small ints for the move arrays.
TYPE_CODES = {
    "NONE": 0,
    "WALL-OUTER": 1,
    "WALL-INNER": 2,
    "SKIN": 3,
    "SUPPORT": 4,
    "SKIRT": 5,
    "FILL": 6,
    "SUPPORT-INTERFACE": 7,
    "PRIME-TOWER": 8,
    "SUPPORT-INFILL": 9,
}
FILL = TYPE_CODES["FILL"]
WALL_OUTER = TYPE_CODES["WALL-OUTER"]
WALL_INNER = TYPE_CODES["WALL-INNER"]
SKIN = TYPE_CODES["SKIN"]

_MOVE_COLUMNS = ("line", "x0", "y0", "z0", "x1", "y1", "z1", "de", "f", "kind", "mesh", "block", "ext")
_PARAM = re.compile(r"([XYZEF])\s*(-?\d*\.?\d+)")
_LAYER_LINE = re.compile(r"^;LAYER:(-?\d+)", re.M)


class GCodeError(ValueError):
    """The input is not G-code this tool can process (message says why)."""


class ProcessCancelled(Exception):
    """Raised when the caller's ``cancel()`` returns True."""


@dataclass
class MachineState:
    """Printer state as the firmware sees it after a line.

    ``e`` is the E register (absolute mode) or the running sum of E moves
    (relative mode); ``depth`` is how far the filament is retracted (E units),
    ``fw_retracted`` the G10/G11 state.
    """

    x: float = float("nan")
    y: float = float("nan")
    z: float = 0.0
    e: float = 0.0
    f: float = 0.0
    relative_e: bool = False
    relative_xyz: bool = False  # G91 (end G-code's "raise Z"): X/Y/Z and E move by their values
    e_mode_relative: bool = False  # the M82/M83 mode, which G90 returns E to
    depth: float = 0.0
    fw_retracted: bool = False
    extruder: int = 0
    type: str = "NONE"
    mesh: str = "NONMESH"

    def copy(self) -> MachineState:
        return copy.copy(self)


@dataclass
class RetractionModel:
    """What the original G-code does when it retracts (learned while reading).

    Amounts are in E units, speeds as G-code F values (mm/min).
    """

    amount: float = 0.0
    retract_f: float = 0.0
    prime_f: float = 0.0
    hop: float = 0.0
    hop_f: float = 0.0
    firmware: bool = False
    travel_f: float = 0.0
    seen: bool = False


@dataclass
class FillBlock:
    """One ``;TYPE:FILL`` block of a layer: lines ``[start, stop)`` of the layer.

    ``start`` is the comment line that opened the block (kept verbatim);
    ``before``/``after`` the machine state before line ``start`` and after
    line ``stop - 1``.
    """

    start: int
    stop: int
    mesh: str
    extruder: int
    before: MachineState
    after: MachineState
    has_moves: bool = False
    unsupported: str = ""  # why this block cannot be rewritten (G2/G3, M82/M83 inside, ...)
    extra_lines: list[str] = field(default_factory=list)  # non-motion commands inside (M204, M106, ...)


@dataclass
class LayerParse:
    """One parsed chunk.

    Move arrays (one entry per G0/G1 line), shape (n,): ``line`` index into
    ``lines``; ``x0, y0, z0, x1, y1, z1`` mm; ``de`` signed E change; ``f``
    feedrate mm/min; ``kind`` TYPE_CODES; ``mesh`` index into ``meshes``;
    ``block`` index into ``blocks`` or -1; ``ext`` extruder number.
    """

    lines: list[str]
    number: int | None
    z: float
    moves: dict[str, np.ndarray]
    meshes: list[str]
    blocks: list[FillBlock]
    end_state: MachineState
    time_elapsed_lines: list[int]

    def mesh_mask(self, name: str) -> np.ndarray:
        if name not in self.meshes:
            return np.zeros(len(self.moves["line"]), dtype=bool)
        return self.moves["mesh"] == self.meshes.index(name)


@dataclass
class HeaderInfo:
    """Facts from the header and start chunk."""

    flavor: str = ""
    griffin: bool = False
    volumetric: bool = False
    layer_height: float | None = None
    generator: str = ""
    processed: bool = False


def read_header(text: str) -> HeaderInfo:
    """Header facts from the first chunk (header + start G-code)."""
    info = HeaderInfo()
    m = re.search(r"^;FLAVOR:(.*)$", text, re.M)
    if m:
        info.flavor = m.group(1).strip()
    info.griffin = info.flavor in ("Griffin", "Cheetah")
    info.volumetric = info.flavor in ("UltiGCode", "Marlin(Volumetric)")
    m = re.search(r"^;Layer height:\s*([\d.]+)", text, re.M)
    if m:
        info.layer_height = float(m.group(1))
    m = re.search(r"^;(?:Generated with|GENERATOR\.NAME:)\s*(.*)$", text, re.M)
    if m:
        info.generator = m.group(1).strip()
    info.processed = MARKER in text
    return info


def check_cura_gcode(first_chunk: str, last_chunk: str, layer_count: int) -> HeaderInfo:
    """Refuse what is not complete Cura G-code.

    Raises
    ------
    GCodeError
        Other slicers, no layers, or a truncated file.
    """
    info = read_header(first_chunk)
    if info.processed:
        return info
    if not info.flavor:
        if not first_chunk.strip():
            raise GCodeError("the input is empty")
        raise GCodeError("not Cura G-code: no ';FLAVOR:' header line (only Cura/CuraEngine output is supported)")
    if "Cura_SteamEngine" not in first_chunk and "CuraEngine" not in first_chunk:
        raise GCodeError("not Cura G-code: no 'Generated with Cura_SteamEngine' line")
    if layer_count == 0:
        raise GCodeError("no ';LAYER:' lines: the G-code has no layers")
    if ";TIME_ELAPSED:" not in last_chunk and ";End of Gcode" not in last_chunk:
        raise GCodeError("the G-code looks truncated: the last layer has no ';TIME_ELAPSED:' line")
    return info


def iter_chunks(layers: Iterable[str]) -> Iterator[str]:
    """Re-split Cura's in-memory list so that every ``;LAYER:`` line starts a chunk.

    Strings that already start at a layer pass through unchanged (no copy).
    """
    for text in layers:
        starts = [m.start() for m in _LAYER_LINE.finditer(text)]
        if not starts or starts == [0]:
            yield text
            continue
        if starts[0] != 0:
            starts.insert(0, 0)
        for a, b in zip(starts, [*starts[1:], len(text)], strict=True):
            yield text[a:b]


def as_cura_list(text: str) -> list[str]:
    """Split a G-code file's text into Cura's in-memory form (``scene.gcode_dict[plate]``).

    ``[0]`` the header (up to ``;Generated with``), ``[1]`` the start G-code up
    to the first ``;LAYER:``, one string per layer ending after its
    ``;TIME_ELAPSED:`` line, ``[-1]`` the end G-code.  ``"".join`` gives `text`
    back.
    """
    gen = text.find(";Generated with")
    first = _LAYER_LINE.search(text)
    if gen < 0 or first is None or gen > first.start():
        return [text]
    out = [text[:gen], text[gen : first.start()]]
    layers = list(iter_chunks([text[first.start() :]]))
    last = layers[-1]
    cut = last.rfind(";TIME_ELAPSED:")
    if cut >= 0:
        eol = last.find("\n", cut)
        eol = len(last) if eol < 0 else eol + 1
        layers[-1:] = [last[:eol], last[eol:]] if eol < len(last) else [last]
    out.extend(layers)
    return out


def iter_file_chunks(stream) -> Iterator[str]:
    """Chunks of a text stream: what precedes the first layer, then one per ``;LAYER:``.

    Holds one layer in memory at a time.
    """
    buf: list[str] = []
    for line in stream:
        if line.startswith(";LAYER:") and buf:
            yield "".join(buf)
            buf = []
        buf.append(line)
    if buf:
        yield "".join(buf)


def parse_layer(text: str, state: MachineState, retraction: RetractionModel) -> LayerParse:
    """Parse one chunk, advancing `state` (mutated) and learning `retraction`.

    Returns
    -------
    LayerParse
    """
    lines = text.split("\n")
    n_lines = len(lines)
    number = None
    rows: list[tuple] = []
    add_row = rows.append
    meshes: list[str] = [state.mesh]
    mesh_index = {state.mesh: 0}
    blocks: list[FillBlock] = []
    time_lines: list[int] = []
    current: FillBlock | None = None
    kind = TYPE_CODES.get(state.type, 0)
    cur_mesh = mesh_index[state.mesh]
    start_z = state.z
    last_retract_line = -10
    learn = True

    def close_block(stop: int):
        nonlocal current
        if current is not None:
            current.stop = stop
            current.after = state.copy()
            blocks.append(current)
            current = None

    for i in range(n_lines):
        line = lines[i]
        if not line:
            continue
        c = line[0]
        if c == ";":
            if line.startswith(";TYPE:"):
                close_block(i)
                state.type = line[6:].strip()
                kind = TYPE_CODES.get(state.type, 0)
                if kind == FILL and state.mesh != "NONMESH":
                    current = FillBlock(i, i, state.mesh, state.extruder, state.copy(), state)
            elif line.startswith(";MESH:"):
                close_block(i)
                state.mesh = line[6:].strip()
                if state.mesh not in mesh_index:
                    mesh_index[state.mesh] = len(meshes)
                    meshes.append(state.mesh)
                cur_mesh = mesh_index[state.mesh]
                # Moves under NONMESH are travels between objects (layer change, next part): never infill.
                if kind == FILL and state.mesh != "NONMESH":
                    current = FillBlock(i, i, state.mesh, state.extruder, state.copy(), state)
            elif line.startswith(";LAYER:"):
                close_block(i)
                try:
                    number = int(line[7:].strip())
                except ValueError:
                    number = None
            elif line.startswith(";TIME_ELAPSED:"):
                close_block(i)
                time_lines.append(i)
                # What follows a layer's end is end G-code or next-group code, not Cura's own retraction.
                learn = False
            continue
        if c == "G" and line[1:2] in ("0", "1") and line[2:3] in (" ", ""):
            # Cura's motion lines, the bulk of a layer: no splitting needed
            word = line[:2]
            code = line if ";" not in line else line.split(";", 1)[0]
        else:
            code = line.split(";", 1)[0].strip()
            if not code:
                continue
            word = code.split(None, 1)[0].upper()
        if word in ("G0", "G1", "G00", "G01"):
            x0, y0, z0 = state.x, state.y, state.z
            de = 0.0
            has_e = False
            for key, val in _PARAM.findall(code):
                v = float(val)
                if key == "X":
                    state.x = state.x + v if state.relative_xyz else v
                elif key == "Y":
                    state.y = state.y + v if state.relative_xyz else v
                elif key == "Z":
                    state.z = state.z + v if state.relative_xyz else v
                elif key == "E":
                    has_e = True
                    if state.relative_e:
                        de = v
                        state.e += v
                    else:
                        de = v - state.e
                        state.e = v
                else:
                    state.f = v
            # NaN (position unknown before the first move) counts as no motion on that axis
            moved_xy = (state.x != x0 and (x0 == x0 or state.x == state.x)) or (
                state.y != y0 and (y0 == y0 or state.y == state.y)
            )
            if has_e and de != 0.0:
                if moved_xy:
                    if de > 0:
                        state.depth = 0.0
                elif de < 0:
                    state.depth -= de
                    if learn:
                        retraction.amount = -de
                        retraction.retract_f = state.f
                        retraction.seen = True
                    last_retract_line = i
                else:
                    state.depth = max(0.0, state.depth - de)
                    if learn:
                        retraction.prime_f = state.f
            elif not moved_xy and state.z > z0 and i - last_retract_line <= 2:
                if learn:
                    retraction.hop = state.z - z0
                    retraction.hop_f = state.f
            elif word in ("G0", "G00") and moved_xy and learn:
                retraction.travel_f = state.f
            if current is not None:
                current.has_moves = True
            add_row((i, x0, y0, z0, state.x, state.y, state.z, de, state.f, kind, cur_mesh,
                     len(blocks) if current is not None else -1, state.extruder))
        elif word == "G92":
            for key, val in _PARAM.findall(code):
                if key == "E":
                    state.e = float(val)
                elif key in "XYZ":
                    if current is not None:
                        current.unsupported = "G92 X/Y/Z inside FILL"
            # G92 E is fine inside a block: the block ends with the original E register.
        elif word == "G10":
            state.fw_retracted = True
            if learn:
                retraction.firmware = True
                retraction.seen = True
        elif word == "G11":
            state.fw_retracted = False
        elif word == "M82":
            state.relative_e = state.e_mode_relative = False
            if current is not None:
                current.unsupported = "M82 inside FILL"
        elif word == "M83":
            state.relative_e = state.e_mode_relative = True
            if current is not None:
                current.unsupported = "M83 inside FILL"
        elif word[0] == "T" and word[1:].isdigit():
            close_block(i)
            state.extruder = int(word[1:])
        elif word in ("G2", "G3", "G02", "G03", "G28", "G90", "G91", "G29"):
            # Marlin: G91 makes every axis relative, E too; G90 returns E to its M82/M83 mode
            if word == "G91":
                state.relative_xyz = state.relative_e = True
            elif word == "G90":
                state.relative_xyz = False
                state.relative_e = state.e_mode_relative
            if current is not None:
                current.unsupported = f"{word} inside FILL"
        elif current is not None:
            current.extra_lines.append(line)
    close_block(n_lines)
    table = np.array(rows, dtype=np.float64).reshape(-1, len(_MOVE_COLUMNS))
    moves = {
        k: table[:, j].astype(np.int64) if k in ("line", "kind", "mesh", "block", "ext") else table[:, j].copy()
        for j, k in enumerate(_MOVE_COLUMNS)
    }
    # A move from an unknown position (nothing before it set X/Y) is no segment: start it where it ends.
    for a, b in (("x0", "x1"), ("y0", "y1")):
        unknown = ~np.isfinite(moves[a])
        if unknown.any():
            moves[a][unknown] = moves[b][unknown]
    # The layer's height is where it extrudes (the Z move to it may sit in the previous chunk).
    extruding = (moves["de"] > 0) & ((moves["x1"] != moves["x0"]) | (moves["y1"] != moves["y0"]))
    layer_z = float(moves["z1"][np.argmax(extruding)]) if extruding.any() else start_z
    return LayerParse(lines, number, layer_z, moves, meshes, blocks, state.copy(), time_lines)
