"""An independent checker for everyday models: infill only where Cura printed infill.

The prismatic checks of :mod:`gcode_check` build the infill area from a prism's
outline.  Everyday models (holes, rings, skin beside infill in one layer,
lettering, domes, thin pillars) have no such outline, so this checker takes its
truth from two other sources:

* a REFERENCE slice: the same model sliced by CuraEngine with identical
  settings except infill pattern "lines" and ``infill_line_distance`` equal to
  the infill line width.  Its FILL lines, buffered by half a line width, tile
  Cura's sparse-infill area of each layer (the *reference area*);
* ``section_at(z)``: the model's true cross-section at height z, in G-code XY,
  which says where there is material at all.

It shares no code with ``DelaunayInfill.gcode`` (the reconstruction under test),
nor with :mod:`gcode_check`: the G-code is read by :func:`extract_layers`, a
vectorized reader of its own (numpy over the whole text, about a million lines
a second), the geometry is shapely, numpy and scipy.

Usage::

    result = check_everyday(original, processed, reference, section_at, spacing=4.0, line_width=0.4)
    assert result.ok, result.report() + "\\n" + layer_table(result)

Lengths are measured by sampling each segment every :data:`SAMPLE_STEP_MM` and
weighting each sample with its share of the segment's length, so "mm outside"
is exact up to one step per boundary crossing.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

# --------------------------------------------------------------------------- thresholds

#: check 1, containment: new FILL length outside the reference area grown by half a line width,
#: as a fraction of the file's new FILL length ...
MAX_OUTSIDE_FRACTION_FILE = 0.003
#: ... and of one layer's new FILL length (for layers with at least MIN_LAYER_MM_FOR_FRACTION of it)
MAX_OUTSIDE_FRACTION_LAYER = 0.01
#: layers with less new FILL than this (mm) are left out of the per-layer fraction (counted in the file's)
MIN_LAYER_MM_FOR_FRACTION = 20.0

#: check 2, material: new FILL length outside the true section grown by half a line width must stay
#: under this fraction of the file's new FILL length ...
MAX_MATERIAL_FRACTION_FILE = 0.0005
#: ... and under this length (mm) in any one layer
MAX_MATERIAL_MM_LAYER = 2.0

#: check 4, coverage: file-wide share of the points along Cura's FILL with new FILL within `spacing`
MIN_COVERAGE = 0.99

#: check 6, walls: new FILL within this many line widths of a wall line's centre is on the wall (Cura's
#: lines end half a line width minus the infill overlap from the inner wall's centre) ...
ON_WALL_RADIUS_WIDTHS = 0.25
#: ... and a layer may have this much more of it (mm) than Cura's FILL had, scaled to the new length
MAX_ON_WALL_MM_LAYER = 1.0

#: check 5, islands: an island counts when Cura's FILL in it is at least this many line widths long,
#: and it is lost unless the new FILL within it (grown by a line width) is at least as long; Cura's
#: stubs, runs of FILL shorter than this, do not count (they print as blobs: the pass leaves them out)
ISLAND_MIN_LINE_WIDTHS = 1.0

#: the feature types of the original file that are skin
SKIN_TYPES = frozenset({"SKIN"})
#: ... and that are walls
WALL_TYPES = frozenset({"WALL-OUTER", "WALL-INNER"})

#: sampling step along segments for the length measurements, mm
SAMPLE_STEP_MM = 0.2
#: buffer resolution (segments per quarter circle): round caps need no precision at 0.2 mm radii
QUAD_SEGS = 3
#: the dense reference lines lie exactly one line width apart, so their half-width buffers only
#: touch; this much extra radius (mm) makes them overlap, so that an island is one polygon
REFERENCE_MERGE_MM = 0.01

#: at most this many problems are kept (the figures still count everything)
MAX_PROBLEMS = 200


# --------------------------------------------------------------------------- results


@dataclass
class LayerRow:
    """The figures of one layer (lengths in mm)."""

    layer: int  # the ;LAYER: number
    occurrence: int  # 0, or 1, 2... when layer numbers restart (one-at-a-time printing)
    z: float  # top of the layer, mm (from its moves)
    new_mm: float  # new FILL extrusion length
    outside_mm: float  # of it, outside the reference area grown by line_width / 2
    material_mm: float  # of it, outside the true section grown by line_width / 2
    on_skin_mm: float  # of it, on Cura's skin that is not infill area
    on_wall_mm: float  # of it, on a wall line of any mesh (check 6)
    original_on_wall_mm: float  # Cura's FILL on a wall line
    original_mm: float  # Cura's FILL extrusion length
    coverage_samples: int  # points along Cura's FILL, one per line width
    coverage_hits: int  # of them, with new FILL within `spacing`
    islands: int  # islands of the reference area where Cura printed FILL
    lost_islands: int  # of them, without new FILL

    @property
    def label(self) -> str:
        return str(self.layer) if self.occurrence == 0 else f"{self.layer}#{self.occurrence}"

    @property
    def outside_fraction(self) -> float:
        return self.outside_mm / self.new_mm if self.new_mm > 0 else 0.0

    @property
    def coverage(self) -> float:
        return self.coverage_hits / self.coverage_samples if self.coverage_samples else math.nan


@dataclass
class LostIsland:
    """An island of the reference area where Cura printed FILL and the processed file prints none."""

    layer: str  # LayerRow.label
    centroid: tuple[float, float]  # G-code XY, mm
    area: float  # mm^2
    original_mm: float  # Cura's FILL length in it
    new_mm: float  # new FILL length within it grown by a line width


@dataclass
class EverydayResult:
    """What :func:`check_everyday` found."""

    problems: list[str] = field(default_factory=list)
    figures: dict = field(default_factory=dict)
    rows: list[LayerRow] = field(default_factory=list)
    lost_islands: list[LostIsland] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def add_problem(self, message: str) -> None:
        if len(self.problems) < MAX_PROBLEMS:
            self.problems.append(message)

    def report(self, max_problems: int = 10) -> str:
        """A short multi-line summary: verdict, the figures, the first problems."""
        lines = [f"everyday check: {'ok' if self.ok else f'FAILED ({len(self.problems)} problems)'}"]
        lines += [f"  {key}: {value}" for key, value in self.figures.items()]
        lines += [f"  - {problem}" for problem in self.problems[:max_problems]]
        if len(self.problems) > max_problems:
            lines.append(f"  ... and {len(self.problems) - max_problems} more")
        return "\n".join(lines)


# --------------------------------------------------------------------------- G-code per layer
#
# A small reader of its own (it shares no code with DelaunayInfill.gcode nor with
# gcode_check.parse_gcode): the text is read as one byte array and every step is a numpy
# operation over all lines, or over all words of one letter, at once.  Only the few structure
# comments (;TYPE:, ;LAYER:, ...) are looked at one by one.


@dataclass
class LayerMoves:
    """The extrusion segments of one layer of one file.

    Attributes
    ----------
    z : float
        Z of the layer's first extruding move, mm (nan when it has none).
    fill, skin, walls : np.ndarray
        (k, 2, 2) XY segments of the extruding ``;TYPE:FILL``, ``;TYPE:SKIN`` and wall
        (``WALL-OUTER``, ``WALL-INNER``) moves, mm, in file order: ``segments[i, 0]`` is
        where move i starts, ``segments[i, 1]`` where it ends.
    """

    z: float
    fill: np.ndarray
    skin: np.ndarray
    walls: np.ndarray = field(default_factory=lambda: _EMPTY_SEGMENTS)


_EMPTY_SEGMENTS = np.zeros((0, 2, 2))

_NEWLINE, _SEMICOLON, _DOT, _MINUS, _PLUS = b"\n;.-+"
_ZERO = ord("0")
#: numbers of this many bytes or more (sign, digits and point) are read with float() instead;
#: at most 15, so that the digits make an exact float64 integer
_NUMBER_WIDTH = 12
_POWERS_OF_TEN = 10 ** np.arange(19, dtype=np.int64)
_POWERS_OF_TEN_FLOAT = _POWERS_OF_TEN.astype(float)  # exact: 10**18 = 2**18 * 5**18
_LONG_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)")
#: the structure comments the reader follows, at the start of a line
#: (searched in the text after a newline: a literal start is what makes the search fast)
_STRUCTURE = re.compile(rb"\n;(TYPE|LAYER|MESH|TIME_ELAPSED):([^\n]*)")
#: a move's "extruding" needs more XY travel (mm) and more E (mm of filament) than this
_EPSILON = 1e-9

# feature contexts of the lines (the codes of _context_of)
_OTHER, _FILL, _SKIN, _WALL = 0, 1, 2, 3


@dataclass
class _Text:
    """A G-code text as bytes, with ``\\n`` line ends and no blanks at the start of a line."""

    data: bytes
    buf: np.ndarray  # (b,) uint8, the bytes
    padded: np.ndarray  # (b + pad,) uint8, the bytes and zeros (for windows that run past the end)
    newlines: np.ndarray  # (n - 1,) int, offsets of the newlines
    line_starts: np.ndarray  # (n,) int, offsets of the line starts: line i runs up to newlines[i]
    semicolons: np.ndarray  # (c,) int, offsets of the semicolons (comment starts)


def _text(text: str) -> _Text:
    """Index the lines of `text` (CR LF and CR line ends become LF, indented lines lose their indent)."""
    data = text.encode("utf-8")
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    while True:
        buf = np.frombuffer(data, dtype=np.uint8)
        padded = np.concatenate([buf, np.zeros(_NUMBER_WIDTH + 4, dtype=np.uint8)])
        newlines = np.flatnonzero(buf == _NEWLINE)
        line_starts = np.concatenate([[0], newlines + 1])
        first = padded[line_starts]
        if not ((first == ord(" ")) | (first == ord("\t"))).any():
            return _Text(data, buf, padded, newlines, line_starts, np.flatnonzero(buf == _SEMICOLON))
        data = re.sub(rb"^[ \t]+", b"", data, flags=re.M)  # rare: not Cura's output


def _window(padded: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """(n, width) uint8: the `width` bytes from each offset of `starts` (n,) (zero past the end)."""
    return np.lib.stride_tricks.sliding_window_view(padded, width)[starts]


def _is_number_byte(chars: np.ndarray) -> np.ndarray:
    """Bool, the shape of `chars`: a digit or a decimal point (what continues a G-code command number)."""
    return ((chars >= _ZERO) & (chars <= _ZERO + 9)) | (chars == _DOT)


def _command_is(head: np.ndarray, word: bytes) -> np.ndarray:
    """(n,) bool: the lines whose head (n, 4) bytes are the command `word` (``b"G1"``, ``b"M83"``)."""
    match = ~_is_number_byte(head[:, len(word)])
    for column, char in enumerate(word):
        match &= head[:, column] == char
    return match


def _parse_numbers(padded: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """The decimal numbers ``[-+]digits[.digits]`` that begin at the byte offsets `starts`.

    Each number's digits are weighed by their column in a window of
    :data:`_NUMBER_WIDTH` bytes (one matrix product, the point and the sign counting
    as a digit 0), and the integer so made is split at the point: every step is
    exact integer arithmetic in float64, and the one division at the end by a
    power of ten rounds correctly, so every value equals ``float()`` of its text.
    A number that fills the window or has two points (never in Cura's output) is
    read with ``float()``.

    Parameters
    ----------
    padded : np.ndarray
        The text, uint8, followed by at least :data:`_NUMBER_WIDTH` zero bytes.
    starts : np.ndarray
        (k,) int byte offsets.

    Returns
    -------
    np.ndarray
        (k,) float; nan where no digit follows.
    """
    width = _NUMBER_WIDTH
    chars = _window(padded, starts, width)  # (k, w)
    digit = chars - np.uint8(_ZERO)  # wraps round for the bytes below "0"
    is_digit = digit <= 9
    is_dot = chars == _DOT
    acceptable = is_digit | is_dot
    acceptable[:, 0] |= (chars[:, 0] == _MINUS) | (chars[:, 0] == _PLUS)
    length = np.argmin(acceptable, axis=1)  # bytes of the number: up to the first other byte
    too_long = acceptable[:, 0] & (length == 0)  # all acceptable (argmin of all True is 0)
    inside = np.arange(width) < length[:, None]
    digits = is_digit & inside
    dots = is_dot & inside
    points = np.count_nonzero(dots, axis=1)
    point = np.where(points > 0, np.argmax(dots, axis=1), length)  # column of the point, or the end
    # the bytes as one integer, column j weighing 10 ** (w - 1 - j)
    whole = (digit * digits).astype(np.float64) @ _POWERS_OF_TEN_FLOAT[width - 1::-1]
    before_point, after_point = np.divmod(whole, _POWERS_OF_TEN_FLOAT[width - point])
    decimals = np.where(points > 0, length - 1 - point, 0)
    mantissa = before_point * _POWERS_OF_TEN_FLOAT[decimals] + after_point / _POWERS_OF_TEN_FLOAT[width - length]
    values = mantissa / _POWERS_OF_TEN_FLOAT[decimals]
    values[chars[:, 0] == _MINUS] *= -1
    values[~digits.any(axis=1)] = np.nan
    for index in np.flatnonzero(too_long | (points > 1)):
        start = int(starts[index])
        number = _LONG_NUMBER.match(padded[start:start + 64].tobytes())
        values[index] = float(number.group()) if number else np.nan
    return values


def _register(values: np.ndarray, given: np.ndarray, relative: np.ndarray, initial: float) -> np.ndarray:
    """A machine register (an axis position or the E counter) after each line.

    Parameters
    ----------
    values : np.ndarray
        (n,) float: the line's word for this register (mm); read only where `given`.
    given : np.ndarray
        (n,) bool: the line sets the register (a move or G92 with the word).
    relative : np.ndarray
        (n,) bool: the word is an increment (relative mode), not a new value.
    initial : float
        The register before the first line, mm (nan: unknown).

    Returns
    -------
    np.ndarray
        (n,) float, mm.
    """
    increments = np.cumsum(np.where(given & relative, values, 0.0))
    absolute = given & ~relative
    last = np.maximum.accumulate(np.where(absolute, np.arange(len(values)), -1))
    # since the last absolute value: that value plus the increments after it
    base = np.where(last >= 0, values[last] - increments[last], initial)
    return base + increments


def _latest_mode(sets_on: np.ndarray, sets_off: np.ndarray) -> np.ndarray:
    """(n,) bool: whether the last of the lines (n,) that switch a mode on or off switched it on (off at first)."""
    switch = np.flatnonzero(sets_on | sets_off)
    if len(switch) == 0:
        return np.zeros(len(sets_on), dtype=bool)
    last = np.searchsorted(switch, np.arange(len(sets_on)), side="right") - 1
    return (last >= 0) & sets_on[switch[np.maximum(last, 0)]]


@dataclass
class _Structure:
    """The structure comments of a file, by line index (0-based)."""

    layer_lines: np.ndarray  # (L,) int: the ;LAYER: lines, in file order
    layer_numbers: list  # (L,) their numbers (None when not an integer)
    mark_lines: np.ndarray  # (M,) int: lines that start a feature context (sorted)
    mark_context: np.ndarray  # (M,) int: the context each starts (_FILL, _SKIN, _OTHER)


def _structure(data: bytes, newlines: np.ndarray, tool_lines: np.ndarray) -> _Structure:
    """Layers and feature contexts from the comments (and the tool changes `tool_lines`, (t,) int).

    A ``;TYPE:`` starts its feature; ``;LAYER:``, ``;MESH:NONMESH`` (travel between
    meshes), ``;TIME_ELAPSED:`` (a layer's end) and a tool change end it.  A
    ``;MESH:`` naming a mesh leaves the feature as it is.
    """
    layer_offsets, layer_numbers, mark_offsets, mark_context = [], [], [], []
    for match in _STRUCTURE.finditer(b"\n" + data):  # match.start(): the comment's offset in `data`
        tag, value = match.group(1), match.group(2).strip().decode("utf-8", "replace")
        if tag == b"MESH" and value != "NONMESH":
            continue
        if tag == b"TYPE":
            context = (_FILL if value == "FILL" else _SKIN if value in SKIN_TYPES
                       else _WALL if value in WALL_TYPES else _OTHER)
        else:
            context = _OTHER
        mark_offsets.append(match.start())
        mark_context.append(context)
        if tag == b"LAYER":
            layer_offsets.append(match.start())
            try:
                layer_numbers.append(int(value))
            except ValueError:
                layer_numbers.append(None)
    mark_lines = np.searchsorted(newlines, np.asarray(mark_offsets, dtype=np.int64))
    order = np.argsort(np.concatenate([mark_lines, tool_lines]), kind="stable")
    return _Structure(
        layer_lines=np.searchsorted(newlines, np.asarray(layer_offsets, dtype=np.int64)),
        layer_numbers=layer_numbers,
        mark_lines=np.concatenate([mark_lines, tool_lines])[order],
        mark_context=np.concatenate([np.asarray(mark_context, dtype=np.int8),
                                     np.full(len(tool_lines), _OTHER, dtype=np.int8)])[order],
    )


def _context_of(structure: _Structure, lines: np.ndarray) -> np.ndarray:
    """(k,) int8: the feature context (_FILL, _SKIN, _WALL, _OTHER) of each of the lines (k,) int."""
    mark = np.searchsorted(structure.mark_lines, lines, side="right") - 1
    if len(structure.mark_lines) == 0:
        return np.full(len(lines), _OTHER, dtype=np.int8)
    return np.where(mark >= 0, structure.mark_context[np.maximum(mark, 0)], _OTHER).astype(np.int8)


@dataclass
class _Commands:
    """What each line (n,) of a text is, and the modes in force on it."""

    move: np.ndarray  # (n,) bool: G0 / G1
    g92: np.ndarray  # (n,) bool: G92 (sets positions)
    relative_xyz: np.ndarray  # (n,) bool: after G91, until G90
    relative_e: np.ndarray  # (n,) bool: after M83 or G91, until M82 or G90
    tool_lines: np.ndarray  # (t,) int: the tool changes (T0, T1...)


def _commands(lines: _Text) -> _Commands:
    """Classify the lines of `lines` by their first word."""
    head = _window(lines.padded, lines.line_starts, 4)
    move = (_command_is(head, b"G0") | _command_is(head, b"G1")
            | _command_is(head, b"G00") | _command_is(head, b"G01"))
    g90, g91 = _command_is(head, b"G90"), _command_is(head, b"G91")
    return _Commands(
        move=move,
        g92=_command_is(head, b"G92"),
        relative_xyz=_latest_mode(g91, g90),
        # Marlin: G90 / G91 switch E too; M82 / M83 switch E alone
        relative_e=_latest_mode(g91 | _command_is(head, b"M83"), g90 | _command_is(head, b"M82")),
        tool_lines=np.flatnonzero((head[:, 0] == ord("T")) & (head[:, 1] >= _ZERO) & (head[:, 1] <= _ZERO + 9)),
    )


def _word_values(lines: _Text, wanted: np.ndarray, letter: str) -> np.ndarray:
    """(n,) float: the `letter` word of each `wanted` line ((n,) bool), mm; nan where there is none.

    Words may come in any order; what follows a ``;`` is a comment; a letter given
    twice keeps its last value.
    """
    semicolons = lines.semicolons
    at = np.flatnonzero(lines.buf == ord(letter))
    line = np.searchsorted(lines.newlines, at)
    # in a wanted line, and no semicolon between the line's start and the letter
    uncommented = np.searchsorted(semicolons, at) == np.searchsorted(semicolons, lines.line_starts[line])
    keep = wanted[line] & uncommented
    values = np.full(len(lines.line_starts), np.nan)
    values[line[keep]] = _parse_numbers(lines.padded, at[keep] + 1)
    return values


@dataclass
class _Moves:
    """The G0 / G1 moves (m,) of a text, in absolute coordinates (mm)."""

    lines: np.ndarray  # (m,) int: their line indices
    start: np.ndarray  # (m, 2) XY before the move (nan before the first X / Y)
    end: np.ndarray  # (m, 2) XY after it
    z: np.ndarray  # (m,) Z after it
    de: np.ndarray  # (m,) E increase, mm of filament (negative: a retraction)


def _moves(lines: _Text, commands: _Commands) -> _Moves:
    """Follow the machine's X, Y, Z and E registers through the text: its moves."""
    wanted = commands.move | commands.g92
    words, registers = {}, {}
    for axis, relative, initial in (("X", commands.relative_xyz, np.nan), ("Y", commands.relative_xyz, np.nan),
                                    ("Z", commands.relative_xyz, np.nan), ("E", commands.relative_e, 0.0)):
        words[axis] = _word_values(lines, wanted, axis)
        # G92 sets a register, in either mode
        registers[axis] = _register(words[axis], ~np.isnan(words[axis]), relative & ~commands.g92, initial)
    moves = np.flatnonzero(commands.move)
    before = moves - 1  # the registers after the line before a move are those the move starts from

    def start_of(axis: str, initial: float) -> np.ndarray:
        return np.where(moves > 0, registers[axis][np.maximum(before, 0)], initial)

    e_word = words["E"][moves]
    absolute_de = registers["E"][moves] - start_of("E", 0.0)
    de = np.where(np.isnan(e_word), 0.0, np.where(commands.relative_e[moves], e_word, absolute_de))
    return _Moves(
        lines=moves,
        start=np.stack([start_of("X", np.nan), start_of("Y", np.nan)], axis=1),
        end=np.stack([registers["X"][moves], registers["Y"][moves]], axis=1),
        z=registers["Z"][moves],
        de=de,
    )


def extract_layers(text: str) -> dict[tuple[int, int], LayerMoves]:
    """Per ``;LAYER:`` of a G-code text: its z and its extruding FILL and SKIN segments.

    The reader follows what Cura writes: G0/G1 with X, Y, Z, E (and F) words in
    any order, a comment after ``;``; absolute (M82) or relative (M83) E, G92
    resets of E (and of X, Y, Z); G91/G90 relative positioning (as in Marlin,
    they switch E too, until the next M82/M83).  A move extrudes when its XY
    position changes and E increases, so retractions, primes (E only) and
    firmware retraction (G10/G11, no E at all) never count.  The feature of a
    move is that of the last ``;TYPE:`` before it in its layer (see
    :func:`_structure`); moves before the first ``;LAYER:`` belong to no layer.

    Parameters
    ----------
    text : str
        The G-code.

    Returns
    -------
    dict
        (layer number, occurrence) -> :class:`LayerMoves`, in file order.  The
        occurrence is 0, or 1, 2... when a layer number comes again (one object
        at a time printing restarts the numbers); a ``;LAYER:`` without an
        integer gets the number -10000 - its position in the file.
    """
    lines = _text(text)
    commands = _commands(lines)
    moves = _moves(lines, commands)
    extruding = (moves.de > _EPSILON) & (np.hypot(*(moves.end - moves.start).T) > _EPSILON)
    at = moves.lines[extruding]
    segments = np.stack([moves.start[extruding], moves.end[extruding]], axis=1)  # (k, 2, 2)
    structure = _structure(lines.data, lines.newlines, commands.tool_lines)
    layer = np.searchsorted(structure.layer_lines, at, side="right") - 1  # -1: before the first layer
    bounds = np.searchsorted(layer, np.arange(len(structure.layer_lines) + 1))
    return _per_layer(structure.layer_numbers, bounds, segments, moves.z[extruding], _context_of(structure, at))


def _per_layer(numbers: list, bounds: np.ndarray, segments: np.ndarray, z: np.ndarray,
               context: np.ndarray) -> dict[tuple[int, int], LayerMoves]:
    """Cut the extruding moves (k,) into layers: layer i holds moves bounds[i] to bounds[i + 1]."""
    seen: dict[int, int] = {}
    out: dict[tuple[int, int], LayerMoves] = {}
    for seq, number in enumerate(numbers):
        key_number = number if number is not None else -10_000 - seq
        occurrence = seen.get(key_number, 0)
        seen[key_number] = occurrence + 1
        here = slice(bounds[seq], bounds[seq + 1])
        kinds = context[here]
        out[(key_number, occurrence)] = LayerMoves(
            z=float(z[here][0]) if bounds[seq + 1] > bounds[seq] else math.nan,
            fill=segments[here][kinds == _FILL],
            skin=segments[here][kinds == _SKIN],
            walls=segments[here][kinds == _WALL],
        )
    return out


def _layer_heights(layers: dict[tuple[int, int], LayerMoves]) -> dict[tuple[int, int], float]:
    """Each layer's height, mm: its z minus the previous layer's z, in file order.

    A first layer, a layer after a restart (one at a time) or after a raft's air
    gap has no sensible difference; it gets the typical (median) layer height,
    or its own z when that is smaller.
    """
    keys = [k for k, layer in layers.items() if not math.isnan(layer.z)]
    zs = np.array([layers[k].z for k in keys])
    steps = np.diff(zs)
    positive = steps[steps > 1e-6]
    typical = float(np.median(positive)) if len(positive) else (float(zs[0]) if len(zs) else 0.2)
    heights = {}
    for i, key in enumerate(keys):
        step = float(steps[i - 1]) if i > 0 else math.nan
        if 1e-6 < step <= 2 * typical:
            heights[key] = step
        else:
            heights[key] = min(typical, float(zs[i])) if zs[i] > 0 else typical
    return heights


# --------------------------------------------------------------------------- geometry helpers


def _samples_per_segment(segments: np.ndarray, step: float) -> np.ndarray:
    """How many points `sample_segments(segments, step)` puts on each segment: int (k,)."""
    delta = segments[:, 1] - segments[:, 0]
    return np.maximum(1, np.ceil(np.hypot(delta[:, 0], delta[:, 1]) / step).astype(int))


def sample_segments(segments: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along segments, at the midpoints of equal pieces no longer than `step`.

    Parameters
    ----------
    segments : np.ndarray
        (k, 2, 2) segment end points, mm.
    step : float
        Largest piece length, mm.

    Returns
    -------
    points : np.ndarray
        (n, 2) mm.
    weights : np.ndarray
        (n,) the length each point stands for, mm; they sum to the segments' length.
    """
    if len(segments) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    delta = segments[:, 1] - segments[:, 0]
    length = np.hypot(delta[:, 0], delta[:, 1])
    counts = _samples_per_segment(segments, step)
    owner = np.repeat(np.arange(len(segments)), counts)
    index_in_segment = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t = (index_in_segment + 0.5) / counts[owner]
    points = segments[owner, 0] + t[:, None] * delta[owner]
    return points, (length / counts)[owner]


def lines_buffer(segments: np.ndarray, radius: float, ends: str = "square") -> BaseGeometry:
    """The union of the segments buffered by `radius` (mm): the area the extrusion covers.

    Square ends and mitred joins: the union of many dense lines then has a few
    straight edges instead of a scallop of round caps, which makes it several
    times cheaper to build, grow and test points against.  A square end lies
    at most (sqrt(2) - 1) * radius (0.08 mm for a 0.4 mm line) beyond a round one,
    at its corners only.  `ends` "flat": the buffers end at the segments' ends.
    """
    if len(segments) == 0:
        return Polygon()
    lines = shapely.multilinestrings(shapely.linestrings(segments))
    area = shapely.buffer(lines, radius, cap_style=ends, join_style="mitre")
    # the line ends along a straight border are collinear vertices: drop them
    return area.simplify(radius / 50)


def _inside(area: BaseGeometry | None, points: np.ndarray) -> np.ndarray:
    """(n,) bool: the points (n, 2) that lie inside `area` (nothing is inside an empty area)."""
    if area is None or area.is_empty or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    shapely.prepare(area)
    return shapely.contains_xy(area, points[:, 0], points[:, 1])


def _inside_near(area: BaseGeometry, points: np.ndarray) -> np.ndarray:
    """Like :func:`_inside`, testing only the points in the area's bounding box (many small islands)."""
    x0, y0, x1, y1 = area.bounds
    near = (points[:, 0] >= x0) & (points[:, 0] <= x1) & (points[:, 1] >= y0) & (points[:, 1] <= y1)
    inside = np.zeros(len(points), dtype=bool)
    if near.any():
        inside[near] = _inside(area, points[near])
    return inside


# --------------------------------------------------------------------------- the check


@dataclass
class _LayerFindings:
    row: LayerRow
    lost: list[LostIsland]


class _GrownSections:
    """``section_at(z)`` grown by half a line width, built once per distinct section.

    Prismatic parts return the same polygon for many heights; its buffer is
    reused while ``section_at`` keeps returning an equal geometry.
    """

    def __init__(self, section_at: Callable[[float], BaseGeometry], radius: float):
        self.section_at = section_at
        self.radius = radius
        self._last: BaseGeometry | None = None
        self._last_grown: BaseGeometry | None = None

    def grown_section(self, z: float) -> BaseGeometry | None:
        """The grown section at height z (mm); None where the model has no material."""
        section = self.section_at(z)
        if section is None or section.is_empty:
            return None
        if self._last is None or not (section is self._last or section.equals_exact(self._last, 0.0)):
            self._last = section
            self._last_grown = section.buffer(self.radius, quad_segs=QUAD_SEGS)
        return self._last_grown


def _segment_keys(segments: np.ndarray) -> np.ndarray:
    """One key per segment (k, 2, 2), the same whichever way it runs (ends to 0.001 mm)."""
    ends = np.round(segments, 3).reshape(-1, 4)
    swap = (ends[:, 0] > ends[:, 2]) | ((ends[:, 0] == ends[:, 2]) & (ends[:, 1] > ends[:, 3]))
    canonical = np.ascontiguousarray(np.where(swap[:, None], ends[:, [2, 3, 0, 1]], ends))
    return canonical.view(np.dtype((np.void, canonical.dtype.itemsize * 4))).ravel()


def _same_segments(segments: np.ndarray, cura: np.ndarray) -> np.ndarray:
    """Which of `segments` (k, 2, 2) are one of Cura's own (m, 2, 2), either way round: bool (k,)."""
    return np.isin(_segment_keys(segments), _segment_keys(cura))


#: a piece of one of Cura's segments: both its ends this close to that segment (mm; G-code has 3 decimals)
ON_CURA_TOLERANCE = 0.002


def _on_cura_segments(segments: np.ndarray, cura: np.ndarray, flagged: np.ndarray) -> np.ndarray:
    """Which of `segments` (k, 2, 2) lie on one of Cura's own (m, 2, 2): the whole of one, or a piece of
    it (the pass keeps the stretch of a Cura line that its new infill does not take over).  Only the
    `flagged` ones (bool (k,)) are looked at, each against every Cura segment: bool (k,)."""
    on = np.zeros(len(segments), dtype=bool)
    rows = np.flatnonzero(flagged)
    if not len(rows) or not len(cura):
        return on
    on[rows] = _same_segments(segments[rows], cura)
    rows = rows[~on[rows]]
    a, d = cura[:, 0], cura[:, 1] - cura[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    unit = d / np.maximum(length, 1e-12)[:, None]
    for start in range(0, len(rows), 64):  # (a few segments are flagged: 64 x m at a time)
        chunk = rows[start:start + 64]
        ends = segments[chunk]  # (c, 2, 2)
        rel = ends[:, None, :, :] - a[None, :, None, :]  # (c, m, 2 ends, 2)
        along = (rel * unit[None, :, None, :]).sum(-1)
        across = np.abs(rel[..., 0] * unit[None, :, None, 1] - rel[..., 1] * unit[None, :, None, 0])
        fits = (across <= ON_CURA_TOLERANCE) & (along >= -ON_CURA_TOLERANCE) & (along <= length[None, :, None] + ON_CURA_TOLERANCE)
        on[chunk] = fits.all(axis=2).any(axis=1)
    return on


def _without_stubs(segments: np.ndarray, min_length: float) -> np.ndarray:
    """`segments` (k, 2, 2) less its runs (segments each starting where the one before ends) shorter
    than `min_length` (mm)."""
    if not len(segments):
        return segments
    lengths = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    joined = np.zeros(len(segments), dtype=bool)
    joined[1:] = np.all(np.abs(segments[1:, 0] - segments[:-1, 1]) < 1e-6, axis=1)
    run = np.cumsum(~joined) - 1
    return segments[np.bincount(run, weights=lengths)[run] >= min_length]


def _check_layer(key: tuple[int, int], z: float, layer_height: float, original: LayerMoves | None,
                 new_fill: np.ndarray, reference_fill: np.ndarray, material: _GrownSections,
                 spacing: float, line_width: float) -> _LayerFindings:
    """All five measurements on one layer (see :func:`check_everyday`)."""
    half = line_width / 2
    original_fill = original.fill if original is not None else _EMPTY_SEGMENTS
    original_skin = original.skin if original is not None else _EMPTY_SEGMENTS
    # Reference area: the dense lines' footprint; allowed: that grown by another half width.
    reference_area = lines_buffer(reference_fill, half + REFERENCE_MERGE_MM)
    # growing the (few-vertex) area is cheaper than buffering the many dense lines again
    allowed = reference_area.buffer(half, quad_segs=QUAD_SEGS) if not reference_area.is_empty else reference_area

    # one sampling serves all checks: fine enough for lengths, and at most half a line width apart
    # for the coverage check's nearest-neighbour search
    step = min(SAMPLE_STEP_MM, half)
    new_points, new_weights = sample_segments(new_fill, step)
    new_mm = float(new_weights.sum())

    # 1 containment (Cura's own lines, kept as they were, are where Cura prints by definition: the
    # reference slice's own single lines of combined infill layers need not agree with them)
    outside = ~_inside(allowed, new_points)
    if len(original_fill) and outside.any():
        per_segment = _samples_per_segment(new_fill, step)
        flagged = np.add.reduceat(outside, np.r_[0, np.cumsum(per_segment)[:-1]]) > 0
        outside &= ~np.repeat(_on_cura_segments(new_fill, original_fill, flagged), per_segment)
    outside_mm = float(new_weights[outside].sum())

    # 3 skin: Cura's skin lines that are not infill area; such points are outside `allowed` already
    on_skin_mm = 0.0
    if len(original_skin) and outside.any():
        skin_only = lines_buffer(original_skin, half).difference(allowed)
        on_skin = _inside(skin_only, new_points[outside])
        on_skin_mm = float(new_weights[outside][on_skin].sum())

    # 6 walls: new FILL on a wall line of any mesh (an infill mesh's walls lie inside the reference
    # area of the mesh around it: containment cannot see infill printed across them)
    on_wall_mm = original_on_wall_mm = 0.0
    original_walls = original.walls if original is not None else _EMPTY_SEGMENTS
    if len(original_walls) and len(new_points):
        on_walls = lines_buffer(original_walls, ON_WALL_RADIUS_WIDTHS * line_width)
        new_on_wall = _inside(on_walls, new_points)
        if len(original_fill) and new_on_wall.any():
            per_segment = _samples_per_segment(new_fill, step)
            flagged = np.add.reduceat(new_on_wall, np.r_[0, np.cumsum(per_segment)[:-1]]) > 0
            new_on_wall &= ~np.repeat(_on_cura_segments(new_fill, original_fill, flagged), per_segment)
        on_wall_mm = float(new_weights[new_on_wall].sum())
        if len(original_fill):
            points, weights = sample_segments(original_fill, step)
            original_on_wall_mm = float(weights[_inside(on_walls, points)].sum())

    # 2 material: the true section at mid-layer
    material_mm = 0.0
    if len(new_points):
        grown = material.grown_section(z - layer_height / 2)
        no_material = ~_inside(grown, new_points)
        material_mm = float(new_weights[no_material].sum())

    # 4 coverage: points one line width apart along Cura's FILL, against the new FILL's samples
    coverage_points, _ = sample_segments(original_fill, line_width)
    hits = 0
    if len(coverage_points) and len(new_points):
        # a point within `spacing` of a new line is within spacing + step / 2 of one of its samples
        distance, _ = cKDTree(new_points).query(coverage_points, distance_upper_bound=spacing + step / 2)
        hits = int(np.isfinite(distance).sum())

    # 5 islands of the reference area where Cura printed FILL
    label = str(key[0]) if key[1] == 0 else f"{key[0]}#{key[1]}"
    original_points, original_weights = sample_segments(_without_stubs(original_fill, line_width), step)
    counted = 0
    lost: list[LostIsland] = []
    minimum = ISLAND_MIN_LINE_WIDTHS * line_width
    if len(original_points) and not reference_area.is_empty:
        for island in shapely.get_parts(reference_area):
            cura_mm = float(original_weights[_inside_near(island, original_points)].sum())
            if cura_mm < minimum:
                continue
            counted += 1
            if not len(new_points):
                island_new_mm = 0.0
            else:
                island_new_mm = float(new_weights[_inside_near(island, new_points)].sum())
                if island_new_mm < minimum:  # only then is the grown island (a buffer) worth building
                    reach = island.buffer(line_width, quad_segs=QUAD_SEGS)
                    island_new_mm = float(new_weights[_inside_near(reach, new_points)].sum())
            if island_new_mm < minimum:
                c = island.centroid
                lost.append(LostIsland(label, (round(c.x, 2), round(c.y, 2)), round(island.area, 2),
                                       round(cura_mm, 2), round(island_new_mm, 2)))

    row = LayerRow(layer=key[0], occurrence=key[1], z=z, new_mm=new_mm, outside_mm=outside_mm,
                   material_mm=material_mm, on_skin_mm=on_skin_mm, on_wall_mm=on_wall_mm,
                   original_on_wall_mm=original_on_wall_mm, original_mm=float(original_weights.sum()),
                   coverage_samples=len(coverage_points), coverage_hits=hits, islands=counted,
                   lost_islands=len(lost))
    return _LayerFindings(row, lost)


def check_everyday(original: str, processed: str, reference: str, section_at: Callable[[float], BaseGeometry],
                   spacing: float, line_width: float) -> EverydayResult:
    """Check that the processed G-code prints infill only where Cura printed infill.

    Layers are matched by their ``;LAYER:`` number (and, when numbers restart,
    by occurrence).  "New FILL" is every extruding FILL move of `processed`
    (infill the pass kept is Cura's, hence inside by definition: check 1 leaves out the moves that are
    one of Cura's own in that layer).  Per layer:

    1. containment: new FILL length outside the *allowed area* = the reference
       layer's FILL segments buffered by ``line_width`` (the reference area,
       buffered by ``line_width / 2``, grown by another ``line_width / 2``).
       At most :data:`MAX_OUTSIDE_FRACTION_FILE` of the file's new FILL, and
       :data:`MAX_OUTSIDE_FRACTION_LAYER` of a layer's (layers with at least
       :data:`MIN_LAYER_MM_FOR_FRACTION` mm of it).
    2. material: new FILL length outside ``section_at(z - layer_height / 2)``
       grown by ``line_width / 2``: under :data:`MAX_MATERIAL_FRACTION_FILE` of
       the file's new FILL and under :data:`MAX_MATERIAL_MM_LAYER` mm per layer.
    3. skin: new FILL length on the original layer's SKIN lines (buffered by
       ``line_width / 2``) outside the allowed area; part of 1, reported apart.
    4. coverage: of the points every ``line_width`` along Cura's FILL, the
       share with new FILL within `spacing`, file-wide at least :data:`MIN_COVERAGE`.
    5. islands: every connected part of the reference area holding at least one
       line width of Cura's FILL holds at least one line width of new FILL
       (within the island grown by ``line_width``).
    6. walls: new FILL length within ``ON_WALL_RADIUS_WIDTHS * line_width`` of
       the original layer's wall lines (of any mesh: an infill mesh's walls lie
       inside the reference area of the mesh around it) at most 1.5 times
       Cura's own FILL there (scaled to the new length) plus
       :data:`MAX_ON_WALL_MM_LAYER` mm per layer.

    Parameters
    ----------
    original, processed, reference : str
        G-code texts: Cura's (sparse infill), the same after the pass, and the
        dense "lines" reference slice.
    section_at : callable
        z (mm) -> shapely (Multi)Polygon, the model's cross-section in G-code XY.
    spacing : float
        Cura's infill line distance, mm.
    line_width : float
        Infill line width, mm.
    """
    result = EverydayResult()
    started = time.perf_counter()
    original_layers = extract_layers(original)
    new_layers = extract_layers(processed)
    reference_layers = extract_layers(reference)
    parsed = time.perf_counter()
    heights = _layer_heights(new_layers)
    # every layer with FILL in either file, in the original's order
    in_order = list(original_layers) + [k for k in new_layers if k not in original_layers]
    keys = [k for k in in_order
            if (k in new_layers and len(new_layers[k].fill)) or (k in original_layers and len(original_layers[k].fill))]
    lost: list[LostIsland] = []
    material = _GrownSections(section_at, line_width / 2)
    for key in keys:
        new = new_layers.get(key)
        original_layer = original_layers.get(key)
        z = new.z if new is not None and not math.isnan(new.z) else (original_layer.z if original_layer else math.nan)
        findings = _check_layer(
            key, z, heights.get(key, 0.2), original_layer,
            new.fill if new is not None else _EMPTY_SEGMENTS,
            reference_layers[key].fill if key in reference_layers else _EMPTY_SEGMENTS,
            material, spacing, line_width)
        result.rows.append(findings.row)
        lost += findings.lost
    result.lost_islands = lost
    _judge(result, reference_layers)
    result.figures["seconds"] = {"parse": round(parsed - started, 3),
                                 "layers": round(time.perf_counter() - parsed, 3)}
    return result


def _judge(result: EverydayResult, reference_layers: dict[tuple[int, int], LayerMoves]) -> None:
    """Figures and problems from the per-layer rows."""
    rows = result.rows
    figures = result.figures
    new_mm = sum(r.new_mm for r in rows)
    original_mm = sum(r.original_mm for r in rows)
    figures["layers_checked"] = len(rows)
    figures["new_fill_mm"] = round(new_mm, 1)
    figures["original_fill_mm"] = round(original_mm, 1)
    if original_mm == 0:
        result.add_problem("the original has no FILL extrusion: nothing to check against")
    if not any(len(layer.fill) for layer in reference_layers.values()):
        result.add_problem("the reference slice has no FILL extrusion")

    # 1 containment
    outside_mm = sum(r.outside_mm for r in rows)
    outside_fraction = outside_mm / new_mm if new_mm else 0.0
    judged = [r for r in rows if r.new_mm >= MIN_LAYER_MM_FOR_FRACTION]
    worst = max(judged, key=lambda r: r.outside_fraction, default=None)
    worst_mm = max(rows, key=lambda r: r.outside_mm, default=None)
    figures["outside_fraction"] = round(outside_fraction, 5)
    figures["outside_mm"] = round(outside_mm, 2)
    figures["worst_outside_layer"] = (worst.label, round(worst.outside_fraction, 5)) if worst else None
    figures["worst_outside_mm"] = (worst_mm.label, round(worst_mm.outside_mm, 2)) if worst_mm else None
    if outside_fraction > MAX_OUTSIDE_FRACTION_FILE:
        result.add_problem(f"containment: {100 * outside_fraction:.2f} % of the new infill ({outside_mm:.1f} of "
                           f"{new_mm:.1f} mm) lies outside Cura's infill area (limit "
                           f"{100 * MAX_OUTSIDE_FRACTION_FILE:g} %)")
    for r in judged:
        if r.outside_fraction > MAX_OUTSIDE_FRACTION_LAYER:
            result.add_problem(f"containment: layer {r.label} (z {r.z:.2f}): {r.outside_mm:.1f} of {r.new_mm:.1f} mm "
                               f"({100 * r.outside_fraction:.1f} %) of new infill outside Cura's infill area "
                               f"(limit {100 * MAX_OUTSIDE_FRACTION_LAYER:g} %)")

    # 3 skin (already part of the containment figure)
    on_skin_mm = sum(r.on_skin_mm for r in rows)
    worst_skin = max(rows, key=lambda r: r.on_skin_mm, default=None)
    figures["on_skin_mm"] = round(on_skin_mm, 2)
    figures["worst_on_skin_layer"] = (worst_skin.label, round(worst_skin.on_skin_mm, 2)) if worst_skin else None

    # 6 walls
    on_wall_mm = sum(r.on_wall_mm for r in rows)
    figures["on_wall_mm"] = round(on_wall_mm, 2)
    figures["original_on_wall_mm"] = round(sum(r.original_on_wall_mm for r in rows), 2)
    for r in rows:
        allowed = _on_wall_allowance(r)
        if r.on_wall_mm > allowed:
            result.add_problem(f"walls: layer {r.label} (z {r.z:.2f}): {r.on_wall_mm:.1f} mm of new infill on walls "
                               f"(Cura's infill had {r.original_on_wall_mm:.1f} mm there; limit {allowed:.1f} mm)")

    # 2 material
    material_mm = sum(r.material_mm for r in rows)
    material_fraction = material_mm / new_mm if new_mm else 0.0
    worst_material = max(rows, key=lambda r: r.material_mm, default=None)
    figures["material_fraction"] = round(material_fraction, 6)
    figures["material_mm"] = round(material_mm, 2)
    figures["worst_material_layer"] = (worst_material.label, round(worst_material.material_mm, 2)) if worst_material else None
    if material_fraction >= MAX_MATERIAL_FRACTION_FILE:
        result.add_problem(f"material: {material_mm:.2f} mm of new infill ({100 * material_fraction:.3f} %) "
                           f"where the model has no material (limit {100 * MAX_MATERIAL_FRACTION_FILE:g} %)")
    for r in rows:
        if r.material_mm >= MAX_MATERIAL_MM_LAYER:
            result.add_problem(f"material: layer {r.label} (z {r.z:.2f}): {r.material_mm:.1f} mm of new infill where "
                               f"the model has no material (a hole, or mid-air; limit {MAX_MATERIAL_MM_LAYER:g} mm)")

    # 4 coverage
    samples = sum(r.coverage_samples for r in rows)
    hits = sum(r.coverage_hits for r in rows)
    coverage = hits / samples if samples else 1.0
    sampled = [r for r in rows if r.coverage_samples]
    worst_coverage = min(sampled, key=lambda r: r.coverage, default=None)
    figures["coverage"] = round(coverage, 4)
    figures["worst_coverage_layer"] = (worst_coverage.label, round(worst_coverage.coverage, 4)) if worst_coverage else None
    if coverage < MIN_COVERAGE:
        where = f"; worst layer {worst_coverage.label}: {100 * worst_coverage.coverage:.1f} %" if worst_coverage else ""
        result.add_problem(f"coverage: only {100 * coverage:.1f} % of the places along Cura's infill have new infill "
                           f"within the line spacing (limit {100 * MIN_COVERAGE:g} %){where}")

    # 5 islands
    figures["islands"] = sum(r.islands for r in rows)
    figures["lost_islands"] = len(result.lost_islands)
    for island in result.lost_islands:
        result.add_problem(f"islands: layer {island.layer}: island at {island.centroid} ({island.area:g} mm^2) had "
                           f"{island.original_mm:g} mm of Cura's infill, has {island.new_mm:g} mm of new infill")


# --------------------------------------------------------------------------- the table


def _on_wall_allowance(row: LayerRow) -> float:
    """How much new FILL a layer may print on walls (mm): Cura's own share, and MAX_ON_WALL_MM_LAYER."""
    scale = row.new_mm / row.original_mm if row.original_mm > 0 else 1.0
    return 1.5 * row.original_on_wall_mm * max(scale, 1.0) + MAX_ON_WALL_MM_LAYER


def _badness(row: LayerRow) -> float:
    """How far a layer is from its limits (1.0 = at a limit), for ranking the worst layers."""
    coverage_gap = (1 - row.coverage) / (1 - MIN_COVERAGE) if row.coverage_samples else 0.0
    return max(row.outside_fraction / MAX_OUTSIDE_FRACTION_LAYER, row.material_mm / MAX_MATERIAL_MM_LAYER,
               coverage_gap, 10.0 * row.lost_islands, row.on_wall_mm / _on_wall_allowance(row))


def layer_table(result: EverydayResult, count: int = 12) -> str:
    """A fixed-width table of the `count` worst layers (by distance to their limits)."""
    header = f"{'layer':>7} {'z mm':>7} {'new mm':>9} {'outside %':>9} {'material mm':>11} {'on skin mm':>10} " \
             f"{'coverage %':>10} {'lost isl.':>9}"
    lines = [header, "-" * len(header)]
    for row in sorted(result.rows, key=_badness, reverse=True)[:count]:
        coverage = f"{100 * row.coverage:10.1f}" if row.coverage_samples else f"{'-':>10}"
        lines.append(f"{row.label:>7} {row.z:7.2f} {row.new_mm:9.1f} {100 * row.outside_fraction:9.2f} "
                     f"{row.material_mm:11.2f} {row.on_skin_mm:10.2f} {coverage} {row.lost_islands:9d}")
    return "\n".join(lines)
