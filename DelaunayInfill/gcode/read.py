"""Reading Cura G-code: chunks, header facts, and one layer's moves and FILL blocks.

A layer is parsed in one regex pass over its text (Cura's motion lines give
their X/Y/Z/E/F words, in one order) and a few numpy operations; only the
other lines (comments, commands, odd motion lines) are looked at one by one.
The result is numpy arrays of moves plus the list of ``;TYPE:FILL`` blocks,
each with the machine state before and after it.  ``parse_layer_lines`` is
the same parser line by line: the reference, and the fallback for chunks the
fast path does not take (mode changes, a word given twice).  The machine
state is carried from chunk to chunk, so the parser sees the file as one
stream.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from itertools import chain

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
    "parse_layer_lines",
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
_ENGINE_ENDS = re.compile(r"(?:Cura_SteamEngine|CuraEngine)\s*(?:[4-9]|\d\d)\.")  # versions that write ;End of Gcode


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
        # what copy.copy does for a plain dataclass, without its generic protocol (called per block)
        new = MachineState.__new__(MachineState)
        new.__dict__.update(self.__dict__)
        return new


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
    # masks derived from `moves`, computed once per layer (read-only arrays; the moves are not changed)
    _derived: dict = field(default_factory=dict, repr=False, compare=False)

    def _remember(self, key, value: np.ndarray) -> np.ndarray:
        value.setflags(write=False)
        self._derived[key] = value
        return value

    def mesh_mask(self, name: str) -> np.ndarray:
        """Moves of mesh `name`, shape (n,) bool (read-only)."""
        hit = self._derived.get(("mesh", name))
        if hit is not None:
            return hit
        if name not in self.meshes:
            return self._remember(("mesh", name), np.zeros(len(self.moves["line"]), dtype=bool))
        return self._remember(("mesh", name), self.moves["mesh"] == self.meshes.index(name))

    def moved(self) -> np.ndarray:
        """Moves that change X or Y, shape (n,) bool (read-only)."""
        hit = self._derived.get("moved")
        if hit is None:
            m = self.moves
            hit = self._remember("moved", (m["x1"] != m["x0"]) | (m["y1"] != m["y0"]))
        return hit

    def extruding(self) -> np.ndarray:
        """Moves that change X or Y and extrude (dE > 0), shape (n,) bool (read-only)."""
        hit = self._derived.get("extruding")
        if hit is None:
            hit = self._remember("extruding", self.moved() & (self.moves["de"] > 0))
        return hit

    def kind_mask(self, kind: int) -> np.ndarray:
        """Moves of feature `kind` (TYPE_CODES), shape (n,) bool (read-only)."""
        hit = self._derived.get(("kind", kind))
        if hit is None:
            hit = self._remember(("kind", kind), self.moves["kind"] == kind)
        return hit

    def xy_segments(self) -> np.ndarray:
        """Every move as a segment, shape (n, 2, 2) (start, end; x, y) mm (read-only)."""
        hit = self._derived.get("xy_segments")
        if hit is None:
            m = self.moves
            hit = self._remember("xy_segments", np.stack([m["x0"], m["y0"], m["x1"], m["y1"]], axis=1).reshape(-1, 2, 2))
        return hit

    def xy_length(self) -> np.ndarray:
        """XY length of every move, shape (n,) mm (read-only)."""
        hit = self._derived.get("xy_length")
        if hit is None:
            m = self.moves
            hit = self._remember("xy_length", np.hypot(m["x1"] - m["x0"], m["y1"] - m["y0"]))
        return hit


@dataclass
class HeaderInfo:
    """Facts from the header and start chunk."""

    flavor: str = ""
    griffin: bool = False
    volumetric: bool = False
    layer_height: float | None = None
    generator: str = ""
    engine_version: tuple[int, int] | None = None  # CuraEngine's (major, minor), when the header says
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
    # "Cura_SteamEngine 4.13.1"; UltiGCode/Griffin headers give the version on a line of its own
    m = re.search(r"^;(?:Generated with Cura_SteamEngine|Generated with CuraEngine|GENERATOR\.VERSION:)\s*(\d+)\.(\d+)",
                  text, re.M)
    if m:
        info.engine_version = (int(m.group(1)), int(m.group(2)))
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
    if ";End of Gcode" not in last_chunk and ";End of Gcode" not in first_chunk and _ENGINE_ENDS.search(info.generator):
        # CuraEngine 4 and 5 end every file with this line, after the end G-code
        raise GCodeError("the G-code looks truncated: it ends without CuraEngine's ';End of Gcode' line")
    return info


def iter_chunks(layers: Iterable[str]) -> Iterator[str]:
    """Re-split Cura's in-memory list so that every ``;LAYER:`` line starts a chunk.

    Strings that already start at a layer pass through unchanged (no copy).
    """
    for text in layers:
        if "\n;LAYER:" not in text:  # no layer line but maybe the first: the string is one chunk
            yield text
            continue
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


def _command(line: str) -> tuple[str, str]:
    """A line's command word (upper case) and its code without the comment; ("", "") for none."""
    if line[:1] == "G" and line[1:2] in ("0", "1") and line[2:3] in (" ", ""):
        # Cura's motion lines, the bulk of a layer: no splitting needed
        return line[:2], line if ";" not in line else line.split(";", 1)[0]
    code = line.split(";", 1)[0].strip()
    return (code.split(None, 1)[0].upper(), code) if code else ("", "")


