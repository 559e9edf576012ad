"""The vectorized parser and the line-by-line parser read every chunk the same way.

`parse_layer` takes a fast path (one regex pass and numpy) for Cura's motion
lines and falls back on `parse_layer_lines` for unusual chunks.  Random
chunks mixing Cura's lines with odd ones (reordered words, doubled words,
CR line ends, G92, G10/G11, T, mode changes, unknown commands) must give
identical moves, blocks, machine state and retraction model, chunk after
chunk; and clip_segments must give the same pieces with or without its
k-d tree pair search.
"""

from __future__ import annotations

import copy
import random

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from shapely.geometry import Point

from DelaunayInfill import routing
from DelaunayInfill.gcode import read
from DelaunayInfill.gcode.read import MachineState, RetractionModel


def _number(rng, scale=100.0, negative=False):
    value = rng.uniform(-scale if negative else 0.0, scale)
    text = rng.choice(["{:.3f}", "{:.5f}", "{:.0f}", "{:.1f}", "{:g}"]).format(value)
    return (text.lstrip("0") or "0") if rng.random() < 0.05 else text


def _line(rng, relative):
    r = rng.random()
    if r < 0.55:
        words = [rng.choice(["G0", "G1"])]
        if rng.random() < 0.2:
            words.append("F" + _number(rng, 9000))
        if rng.random() < 0.8:
            words.append("X" + _number(rng, 200))
        if rng.random() < 0.8:
            words.append("Y" + _number(rng))
        if rng.random() < 0.1:
            words.append("Z" + _number(rng, 2))
        if rng.random() < 0.6:
            words.append("E" + (_number(rng, 1, True) if relative else _number(rng, 500, rng.random() < 0.1)))
        if rng.random() < 0.03:
            rng.shuffle(words)
        text = " ".join(words)
        for p, change in ((0.03, lambda t: t + " ;c X5"), (0.02, lambda t: t + "\r"), (0.02, lambda t: t.replace(" ", "  ", 1)),
                          (0.01, lambda t: t.replace("X", "X ", 1)), (0.01, lambda t: t + " X1"),
                          (0.01, lambda t: t.replace("G1", "G01", 1)), (0.01, lambda t: t.replace("G", "g", 1)),
                          (0.01, lambda t: t + "."), (0.01, lambda t: t.replace("E", "E-0", 1)),
                          (0.01, lambda t: t.replace("X1", "X\u0661", 1)),  # an Arabic-Indic 1: float() takes it
                          (0.005, lambda t: t.replace("Y", "Y-", 1).replace("Y--", "Y-")),
                          (0.005, lambda t: t.replace(".", "", 1) + "123456789012"),  # more digits than 15
                          (0.005, lambda t: t.replace("Y", "Y-.", 1))):
            if rng.random() < p:
                text = change(text)
        return text
    if r < 0.62:
        return rng.choice(["G1 F1500 E" + _number(rng, 5, True), "G1 F2700 E-6.5", "G0 F300 Z" + _number(rng, 3), "G1 E" + _number(rng, 3)])
    if r < 0.80:
        return rng.choice([";TYPE:FILL", ";TYPE:WALL-OUTER", ";TYPE:WALL-INNER", ";TYPE:SKIN", ";TYPE:FILL ", ";TYPE:ODD"])
    if r < 0.86:
        return rng.choice([";MESH:a", ";MESH:b.stl", ";MESH:NONMESH", ";MESH:a ", ";MESH:ü"])
    if r < 0.88:
        return rng.choice(["T0", "T1", "t1"])
    if r < 0.93:
        return rng.choice(["G92 E0", "G92 E" + _number(rng, 50), "G92 X1", "G10", "G11", "M106 S255", "M204 S500", "",
                           "; comment", "G2 X1 Y1 I1 J0 E1", "G28", "G4 P0"])
    if r < 0.95:
        return rng.choice(["M82", "M83", "G90", "G91", "M82 ;absolute"])
    return rng.choice([";TIME_ELAPSED:" + _number(rng, 500), ";LAYER:" + str(rng.randint(-2, 50)), ";LAYER:x"])


def _assert_same(a, b):
    assert a.lines == b.lines and a.number == b.number and a.meshes == b.meshes
    assert a.z == b.z or (a.z != a.z and b.z != b.z)
    assert list(a.moves) == list(b.moves)
    for key in a.moves:
        assert a.moves[key].dtype == b.moves[key].dtype, key
        assert np.array_equal(a.moves[key], b.moves[key], equal_nan=True), key
    assert repr(a.blocks) == repr(b.blocks)
    assert repr(a.end_state) == repr(b.end_state)
    assert a.time_elapsed_lines == b.time_elapsed_lines


