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


def test_the_summary_says_what_happened_to_each_layer(star, tmp_path):
    import sys

    out = tmp_path / "o.gcode"
    proc = subprocess.run([sys.executable, "-c", _FAILING, "process", str(star), "-o", str(out), "--keep-going"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    layers = re.search(r"^layers (\d+): (\d+) processed, (\d+) left as Cura's \(no infill to replace\), "
                       r"(\d+) kept Cura's infill after a FAILURE$", proc.stdout, re.M)
    assert layers, proc.stdout
    total, processed, left, failed = map(int, layers.groups())
    assert failed == 1 and processed > 30 and total == processed + left + failed
    assert "written from an earlier layer" not in proc.stdout  # no repeats: none is claimed


def test_the_summary_names_regions_by_file_and_gives_areas_per_layer(star, tmp_path):
    folder = tmp_path / "a folder with a long name that used to fill the column"
    folder.mkdir()
    stl = folder / "dense.stl"
    write_stl(stl, box(12, 12, 30, 110, 112))
    proc = run("process", star, "-o", tmp_path / "o.gcode", "--modifier", f"{stl}:60")
    assert proc.returncode == 0, proc.stderr
    row = re.search(r"^dense\.stl\s+60\.0 %\s+([\d.]+) %\s+(\d+)\s+(\d+)$", proc.stdout, re.M)
    assert row, proc.stdout
    measured, per_layer, layers = float(row[1]), int(row[2]), int(row[3])
    assert abs(measured - 60) <= 2
    assert 100 <= per_layer <= 144 and layers == 42  # one layer's share of a 12 x 12 mm box, not a sum
    assert "mm2 per layer" in proc.stdout


def test_progress_goes_to_logs_as_plain_lines(star, tmp_path):
    env = dict(os.environ, DELAUNAY_INFILL_PROGRESS_AFTER="0")
    exe = shutil.which("delaunay-infill")
    proc = subprocess.run([exe, "process", str(star), "-o", str(tmp_path / "o.gcode")], capture_output=True,
                          text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("processing star.gcode:")]
    assert lines and lines[-1].startswith("processing star.gcode: 100 %"), proc.stderr
    assert "\r" not in proc.stderr
    assert sum("100 %" in ln for ln in lines) == 1


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class _Terminal:
    def __init__(self):
        self.text = ""

    def write(self, text):
        self.text += text

    def flush(self):
        pass

    def isatty(self):
        return True


def test_progress_waits_two_seconds_then_a_line_every_ten_in_a_log():
    import io

    from DelaunayInfill.cli import Progress

    clock, log = _Clock(), io.StringIO()
    progress = Progress("processing x.gcode", enabled=True, stream=log, clock=clock)
    for step in range(1, 301):  # a 30 s run, called every 0.1 s
        clock.now = step * 0.1
        progress(step / 300)
    progress(1.0)
    progress.done()
    lines = log.getvalue().splitlines()
    assert lines[0].startswith("processing x.gcode: 7 % (2 s, about 28 s left)"), lines
    assert len(lines) == 4 and lines[-1] == "processing x.gcode: 100 % (30 s)", lines  # 2, 12, 22 s and the end


def test_progress_draws_a_bar_on_a_terminal_and_nothing_for_a_short_run():
    from DelaunayInfill.cli import Progress

    clock, terminal = _Clock(), _Terminal()
    progress = Progress("p", enabled=True, stream=terminal, clock=clock)
    clock.now = 1.9
    progress(0.95)
    assert terminal.text == ""  # under two seconds: nothing
    clock.now = 3.0
    progress(0.5)
    progress.done()
    assert terminal.text.startswith("\rp [###############...............]  50 %") and terminal.text.endswith("\n")


def test_preview_draws_region_outlines_and_keeps_titles_on_the_canvas(star, tmp_path):
    import matplotlib.image  # a test dependency

    stl = tmp_path / "dense.stl"
    write_stl(stl, box(12, 12, 30, 110, 112))
    long_name = tmp_path / ("a" * 70 + ".gcode")
    shutil.copy(star, long_name)
    plain, with_region = tmp_path / "plain.png", tmp_path / "region.png"
    assert run("preview", long_name, "--layer", "20", "-o", plain).returncode == 0
    proc = run("preview", long_name, "--layer", "20", "-o", with_region, "--modifier", f"{stl}:60")
    assert proc.returncode == 0, proc.stderr
    a, b = matplotlib.image.imread(plain), matplotlib.image.imread(with_region)
    assert a.shape == b.shape
    # the outline is black and dash-dotted: many more near-black pixels with the region drawn
    dark = lambda img: int((img[..., :3].max(axis=2) < 0.15).sum())  # noqa: E731
    assert dark(b) > dark(a) + 500
    # the long title is on the canvas: text near the top, and nothing dark runs into any edge of the image
    ink = b[..., :3].max(axis=2) < 0.5
    assert ink[:60].sum() > 50
    assert not (ink[0].any() or ink[-1].any() or ink[:, 0].any() or ink[:, -1].any())


def test_package_output_paths_that_cannot_be_written(tmp_path):
    (tmp_path / "file").write_text("")
    quiet_failure(run("package", "-o", tmp_path / "file"), 2, "is a file: give a folder with -o")
    proc = run("package", "-o", "/proc/no-such-folder")  # not writable even for root
    quiet_failure(proc, 2, "cannot write the package into /proc/no-such-folder")
    assert "Errno" not in proc.stderr


def test_a_painted_model_off_the_part_says_to_give_the_offset(star, tmp_path):
    stl, faces = tmp_path / "model.stl", tmp_path / "faces.json"
    write_stl(stl, box(20, 20, 12))  # model coordinates: off the star, which CuraEngine put at (110, 110)
    faces.write_text('{"faces": [0, 1, 2, 3]}')
    proc = run("process", star, "-o", tmp_path / "p.gcode", "--paint", f"{stl}:{faces}:60:4")
    assert proc.returncode == 0, proc.stderr
    assert "touches no infill" in proc.stderr and "--modifier-offset 110,110" in proc.stderr
