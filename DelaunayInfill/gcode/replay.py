"""Repeated layers: written from an earlier layer's result instead of being processed again.

A prism's middle layers are the same G-code but for their Z and (absolute E) E numbers: the same
walls, the same FILL, the same travel.  Such a layer gets the earlier layer's new FILL blocks, their
E numbers moved by the change of the E register where each block starts and their Z numbers by the
layer step, and its own exact E register handed back after each block (``G92 E``).  Everything
outside the FILL blocks is the layer's own text, as always.

A layer repeats a recorded one when

* its text, without its Z and E numbers, ``;LAYER:`` and ``;TIME_ELAPSED:`` values, is the recorded
  layer's (`layer_words`), and the caller's key (machine state before the layer, what the processing
  remembers from layer to layer) is equal too;
* every E word moves the filament by what the recorded one did, to Cura's rounding (1e-5), and every
  Z word is the recorded one plus the same step as the Z before the layer.

The caller checks what the G-code cannot say (the user's density regions at the layer's height).
"""

from __future__ import annotations

import re
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from .emit import fmt
from .read import MachineState, RetractionModel

__all__ = ["LayerWords", "BlockEdit", "LayerRecord", "RepeatCache", "layer_words", "record_layer", "replay_layer",
           "shifted_time_line", "splice_blocks"]

# an E or Z word (with the space before it, which `split` drops): the numbers a repeated layer changes
_WORD = re.compile(r" ([EZ]-?[\d.]+)")
_LETTER_E_OR_Z = min(ord("E"), ord("Z"))
_E = ord("E")
_E_TOLERANCE = 3e-5  # E units: Cura rounds every E word to 1e-5, so two equal moves may differ by that twice
_Z_TOLERANCE = 1e-7  # mm


@dataclass
class LayerWords:
    """A layer chunk split into its skeleton and its E and Z words.

    ``key`` the text without its E/Z numbers and counters, plus the letters of the words in order;
    ``values`` shape (n,) the words' numbers; ``is_e`` shape (n,) bool, True for E words, False for Z.
    """

    key: str
    values: np.ndarray
    is_e: np.ndarray


def layer_words(text: str) -> LayerWords | None:
    """`text` (a chunk that starts with ``;LAYER:``) split for look-ups; None when a word is no number."""
    parts = _WORD.split(text)
    skeleton = "".join(parts[::2])
    # the counters that differ from layer to layer: the first line's layer number, the last
    # ;TIME_ELAPSED: (one anywhere else stays in the key: such a layer is just never repeated)
    skeleton = skeleton[skeleton.find("\n") :]
    at = skeleton.rfind(";TIME_ELAPSED:", len(skeleton) - 200)
    if at >= 0:
        end = skeleton.find("\n", at)
        skeleton = skeleton[: at + 14] + (skeleton[end:] if end >= 0 else "")
    words = parts[1::2]
    if not words:
        return LayerWords(skeleton, np.zeros(0), np.zeros(0, dtype=bool))
    joined = " ".join(words)
    chars = np.frombuffer(joined.encode("ascii"), dtype=np.uint8)
    letters = chars[chars >= _LETTER_E_OR_Z]  # (the words are [EZ][-.0-9]*: only their letters are that high)
    try:
        values = np.array(joined.replace("E", "").replace("Z", "").split(), dtype=np.float64)
    except ValueError:
        return None
    if len(values) != len(words) or not np.isfinite(values).all():
        return None
    return LayerWords(skeleton + "\n" + letters.tobytes().decode("ascii"), values, letters == _E)


