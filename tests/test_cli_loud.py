"""The command line never fails quietly (issue 12): every row of the issue's table, run as a user runs it.

Each test runs the console script (`delaunay-infill`, as installed) and checks the exit status, the
message in the CLI's own words (one line, no traceback, no temporary file names) and that nothing was
written or the input changed.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest

from DelaunayInfill.gcode.read import MARKER
from DelaunayInfill.models import box, write_stl

DATA = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data")


def run(*args, cwd=None) -> subprocess.CompletedProcess:
    exe = shutil.which("delaunay-infill")
    assert exe, "the delaunay-infill console script is not installed (pip install -e .)"
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)


def quiet_failure(proc: subprocess.CompletedProcess, status: int, words: str) -> None:
    """Exit `status`, a message with `words`, no traceback, no temporary names."""
    assert proc.returncode == status, (proc.returncode, proc.stdout, proc.stderr)
    assert words in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    assert ".delaunay-" not in proc.stderr


@pytest.fixture()
def star(star_gcode):
    return star_gcode


def _nothing_new(folder, *keep) -> None:
    assert sorted(p.name for p in folder.iterdir()) == sorted(keep), list(folder.iterdir())


def test_relax_below_zero_is_refused(star, tmp_path):
    quiet_failure(run("process", star, "-o", tmp_path / "o.gcode", "--relax", "-1"), 2, "--relax takes 0 to 1000")
    _nothing_new(tmp_path, "star.gcode")


def test_in_place_verify_verifies_before_replacing(star):
    before = star.read_bytes()
    proc = run("process", star, "--in-place", "--verify")
    assert proc.returncode == 0, proc.stderr
    assert "verify: OK" in proc.stdout
    assert star.read_bytes() != before and MARKER in star.read_text()
    _nothing_new(star.parent, "star.gcode")  # the checked copy went over the input


@pytest.mark.parametrize("output, words", [("folder/", "is a folder"), ("missing/x.gcode", "does not exist")])
def test_output_paths_that_cannot_be_written(star, tmp_path, output, words):
    (tmp_path / "folder").mkdir()
    proc = run("process", star, "-o", tmp_path / output if not output.endswith("/") else str(tmp_path / output))
    quiet_failure(proc, 2, words)
    assert len(proc.stderr.strip().splitlines()) == 1


def test_an_unwritable_folder(star, tmp_path):
    if os.geteuid() == 0:
        # root may write anywhere: a folder that is a file stands in for one that cannot be written
        (tmp_path / "file").write_text("")
        quiet_failure(run("process", star, "-o", tmp_path / "file" / "x.gcode"), 2, "does not exist")
        return
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    quiet_failure(run("process", star, "-o", locked / "x.gcode"), 2, "no permission")


def test_preview_into_a_missing_folder(star, tmp_path):
    pytest.importorskip("matplotlib")
    quiet_failure(run("preview", star, "--layer", "5", "-o", tmp_path / "missing" / "p.png"), 2, "does not exist")


def test_a_modifier_off_the_part_says_to_give_the_offset(star, tmp_path):
    stl = tmp_path / "dense.stl"
    write_stl(stl, box(20, 20, 12))  # model coordinates: off the star, which CuraEngine put at (110, 110)
    proc = run("process", star, "-o", tmp_path / "o.gcode", "--modifier", f"{stl}:50")
    assert proc.returncode == 0
    assert "--modifier-offset 110,110" in proc.stderr


def test_an_unknown_mesh_name_is_named(star, tmp_path):
    proc = run("process", star, "-o", tmp_path / "o.gcode", "--mesh", "nosuch:50")
    assert proc.returncode == 0
    assert "--mesh nosuch: no such ;MESH:" in proc.stderr and "star.stl" in proc.stderr


def test_a_file_without_infill_is_not_marked_and_says_why(star, tmp_path):
    no_fill = tmp_path / "nofill.gcode"
    # Cura's 0 % infill: no FILL blocks (the FILL lines become travel)
    text = re.sub(r"^;TYPE:FILL$", ";TYPE:SKIN", star.read_text(), flags=re.M)
    text = "".join(line for line in text.splitlines(keepends=True))
    no_fill.write_text(text)
    out = tmp_path / "o.gcode"
    proc = run("process", no_fill, "-o", out, "--density", "20")
    quiet_failure(proc, 1, "nothing was written")
    assert "no infill" in proc.stderr and not out.exists()


def test_a_density_under_one_percent_asks_what_was_meant(star, tmp_path):
    proc = run("process", star, "-o", tmp_path / "o.gcode", "--density", "0.5")
    assert proc.returncode == 0 and "did you mean 50 %" in proc.stderr


def test_a_line_width_far_from_the_file_s_own_is_warned_about(star, tmp_path):
    proc = run("process", star, "-o", tmp_path / "o.gcode", "--line-width", "1.5")
    assert proc.returncode == 0 and "far from the file's own 0.4 mm" in proc.stderr
    quiet_failure(run("process", star, "-o", tmp_path / "p.gcode", "--line-width", "6"), 2, "outside 0.05-5 mm")


def test_flow_has_its_own_range_and_words(star, tmp_path):
    assert run("process", star, "-o", tmp_path / "o.gcode", "--flow", "110", "-q").returncode == 0
    quiet_failure(run("process", star, "-o", tmp_path / "p.gcode", "--flow", "400"), 2,
                  "--flow is the extrusion relative to Cura's infill, 10 to 300 %")


def test_the_output_being_the_input_names_the_flag(star):
    quiet_failure(run("process", star, "-o", star), 2, "give --in-place to replace it")


def test_binary_input_is_named_once(tmp_path):
    binary = tmp_path / "part.gcode"
    binary.write_bytes(b";FLAVOR:Marlin\n;Generated with Cura_SteamEngine 4.13.0\n\xff\xfe\x00\x01" * 10)
    proc = run("process", binary, "-o", tmp_path / "o.gcode")
    quiet_failure(proc, 2, "not a text G-code file")
    assert proc.stderr.count(str(binary)) == 1


def test_a_file_cut_inside_its_end_gcode_is_refused(star, tmp_path):
    text = star.read_text()
    cut = tmp_path / "cut.gcode"
    cut.write_text(text[: text.index(";End of Gcode") - 40])
    out = tmp_path / "o.gcode"
    quiet_failure(run("process", cut, "-o", out), 2, "truncated")
    assert not out.exists()


_FAILING = """
import sys
import DelaunayInfill.gcode.process as process
real = process._Run._layer
def failing(self, parse):
    if parse.number == 20:
        raise RuntimeError("injected failure")
    return real(self, parse)
