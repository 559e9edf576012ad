"""How much of the G-code pass could run beside itself in threads (issue 16: inside Cura, one process).

Cura has no interpreter to start worker processes with, so inside Cura the pass could only gain from
threads, and only where numpy, scipy and GEOS release Python's global interpreter lock.  This bench
measures that share directly: the same in-process work (``process_gcode`` over everyday slices)
done twice one after the other, then twice at once in two threads.  If all of the pass ran without
the lock, the two threads would take half the sequential time on two free cores (ratio 0.5); if none
of it did, the same time (1.0).  A pipeline that rebuilds the next layer's areas in a thread while
this layer is written can gain at most what this ratio leaves below 1.0.

    .venvs/current/bin/python bench/bench_threads.py [--slices DIR] [--repeats 3]

``--slices`` is a folder of ``bench_everyday.py --out`` slices (``*/cura.gcode``); without it the
bench slices four everyday models with CuraEngine 4.13 first.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from DelaunayInfill.gcode import ProcessSettings, process_gcode  # noqa: E402
from DelaunayInfill.gcode.read import as_cura_list  # noqa: E402

MODELS = ("dome", "arch", "bushing", "lofted_hull")


def _slices(folder: str | None) -> list[str]:
    if folder:
        paths = sorted(glob.glob(os.path.join(folder, "*", "cura.gcode")))
        if not paths:
            raise SystemExit(f"bench_threads: no */cura.gcode under {folder}")
        return paths
    import bench_everyday

    from tests.engine.everyday import CASES

    cases = {c.name: c for c in CASES}
    out = tempfile.mkdtemp(prefix="bench-threads-")
    return [bench_everyday.slice_case(cases[m], 20.0, "4.13", os.path.join(out, m))[0] for m in MODELS]


def _pass_over(texts: list[str]) -> None:
    for text in texts:
        process_gcode(as_cura_list(text), ProcessSettings())


def measure(texts: list[str], repeats: int) -> list[tuple[float, float]]:
    """(two passes one after the other s, two passes in two threads at once s), `repeats` times."""
    _pass_over(texts)  # warm: imports, caches of numpy and shapely
    rows = []
    for _ in range(repeats):
        start = time.perf_counter()
        _pass_over(texts)
        _pass_over(texts)
        sequential = time.perf_counter() - start
        threads = [threading.Thread(target=_pass_over, args=(texts,)) for _ in range(2)]
        start = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        rows.append((sequential, time.perf_counter() - start))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--slices", default=None, help="folder of bench_everyday.py --out slices")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    paths = _slices(args.slices)
    texts = []
    for path in paths:
        with open(path, encoding="utf-8", newline="") as f:
            texts.append(f.read())
    rows = measure(texts, args.repeats)
    print(f"The pass over {len(paths)} slices ({', '.join(os.path.basename(os.path.dirname(p)) for p in paths)}), "
          f"{os.cpu_count()} cores\n")
    print("| run | two passes one after the other s | two passes in two threads s | threads / sequential |")
    print("|---|---:|---:|---:|")
    for k, (seq, par) in enumerate(rows, 1):
        print(f"| {k} | {seq:.2f} | {par:.2f} | {par / seq:.2f} |")
    ratio = statistics.median(par / seq for seq, par in rows)
    print(f"\nmedian threads / sequential: {ratio:.2f} (0.50: all of the pass runs beside itself; 1.00: none)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