def parse_layer(text: str, state: MachineState, retraction: RetractionModel) -> LayerParse:
    """Parse one chunk, advancing `state` (mutated) and learning `retraction`.

    Cura's motion lines are read with one regex pass over the chunk and
    numpy; the few other lines (comments, commands) line by line.  A chunk
    that changes the positioning or extrusion mode (M82/M83/G90/G91), or has
    motion lines this fast path does not take, is parsed line by line
    (`parse_layer_lines`, the same result).

    Returns
    -------
    LayerParse
    """
    parse = _parse_layer_fast(text, state, retraction)
    return parse if parse is not None else parse_layer_lines(text, state, retraction)


def parse_layer_lines(text: str, state: MachineState, retraction: RetractionModel) -> LayerParse:
    """`parse_layer`, one line at a time (the reference semantics; used for unusual chunks)."""
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
        word, code = _command(line)
        if not code:
            continue
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


# ----------------------------------------------------------------------------- fast path
# ASCII digits, "." and "-" (faster than -?\d*\.?\d+); `_decimal_values` refuses the odd ones ("1.2.3",
# "-", "1-2") as float() does, and reads those it takes as the line parser reads them ("5." is 5 for both).
# Other digits (float() takes Unicode ones) leave the line to the line-by-line branch of pass A.
_NUMBER = r"([-.0-9]+)"
# One match per line: Cura's motion lines ("G1 F.. X.. Y.. Z.. E..", each word optional, in this
# order, single spaces) with their values; any other line matches the last branch with empty groups.
_CURA_LINE = re.compile(
    r"^(?:G([01])(?: F" + _NUMBER + r")?(?: X" + _NUMBER + r")?(?: Y" + _NUMBER + r")?(?: Z" + _NUMBER
    + r")?(?: E" + _NUMBER + r")?[ \t\r]*(?:;[^\n]*)?$|[^\n]*)",
    re.M,
)
_WORD_COLUMN = {"F": 0, "X": 1, "Y": 2, "Z": 3, "E": 4}
_NAN = float("nan")
_COLUMNS = np.arange(5)
_GROUPS = 6  # the regex's groups: G code, F, X, Y, Z, E
# A token of at most this many digits is an integer below 2**53, exact in float64, and 10**k (k <= 15)
# is exact too: their quotient is then correctly rounded, the value float() gives the same text.
_MAX_DIGITS = 15
_POWERS_OF_TEN = 10.0 ** np.arange(_MAX_DIGITS + 1)
_COMMA, _MINUS, _DOT, _ZERO = (ord(c) for c in ",-.0")


class _TooLong(Exception):
    """A number with more digits than `_decimal_values` reads exactly."""


