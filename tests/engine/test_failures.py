"""Check 6: a failing layer keeps Cura's infill and is reported; writes are atomic.

A layer failure is injected into the real pipeline run (the layer step raises
for chosen layer numbers, and those layers are not written as repeats of an
earlier one: they are processed, and fail); everything else is the real pipeline.
"""

from __future__ import annotations

import hashlib
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from . import gcode_check as gc
from .conftest import MATRIX, cli_command

FAIL_LAYERS = (12, 13, 30)

_INJECT = """
import sys
import DelaunayInfill.gcode.process as process
real = process._Run._layer
def failing(self, parse):
    if parse.number in {layers}:
        raise RuntimeError("injected failure")
    return real(self, parse)
process._Run._layer = failing
real_replay = process._Run._replay
def no_replay(self, text, words, record):
    if int(text.split("\\n", 1)[0][7:]) in {layers}:
        return None
    return real_replay(self, text, words, record)
process._Run._replay = no_replay
from DelaunayInfill.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _sha(path) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _layer_fill(text: str, number: int) -> list[str]:
    """The FILL-context lines of the first layer with that number (G92 excluded)."""
    out, in_layer, in_fill = [], False, False
    for line in text.split("\n"):
        if line.startswith(";LAYER:"):
            if in_layer:
                break
            in_layer = line == f";LAYER:{number}"
            continue
        if not in_layer:
            continue
        if line.startswith(";TYPE:"):
            in_fill = line == ";TYPE:FILL"
        elif line.startswith(";MESH:NONMESH") or line.startswith(";TIME_ELAPSED"):
            in_fill = False
        elif in_fill and not line.startswith("G92"):
            out.append(line)
    return out


@pytest.fixture(scope="module")
def hbracket(slices):
    return slices.get(MATRIX["hbracket"])


@pytest.fixture
def injected_failures(monkeypatch):
    import DelaunayInfill.gcode.process as process

    real = getattr(process._Run, "_layer", None)
    if real is None:
        pytest.fail("fault injection point DelaunayInfill.gcode.process._Run._layer is gone; update this test")

    def failing(self, parse):
        if parse.number in FAIL_LAYERS:
            raise RuntimeError("injected failure")
        return real(self, parse)

    monkeypatch.setattr(process._Run, "_layer", failing)
    real_replay = getattr(process._Run, "_replay", None)
    if real_replay is None:
        pytest.fail("DelaunayInfill.gcode.process._Run._replay is gone; update this test")

    def no_replay(self, text, words, record):  # an injected layer is processed (and fails), not repeated
        if int(text.split("\n", 1)[0][7:]) in FAIL_LAYERS:
            return None
        return real_replay(self, text, words, record)

    monkeypatch.setattr(process._Run, "_replay", no_replay)


def test_6_failed_layers_keep_cura_infill_and_are_reported(hbracket, injected_failures, tmp_path):
    from DelaunayInfill import process_file

    out = tmp_path / "out.gcode"
    report = process_file(hbracket.gcode, str(out))
    assert sorted(report.failed_layers) == list(FAIL_LAYERS)
    assert len(report.failure_messages) == len(FAIL_LAYERS)
    assert "injected failure" in report.failure_messages[0]
    assert report.layers_processed > 0
    original = open(hbracket.gcode, encoding="utf-8").read()
    new = out.read_text(encoding="utf-8")
    for number in FAIL_LAYERS:
        assert _layer_fill(new, number) == _layer_fill(original, number), f"layer {number} lost Cura's infill"
    assert _layer_fill(new, 20) != _layer_fill(original, 20), "other layers must still be processed"
    # the kept layers sit between processed ones: E and state must still be continuous
    orig, parsed = gc.parse_gcode(original), gc.parse_gcode(new)
    for result in (gc.check_unchanged(orig, parsed), gc.check_extrusion(orig, parsed, hbracket.case.geometry())):
        assert result.ok, result.report()


def test_6_cli_tells_the_user_about_failed_layers(hbracket, tmp_path):
    out = tmp_path / "out.gcode"
    command = [sys.executable, "-c", _INJECT.format(layers=set(FAIL_LAYERS)), "process", hbracket.gcode, "-o", str(out)]
    # failed layers: exit 1 and nothing written, unless the user asks to keep going
    proc = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and not out.exists(), (proc.returncode, proc.stderr)
    assert "--keep-going" in proc.stderr
    proc = subprocess.run([*command, "--keep-going"], capture_output=True, text=True, timeout=300)
    text = proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == 0 and out.exists()
    assert "fail" in text.lower()
    for number in FAIL_LAYERS:
        assert re.search(rf"\b{number}\b", text), f"layer {number} not reported:\n{text}"
    assert f"layers_failed={len(FAIL_LAYERS)}" in out.read_text()  # the marker says so


def test_6_input_is_never_modified_without_in_place(hbracket, tmp_path):
    src = tmp_path / "in.gcode"
    src.write_bytes(open(hbracket.gcode, "rb").read())
    before = _sha(src)
    proc = subprocess.run([*cli_command(), "process", str(src), "-o", str(tmp_path / "out.gcode"), "--density", "20"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert _sha(src) == before
    # no output path and no --in-place: refused, input untouched, nothing else written
    proc = subprocess.run([*cli_command(), "process", str(src)], capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert _sha(src) == before
    assert sorted(os.listdir(tmp_path)) == ["in.gcode", "out.gcode"]


def test_6_in_place_replaces_the_input_with_a_complete_processed_file(hbracket, tmp_path):
    src = tmp_path / "in.gcode"
    original = open(hbracket.gcode, encoding="utf-8").read()
    src.write_text(original, encoding="utf-8")
    os.chmod(src, 0o640)
    proc = subprocess.run([*cli_command(), "process", str(src), "--in-place", "--density", "20"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    new = gc.parse_gcode(src.read_text(encoding="utf-8"))
    assert gc.check_marker(new).ok
    assert gc.check_unchanged(gc.parse_gcode(original), new).ok
    assert os.listdir(tmp_path) == ["in.gcode"], "temporary files left behind"
    assert src.stat().st_mode & 0o777 == 0o640, "--in-place changed the file's permissions"


def test_6_refused_input_leaves_an_existing_output_untouched(tmp_path):
    src = tmp_path / "junk.gcode"
    src.write_bytes(b"G1 X10 Y10\n" * 50 + bytes(range(256)) * 4)
    out = tmp_path / "out.gcode"
    out.write_text("precious earlier result\n")
    proc = subprocess.run([*cli_command(), "process", str(src), "-o", str(out)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr and proc.stderr.strip()
    assert out.read_text() == "precious earlier result\n"
    assert sorted(os.listdir(tmp_path)) == ["junk.gcode", "out.gcode"]


def test_6_a_killed_run_leaves_no_partial_output(big_gcode, tmp_path):
    """SIGKILL in the middle of a long run: the output path holds nothing (no partial file)."""
    out = tmp_path / "out.gcode"
    proc = subprocess.Popen([*cli_command(), "process", big_gcode.path, "-o", str(out), "--density", "20"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # wait until the run has written something (its temporary file) or 20 s passed
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not any(p.name != "out.gcode" for p in tmp_path.iterdir()):
            time.sleep(0.2)
        time.sleep(1.0)
        assert proc.poll() is None, "the run finished too early to be interrupted"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert not out.exists()


def test_6_output_files_get_the_usual_permissions(hbracket, tmp_path):
    """An atomic write must not leave the temporary file's private mode (0600) on the user's G-code."""
    out = tmp_path / "out.gcode"
    umask = os.umask(0o022)
    try:
        proc = subprocess.run([*cli_command(), "process", hbracket.gcode, "-o", str(out), "--density", "20"],
                              capture_output=True, text=True, timeout=300)
    finally:
        os.umask(umask)
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_mode & 0o777 == 0o644, oct(out.stat().st_mode & 0o777)
    assert os.stat(hbracket.gcode).st_mode & 0o777 == 0o644  # slice_models' own output
