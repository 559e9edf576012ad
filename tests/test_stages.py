"""`--stages`: where a run's time goes, each stage timed exclusively."""

from __future__ import annotations

import re
import shutil
import subprocess

from DelaunayInfill.gcode import stages
from DelaunayInfill.gcode.stages import OFF, STAGES, StageClock


class _FakeTime:
    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        return self.now


def test_a_stage_inside_another_is_taken_out_of_the_outer_one(monkeypatch):
    fake = _FakeTime()
    monkeypatch.setattr(stages, "time", fake)
    clock = StageClock()
    with clock("areas"):
        fake.now += 1.0
        with clock("patterns"):
            fake.now += 2.0
        fake.now += 0.5
    with clock("areas"):
        fake.now += 0.25
    assert clock.seconds == {"areas": 1.75, "patterns": 2.0}
    clock.total = 5.0
    table = clock.table(layers_processed=2)
    assert re.search(r"^other\s+1\.250\s+625\.00\s+25\.0%", table, re.M), table  # the rest of the run
    assert re.search(r"^total\s+5\.000\s+2500\.00\s+100\.0%", table, re.M), table


def test_the_clock_that_is_off_times_nothing():
    with OFF("areas"):
        pass
    assert not OFF.enabled and not hasattr(OFF, "seconds")


def test_process_stages_prints_every_stage_and_they_add_up(star_gcode, tmp_path):
    exe = shutil.which("delaunay-infill")
    assert exe, "the delaunay-infill console script is not installed (pip install -e .)"
    proc = subprocess.run([exe, "process", str(star_gcode), "-o", str(tmp_path / "o.gcode"), "--stages", "-q"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rows = dict(re.findall(r"^(\S.*?)\s{2,}(\d+\.\d{3})\s+\d+\.\d\d\s+[\d.]+%", proc.stdout, re.M))
    for name in ("parse", "areas", "patterns", "emit", "estimate", "other", "total"):
        assert name in rows, proc.stdout
    assert set(rows) - {"total"} <= set(STAGES)
    parts = sum(float(v) for k, v in rows.items() if k != "total")
    assert abs(parts - float(rows["total"])) <= 0.004, proc.stdout  # rounding of the printed figures only
    assert float(rows["patterns"]) > 0 and float(rows["parse"]) > 0
