"""The checker (DelaunayInfill.gcode.verify) catches every kind of broken output.

Each test takes a correct processed G-code, breaks it in one way, and asserts
that verify reports exactly that kind of problem.  So the process tests that
rely on verify can fail.
"""

from __future__ import annotations

import gzip
import os
import re

import pytest

from DelaunayInfill.gcode import ProcessSettings, process_gcode
from DelaunayInfill.gcode.read import as_cura_list
from DelaunayInfill.gcode.verify import verify

DATA = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data")


@pytest.fixture(scope="module")
def pair():
    with gzip.open(os.path.join(DATA, "star.gcode.gz"), "rt", encoding="utf-8", newline="") as f:
        original = as_cura_list(f.read())
    processed, _ = process_gcode(original, ProcessSettings(seed=7))
    assert verify(original, processed, min_density=0.2).ok
    return original, processed


def layer_index(layers, n):
    return next(i for i, t in enumerate(layers) if t.startswith(f";LAYER:{n}\n"))


def edit(layers, n, fn):
    out = list(layers)
    k = layer_index(out, n)
    lines = out[k].split("\n")
    fn(lines)
    out[k] = "\n".join(lines)
    return out


def fill_range(lines):
    start = lines.index(";TYPE:FILL")
    stop = next(i for i in range(start + 1, len(lines)) if lines[i].startswith(";TYPE:"))
    return start, stop


def check(original, broken):
    return verify(original, broken, min_density=0.2)


def test_a_changed_wall_line_is_caught(pair):
    original, processed = pair

    def move_wall(lines):
        i = lines.index(";TYPE:WALL-OUTER") + 1
        lines[i] = re.sub(r"X([\d.]+)", lambda m: f"X{float(m.group(1)) + 0.5:.3f}", lines[i])

    result = check(original, edit(processed, 12, move_wall))
    assert any("non-FILL line changed" in p for p in result.problems)


def test_a_missing_e_shift_is_caught(pair):
    original, processed = pair

    def drop_g92(lines):
        start, stop = fill_range(lines)
        g92 = [i for i in range(start, stop) if lines[i].startswith("G92 E")]
        assert g92
        del lines[g92[-1]]

    result = check(original, edit(processed, 15, drop_g92))
    assert any("state after FILL block" in p and "E " in p for p in result.problems)


def test_an_e_jump_is_caught(pair):
    original, processed = pair

    def jump(lines):
        start, stop = fill_range(lines)
        i = next(j for j in range(start, stop) if lines[j].startswith("G1 X") and " E" in lines[j])
        lines[i] = re.sub(r"E([\d.]+)", lambda m: f"E{float(m.group(1)) + 3:.5f}", lines[i])
        lines.insert(i + 1, "G92 E" + re.search(r"E([\d.]+)", lines[i]).group(1))

    result = check(original, edit(processed, 16, jump))
    assert any("jumps E" in p for p in result.problems)


def test_wrong_extrusion_per_mm_is_caught(pair):
    original, processed = pair
    result = verify(original, processed, flow=1.05, min_density=0.2)
    assert any("extrudes" in p for p in result.problems)


def test_infill_outside_the_part_is_caught(pair):
    original, processed = pair

    def shift(lines):
        start, stop = fill_range(lines)
        for j in range(start, stop):
            if lines[j].startswith(("G1 X", "G1 F")) and " E" in lines[j] and "X" in lines[j]:
                lines[j] = re.sub(r"X([\d.]+)", lambda m: f"X{float(m.group(1)) + 40:.3f}", lines[j])

    result = check(original, edit(processed, 18, shift))
    assert any("outside the infill area" in p for p in result.problems)


def test_missing_infill_is_caught(pair):
    original, processed = pair
    broken = list(processed)
    for n in range(5, 40):

        def strip(lines):
            start, stop = fill_range(lines)
            keep = [line for line in lines[start:stop] if not (line.startswith("G1 X") or line.startswith("G1 F3000 X"))]
            lines[start:stop] = keep

        broken = edit(broken, n, strip)
    result = check(original, broken)
    assert any("no new infill nearby" in p for p in result.problems)


def test_unpaired_retraction_is_caught(pair):
    original, _ = pair
    # without combing the star's infill retracts at its concave corners: a retraction to break
    processed, _ = process_gcode(original, ProcessSettings(seed=7, combing=False))
    assert verify(original, processed, min_density=0.2).ok

    def over_prime(lines):
        # the first prime after a retraction pushes 1 mm more than was retracted (a blob)
        start, stop = fill_range(lines)
        moves = [j for j in range(start + 1, stop) if re.match(r"G1 F\d+ E", lines[j])]
        assert len(moves) >= 2, "this layer has a retraction inside its infill"
        i = moves[1]
        lines[i] = re.sub(r"E(-?[\d.]+)", lambda m: f"E{float(m.group(1)) + 1:.5f}", lines[i])
        lines.insert(i + 1, "G92 E" + re.search(r"E(-?[\d.]+)", lines[i]).group(1).rstrip("0"))
        lines[i + 1] = f"G92 E{float(lines[i + 1][5:]) - 1:.5f}"

    result = check(original, edit(processed, 10, over_prime))
    assert any("retracts/primes a net" in p for p in result.problems), result.problems