class BlockEdit:
    """One new FILL block of a recorded layer, ready to be written for a repeat of that layer.

    ``start``/``stop`` the block's lines in the layer (``start`` kept, as `emit_block` expects);
    ``e_before`` the E register before the block; ``e_word_before``/``e_word_after`` how many of the
    layer's E words come before the block's first/after its last line (0: the register is the one
    before the layer).
    """

    def __init__(self, start: int, stop: int, lines: list[str], e_before: float, e_word_before: int,
                 e_word_after: int):
        self.start, self.stop = start, stop
        self.e_before = e_before
        self.e_word_before, self.e_word_after = e_word_before, e_word_after
        self.empty = not lines
        parts = _WORD.split("\n".join(lines))
        # The block as one %-format: each word a placeholder, so `render` writes it in one call.
        # An extrusion's E has five decimals always ("%.5f" of the register, as the emitter writes
        # it); retraction/prime E, Z and G92 E are written by `fmt` (placeholders "%s").
        literal = [p.replace("%", "%%") for p in parts[::2]]
        placeholders = []
        fixed, loose, e_units = [], [], []  # word indices: extrusion E / retraction E; their units 1e-5
        z_at, z_values, g92_at = [], [], []
        for w in range(len(parts) // 2):
            word, before = parts[2 * w + 1], parts[2 * w]
            line_head = before[before.rfind("\n") + 1 :]
            if word[0] == "Z":
                z_at.append(w)
                z_values.append(float(word[1:]))
                placeholders.append(" Z%s")
            elif line_head.startswith("G92"):
                g92_at.append(w)
                placeholders.append(" E%s")
            else:
                is_fixed = "X" in line_head or "Y" in line_head
                (fixed if is_fixed else loose).append(w)
                e_units.append(round(float(word[1:]) * 100000))
                placeholders.append(" E%.5f" if is_fixed else " E%s")
        self.template = "".join(lit + ph for lit, ph in zip(literal, placeholders)) + literal[-1]
        self.words = len(placeholders)
        # the E words in text order (their units in e_units): which of them are extrusions
        self.e_at = np.array(sorted(fixed + loose), dtype=np.intp)
        self.e_units = np.array(e_units, dtype=np.int64)
        is_fixed = np.zeros(len(e_units), dtype=bool)
        is_fixed[np.searchsorted(self.e_at, np.array(fixed, dtype=np.intp))] = True
        self.e_loose = np.flatnonzero(~is_fixed).tolist()  # positions among the E words
        self.z_values, self.g92_count = z_values, len(g92_at)
        # `render` lists the E words, then the Z words, then the G92 words: where each word is in that list
        listed = np.empty(self.words, dtype=np.intp)
        listed[np.concatenate([self.e_at, np.array(z_at + g92_at, dtype=np.intp)]).astype(np.intp)] = np.arange(self.words)
        self.slots = None if (listed == np.arange(self.words)).all() else listed.tolist()

    def render(self, e_shift_units: int, z_shift: float, e_after: float) -> str:
        """The block's text with E words moved by `e_shift_units` (1e-5 E), Z words by `z_shift` mm."""
        args = ((self.e_units + e_shift_units) / 100000).tolist()
        for i in self.e_loose:
            args[i] = fmt(args[i], 5)
        args += [fmt(z + z_shift, 3) for z in self.z_values]
        if self.g92_count:
            args += [fmt(e_after, 5)] * self.g92_count
        if self.slots is not None:
            args = [args[i] for i in self.slots]
        return self.template % tuple(args)


@dataclass
class LayerRecord:
    """What a processed layer did, to be done again for its repeats.

    ``values`` the recorded layer's word numbers (`LayerWords`); ``e_start``/``z_start`` the E register
    and Z before it; ``end`` the machine state after it; ``layer_z`` its height; ``time_lines`` its
    ``;TIME_ELAPSED:`` lines; ``blocks`` its new FILL blocks (none: its text stays); ``extra`` the caller's
    (totals to add again, the retraction model after the layer, the regions' sections).
    """

    values: np.ndarray
    is_e: np.ndarray
    relative_e: bool
    e_start: float
    z_start: float
    end: MachineState
    layer_z: float
    time_lines: list[int]
    retraction_after: RetractionModel
    extra: dict = field(default_factory=dict)
    # (text, edits) until the first repeat asks for the blocks (`ready`): most layers of a model whose
    # sections change are never repeated, and building the blocks' templates costs about a millisecond
    pending: tuple | None = None
    blocks: list[BlockEdit] | None = None

    def ready(self) -> bool:
        """Build the new blocks' templates (once); False when `render` would not write them as they were."""
        if self.pending is not None:
            text, edits = self.pending
            self.pending = None
            self.blocks = _block_edits(text, self.values, self.is_e, self.relative_e, self.e_start, edits)
        return self.blocks is not None


class RepeatCache:
    """The last `size` recorded layers, by their words' key and the caller's key."""

    def __init__(self, size: int = 16):
        self.size = size
        self._records: OrderedDict = OrderedDict()

    def get(self, key) -> LayerRecord | None:
        rec = self._records.get(key)
        if rec is not None:
            self._records.move_to_end(key)
        return rec

    def put(self, key, record: LayerRecord) -> None:
        self._records[key] = record
        self._records.move_to_end(key)
        while len(self._records) > self.size:
            self._records.popitem(last=False)


def shifted_time_line(line: str, delta: float) -> str:
    """A ``;TIME_ELAPSED:`` line with `delta` seconds added (how every rewritten one is written)."""
    return f";TIME_ELAPSED:{float(line[14:].strip() or 0) + delta:.6f}"


def splice_blocks(lines: list[str], blocks: list[tuple[int, int, list[str]]]) -> list[str]:
    """`lines` with each block's inner lines replaced.

    Parameters
    ----------
    lines : list of str
        A layer's lines.
    blocks : list of (start, stop, new lines)
        In order, disjoint: lines ``start + 1 .. stop - 1`` give way to the new lines (line ``start``,
        the block's ``;TYPE:`` line, stays).
    """
    out: list[str] = []
    pos = 0
    for start, stop, new_lines in blocks:
        out.extend(lines[pos : start + 1])
        out.extend(new_lines)
        pos = stop
    out.extend(lines[pos:])
    return out


def _register_at(e_values: list[float], count: int, start: float) -> float:
    """The E register after the layer's first `count` E words (`e_values`; `start`: before the layer)."""
    return e_values[count - 1] if count else start


def record_layer(
    text: str,
    words: LayerWords,
    lines: list[str],
    state_before: MachineState,
    end: MachineState,
    layer_z: float,
    edits: list[tuple[int, int, list[str], MachineState, MachineState]],
    time_lines: list[int],
    retraction_after: RetractionModel,
) -> LayerRecord | None:
    """A record of a processed layer, or None when its repeats could not be written from it.

    Parameters
    ----------
    text, words, lines : the layer chunk, its `layer_words` and its lines (``text.split("\\n")``).
    state_before, end : MachineState before and after the layer.
    layer_z : float, mm.
    edits : list of (start, stop, new lines, state before, state after), one per replaced FILL block.
    time_lines : indices of the chunk's ``;TIME_ELAPSED:`` lines.
    retraction_after : RetractionModel after the layer.
    """
    if state_before.relative_xyz or end.relative_xyz or state_before.relative_e != end.relative_e:
        return None
    if "M82" in text or "M83" in text or "G91" in text or "G90" in text:
        return None  # a mode change: E words would not all be registers (or all deltas)
    relative = end.relative_e
    e_values = words.values[words.is_e]
    z_values = words.values[~words.is_e]
    # The words must be what the parse saw: the last E and Z words set the state after the layer.
    if not relative and (e_values[-1] if len(e_values) else state_before.e) != end.e:
        return None
    if (z_values[-1] if len(z_values) else state_before.z) != end.z:
        return None
    del lines  # (the blocks are found in `text` itself when a repeat asks for them)
    return LayerRecord(words.values, words.is_e, relative, state_before.e, state_before.z, end.copy(), layer_z,
                       list(time_lines), retraction_after, pending=(text, list(edits)) if edits else None,
                       blocks=None if edits else [])


def _block_edits(text: str, values: np.ndarray, is_e: np.ndarray, relative: bool, e_start: float,
                 edits: list[tuple[int, int, list[str], MachineState, MachineState]]) -> list[BlockEdit] | None:
    """The recorded layer's new blocks as `BlockEdit` templates (None: one would not be rewritten exactly).

    `values`/`is_e` the layer's words (`LayerWords`), `e_start` the E register before it, `edits` as
    for `record_layer`.
    """
    e_values = values[is_e]
    e_list = e_values.tolist()
    if len(e_values) and not relative:
        # where each line starts, and where each E word is, in characters
        lines = text.split("\n")
        line_start = np.zeros(len(lines) + 1, dtype=np.int64)
        np.cumsum([len(line) + 1 for line in lines], out=line_start[1:])
        e_offsets = np.array([m.start(1) for m in _WORD.finditer(text) if m.group(1)[0] == "E"], dtype=np.int64)
        if len(e_offsets) != len(e_values):
            return None
    blocks = []
    for start, stop, new_lines, before, after in edits:
        if relative:
            e_before_count = e_after_count = 0
        else:
            e_before_count = int(np.searchsorted(e_offsets, line_start[start])) if len(e_values) else 0
            e_after_count = int(np.searchsorted(e_offsets, line_start[stop])) if len(e_values) else 0
            if _register_at(e_list, e_before_count, e_start) != before.e:
                return None
            if _register_at(e_list, e_after_count, e_start) != after.e:
                return None
        edit = BlockEdit(start, stop, new_lines, before.e, e_before_count, e_after_count)
        if relative and edit.g92_count:
            return None
        if not edit.empty and edit.render(0, 0.0, after.e) != "\n".join(new_lines):
            return None  # written in a way `render` does not reproduce
        blocks.append(edit)
    return blocks


def replay_layer(
    text: str, words: LayerWords, record: LayerRecord, state_before: MachineState, time_delta: float
) -> tuple[str, MachineState, float] | None:
    """The layer `text` written from `record`, the machine state after it and its height.

    None when its E or Z words do not repeat the recorded layer's (then process it).  `time_delta`
    (s) is added to its ``;TIME_ELAPSED:`` lines (the layer's own change included).
    """
    if len(words.values) != len(record.values) or state_before.relative_e != record.relative_e:
        return None
    if not record.ready():
        return None
    is_e = record.is_e
    diff = words.values - record.values
    z_shift = state_before.z - record.z_start
    if not (np.abs(diff[~is_e] - z_shift) <= _Z_TOLERANCE).all():
        return None
    e_shift = 0.0 if record.relative_e else state_before.e - record.e_start
    if not (np.abs(diff[is_e] - e_shift) <= _E_TOLERANCE).all():
        return None
    e_list = words.values[is_e].tolist()
    lines = text.split("\n")
    for i in record.time_lines:
        lines[i] = shifted_time_line(lines[i], time_delta)
    texts = []
    for blk in record.blocks:
        if blk.empty:
            texts.append((blk.start, blk.stop, []))
        elif record.relative_e:
            texts.append((blk.start, blk.stop, [blk.render(0, z_shift, 0.0)]))
        else:
            e_before = _register_at(e_list, blk.e_word_before, state_before.e)
            e_after = _register_at(e_list, blk.e_word_after, state_before.e)
            texts.append((blk.start, blk.stop, [blk.render(round((e_before - blk.e_before) * 100000), z_shift, e_after)]))
    out = splice_blocks(lines, texts)
    end = record.end.copy()
    z_words = words.values[~is_e]
    end.z = float(z_words[-1]) if len(z_words) else state_before.z
    if record.relative_e:
        end.e = state_before.e + (record.end.e - record.e_start)
    else:
        end.e = _register_at(e_list, len(e_list), state_before.e)
    layer_z = round(record.layer_z + z_shift, 6)
    return "\n".join(out), end, layer_z
