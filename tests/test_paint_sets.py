"""Painted sets of a model: editing, strokes' undo/redo state, the saved form (DelaunayInfill/cura/paint.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from DelaunayInfill.cura import paint


def test_a_face_belongs_to_one_set_and_painting_moves_it():
    data = paint.PaintData(100)
    a = data.add_set(60, 6).number
    b = data.add_set(10, 2).number
    assert (a, b) == (1, 2)
    assert data.paint(a, [1, 2, 3, 3]) == 3
    assert data.paint(b, [3, 4]) == 2
    assert list(data.get(a).faces) == [1, 2] and list(data.get(b).faces) == [3, 4]
    assert data.paint(b, [4]) == 0
    assert data.erase([2, 4, 50]) == 2
    assert list(data.get(a).faces) == [1] and list(data.get(b).faces) == [3]
    data.erase([3])
    data.drop_empty()
    assert [s.number for s in data.sets] == [1]
    assert data.next_number() == 2
    with pytest.raises(ValueError, match="not one of the model's 100 triangles"):
        data.paint(a, [100])


def test_values_are_clamped_and_checked():
    s = paint.PaintSet(1, 250, 0.0, [3, 1, 1])
    assert (s.density, s.depth, list(s.faces)) == (100.0, paint.MIN_DEPTH_MM, [1, 3])
    with pytest.raises(ValueError):
        paint.PaintSet(1, float("nan"), 2)


def test_the_saved_form_round_trips():
    data = paint.PaintData(5000)
    data.add_set(60, 6)
    data.paint(1, list(range(10, 400)) + [1000, 1002, 4999])
    data.add_set(12.5, 1.25)
    data.paint(2, [0, 1, 2, 7])
    text = data.to_json()
    doc = json.loads(text)
    assert doc["version"] == paint.FORMAT_VERSION and doc["face_count"] == 5000
    assert doc["sets"][0]["faces"] == [[10, 400], [1000, 1001], [1002, 1003], [4999, 5000]]  # runs
    back = paint.PaintData.from_json(text, 5000)
    assert back == data
    assert back.to_json() == text
    with pytest.raises(ValueError, match="mesh of 5000 triangles, this one has 4999"):
        paint.PaintData.from_json(text, 4999)


@pytest.mark.parametrize("text, message", [
    ("nope", "not JSON"),
    ('{"sets": 3}', "no list of sets"),
    ('{"version": 99, "face_count": 4, "sets": []}', "newer plugin"),
    ('{"face_count": 4, "sets": [{"number": 1, "density": 5, "depth": 1, "faces": [[3, 2]]}]}', "bad run"),
    ('{"face_count": 4, "sets": [{"number": 1, "density": 5, "depth": 1, "faces": [[0, 9]]}]}', "not one of"),
    ('{"face_count": 4, "sets": [{"number": 1, "density": 5, "depth": 1}, {"number": 1, "density": 5, "depth": 1}]}',
     "share a number"),
])
def test_bad_saved_paintings_are_refused(text, message):
    with pytest.raises(ValueError, match=message):
        paint.PaintData.from_json(text)


def test_ranges_encode_and_decode():
    faces = np.array([9, 1, 2, 3, 7, 8])
    assert paint.encode_ranges(faces) == [[1, 4], [7, 10]]
    assert list(paint.decode_ranges([[1, 4], [7, 10]])) == [1, 2, 3, 7, 8, 9]
    assert paint.encode_ranges([]) == [] and len(paint.decode_ranges([])) == 0


def test_a_stroke_undoes_and_redoes_to_the_exact_states():
    shown = {}

    def apply(data):
        shown["data"] = data

    before = paint.PaintData(20)
    before.add_set(60, 6)
    before.paint(1, [1, 2])
    after = before.copy()
    after.paint(1, [3, 4])
    after.add_set(30, 2)
    after.paint(2, [2])
    edit = paint.PaintEdit(before, after, apply, "stroke")
    before.paint(1, [9])  # the edit keeps its own copies
    assert edit.changes
    edit.redo()
    assert shown["data"] == after
    shown["data"].paint(1, [10])  # what was shown may be changed without touching the edit
    edit.undo()
    assert list(shown["data"].get(1).faces) == [1, 2] and shown["data"].get(2) is None
    edit.redo()
    assert shown["data"] == after
    first = paint.PaintEdit(None, after, apply)
    first.undo()
    assert shown["data"] is None  # the model had no painting before its first stroke
    assert not paint.PaintEdit(after, after.copy(), apply).changes


def test_colours_differ_per_set():
    assert len({paint.set_color_hex(n) for n in range(1, len(paint.PALETTE) + 1)}) == len(paint.PALETTE)
    assert paint.set_color(1) == paint.set_color(1 + len(paint.PALETTE))


def test_the_set_of_a_clicked_face():
    """A click on a painted face selects the set that face is painted in (0: not painted)."""
    data = paint.PaintData(20)
    data.add_set(60, 6)
    data.add_set(10, 2)
    data.paint(1, [0, 5, 6])
    data.paint(2, [6, 19])  # face 6 moves to set 2
    assert [data.set_of_face(f) for f in (0, 5, 6, 19, 1, 7, 18)] == [1, 1, 2, 2, 0, 0, 0]
    assert paint.PaintData(3).set_of_face(1) == 0


@pytest.mark.parametrize("chosen, expected", [
    ("file:///tmp/out/box_paint1.stl", "/tmp/out/box_paint1.stl"),
    ("file:///tmp/with%20space/a.stl", "/tmp/with space/a.stl"),
    ("file://localhost/tmp/b.stl", "/tmp/b.stl"),
    ("/tmp/c.stl", "/tmp/c.stl"),
])
def test_a_file_dialogs_choice_becomes_a_local_path(chosen, expected):
    assert paint.local_path(chosen) == expected
    stl, faces = paint.export_paths(paint.local_path(chosen))
    assert stl == expected and faces == expected[: -len(".stl")] + ".faces.json"


def test_no_choice_is_refused():
    with pytest.raises(ValueError, match="no file chosen"):
        paint.local_path("  ")
