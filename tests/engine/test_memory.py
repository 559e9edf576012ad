"""Check 7: a 500 MB G-code processes under 1 GB peak RSS (the child process's, measured).

The file is a real slice with its middle layers repeated (bigfile.py); set
DELAUNAY_BIG_GCODE_MB to change its size.  Slow by nature: it reports its
wall time but asserts none.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import time

from . import gcode_check as gc
from .conftest import cli_command

PEAK_RSS_LIMIT_KB = 1024 * 1024  # 1 GiB


def _run_measured(argv: list[str]) -> tuple[subprocess.CompletedProcess, int, float]:
    """Run argv; return the result, the child's peak RSS in kB and the wall time in s."""
    start = time.perf_counter()
    if os.path.exists("/usr/bin/time"):
        proc = subprocess.run(["/usr/bin/time", "-v", *argv], capture_output=True, text=True)
        match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
        assert match, proc.stderr[-2000:]
        peak = int(match.group(1))
    else:  # RUSAGE_CHILDREN is the maximum over all children so far: a bound, never an underestimate
        proc = subprocess.run(argv, capture_output=True, text=True)
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return proc, peak, time.perf_counter() - start


def test_7_large_file_in_bounded_memory(big_gcode, tmp_path, capsys):
    out = tmp_path / "big.out.gcode"
    proc, peak_kb, seconds = _run_measured([*cli_command(), "process", big_gcode.path, "-o", str(out),
                                            "--density", "20", "--quiet"])
    with capsys.disabled():
        print(f"\n[check 7] {big_gcode.size / 1e6:.0f} MB, {big_gcode.layers} layers: "
              f"{seconds:.0f} s wall, peak RSS {peak_kb / 1024:.0f} MB")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert peak_kb < PEAK_RSS_LIMIT_KB, f"peak RSS {peak_kb / 1024:.0f} MB"
    # the output is complete: processed header, every layer, the same end G-code
    size = out.stat().st_size
    assert size > 0.8 * big_gcode.size
    with open(out, "rb") as f:
        head = f.read(4096).decode("utf-8", "replace")
        f.seek(size - 2000)
        tail = f.read()
    with open(big_gcode.path, "rb") as f:
        f.seek(big_gcode.size - 2000)
        original_tail = f.read()
    assert ";DELAUNAYINFILL_PROCESSED" in head
    assert tail.split(b";TIME_ELAPSED")[-1].split(b"\n", 1)[1] == original_tail.split(b";TIME_ELAPSED")[-1].split(b"\n", 1)[1]
    layers = 0
    with open(out, encoding="utf-8") as f:
        for line in f:
            layers += line.startswith(";LAYER:")
    out.unlink()  # half a gigabyte
    assert layers == big_gcode.layers


def test_big_file_generator_makes_consistent_gcode(slices, tmp_path):
    """The repeated-layer file is itself sound: continuous layers, rising Z, E per mm as Cura's."""
    from .bigfile import write_big_gcode
    from .conftest import MATRIX

    source = slices.get(MATRIX["relative_e"])
    text = open(source.gcode, encoding="utf-8").read()
    big = write_big_gcode(text, str(tmp_path / "b.gcode"), 2 * len(text))
    big_text = open(big.path, encoding="utf-8").read()
    parsed = gc.parse_gcode(big_text)
    numbers = [layer["number"] for layer in parsed.layers]
    assert numbers == list(range(big.layers)) and big.layers > 90
    z = [layer["z"] for layer in parsed.layers]
    assert all(b > a for a, b in zip(z[:-1], z[1:], strict=True))
    assert "\nM83" in big_text and big_text.count(";LAYER_COUNT:") == 1
    moves = parsed.moves
    xy = ((moves[:, gc.C_X1] - moves[:, gc.C_X0]) ** 2 + (moves[:, gc.C_Y1] - moves[:, gc.C_Y0]) ** 2) ** 0.5
    extruding = (moves[:, gc.C_DE] > 0) & (xy > 1.0)
    orig = gc.parse_gcode(text).moves
    oxy = ((orig[:, gc.C_X1] - orig[:, gc.C_X0]) ** 2 + (orig[:, gc.C_Y1] - orig[:, gc.C_Y0]) ** 2) ** 0.5
    limit = (orig[:, gc.C_DE][oxy > 1.0] / oxy[oxy > 1.0]).max()
    assert (moves[extruding, gc.C_DE] / xy[extruding]).max() <= limit * 1.001
