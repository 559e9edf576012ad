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

from ..geometry import contains_xy
from ..routing import clip_segments
from .read import MachineState, RetractionModel

__all__ = ["EmitParams", "EmitResult", "emit_block", "fmt"]


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
    step: float = 0.2
    layer_z: float | None = None
    xy_words: dict | None = None  # cache: id(path) -> (path, its "G1 X.. Y.." words); paths repeat layer after layer


@dataclass
class EmitResult:
    """Lines of the new block and what they do.

    ``dist``/``feed`` per move (mm, mm/min) for the time estimate;
    ``net_e`` the sum of every E move of the block (extrusion, retractions and
    primes; E units), which is what the block changes the filament used by.
    """

    lines: list[str]
    extruded_e: float = 0.0
    net_e: float = 0.0
    extrude_mm: float = 0.0
    travel_mm: float = 0.0
    retractions: int = 0
    dist: list[np.ndarray] = field(default_factory=list)
    feed: list[np.ndarray] = field(default_factory=list)


def _travels_inside(starts: np.ndarray, ends: np.ndarray, part, step: float) -> np.ndarray:
    """Whether each straight travel stays inside `part` (exactly: clipped length equals length).

    `step` is kept for the callers' signature; the test no longer samples.
    """
    k = len(starts)
    if k == 0:
        return np.zeros(0, dtype=bool)
    known = np.isfinite(starts).all(axis=1) & np.isfinite(ends).all(axis=1)
    result = np.zeros(k, dtype=bool)
    if part is None or part.is_empty or not known.any():
        return result
    segs = np.stack([starts[known], ends[known]], axis=1)
    length = np.hypot(*(segs[:, 1] - segs[:, 0]).T)
    pieces, source = clip_segments(segs, part, return_index=True)
    inside = np.bincount(source, np.hypot(*(pieces[:, 1] - pieces[:, 0]).T), minlength=len(segs))
    # zero-length travels: inside when their point is
    point = length <= 1e-9
    inside_point = contains_xy(part, segs[:, 0, 0], segs[:, 0, 1])
    result[known] = np.where(point, inside_point, inside >= length - 1e-6)
    return result


def _xy_words(paths: list[np.ndarray], cache: dict | None) -> list[str]:
    """``G1 X.. Y..`` for every point but the first of each path, in order."""
    out: list[str] = []
    for path in paths:
        hit = cache.get(id(path)) if cache is not None else None
        if hit is None or hit[0] is not path:
            words = [f"G1 X{x:.3f} Y{y:.3f}" for x, y in path[1:].tolist()]
            if cache is not None:
                if len(cache) > 20000:
                    cache.clear()
                cache[id(path)] = hit = (path, words)
            else:
                hit = (path, words)
        out.extend(hit[1])
    return out


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
            return f"F{fmt(f, 0)} "
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
        if amount <= 0:
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
        if amount <= 1e-9:
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
        if not free and d >= self.p.min_travel and self.r.seen:
            if self.depth <= 1e-9 and not self.fw:
                self.retract()
                if self.r.hop > 0:
                    self.move_z(self.layer_z + self.r.hop)
        self.out.lines.append(f"G0 {self.set_feed(self.p.travel_f)}X{x:.3f} Y{y:.3f}")
        self._time(d, self.f)
        self.out.travel_mm += d
        self.x, self.y = x, y

    def extrude_all(self, paths: list[np.ndarray], free: np.ndarray):
        """All paths with their travels; the extrusion lines are formatted in one pass."""
        sizes = np.array([len(p) for p in paths])
        pts = np.concatenate(paths)
        first = np.r_[0, np.cumsum(sizes)[:-1]]
        steps = np.diff(pts, axis=0)
        lengths = np.hypot(steps[:, 0], steps[:, 1])
        is_ext = np.ones(len(pts), dtype=bool)
        is_ext[first] = False  # a path's first point is reached by travel
        seg_len = lengths[is_ext[1:]]  # step i ends at point i + 1
        de = seg_len * self.p.e_per_mm
        cum = np.concatenate([[0.0], np.cumsum(de)])  # E extruded before each extrusion line
        xy = _xy_words(paths, self.p.xy_words)
        # extrusion lines of path k are xy[ext_first[k] : ext_first[k] + sizes[k] - 1]
        ext_first = first - np.arange(len(paths))
        lines = self.out.lines
        for k, path in enumerate(paths):
            self.travel(float(path[0, 0]), float(path[0, 1]), bool(free[k]))
            if self.z != self.layer_z:
                self.move_z(self.layer_z)
            if self.depth > 1e-9 or self.fw:
                self.prime()
            a = int(ext_first[k])
            b = a + int(sizes[k]) - 1
            if b <= a:
                continue
            # E words from the register as it is now: a prime just above (the block may start
            # retracted) has moved it, so values computed before the loop would run backwards.
            e_vals = de[a:b] if self.relative else self.e + (cum[a + 1 : b + 1] - cum[a])
            words = [f"{w} E{e:.5f}" for w, e in zip(xy[a:b], e_vals.tolist(), strict=True)]
            feed = self.set_feed(self.p.print_f)
            if feed:
                words[0] = "G1 " + feed + words[0][3:]
            lines.extend(words)
            if not self.relative:
                self.e = float(e_vals[-1])
            self.x, self.y = float(path[-1, 0]), float(path[-1, 1])
        self.out.dist.append(seg_len)
        self.out.feed.append(np.full(len(seg_len), self.p.print_f))
        self.out.extruded_e += float(de.sum())
        self.out.net_e += float(de.sum())
        self.out.extrude_mm += float(seg_len.sum())


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
    target = np.array([[after.x, after.y]])
    if paths:
        # every travel of the block at once: before each path, and from the last path to Cura's end point
        starts = np.array([p[0] for p in paths])
        ends = np.array([p[-1] for p in paths])
        free = _travels_inside(np.vstack([[before.x, before.y], ends]), np.vstack([starts, target]), params.part, params.step)
        w.extrude_all(paths, free[:-1])
        free_end = bool(free[-1])
    else:
        free_end = bool(_travels_inside(np.array([[w.x, w.y]]), target, params.part, params.step)[0])
    # Hand back Cura's end state.
    if np.isfinite(target).all():
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
    if after.depth > w.depth + 1e-7:
        w.retract(after.depth - w.depth)
    elif after.depth < w.depth - 1e-7:
        w.prime(w.depth - after.depth)
    if going_up:
        w.move_z(after.z)
    if not w.relative and abs(w.e - after.e) > 5e-6:
        result.lines.append(f"G92 E{fmt(after.e, 5)}")
    if abs(w.f - after.f) > 1e-9:
        result.lines.append(f"G1 F{fmt(after.f, 0)}")
    w.flush_times()
    return result