def _decimal_values(joined: str, count: int) -> np.ndarray | None:
    """Read `count` comma-separated tokens of ``[-.0-9]*``, all at once.

    Parameters
    ----------
    joined : str
        The tokens joined with ``","``; an empty token is a word not given.
    count : int
        Number of tokens (commas + 1).

    Returns
    -------
    numpy.ndarray or None
        Shape (count,) float64: the value ``float(token)`` gives, NaN for an
        empty token; None when a token is no number (``float`` would raise).

    Raises
    ------
    _TooLong
        A token has more than `_MAX_DIGITS` digits (read it with ``float``).
    """
    chars = np.frombuffer(joined.encode("ascii"), dtype=np.uint8)
    is_comma = chars == _COMMA
    is_digit = chars >= _ZERO  # the alphabet is "-.,0-9": only digits are >= "0"
    digits_through = is_digit.cumsum()  # digits up to and including each char
    # digits before token t: bounds[t]; up to its end: bounds[t + 1]
    bounds = np.empty(count + 1, dtype=digits_through.dtype)
    bounds[0] = 0
    bounds[1:-1] = digits_through[is_comma]
    bounds[-1] = digits_through[-1]
    token_end = bounds[1:]
    n_digits = token_end - bounds[:-1]
    if n_digits.max() > _MAX_DIGITS:
        raise _TooLong
    token_of = is_comma.cumsum()  # token index of each char (a comma opens the next token)
    where = is_digit.nonzero()[0]
    token = token_of[where]
    after = token_end[token] - digits_through[where]  # digits after this one in its token
    values = np.bincount(token, weights=_POWERS_OF_TEN[after] * (chars[where] - _ZERO), minlength=count)
    values = values.astype(np.float64, copy=False)  # bincount of nothing is int64
    dots = (chars == _DOT).nonzero()[0]
    if len(dots):
        dot_token = token_of[dots]
        if (dot_token[1:] == dot_token[:-1]).any():
            return None  # two points in one number
        values[dot_token] /= _POWERS_OF_TEN[token_end[dot_token] - digits_through[dots]]
    minus = (chars == _MINUS).nonzero()[0]
    if len(minus):
        if not is_comma[minus[minus > 0] - 1].all():
            return None  # a minus inside a number ("1-2", "--1")
        values[token_of[minus]] *= -1.0  # -0 stays a signed zero, as float("-0") gives
    empty = n_digits == 0
    if empty.any():
        if len(dots) and empty[token_of[dots]].any() or len(minus) and empty[token_of[minus]].any():
            return None  # "-", ".", "-.": no digits
        values[empty] = _NAN
    return values


def _word_table(matches: list[tuple[str, ...]]) -> np.ndarray | None:
    """The regex groups of every line as numbers, shape (lines, 6): G code, F, X, Y, Z, E; NaN not given.

    None when a word's value is no number.
    """
    if not matches:
        return np.zeros((0, _GROUPS))
    try:
        values = _decimal_values(",".join(chain.from_iterable(matches)), _GROUPS * len(matches))
    except _TooLong:
        try:
            values = np.array([float(v) if v else _NAN for match in matches for v in match], dtype=np.float64)
        except ValueError:
            return None
    return None if values is None else values.reshape(-1, _GROUPS)


