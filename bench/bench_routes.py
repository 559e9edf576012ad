"""Infill routes on everyday models: the route's start against one start only, and against the shortest.

``order_paths`` routes up to `_EXACT_MOST` paths exactly (Held-Karp) and, up to `_TWO_STARTS_MOST`
paths, improves two first routes (nearest end first, shortest links first) and keeps the shorter.  Its
reference here is the routing before that (session 16): nearest end first alone, improved the same
way, at every count (both limits set to 0 in the same process).  CuraEngine slices the everyday
models (``bench_everyday.slice_case``), the pass processes each G-code with either routing, and

* the first table gives, per file, the infill travel in the G-code (travel moves inside FILL, combed
  round the part as printed) and the pass's CPU time (best of ``--repeats``);
* the second, per count of paths, every route the pass asked for (recorded from the default run): its
  straight travel with either routing, the shortest route's where it can be computed (up to
  ``--exact-up-to`` paths), and the routing's CPU time.

    .venvs/current/bin/python bench/bench_routes.py [--density 20] [--engines 4.13,5.0] [--repeats 3]
        [--models dome,sphere,...] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from unittest import mock

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402
from bench_everyday import DEFAULT_MODELS, slice_case  # noqa: E402
from bench_gcode import gcode_stats  # noqa: E402

from DelaunayInfill import pattern, routing  # noqa: E402
from DelaunayInfill.first_routes import route_ends, route_travel, shortest_route  # noqa: E402
from DelaunayInfill.gcode import ProcessSettings, process_gcode  # noqa: E402
from DelaunayInfill.gcode import process as process_module  # noqa: E402
from DelaunayInfill.gcode.read import as_cura_list  # noqa: E402

BANDS = ((2, 9), (10, 12), (13, 16), (17, 24), (25, 32), (33, 10**9))


def one_start():
    """The routing before session 17: nearest end first at every count, no exact routes."""
    return mock.patch.multiple(routing, _EXACT_MOST=0, _TWO_STARTS_MOST=0)


def process(layers: list[str], repeats: int, record: list | None = None) -> tuple[str, float]:
    """(processed text, best CPU s); `record` collects every order_paths call (paths, start, end)."""
    original = routing.order_paths

    def recording(paths, start=None, *, end=None, **kw):
        record.append(([np.array(p) for p in paths], start, end))
        return original(paths, start, end=end, **kw)

    best, text = float("inf"), ""
    for k in range(repeats):
        patches = []
        if record is not None and k == 0:
            # (every module that calls it: patching routing's alone would miss names imported before)
            patches = [mock.patch.object(module, "order_paths", recording)
                       for module in (routing, process_module, pattern)]
        for p in patches:
            p.start()
        try:
            start = time.process_time()
            out, _ = process_gcode(layers, ProcessSettings())
            best = min(best, time.process_time() - start)
        finally:
            for p in patches:
                p.stop()
        text = "".join(out)
    return text, best


def shortest_travel(paths, start, end) -> float:
    """The straight travel of the shortest route through `paths` (as `order_paths` is given them), mm."""
    ends = np.array([p[0] for p in paths] + [p[-1] for p in paths], dtype=float)
    ends = ends[:, 0] + 1j * ends[:, 1]
    origin = complex(*start) if start is not None else complex(np.nan, np.nan)
    terminus = complex(*end) if end is not None else complex(np.nan, np.nan)
    return route_travel(*route_ends(ends, *shortest_route(ends, origin, terminus)), origin, terminus)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--density", type=float, default=20.0)
    parser.add_argument("--engines", default="4.13,5.0")
    parser.add_argument("--models", default=",".join(DEFAULT_MODELS))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--exact-up-to", type=int, default=12,
                        help="paths: the shortest route is computed up to this")
    parser.add_argument("--out", default=None, help="keep the slices here")
    args = parser.parse_args(argv)
    from tests.engine.everyday import CASES

    cases = {c.name: c for c in CASES}
    out = args.out or tempfile.mkdtemp(prefix="bench-routes-")
    calls: list = []
    rows = []
    for version in args.engines.split(","):
        for name in args.models.split(","):
            path, _ = slice_case(cases[name], args.density, version, os.path.join(out, f"{name}-{version}"))
            with open(path, encoding="utf-8", newline="") as f:
                layers = as_cura_list(f.read())
            new_text, new_cpu = process(layers, args.repeats, calls)
            with one_start():
                old_text, old_cpu = process(layers, args.repeats)
            old, new = gcode_stats(old_text)["infill_travel_m"], gcode_stats(new_text)["infill_travel_m"]
            rows.append((name, version, old, new, old_cpu, new_cpu))
            print(f"{name:18s} {version:>4s} travel {old:6.2f} -> {new:6.2f} m", file=sys.stderr, flush=True)

    print(f"Infill travel in the G-code and the pass's CPU time, {args.density:g} %, best of {args.repeats}"
          " (one start: the routing before session 17)\n")
    print("| model | engine | infill travel, one start (m) | default (m) | ratio | pass CPU, one start (s) | "
          "default (s) | ratio |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name, version, old, new, oc, nc in rows:
        print(f"| {name} | {version} | {old:.2f} | {new:.2f} | {new / old:.3f}x | {oc:.3f} | {nc:.3f} | "
              f"{nc / oc:.3f}x |")
    t = [sum(r[k] for r in rows) for k in (2, 3, 4, 5)]
    print(f"| **all** | | {t[0]:.2f} | {t[1]:.2f} | {t[1] / t[0]:.3f}x | {t[2]:.3f} | {t[3]:.3f} | "
          f"{t[3] / t[2]:.3f}x |")

    print(f"\nEvery route the pass asked for ({len(calls)}), straight travel; shortest up to "
          f"{args.exact_up_to} paths\n")
    print("| paths | routes | one start (m) | default (m) | ratio | shortest (m) | default over shortest | "
          "routing CPU, one start (s) | default (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for lo, hi in BANDS:
        band = [c for c in calls if lo <= len(c[0]) <= hi]
        if not band:
            continue
        sums = np.zeros(5)
        for paths, start, end in band:
            t0 = time.process_time()
            with one_start():
                _, old = routing.order_paths(paths, start, end=end)
            t1 = time.process_time()
            _, new = routing.order_paths(paths, start, end=end)
            t2 = time.process_time()
            best = shortest_travel(paths, start, end) if len(paths) <= args.exact_up_to else np.nan
            sums += (old, new, best, t1 - t0, t2 - t1)
        label = f"{lo}-{hi}" if hi < 10**9 else f"{lo}+"
        exact = hi <= args.exact_up_to
        shortest = f"{sums[2] / 1000:.2f} | {sums[1] / sums[2]:.3f}x" if exact else "— | —"
        print(f"| {label} | {len(band)} | {sums[0] / 1000:.2f} | {sums[1] / 1000:.2f} | "
              f"{sums[1] / sums[0]:.3f}x | "
              f"{shortest} | {sums[3]:.2f} | {sums[4]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
