"""Make a large, consistent G-code file by repeating the middle layers of a real slice.

Used for check 7 (bounded memory) and the interrupted-run test.  The source must
use relative extrusion (M83), so repeated layers need no E rewriting; layer
numbers, Z heights, ``;LAYER_COUNT`` and ``;TIME_ELAPSED`` are rewritten so the
result reads like one tall print.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_Z = re.compile(r"Z(-?\d+\.?\d*)")
_ELAPSED = re.compile(r"(?m)^;TIME_ELAPSED:([\d.]+)")


@dataclass
class BigFile:
    path: str
    layers: int
    size: int


def write_big_gcode(source: str, path: str, target_bytes: int, *, first: int = 5, last: int = 44,
                    layer_height: float = 0.2) -> BigFile:
    """Write at least `target_bytes` of G-code to `path`.

    Layers ``first..last`` of `source` (whose chunks all end with the same travel,
    so they can follow each other) are repeated; the layers before and after are
    kept, shifted up.
    """
    if "\nM83" not in source:
        raise ValueError("the source G-code must use relative extrusion (M83)")
    head, *chunks = re.split(r"(?m)^(?=;LAYER:)", source)
    tail_at = chunks[-1].rfind(";TIME_ELAPSED:")
    tail_at = chunks[-1].index("\n", tail_at) + 1
    chunks[-1], end = chunks[-1][:tail_at], chunks[-1][tail_at:]
    elapsed = [float(_ELAPSED.findall(c)[-1]) for c in chunks]
    durations = [elapsed[0]] + [b - a for a, b in zip(elapsed[:-1], elapsed[1:], strict=True)]
    template = list(range(first, last + 1))
    fixed = sum(len(c) for k, c in enumerate(chunks) if k < first or k > last) + len(head) + len(end)
    per_cycle = sum(len(chunks[k]) for k in template)
    cycles = max(1, -(-(target_bytes - fixed) // per_cycle))
    order = list(range(first)) + template * cycles + list(range(last + 1, len(chunks)))
    total_layers = len(order)
    clock = 0.0
    with open(path, "w", encoding="utf-8") as f:
        f.write(re.sub(r"(?m)^;LAYER_COUNT:\d+", f";LAYER_COUNT:{total_layers}", head))
        for number, k in enumerate(order):
            shift = (number - k) * layer_height
            chunk = chunks[k]
            if shift:
                chunk = _Z.sub(lambda m, s=shift: f"Z{float(m.group(1)) + s:.3f}", chunk)
            chunk = chunk.replace(f";LAYER:{k}\n", f";LAYER:{number}\n", 1)
            clock += durations[k]
            chunk = _ELAPSED.sub(f";TIME_ELAPSED:{clock:.6f}", chunk)
            f.write(chunk)
        f.write(end)
        size = f.tell()
    return BigFile(path, total_layers, size)
