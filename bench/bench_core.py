"""Core-engine benchmark: sampler vs scipy, and per-layer clip + route time.

Run:  python3 bench/bench_core.py [--repeat N]

Prints markdown tables with ratios against references measured in the same
run:
1. the ``fast`` Poisson-disk sampler against ``scipy.stats.qmc.PoissonDisk`` on
   a 200 x 200 mm square at r = 3.3 mm (target: >= 50x faster at equal or
   better maximality), with the paper's ``bridson`` for reference;
2. per-layer generate + clip + route for a 200 x 200 mm region at 20 %, 0.4 mm
   lines, reusing the pattern (target: median <= 20 ms), next to one
   ``scipy.spatial.Delaunay`` of the same points.
"""

from __future__ import annotations

import argparse
import statistics
import time

from scipy.spatial import Delaunay
from scipy.stats import qmc
from shapely.geometry import Point, box

from DelaunayInfill import InfillPattern, sample_poisson_disk
from DelaunayInfill.sampling import uncovered_fraction


def timed(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def sampler_table(repeat: int) -> str:
    side, r = 200.0, 3.3
    square = box(0, 0, side, side)
    rows = []
    t_scipy, pts = timed(lambda: qmc.PoissonDisk(2, radius=r / side, seed=1).fill_space() * side, max(1, repeat // 3))
    rows.append(("scipy.stats.qmc.PoissonDisk (reference)", t_scipy, pts))
    t_fast, pts = timed(lambda: sample_poisson_disk(square, r, seed=1, method="fast"), repeat)
    rows.append(("DelaunayInfill fast", t_fast, pts))
    t_bridson, pts = timed(lambda: sample_poisson_disk(square, r, seed=1, method="bridson"), 1)
    rows.append(("DelaunayInfill bridson (paper)", t_bridson, pts))
    lines = [
        f"Sampler, {side:.0f} x {side:.0f} mm square, r = {r} mm (median of runs)",
        "",
        "| sampler | time (ms) | speed-up vs scipy | points | uncovered area |",
        "|---|---|---|---|---|",
    ]
    for name, t, p in rows:
        lines.append(
            f"| {name} | {1e3 * t:.1f} | {t_scipy / t:.1f}x | {len(p)} | {100 * uncovered_fraction(square, p, r):.3f} % |"
        )
    return "\n".join(lines)


def layer_table(repeat: int) -> str:
    region = box(0, 0, 200, 200)
    t_build, pattern = timed(lambda: InfillPattern.build(region, 0.2, 0.4, seed=0), 1)
    # Layers: the square, and the square with a hole that grows layer by layer.
    layers = [region.difference(Point(100, 100).buffer(2.0 * k)) if k else region for k in range(repeat)]
    times = []
    for area in layers:
        t0 = time.perf_counter()
        result = pattern.clip(area, start=(0.0, 0.0))
        times.append(time.perf_counter() - t0)
    t_layer = statistics.median(times)
    t_delaunay, _ = timed(lambda: Delaunay(pattern.points), repeat)
    full = pattern.clip(region)
    lines = [
        "Per layer, 200 x 200 mm at 20 %, 0.4 mm lines, pattern reused",
        "",
        "| step | time (ms) | vs one scipy Delaunay of the pattern |",
        "|---|---|---|",
        f"| build pattern once (sample + triangulate + calibrate, {pattern.iterations} iterations) | {1e3 * t_build:.0f} | {t_build / t_delaunay:.1f}x |",
        f"| clip + chain + order, median of {len(layers)} layers | {1e3 * t_layer:.1f} | {t_layer / t_delaunay:.1f}x |",
        f"| scipy.spatial.Delaunay of {len(pattern.points)} points (reference) | {1e3 * t_delaunay:.1f} | 1.0x |",
        "",
        f"Full square: measured density {full.density:.2%}, {len(full.paths)} paths (lower bound "
        f"{full.odd_vertices // 2}), travel {full.travel_mm / full.extrude_mm:.3f} mm per extruded mm, "
        f"last layer {len(result.paths)} paths.",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    print(sampler_table(args.repeat))
    print()
    print(layer_table(args.repeat))


if __name__ == "__main__":
    main()
