"""Compare two G-code texts that should be the same but for E rounding (test helper, no project code)."""

from __future__ import annotations

import re

_NUMBER = re.compile(r"-?\d*\.?\d+")
_E_WORD = re.compile(r"(?<=[ \t])E(-?\d*\.?\d+)")


def differences(a: str, b: str, e_tolerance: float) -> list[str]:
    """Lines where `a` and `b` differ by more than E numbers within `e_tolerance` (at most 10 listed).

    Everything but the E words must be equal character for character; ``;TIME_ELAPSED:`` values may
    differ by 1e-3 s (they sum per-layer changes), the header's ``;Filament used:`` figures by 2e-5 (m
    or mm3: the sum of every E word's rounding, written to six decimals).
    """
    la, lb = a.split("\n"), b.split("\n")
    if len(la) != len(lb):
        return [f"{len(la)} lines against {len(lb)}"]
    out = []
    for number, (x, y) in enumerate(zip(la, lb, strict=True)):
        if x == y:
            continue
        if x.startswith(";TIME_ELAPSED:") and y.startswith(";TIME_ELAPSED:"):
            if abs(float(x[14:]) - float(y[14:])) <= 1e-3:
                continue
        elif x.startswith(";Filament used:") and y.startswith(";Filament used:"):
            fx, fy = _NUMBER.findall(x), _NUMBER.findall(y)
            if _NUMBER.sub("0", x) == _NUMBER.sub("0", y) and all(
                    abs(float(p) - float(q)) <= 2e-5 for p, q in zip(fx, fy, strict=True)):
                continue
        elif _E_WORD.sub("E", x) == _E_WORD.sub("E", y):
            ex = [float(v) for v in _E_WORD.findall(x)]
            ey = [float(v) for v in _E_WORD.findall(y)]
            # (E words have five decimals: 476.98002 - 476.97999 is 3.0000000006e-05 in floats)
            if all(abs(p - q) <= e_tolerance + 1e-9 for p, q in zip(ex, ey, strict=True)):
                continue
        out.append(f"line {number}: {x!r} != {y!r}")
        if len(out) >= 10:
            break
    return out


def header_numbers(text: str, lines: int = 20) -> list[float]:
    """The numbers of the first `lines` lines (Cura's header: time, filament)."""
    return [float(v) for v in _NUMBER.findall("\n".join(text.split("\n")[:lines]))]
