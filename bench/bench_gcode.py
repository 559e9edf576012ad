"""G-code benchmark: DelaunayInfill's pipeline against CuraEngine, same models, same run.

For every model this script

1. slices it with the real CuraEngine (Debian 4.13) three times with Cura's
   grid infill and once each with triangles and lines, all at the same density;
2. processes the grid G-code in-process with ``process_gcode`` (Cura's
   in-memory list of strings), three times;
3. prints two markdown tables:

   * speed: median ``process_gcode`` time against the median CuraEngine slice
     time (target ratio <= 1.0), wall clock and CPU time (CPU time is steadier
     on a shared machine; CuraEngine's is its child-process rusage), and the
     ratio of the fastest runs of each (what a quiet machine gives);
   * output: filament, estimated print time, infill travel and retractions of
     Delaunay infill against Cura's grid, triangles and lines (targets: filament
     within +-3 % of grid, time <= 1.05 x grid, infill travel <= triangles).

Print time is given twice: the figure the file itself reports (the last
``;TIME_ELAPSED``: CuraEngine's estimate, updated by the pipeline for the new
infill), and this script's own estimate with one motion model for every file
(its own parser; trapezoids at 3000 mm/s^2 with jerk-limited corners between
extrusion moves, the pipeline's model, see bench_estimate.py), so the four
patterns are compared like for like.

With ``--stages`` a third table splits one more ``process_gcode`` run (not
the timed ones) into its stages: parsing, infill areas, pattern lookups and
builds, clipping and routing, rebuilding the modifiers' shapes from Cura's
line ends, sharing the route among Cura's FILL blocks, G-code writing, layers
written as repeats of an earlier one (gcode/replay.py), the rest.

Usage::

    python3 bench/bench_gcode.py [--density PCT] [--models cube,hbracket,star,star_regions,hbracket_box]
                                 [--out DIR] [--stages]
                                 [--height MM]   # every model that tall (more layers; not hbracket_box, the demo's)
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import sys
import tempfile
import time

import numpy as np

from DelaunayInfill import curaengine, models
from DelaunayInfill.gcode.demo import DATA_DIR
from DelaunayInfill.gcode.estimate import DEFAULT_JERK, move_seconds

PATTERNS = ("grid", "triangles", "lines")
_MOVE = re.compile(r"^(G[01])\b([^;\n]*)", re.M)
_WORDS = re.compile(r"([XYZEF])(-?\d*\.?\d+)")
ACCELERATION = 3000.0  # mm/s^2, for this script's own time estimate
# (label, module, attribute) of the pipeline stages timed with --stages; a missing one is left out
STAGES = (
    ("parse", "DelaunayInfill.gcode.process", "parse_layer"),
    ("areas", "DelaunayInfill.gcode.process", "mesh_layer"),
    ("patterns", "DelaunayInfill.gcode.process", "PatternCache.get"),
    ("clip + route", "DelaunayInfill.gcode.process", "_Run._clip"),
    ("modifier split", "DelaunayInfill.gcode.process", "split_by_line_ends"),
    ("runs to blocks", "DelaunayInfill.routing", "plan_runs"),
    ("write G-code", "DelaunayInfill.gcode.process", "emit_block"),
    ("repeated layers", "DelaunayInfill.gcode.process", "_Run._replay"),
)


def _model_files(folder: str, height: float | None = None) -> dict[str, list]:
    """name -> [(stl path, per-mesh settings)], written into `folder`.

    `height` (mm) makes every model that tall (default: the test models, 10 mm, the cube 20 mm): the
    pipeline's one-off work (pattern build, modifier shapes) weighs less over more layers.
    """
    paths = models.write_test_models(folder)
    if height is not None:
        for name, tris in (("cube", models.box(20.0, 20.0, height)), ("hbracket", models.h_bracket(height=height)),
                           ("star", models.star(height=height))):
            models.write_stl(paths[name], tris, name=name)
    regions = []
    for name, tris in models.star_region_prisms(height=height or 10.0, margin=1.0).items():
        path = os.path.join(folder, f"region_{name}.stl")
        models.write_stl(path, tris, name=name)
        percent = 100 * models.STAR_FIGURE10_DENSITIES[name]
        regions.append((path, curaengine.infill_modifier_settings(percent)))
    # the demo's H-bracket with its 60 % infill-mesh box (the bundled STLs, their own height)
    demo = {}
    for stl in ("hbracket.stl", "hbracket_box.stl"):
        demo[stl] = os.path.join(folder, f"demo_{stl}")
        shutil.copyfile(os.path.join(DATA_DIR, stl), demo[stl])
    return {
        "cube": [(paths["cube"], {})],
        "hbracket": [(paths["hbracket"], {})],
        "star": [(paths["star"], {})],
        # the paper's Figure 10: five tips and the centre as infill_mesh modifiers
        "star_regions": [(paths["star"], {}), *regions],
        "hbracket_box": [(demo["hbracket.stl"], {}),
                         (demo["hbracket_box.stl"], curaengine.infill_modifier_settings(60))],
    }


def gcode_stats(text: str) -> dict:
    """Filament, print time (own estimate and the file's), infill travel and retractions.

    Own minimal parser (absolute or relative E, G92), independent of the pipeline.
    """
    x = y = z = e = 0.0
    f = 1500.0
    relative = False
    fill = False
    rows = []  # dx, dy, dz, de, f, fill
    for line in text.split("\n"):
        if line.startswith(";TYPE:"):
            fill = line == ";TYPE:FILL"
            continue
        if line.startswith(";LAYER:") or line.startswith(";MESH:NONMESH"):
            fill = False
            continue
        if line.startswith("M83"):
            relative = True
        elif line.startswith("M82"):
            relative = False
        elif line.startswith("G92"):
            m = re.search(r"E(-?\d*\.?\d+)", line)
            if m:
                e = float(m.group(1))
            continue
        m = _MOVE.match(line)
        if not m:
            continue
        words = dict(_WORDS.findall(m.group(2)))
        nx, ny, nz = float(words.get("X", x)), float(words.get("Y", y)), float(words.get("Z", z))
        if "E" in words:
            de = float(words["E"]) if relative else float(words["E"]) - e
            e = e + de if relative else float(words["E"])
        else:
            de = 0.0
        f = float(words.get("F", f))
        rows.append((nx - x, ny - y, nz - z, de, f, fill))
        x, y, z = nx, ny, nz
    a = np.array(rows, dtype=float)
    dxy = np.hypot(a[:, 0], a[:, 1])
    # the G-code pass's motion model (trapezoids, jerk-limited corners between extrusion moves; checked
    # against CuraEngine's own estimate by bench_estimate.py), the same for every file
    seconds = move_seconds(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], ACCELERATION, DEFAULT_JERK).sum()
    in_fill = a[:, 5] == 1
    travel = in_fill & (a[:, 3] <= 0) & (dxy > 0)
    retract = in_fill & (dxy == 0) & (a[:, 3] < 0)
    elapsed = re.findall(r"^;TIME_ELAPSED:([\d.]+)", text, re.M)
    return {
        "filament_m": float(a[:, 3].sum()) / 1000.0,
        "time_s": float(seconds),
        "file_time_s": float(elapsed[-1]) if elapsed else float("nan"),
        "infill_travel_m": float(dxy[travel].sum()) / 1000.0,
        "retractions": int(retract.sum()),
    }


def split_like_cura(text: str) -> list[str]:
    """Cura's in-memory form: one string before the first ;LAYER:, one per layer."""
    parts = re.split(r"(?m)^(?=;LAYER:)", text)
    return [p for p in parts if p]


def stage_times(chunks: list[str]) -> dict[str, float]:
    """Seconds per pipeline stage (STAGES) in one ``process_gcode`` run; "total" and "other" too."""
    import importlib

    from DelaunayInfill import process_gcode

    spent: dict[str, float] = {}
    undo = []
    for label, module_name, path in STAGES:
        owner = importlib.import_module(module_name)
        *parents, name = path.split(".")
        for parent in parents:
            owner = getattr(owner, parent, None)
        original = getattr(owner, name, None) if owner is not None else None
        if original is None:
            continue

        def timed(*args, _f=original, _label=label, **kwargs):
            start = time.perf_counter()
            try:
                return _f(*args, **kwargs)
            finally:
                spent[_label] = spent.get(_label, 0.0) + time.perf_counter() - start

        setattr(owner, name, timed)
        undo.append((owner, name, original))
    try:
        start = time.perf_counter()
        process_gcode(chunks)
        total = time.perf_counter() - start
    finally:
        for owner, name, original in undo:
            setattr(owner, name, original)
    return {**spent, "total": total, "other": total - sum(spent.values())}


def run(model_names: list[str], density: float, out: str, repeats: int = 3, stages: bool = False,
        height: float | None = None) -> tuple[list, list, list]:
    from DelaunayInfill import process_gcode

    files = _model_files(os.path.join(out, "models"), height)
    speed_rows, output_rows, stage_rows = [], [], []
    for name in model_names:
        meshes = files[name]
        slices = {}
        for pattern in PATTERNS:
            settings = {"infill_sparse_density": density, "infill_pattern": pattern}
            runs, cpu = [], []
            for _ in range(repeats if pattern == "grid" else 1):
                path = os.path.join(out, f"{name}_{pattern}.gcode")
                before = _children_cpu()
                result = curaengine.slice_models([(os.path.basename(p), s) for p, s in meshes], settings, path,
                                                 cwd=os.path.dirname(meshes[0][0]))  # ;MESH: without folders
                cpu.append(_children_cpu() - before)
                runs.append(result.seconds)
            with open(path, encoding="utf-8") as f:
                slices[pattern] = (f.read(), statistics.median(runs), statistics.median(cpu), min(runs))
        grid_text, slice_seconds, slice_cpu, slice_best = slices["grid"]
        chunks = split_like_cura(grid_text)
        times, cpu_times, layers, report = [], [], None, None
        for _ in range(repeats):
            start, start_cpu = time.perf_counter(), time.process_time()
            layers, report = process_gcode(chunks)
            times.append(time.perf_counter() - start)
            cpu_times.append(time.process_time() - start_cpu)
        new_text = "".join(layers)
        with open(os.path.join(out, f"{name}_delaunay.gcode"), "w", encoding="utf-8") as f:
            f.write(new_text)
        process_seconds, process_cpu = statistics.median(times), statistics.median(cpu_times)
        if stages:
            stage_rows.append((name, slice_seconds, stage_times(chunks)))
        speed_rows.append((name, grid_text.count("\n"), slice_seconds, process_seconds, process_seconds / slice_seconds,
                           slice_cpu, process_cpu, process_cpu / slice_cpu, min(times) / slice_best,
                           len(report.failed_layers), f"{report.layers_repeated}/{report.layers_total}"))
        stats = {p: gcode_stats(slices[p][0]) for p in PATTERNS}
        stats["delaunay"] = gcode_stats(new_text)
        for pattern, s in stats.items():
            output_rows.append((name, pattern, s, stats["grid"], stats["triangles"]))
    return speed_rows, output_rows, stage_rows


def format_tables(speed_rows, output_rows, density, stage_rows=()) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    out = [f"Density {density:g} %, 0.2 mm layers, 0.4 mm line width, CuraEngine {_engine_version()}, "
           f"load average {load:.2f}.", ""]
    out += ["| model | G-code lines | CuraEngine slice, wall (s) | process_gcode, wall (s) | ratio (target <= 1.0) "
            "| CuraEngine CPU (s) | process_gcode CPU (s) | CPU ratio | ratio of fastest runs | failed layers "
            "| layers repeated |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, lines, s, p, ratio, s_cpu, p_cpu, cpu_ratio, best_ratio, failed, repeated in speed_rows:
        mark = "" if ratio <= 1.0 else " (over)"
        out.append(f"| {name} | {lines} | {s:.3f} | {p:.3f} | {ratio:.2f}x{mark} | {s_cpu:.3f} | {p_cpu:.3f} | "
                   f"{cpu_ratio:.2f}x | {best_ratio:.2f}x | {failed} | {repeated} |")
    out += ["", "| model | infill | filament (m) | vs grid (target +-3 %) | print time, own estimate (min) | "
                "vs grid (target <= 1.05x) | time in file (min) | infill travel (m) | vs triangles (target <= 1.0x) | "
                "infill retractions |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, pattern, s, grid, tri in output_rows:
        d_fil = 100 * (s["filament_m"] / grid["filament_m"] - 1)
        r_time = s["time_s"] / grid["time_s"]
        r_travel = s["infill_travel_m"] / tri["infill_travel_m"] if tri["infill_travel_m"] else float("nan")
        flag = pattern == "delaunay"
        out.append(
            f"| {name} | {'**delaunay**' if flag else pattern} | {s['filament_m']:.3f} | {d_fil:+.1f} %"
            f"{' (over)' if flag and abs(d_fil) > 3 else ''} | {s['time_s'] / 60:.1f} | {r_time:.3f}x"
            f"{' (over)' if flag and r_time > 1.05 else ''} | {s['file_time_s'] / 60:.1f} | {s['infill_travel_m']:.2f} | "
            f"{r_travel:.2f}x{' (over)' if flag and r_travel > 1.0 else ''} | {s['retractions']} |")
    if stage_rows:
        labels = [label for label, _, _ in STAGES]
        out += ["", "One more process_gcode run split into stages (ms; the stages do not overlap):", "",
                "| model | CuraEngine slice | process_gcode | " + " | ".join(labels) + " | other |",
                "|---|" + "---:|" * (len(labels) + 3)]
        for name, slice_seconds, spent in stage_rows:
            cells = [f"{1e3 * spent[label]:.1f}" if label in spent else "-" for label in labels]
            out.append(f"| {name} | {1e3 * slice_seconds:.1f} | {1e3 * spent['total']:.1f} | " + " | ".join(cells)
                       + f" | {1e3 * spent['other']:.1f} |")
    return "\n".join(out)


def _children_cpu() -> float:
    """User + system CPU seconds of finished child processes (the CuraEngine runs)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _engine_version() -> str:
    import subprocess

    text = subprocess.run([curaengine.find_curaengine(), "help"], capture_output=True, text=True).stderr
    m = re.search(r"version\s+(\S+)", text)
    return m.group(1) if m else "?"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--density", type=float, default=20.0, help="infill density in percent (default 20)")
    parser.add_argument("--models", default="cube,hbracket,star,star_regions,hbracket_box")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=None, help="keep the G-code files in this folder")
    parser.add_argument("--stages", action="store_true", help="also time the pipeline's stages (one extra run)")
    parser.add_argument("--height", type=float, default=None,
                        help="make every model this tall, mm (default: the test models, 10 mm; the cube 20 mm)")
    args = parser.parse_args(argv)
    problem = curaengine.setup_problem()
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    names = [n.strip() for n in args.models.split(",") if n.strip()]
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or tmp
        os.makedirs(out, exist_ok=True)
        speed, output, stage_rows = run(names, args.density, out, args.repeats, args.stages, args.height)
    if args.height is not None:
        print(f"Every model {args.height:g} mm tall.")
    print(format_tables(speed, output, args.density, stage_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