@pytest.mark.parametrize("seed", range(0, 400, 20))
def test_fast_and_line_parsers_agree(seed):
    fast_chunks = 0
    for s in range(seed, seed + 20):
        rng = random.Random(s)
        state_a, model_a = MachineState(), RetractionModel()
        if rng.random() < 0.3:
            state_a.relative_e = state_a.e_mode_relative = True
        if rng.random() < 0.3:
            state_a.x, state_a.y = 10.0, 20.0
        state_b, model_b = copy.deepcopy(state_a), copy.deepcopy(model_a)
        for _ in range(4):
            text = "\n".join(_line(rng, state_a.relative_e) for _ in range(rng.randint(0, 60)))
            fast_chunks += read._parse_layer_fast(text, copy.deepcopy(state_a), copy.deepcopy(model_a)) is not None
            _assert_same(read.parse_layer(text, state_a, model_a), read.parse_layer_lines(text, state_b, model_b))
            assert repr(model_a) == repr(model_b) and repr(state_a) == repr(state_b)
    assert fast_chunks > 20, "the fast path must be exercised"


def _float_or_invalid(token: str):
    """What the line-by-line parser makes of a word's value: float(), NaN when not given, None when invalid."""
    if not token:
        return float("nan")
    try:
        return float(token)
    except ValueError:
        return None


def _bits(values) -> list[str]:
    return ["nan" if v != v else float(v).hex() for v in values]  # hex keeps the sign of zero and every bit


_TOKENS = st.text(alphabet="-.0123456789", max_size=22)


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["", "0", "1"]), _TOKENS, _TOKENS, _TOKENS, _TOKENS, _TOKENS), max_size=12))
@example([("1", "5.", ".5", "-.5", "-0", "007")])
@example([("0", "-0.0", "1234567890.12345", "", "", "")])  # 15 digits: still the vectorized reader
@example([("1", "0.1234567890123456", "9007199254740993", "", "", "1")])  # 16 digits: float()
@example([("1", "1.2.3", "", "", "", "")])
@example([("1", "", "-", "", "", "")])
@example([("1", "", "", ".", "", "")])
@example([("1", "", "", "", "-.", "")])
@example([("1", "--1", "", "", "", "")])
@example([("1", "1-2", "", "", "", "")])
@example([("", "", "", "", "", "")])
def test_word_table_reads_every_value_as_float_does(rows):
    table = read._word_table(rows)
    expected = [_float_or_invalid(token) for row in rows for token in row]
    if any(v is None for v in expected):
        assert table is None
        return
    assert table is not None and table.shape == (len(rows), 6) and table.dtype == np.float64
    assert _bits(table.ravel().tolist()) == _bits(expected)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=30),
       st.sampled_from(["{:.3f}", "{:.5f}", "{:.1f}", "{:.0f}", "{:g}", "{!r}"]))
def test_word_table_reads_cura_numbers_exactly(values, fmt):
    tokens = [fmt.format(v) for v in values]
    if any("e" in t for t in tokens):  # exponents are no G-code
        return
    rows = [("1", t, t, "", "", t) for t in tokens]
    expected = [float(t) for t in tokens]
    table = read._word_table(rows)
    assert _bits(table[:, 1].tolist()) == _bits(expected) and _bits(table[:, 5].tolist()) == _bits(expected)
    assert np.isnan(table[:, 3]).all()


def test_clip_segments_same_with_and_without_kd_trees(monkeypatch):
    rng = np.random.default_rng(1)
    for trial in range(200):
        area = Point(rng.uniform(-5, 5), rng.uniform(-5, 5)).buffer(rng.uniform(5, 20), int(rng.integers(2, 16)))
        if trial % 3 == 0:
            area = area.difference(Point(0, 0).buffer(3, 4))
        if trial % 5 == 0:  # through vertices and along edges
            ring = np.asarray(area.exterior.coords)
            k = int(rng.integers(1, 6))
            segments = np.stack([ring[rng.integers(0, len(ring), k)], ring[rng.integers(0, len(ring), k)]], axis=1)
        else:
            segments = rng.uniform(-30, 30, (int(rng.integers(1, 40)), 2, 2))
        monkeypatch.setattr(routing, "_BRUTE_FORCE_PAIRS", 10**9)
        a, ia = routing.clip_segments(segments, area, return_index=True)
        monkeypatch.setattr(routing, "_BRUTE_FORCE_PAIRS", -1)
        b, ib = routing.clip_segments(segments, area, return_index=True)
        assert np.array_equal(a, b) and np.array_equal(ia, ib)