def _parse_layer_fast(text: str, state: MachineState, retraction: RetractionModel) -> LayerParse | None:
    """`parse_layer` with the motion lines vectorized; None when the chunk needs `parse_layer_lines`.

    Nothing is changed (`state`, `retraction`) before the chunk is known to fit.
    """
    if state.relative_xyz:
        return None
    lines = text.split("\n")
    n_lines = len(lines)
    start_z = state.z
    position_known = math.isfinite(state.x) and math.isfinite(state.y)  # else the first moves start nowhere
    matches = _CURA_LINE.findall(text)
    if len(matches) != n_lines:
        return None
    words = _word_table(matches)
    if words is None:
        return None
    relative_e = state.relative_e
    # ---- pass A: the non-motion lines, in order (comments, commands, unusual motion lines)
    number = None
    meshes: list[str] = [state.mesh]
    mesh_index = {state.mesh: 0}
    type_name, mesh, extruder, fw = state.type, state.mesh, state.extruder, state.fw_retracted
    kind = TYPE_CODES.get(type_name, 0)
    cur_mesh = 0
    learn_until = n_lines  # lines before the first ;TIME_ELAPSED: teach the retraction model
    firmware_seen = False
    time_lines: list[int] = []
    blocks: list[dict] = []
    current: dict | None = None
    # attributes of the moves after each processed line: (line, kind, mesh, block, extruder)
    marks = [(-1, kind, cur_mesh, -1, extruder)]
    extra_rows: list[tuple] = []  # other G0/G1 lines and G92 E (line, F, X, Y, Z, E, is_g0, is_g92)
    code_of_line = words[:, 0]  # 0 or 1 for Cura's motion lines, NaN for any other line
    is_motion = code_of_line == code_of_line

    def close_block(i):
        nonlocal current
        if current is not None:
            current["stop"] = i
            current["fw_after"] = fw
            current["mesh_after"] = mesh
            current["type_after"] = type_name
            current["extruder_after"] = extruder
            blocks.append(current)
            current = None

    for i in (~is_motion).nonzero()[0].tolist():
        line = lines[i]
        if not line:
            continue
        c = line[0]
        if c == ";":
            if line.startswith(";TYPE:"):
                close_block(i)
                type_name = line[6:].strip()
                kind = TYPE_CODES.get(type_name, 0)
                if kind == FILL and mesh != "NONMESH":
                    current = {"start": i, "mesh": mesh, "extruder": extruder, "fw_before": fw, "type": type_name,
                               "unsupported": "", "extra_lines": []}
            elif line.startswith(";MESH:"):
                close_block(i)
                mesh = line[6:].strip()
                if mesh not in mesh_index:
                    mesh_index[mesh] = len(meshes)
                    meshes.append(mesh)
                cur_mesh = mesh_index[mesh]
                if kind == FILL and mesh != "NONMESH":
                    current = {"start": i, "mesh": mesh, "extruder": extruder, "fw_before": fw, "type": type_name,
                               "unsupported": "", "extra_lines": []}
            elif line.startswith(";LAYER:"):
                close_block(i)
                try:
                    number = int(line[7:].strip())
                except ValueError:
                    number = None
            elif line.startswith(";TIME_ELAPSED:"):
                close_block(i)
                time_lines.append(i)
                learn_until = min(learn_until, i)
            else:
                continue
            marks.append((i, kind, cur_mesh, len(blocks) if current is not None else -1, extruder))
            continue
        word, code = _command(line)
        if not code:
            continue
        if word in ("G0", "G1", "G00", "G01"):
            row = [i, _NAN, _NAN, _NAN, _NAN, _NAN, word in ("G0", "G00"), False]
            for key, val in _PARAM.findall(code):
                k = _WORD_COLUMN[key] + 1
                if row[k] == row[k]:
                    return None  # a word given twice: leave it to the line-by-line parser
                row[k] = float(val)
            extra_rows.append(tuple(row))
        elif word == "G92":
            for key, val in _PARAM.findall(code):
                if key == "E":
                    extra_rows.append((i, _NAN, _NAN, _NAN, _NAN, float(val), False, True))
                elif key in "XYZ":
                    if current is not None:
                        current["unsupported"] = "G92 X/Y/Z inside FILL"
        elif word == "G10":
            fw = True
            if i < learn_until:
                firmware_seen = True
        elif word == "G11":
            fw = False
        elif word in ("M82", "M83", "G90", "G91"):
            # a mode change would make the moves after it read differently: not for the fast path
            if word == "M82" and (relative_e or state.e_mode_relative):
                return None
            if word == "M83" and not (relative_e and state.e_mode_relative):
                return None
            if word == "G91" or (word == "G90" and relative_e != state.e_mode_relative):
                return None
            if current is not None:
                current["unsupported"] = f"{word} inside FILL"
        elif word[0] == "T" and word[1:].isdigit():
            close_block(i)
            extruder = int(word[1:])
            marks.append((i, kind, cur_mesh, -1, extruder))
        elif word in ("G2", "G3", "G02", "G03", "G28", "G29"):
            if current is not None:
                current["unsupported"] = f"{word} inside FILL"
        elif current is not None:
            current["extra_lines"].append(line)
    close_block(n_lines)

    # ---- pass B: every move at once
    motion_lines = is_motion.nonzero()[0]
    # row 0: the state before the chunk; row r + 1: the words of move r (NaN: not given)
    table = np.empty((len(motion_lines) + 1, 5), dtype=np.float64)
    table[0] = state.f, state.x, state.y, state.z, state.e
    table[1:] = words[motion_lines, 1:]
    is_g0 = code_of_line[motion_lines] == 0.0  # travels teach the travel speed
    line_of = motion_lines.tolist()
    is_g92 = None  # rows that are G92 E (they set the E register, they are no moves)
    if extra_rows:
        rows = sorted([*zip(line_of, table[1:].tolist(), is_g0.tolist(), [False] * len(line_of)),
                       *((r[0], list(r[1:6]), r[6], r[7]) for r in extra_rows)], key=lambda r: r[0])
        line_of = [r[0] for r in rows]
        table = np.array([table[0].tolist(), *(r[1] for r in rows)], dtype=np.float64)
        is_g0 = np.array([r[2] for r in rows], dtype=bool)
        is_g92 = np.array([r[3] for r in rows], dtype=bool)
        if not is_g92.any():
            is_g92 = None
    n = len(line_of)
    given = table == table
    idx = np.where(given, np.arange(n + 1)[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    full = table[idx, _COLUMNS]  # F X Y Z E after each row (the E register in absolute mode)
    has_e = given[1:, 4]
    if is_g92 is not None:
        has_e = has_e & ~is_g92
    if not relative_e:
        de = np.where(has_e, table[1:, 4] - full[:-1, 4], 0.0)
    else:
        de = np.where(has_e, table[1:, 4], 0.0)
        # the register adds every E word in order (from the last G92 E), like the firmware
        rows_e = np.flatnonzero(given[1:, 4])
        if is_g92 is None:
            e_after = np.cumsum(np.r_[state.e, table[rows_e + 1, 4]])
        else:
            value, e_after = state.e, [state.e]
            for v, reset in zip(table[rows_e + 1, 4].tolist(), is_g92[rows_e].tolist(), strict=True):
                value = v if reset else value + v
                e_after.append(value)
            e_after = np.asarray(e_after, dtype=np.float64)
        reg = np.zeros(n + 1, dtype=np.int64)
        reg[rows_e + 1] = np.arange(1, len(rows_e) + 1)
        np.maximum.accumulate(reg, out=reg)
        full[:, 4] = e_after[reg]
    before, after = full[:-1], full[1:]
    x0, y0, z0 = before[:, 1], before[:, 2], before[:, 3]
    f1, x1, y1, z1 = after[:, 0], after[:, 1], after[:, 2], after[:, 3]
    if position_known:
        moved = (x1 != x0) | (y1 != y0)
    else:  # NaN (position unknown before the first move) counts as no motion on that axis
        moved = ((x1 != x0) & ((x0 == x0) | (x1 == x1))) | ((y1 != y0) & ((y0 == y0) | (y1 == y1)))
    e_move = de != 0.0

    # ---- pass C: retraction depth and what the retraction model learns (few moves)
    learn_rows = bisect.bisect_left(line_of, learn_until)  # rows before the first ;TIME_ELAPSED:
    e_only = (e_move & ~moved).nonzero()[0].tolist()  # retractions and primes
    extruding_all = moved & (de > 0)
    extruding_rows = extruding_all.nonzero()[0].tolist()  # each one resets the depth
    e_only_de = de[e_only].tolist()
    retract_update = prime_update = hop_update = travel_update = None
    retract_rows: list[int] = []
    for r, d in zip(e_only, e_only_de, strict=True):
        if d < 0:
            retract_rows.append(r)
            if r < learn_rows:
                retract_update = (-d, f1[r].item())
        elif r < learn_rows:
            prime_update = f1[r].item()
    hop = ~moved & (z1 > z0)
    if hop.any():
        for r in (hop[:learn_rows] & ~e_move[:learn_rows]).nonzero()[0][::-1].tolist():
            k = bisect.bisect_left(retract_rows, r) - 1  # the last retraction before it
            if line_of[r] - (line_of[retract_rows[k]] if k >= 0 else -10) <= 2:
                hop_update = (z1[r].item() - z0[r].item(), f1[r].item())
                break
    if learn_rows:
        travels = (is_g0[:learn_rows] & moved[:learn_rows] & ~e_move[:learn_rows]).nonzero()[0]
        if len(travels):
            travel_update = f1[travels[-1]].item()

    def depth_before(row: int) -> float:
        """Retraction depth before move `row` (after all moves before it)."""
        k = bisect.bisect_left(extruding_rows, row) - 1
        first = extruding_rows[k] if k >= 0 else -1
        depth = 0.0 if k >= 0 else state.depth
        for j in range(bisect.bisect_right(e_only, first), bisect.bisect_left(e_only, row)):
            d = e_only_de[j]
            depth = depth - d if d < 0 else max(0.0, depth - d)
        return depth

    # ---- commit: the chunk fits the fast path
    if retract_update is not None:
        retraction.amount, retraction.retract_f = retract_update
        retraction.seen = True
    if prime_update is not None:
        retraction.prime_f = prime_update
    if hop_update is not None:
        retraction.hop, retraction.hop_f = hop_update
    if travel_update is not None:
        retraction.travel_f = travel_update
    if firmware_seen:
        retraction.firmware = True
        retraction.seen = True

    def state_before(i: int, fw_now: bool, type_now: str, mesh_now: str, extruder_now: int) -> MachineState:
        r = bisect.bisect_left(line_of, i)  # moves before line i
        f, x, y, z, e = full[r].tolist()
        return MachineState(x, y, z, e, f, relative_e, False, state.e_mode_relative,
                            depth_before(r), fw_now, extruder_now, type_now, mesh_now)

    if is_g92 is not None:
        real = ~is_g92
        move_lines = [i for i, g in zip(line_of, is_g92.tolist(), strict=True) if not g]
    else:
        real = slice(None)
        move_lines = line_of
    fill_blocks = []
    for b in blocks:
        has_moves = bisect.bisect_left(move_lines, b["start"]) < bisect.bisect_left(move_lines, b["stop"])
        fill_blocks.append(FillBlock(
            b["start"], b["stop"], b["mesh"], b["extruder"],
            state_before(b["start"], b["fw_before"], b["type"], b["mesh"], b["extruder"]),
            state_before(b["stop"], b["fw_after"], b["type_after"], b["mesh_after"], b["extruder_after"]),
            has_moves=has_moves, unsupported=b["unsupported"], extra_lines=b["extra_lines"],
        ))
    end = state_before(n_lines, fw, type_name, mesh, extruder)
    for name in ("x", "y", "z", "e", "f", "depth", "fw_retracted", "extruder", "type", "mesh"):
        setattr(state, name, getattr(end, name))

    # kind, mesh, block and extruder of each move: those after the last pass-A mark before it
    attrs = np.array(marks, dtype=np.int64)
    # (the motion lines found by the regex, when no other line made a move)
    move_lines_arr = motion_lines.astype(np.int64) if move_lines is line_of and not extra_rows else np.array(
        move_lines, dtype=np.int64)
    row_attrs = attrs[attrs[:, 0].searchsorted(move_lines_arr) - 1, 1:].T.copy()
    # one copy: each column a contiguous row of its own (no two share memory)
    columns = np.empty((8, n))
    columns[0:3] = before[:, 1:4].T
    columns[3:6] = after[:, 1:4].T
    columns[6] = de
    columns[7] = f1
    if is_g92 is not None:
        columns = columns[:, real]
    moves = {
        "line": move_lines_arr,
        "x0": columns[0], "y0": columns[1], "z0": columns[2],
        "x1": columns[3], "y1": columns[4], "z1": columns[5],
        "de": columns[6], "f": columns[7],
        "kind": row_attrs[0], "mesh": row_attrs[1], "block": row_attrs[2], "ext": row_attrs[3],
    }
    if position_known:
        if is_g92 is not None:
            moved, extruding_all = moved[real], extruding_all[real]
        extruding = extruding_all
    else:
        # A move from an unknown position (nothing before it set X/Y) is no segment: start it where it ends.
        for a, b in (("x0", "x1"), ("y0", "y1")):
            unknown = ~np.isfinite(moves[a])
            if unknown.any():
                moves[a][unknown] = moves[b][unknown]
        moved = (moves["x1"] != moves["x0"]) | (moves["y1"] != moves["y0"])
        extruding = (moves["de"] > 0) & moved
    first = extruding.nonzero()[0][:1]
    layer_z = float(moves["z1"][first[0]]) if len(first) else start_z
    parse = LayerParse(lines, number, layer_z, moves, meshes, fill_blocks, state.copy(), time_lines)
    parse._remember("moved", moved)
    parse._remember("extruding", extruding)
    return parse