process._Run._layer = failing
process._Run._replay = lambda self, text, words, record: None
from DelaunayInfill.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_failed_layers_exit_non_zero_unless_asked_to_keep_going(star, tmp_path):
    import sys

    out = tmp_path / "o.gcode"
    command = [sys.executable, "-c", _FAILING, "process", str(star), "-o", str(out)]
    proc = subprocess.run([*command, "-q"], capture_output=True, text=True, timeout=300)
    quiet_failure(proc, 1, "--keep-going")
    assert "injected failure" in proc.stderr  # told even with -q
    assert not out.exists()
    proc = subprocess.run([*command, "--keep-going", "-q"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and out.exists()
    assert "layers_failed=1" in out.read_text()


def test_the_package_gets_the_mode_of_a_new_file(tmp_path):
    proc = run("package", "-o", tmp_path)
    assert proc.returncode == 0, proc.stderr
    (package,) = tmp_path.glob("*.curapackage")
    umask = os.umask(0)
    os.umask(umask)
    assert package.stat().st_mode & 0o777 == 0o666 & ~umask


def test_figures_refuses_a_file_as_its_folder(tmp_path):
    (tmp_path / "file").write_text("")
    quiet_failure(run("figures", "-o", tmp_path / "file"), 2, "is a file: give a folder with -o")
    quiet_failure(run("figures", "-o", tmp_path / "out", "--table", tmp_path / "missing" / "t.md"), 2,
                  "does not exist")
    assert not (tmp_path / "out").exists()
