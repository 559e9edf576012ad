"""Writing new infill paths as G-code that continues exactly where Cura's block ended.

A block is emitted from the machine state before Cura's FILL block to the
state after it: same position, Z, E register (absolute E is shifted back with
``G92 E``), retraction depth, firmware-retraction flag and feedrate, so the
next original line runs as it would have.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..combing import segments_inside
from .estimate import DEFAULT_JERK, move_seconds
from .read import MachineState, RetractionModel

__all__ = ["EmitParams", "EmitResult", "emit_block", "fmt"]


_E_QUANTUM = 5e-6  # half the last digit of an E word (5 decimals): a smaller E move prints as none


def fmt(value: float, decimals: int) -> str:
    """A number the way Cura writes it (no trailing zeros)."""
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    if text in ("-0", ""):
        text = "0"
    return text


@dataclass
class EmitParams:
    """How to print one block.

    ``e_per_mm`` E units per mm of path; feedrates are G-code F (mm/min);
    ``part`` the area a travel may cross without retraction (None: always
    retract like Cura would); ``min_travel`` mm, shorter travels never retract.
    """

    e_per_mm: float
    print_f: float
    travel_f: float
    retraction: RetractionModel
    part: object = None
    min_travel: float = 0.8
    layer_z: float | None = None
    xy_words: dict | None = None  # cache: id(path) -> (path, its "G1 X.. Y.." words); paths repeat layer after layer
    # a travel that would leave `part` goes round inside it instead (a combing.CombingArea of the
    # part; None: retract as Cura does); a detour longer than comb_max mm retracts (0: no limit)
    comb: object = None
    comb_max: float = 0.0
    # the time estimate's motion model (mm/s², mm/s): see estimate.py
    acceleration: float = 3000.0
    jerk: float = DEFAULT_JERK


@dataclass
class EmitResult:
    """Lines of the new block and what they do.

    ``seconds`` the estimated time of the extrusion moves (corners included), ``dist``/``feed``
    per other move (mm, mm/min) for the time estimate (each from rest to rest);
    ``net_e`` the sum of every E move of the block (extrusion, retractions and
    primes; E units), which is what the block changes the filament used by.
    """

    lines: list[str]
    extruded_e: float = 0.0
    net_e: float = 0.0
    extrude_mm: float = 0.0
    travel_mm: float = 0.0
    retractions: int = 0
    seconds: float = 0.0
    dist: list[np.ndarray] = field(default_factory=list)
    feed: list[np.ndarray] = field(default_factory=list)


def _xy_words(paths: list[np.ndarray], cache: dict | None) -> list[str]:
    """``G1 X.. Y..`` for every point but the first of each path, in order."""
    out: list[str] = []
    for path in paths:
        hit = cache.get(id(path)) if cache is not None else None
        if hit is None or hit[0] is not path:
            # (one %-format for the whole path, split at its line breaks: as each point's f-string)
            words = ("\nG1 X%.3f Y%.3f" * (len(path) - 1) % tuple(path[1:].ravel().tolist())).split("\n")[1:]
            if cache is not None:
                if len(cache) > 20000:
                    cache.clear()
                cache[id(path)] = hit = (path, words)
            else:
                hit = (path, words)
        out.extend(hit[1])
    return out


class _Template:
    """What a block's paths and travel area give, whatever the machine state: computed once per
    (paths, part) and reused while a prism's layers repeat the same clip result.

    ``seg_len`` (m,) length of every extrusion move, mm; ``ext_first`` (n + 1,)
    where each path's extrusion moves start in ``seg_len``/``xy`` (and the end);
    ``xy`` the ``G1 X.. Y..`` word of every extrusion move; ``heads``/``tails``
    path end points as Python floats, ``head_words`` the ``X.. Y..`` of each head;
    ``inner_free`` (n - 1,) whether the travel from path k to path k + 1 stays
    inside the part.
    """

    __slots__ = ("part", "paths", "heads", "tails", "seg_len", "seg_dxy", "seg_joined", "ext_first", "xy", "inner_free",
                 "heads_arr", "tails_arr", "head_words", "counts", "count_list", "count_starts", "_seconds")

    def __init__(self, paths: list[np.ndarray], params: EmitParams, start, end):
        part = self.part = params.part
        self.paths = tuple(paths)
        sizes = np.array([len(p) for p in paths])
        pts = np.concatenate(paths)
        steps = np.diff(pts, axis=0)
        lengths = np.hypot(steps[:, 0], steps[:, 1])
        first = np.r_[0, np.cumsum(sizes)[:-1]]
        is_ext = np.ones(len(pts), dtype=bool)
        is_ext[first] = False  # a path's first point is reached by travel
        self.seg_len = lengths[is_ext[1:]]  # step i ends at point i + 1
        self.seg_dxy = steps[is_ext[1:]]
        path_of = np.repeat(np.arange(len(paths)), sizes - 1)  # each extrusion step's path
        self.seg_joined = path_of[:-1] == path_of[1:]  # corners inside a path; a travel separates paths
        self._seconds: tuple | None = None
        # extrusion lines of path k are xy[ext_first[k] : ext_first[k + 1]]
        self.ext_first = (first - np.arange(len(paths))).tolist() + [len(self.seg_len)]
        # the paths with extrusion moves: how many each has and where they start in seg_len
        per_path = np.diff(self.ext_first)
        self.counts = per_path[per_path > 0]
        self.count_list = self.counts.tolist()
        self.count_starts = np.array(self.ext_first[:-1])[per_path > 0]
        self.heads_arr = pts[first]
        self.tails_arr = pts[first + sizes - 1]
        self.heads = self.heads_arr.tolist()
        self.tails = self.tails_arr.tolist()
        self.head_words = [f"X{x:.3f} Y{y:.3f}" for x, y in self.heads]  # what a travel to each path writes
        self.xy = _xy_words(paths, params.xy_words)
        # every travel of the block in one test: from `start` to the first path, between the
        # paths, from the last path to `end`; the first and last also go to the single-travel memo
        free = segments_inside(np.vstack([[start], self.tails_arr]), np.vstack([self.heads_arr, [end]]), part)
        self.inner_free = free[1:-1]
        (hx, hy), (tx, ty) = self.heads[0], self.tails[-1]
        _remember_travel(start[0], start[1], hx, hy, params, bool(free[0]))
        _remember_travel(tx, ty, end[0], end[1], params, bool(free[-1]))

    def extrusion_seconds(self, print_f: float, acceleration: float, jerk: float) -> float:
        """Estimated time of all extrusion moves at `print_f` (mm/min), corners included."""
        key = (print_f, acceleration, jerk)
        if self._seconds is None or self._seconds[0] != key:
            n = len(self.seg_len)
            seconds = move_seconds(self.seg_dxy[:, 0], self.seg_dxy[:, 1], np.zeros(n), self.seg_len, np.full(n, float(print_f)),
                                   acceleration, jerk, breaks=~self.seg_joined)
            self._seconds = (key, float(seconds.sum()))
        return self._seconds[1]

    def matches(self, paths: list[np.ndarray], part) -> bool:
        return self.part is part and len(self.paths) == len(paths) and all(
            a is b for a, b in zip(self.paths, paths, strict=True)
        )


def _template(paths: list[np.ndarray], params: EmitParams, start, end) -> _Template:
    """The block template of `paths`, from ``params.xy_words`` when the same paths and part came before.

    `start`, `end` (x, y): where the block starts and ends, for the travels to and from it.
    """
    cache = params.xy_words
    if cache is None:
        return _Template(paths, params, start, end)
    templates = cache.setdefault(("block templates",), {})
    key = (id(params.part), *map(id, paths))
    hit = templates.get(key)
    if hit is None or not hit.matches(paths, params.part):
        hit = _Template(paths, params, start, end)
        if len(templates) >= 32:
            templates.pop(next(iter(templates)))
        templates[key] = hit
    return hit


def _remember_travel(x0: float, y0: float, x1: float, y1: float, params: EmitParams, free: bool) -> None:
    if params.xy_words is not None:
        memo = params.xy_words.setdefault(("single travels",), {})
        if len(memo) >= 256:
            memo.pop(next(iter(memo)))
        memo[(id(params.part), x0, y0, x1, y1)] = (params.part, free)


def _travel_free(x0: float, y0: float, x1: float, y1: float, params: EmitParams) -> bool:
    """`segments_inside` for one travel, remembered by its exact end points (they repeat on prisms)."""
    if params.xy_words is not None:
        hit = params.xy_words.setdefault(("single travels",), {}).get((id(params.part), x0, y0, x1, y1))
        if hit is not None and hit[0] is params.part:
            return hit[1]
    free = bool(segments_inside(np.array([[x0, y0]]), np.array([[x1, y1]]), params.part)[0])
    _remember_travel(x0, y0, x1, y1, params, free)
    return free


_FEED_WORDS: dict[float, str] = {}


def _feed_word(f: float) -> str:
    """``"F<f> "`` (a handful of feedrates come back all the time)."""
    word = _FEED_WORDS.get(f)
    if word is None:
        if len(_FEED_WORDS) > 1024:
            _FEED_WORDS.clear()
        word = _FEED_WORDS[f] = f"F{fmt(f, 0)} "
    return word


class _Writer:
    def __init__(self, before: MachineState, params: EmitParams, result: EmitResult):
        self.x, self.y, self.z = before.x, before.y, before.z
        self.e = before.e
        self.f = before.f
        self.depth = before.depth
        self.fw = before.fw_retracted
        self.relative = before.relative_e
        self.p = params
        self.r = params.retraction
        self.layer_z = before.z if params.layer_z is None else params.layer_z
        self.out = result
        self._dist: list[float] = []
        self._feed: list[float] = []

    def _time(self, dist: float, feed: float):
        self._dist.append(dist)
        self._feed.append(feed)

    def flush_times(self):
        if self._dist:
            self.out.dist.append(np.asarray(self._dist, dtype=float))
            self.out.feed.append(np.asarray(self._feed, dtype=float))
            self._dist, self._feed = [], []

    def _e_word(self, delta: float) -> str:
        self.out.net_e += delta
        if self.relative:
            return fmt(delta, 5)
        self.e += delta
        return fmt(self.e, 5)

    def set_feed(self, f: float) -> str:
        if abs(f - self.f) > 1e-9:
            self.f = f
            return _feed_word(f)
        return ""

    def retract(self, amount: float | None = None):
        lines = self.out.lines
        if self.r.firmware and amount is None:
            if not self.fw:
                lines.append("G10")
                self.fw = True
                self.out.retractions += 1
            return
        amount = self.r.amount if amount is None else amount
        if amount < _E_QUANTUM:  # below the E word's last digit: the move would change nothing
            return
        lines.append(f"G1 {self.set_feed(self.r.retract_f or self.f)}E{self._e_word(-amount)}")
        self.depth += amount
        self.out.retractions += 1
        self._time(amount, self.f)

    def prime(self, amount: float | None = None):
        lines = self.out.lines
        if self.fw and amount is None:
            lines.append("G11")
            self.fw = False
        amount = self.depth if amount is None else amount
        if amount < _E_QUANTUM:
            return
        lines.append(f"G1 {self.set_feed(self.r.prime_f or self.r.retract_f or self.f)}E{self._e_word(amount)}")
        self.depth = max(0.0, self.depth - amount)
        self._time(amount, self.f)

    def move_z(self, z: float):
        if abs(z - self.z) > 1e-9:
            f = self.r.hop_f or self.p.travel_f
            self.out.lines.append(f"G0 {self.set_feed(f)}Z{fmt(z, 3)}")
            self._time(abs(z - self.z), self.f)
            self.z = z

    def travel(self, x: float, y: float, free: bool):
        d = math.hypot(x - self.x, y - self.y)
        if not math.isfinite(d):
            # From an unknown position (nothing set X/Y yet): go there, nothing to time.
            self.out.lines.append(f"G0 {self.set_feed(self.p.travel_f)}X{fmt(x, 3)} Y{fmt(y, 3)}")
            self.x, self.y = x, y
            return
        if d < 1e-9:
            return
        if not free and self.p.comb is not None and self._comb(x, y):
            return
        if not free and d >= self.p.min_travel and self.r.seen:
            if self.depth <= 1e-9 and not self.fw:
                self.retract()
                if self.r.hop > 0:
                    self.move_z(self.layer_z + self.r.hop)
        self.out.lines.append(f"G0 {self.set_feed(self.p.travel_f)}X{x:.3f} Y{y:.3f}")
        self._time(d, self.f)
        self.out.travel_mm += d
        self.x, self.y = x, y

    def _comb(self, x: float, y: float) -> bool:
        """Travel to (x, y) round the inside of the part, unretracted; False when there is no such path."""
        bends = self.p.comb.path((self.x, self.y), (x, y))
        if bends is None:
            return False
        points = np.vstack([[self.x, self.y], bends, [x, y]])
        legs = np.hypot(*np.diff(points, axis=0).T)
        if self.p.comb_max > 0 and float(legs.sum()) > self.p.comb_max:
            return False
        feed = self.set_feed(self.p.travel_f)
        for (bx, by), leg in zip(points[1:].tolist(), legs.tolist(), strict=True):
            self.out.lines.append(f"G0 {feed}X{bx:.3f} Y{by:.3f}")
            feed = ""
            self._time(leg, self.f)
            self.out.travel_mm += leg
        self.x, self.y = x, y
        return True

    def extrude_all(self, tpl: _Template, free: list[bool]):
        """All paths of `tpl` with their travels before them.

        The loop over paths only decides travels, retractions and feedrates;
        the extrusion lines are formatted afterwards in one pass (their XY words
        come from the template, their E values from one vectorized sum).
        """
        de = tpl.seg_len * self.p.e_per_mm
        cum = np.concatenate([[0.0], np.cumsum(de)])  # E extruded before each extrusion line
        cum_list = cum.tolist()
        ext_first = tpl.ext_first
        lines = self.out.lines
        print_f = self.p.print_f
        relative = self.relative
        marks: list[int] = []  # where each path's extrusion lines go in `lines`
        feeds: list[str] = []
        bases: list[float] = []  # the E register at each path's start (absolute E)
        tails = tpl.tails
        head_words = tpl.head_words
        travel_f = self.p.travel_f
        travel_feed = "G0 " + _feed_word(travel_f)
        print_feed = _feed_word(print_f)
        min_travel = self.p.min_travel
        seen = self.r.seen
        combing = self.p.comb is not None
        times_d, times_f = self._dist, self._feed
        for k, (hx, hy) in enumerate(tpl.heads):
            d = math.hypot(hx - self.x, hy - self.y)
            if d < 1e-9:
                pass
            elif (free[k] or (not combing and (d < min_travel or not seen or self.depth > 1e-9 or self.fw))) \
                    and math.isfinite(d):
                # `travel` without a retraction, inline: most travels of a block are like this
                if abs(travel_f - self.f) > 1e-9:
                    self.f = travel_f
                    lines.append(travel_feed + head_words[k])
                else:
                    lines.append("G0 " + head_words[k])
                times_d.append(d)
                times_f.append(self.f)
                self.out.travel_mm += d
                self.x, self.y = hx, hy
            else:
                self.travel(hx, hy, free[k])
            if self.z != self.layer_z:
                self.move_z(self.layer_z)
            if self.depth > 1e-9 or self.fw:
                self.prime()
            a = ext_first[k]
            b = ext_first[k + 1]
            if b <= a:
                continue
            # E words from the register as it is now: a prime just above (the block may start
            # retracted) has moved it, so values computed before the loop would run backwards.
            if abs(print_f - self.f) > 1e-9:
                self.f = print_f
                feeds.append(print_feed)
            else:
                feeds.append("")
            marks.append(len(lines))
            if not relative:
                bases.append(self.e)
                self.e = self.e + (cum_list[b] - cum_list[a])
            self.x, self.y = tails[k]
        if marks:
            counts = tpl.counts
            if relative:
                e_vals = de
            else:
                e_vals = np.repeat(bases, counts) + (cum[1:] - np.repeat(cum[tpl.count_starts], counts))
            if len(e_vals) != len(tpl.xy):
                raise ValueError("a block's E values and XY words differ in number")
            flat: list = [None] * (2 * len(tpl.xy))
            flat[::2] = tpl.xy
            flat[1::2] = e_vals.tolist()
            # (one %-format for every line, split at its line breaks: as each line's f-string "{w} E{e:.5f}")
            words = ("\n%s E%.5f" * len(tpl.xy) % tuple(flat)).split("\n")[1:]
            count_list = tpl.count_list
            out: list[str] = lines[: marks[0]]
            at = 0
            for j, mark in enumerate(marks):
                if j:
                    out.extend(lines[marks[j - 1] : mark])
                stop = at + count_list[j]
                if feeds[j]:
                    out.append("G1 " + feeds[j] + words[at][3:])
                    out.extend(words[at + 1 : stop])
                else:
                    out.extend(words[at:stop])
                at = stop
            out.extend(lines[marks[-1] :])
            lines[:] = out
        self.out.seconds += tpl.extrusion_seconds(print_f, self.p.acceleration, self.p.jerk)
        total_de = float(de.sum())
        self.out.extruded_e += total_de
        self.out.net_e += total_de
        self.out.extrude_mm += float(tpl.seg_len.sum())


def emit_block(
    paths: list[np.ndarray],
    before: MachineState,
    after: MachineState,
    params: EmitParams,
    extra_lines: list[str] = (),
) -> EmitResult:
    """G-code lines that print `paths` and leave the machine in state `after`.

    Parameters
    ----------
    paths : list of ndarray, each shape (m, 2)
        Polylines in print order, mm.
    before, after : MachineState
        State before Cura's block and after it.
    params : EmitParams
    extra_lines : list of str
        Non-motion commands from Cura's block (M204, M106, ...), written first.

    Returns
    -------
    EmitResult
    """
    result = EmitResult(lines=list(extra_lines))
    w = _Writer(before, params, result)
    paths = [np.asarray(p, dtype=float) for p in paths if len(p) >= 2]
    if paths:
        # The travels between paths depend on the paths and the part only (cached with them);
        # the first and the last depend on where Cura's block starts and ends.
        tpl = _template(paths, params, (before.x, before.y), (after.x, after.y))
        (hx, hy), (tx, ty) = tpl.heads[0], tpl.tails[-1]
        free = [_travel_free(before.x, before.y, hx, hy, params), *tpl.inner_free.tolist()]
        w.extrude_all(tpl, free)
        free_end = _travel_free(tx, ty, after.x, after.y, params)
    else:
        free_end = _travel_free(w.x, w.y, after.x, after.y, params)
    # Hand back Cura's end state.
    if math.isfinite(after.x) and math.isfinite(after.y):
        w.travel(after.x, after.y, free_end)
    going_up = after.z > w.z + 1e-9
    if not going_up:
        w.move_z(after.z)
    if after.fw_retracted and not w.fw:
        result.lines.append("G10")
        w.fw = True
    elif w.fw and not after.fw_retracted:
        result.lines.append("G11")
        w.fw = False
    if after.depth > w.depth + _E_QUANTUM:
        w.retract(after.depth - w.depth)
    elif after.depth < w.depth - _E_QUANTUM:
        w.prime(w.depth - after.depth)
    if going_up:
        w.move_z(after.z)
    if not w.relative and abs(w.e - after.e) > 5e-6:
        result.lines.append(f"G92 E{fmt(after.e, 5)}")
    if abs(w.f - after.f) > 1e-9:
        result.lines.append(f"G1 F{fmt(after.f, 0)}")
    w.flush_times()
    return result
