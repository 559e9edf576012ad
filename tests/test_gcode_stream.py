"""process_file streams: bounded memory, atomic output, process_file == process_gcode."""

from __future__ import annotations

import gzip
import os
import re
import subprocess
import sys
import textwrap

import pytest

from DelaunayInfill.gcode import GCodeError, ProcessSettings, process_file, process_gcode
from DelaunayInfill.gcode.read import as_cura_list

DATA = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data")


def star_text() -> str:
    with gzip.open(os.path.join(DATA, "star.gcode.gz"), "rt", encoding="utf-8", newline="") as f:
        return f.read()


def tall_gcode(path, copies: int) -> int:
    """A tall print: the star's middle layers stacked `copies` times (Z and layer numbers renumbered).

    The E values repeat from copy to copy; the pipeline tracks E, it does not require it to grow.
    """
    parts = as_cura_list(star_text())
    header, start, layers, end = parts[0], parts[1], parts[2:-1], parts[-1]
    middle = layers[10:40]
    n = 0
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(header)
        f.write(start)
        for _ in range(copies):
            for text in middle:
                z = 0.2 * (n + 1)
                body = re.sub(r"^;LAYER:\d+", f";LAYER:{n}", text, count=1, flags=re.M)
                body = re.sub(r" Z[\d.]+", f" Z{z + 0.2:.2f}", body)
                f.write(body)
                n += 1
        f.write(end)
    return os.path.getsize(path)


def test_process_file_equals_process_gcode(tmp_path):
    text = star_text()
    src = tmp_path / "s.gcode"
    src.write_text(text, encoding="utf-8", newline="")
    out = tmp_path / "o.gcode"
    report_file = process_file(src, out, ProcessSettings(seed=9))
    layers, report_mem = process_gcode(as_cura_list(text), ProcessSettings(seed=9))
    assert out.read_text(encoding="utf-8") == "".join(layers)
    assert report_file.layers_processed == report_mem.layers_processed
    assert report_file.time_after_s == pytest.approx(report_mem.time_after_s)


def test_output_is_not_written_when_processing_raises(tmp_path, monkeypatch):
    from DelaunayInfill.gcode import process as process_module

    src = tmp_path / "s.gcode"
    src.write_text(star_text(), encoding="utf-8", newline="")
    out = tmp_path / "o.gcode"
    out.write_text("old")

    def boom(self, header):
        raise RuntimeError("disk full")

    monkeypatch.setattr(process_module._Run, "finish", boom)
    with pytest.raises(RuntimeError):
        process_file(src, out)
    assert out.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.gcode", "s.gcode"]


def test_refused_file_writes_nothing(tmp_path):
    src = tmp_path / "s.gcode"
    src.write_text(";FLAVOR:Marlin\nG28\n")
    with pytest.raises(GCodeError):
        process_file(src, tmp_path / "o.gcode")
    assert not (tmp_path / "o.gcode").exists()


def test_input_is_never_the_output_without_in_place(tmp_path):
    src = tmp_path / "s.gcode"
    src.write_text(star_text(), encoding="utf-8", newline="")
    with pytest.raises(ValueError, match="in_place"):
        process_file(src, src)
    with pytest.raises(ValueError, match="in_place"):
        process_file(src)


_RSS_PROBE = textwrap.dedent(
    """
    import resource, sys
    from DelaunayInfill.gcode import process_file
    report = process_file(sys.argv[1], sys.argv[2])
    assert report.layers_processed > 0 and not report.failed_layers, report.failure_messages
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    """
)


def _peak_rss_kb(src, out) -> int:
    proc = subprocess.run([sys.executable, "-c", _RSS_PROBE, str(src), str(out)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    return int(proc.stdout.strip().splitlines()[-1])


def test_memory_does_not_grow_with_file_size(tmp_path):
    small = tmp_path / "small.gcode"
    big = tmp_path / "big.gcode"
    small_size = tall_gcode(small, 1)
    big_size = tall_gcode(big, 140)
    assert big_size > 100 * small_size and big_size > 15_000_000
    rss_small = _peak_rss_kb(small, tmp_path / "small_out.gcode")
    rss_big = _peak_rss_kb(big, tmp_path / "big_out.gcode")
    grown_mb = (rss_big - rss_small) / 1024
    # holding the file (and its lines) would add several times its size
    assert grown_mb < 0.25 * big_size / 1e6, f"peak RSS grew by {grown_mb:.0f} MB for a {big_size / 1e6:.0f} MB file"


def test_cancel_stops_without_output_and_progress_reaches_one(tmp_path):
    from DelaunayInfill.gcode import ProcessCancelled

    src = tmp_path / "s.gcode"
    src.write_text(star_text(), encoding="utf-8", newline="")
    calls = []
    with pytest.raises(ProcessCancelled):
        process_file(src, tmp_path / "o.gcode", cancel=lambda: len(calls.append(1) or calls) > 10)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.gcode"]
    seen = []
    process_file(src, tmp_path / "o.gcode", progress=seen.append)
    assert seen and seen[-1] == 1.0 and all(0 <= a <= b <= 1 for a, b in zip(seen, seen[1:], strict=False))
    with pytest.raises(ProcessCancelled):
        process_gcode(as_cura_list(star_text()), cancel=lambda: True)
