"""Speed where layers do not repeat: the G-code pass against CuraEngine's slice on everyday models.

The models are the engine tier's everyday corpus (``tests/engine/everyday.py``: domes, cones, rings,
lettering, pillars, a lofted hull, a twisted vase; built with manifold3d, a test dependency), each
case with its own Cura settings at one density.  Per model and engine, ``--repeats`` pairs are run
one after the other: CuraEngine slices the model (the sparse slice only, wall time), then the pass
processes that G-code twice, in-process (``process_gcode`` on Cura's in-memory list, as the plugin
runs it) and as a whole ``delaunay-infill process`` run (start-up, reading and writing included).
The table gives the medians and their ratios to the slice of the same pair; the summary the median
and the largest ratio over the models, which is what issue 16's targets are stated in (in-process
median <= 0.5x, no model over 1.0x; the whole CLI run <= 1.0x).

    .venvs/current/bin/python bench/bench_everyday.py [--density 20] [--engines 4.13,5.0] [--repeats 3]
        [--models dome,sphere,...] [--out DIR] [--stages]

With ``--stages`` a second table gives each model's split of one more in-process run into the
pass's stages (``DelaunayInfill.gcode.stages``), in ms per processed layer.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from DelaunayInfill import curaengine  # noqa: E402
from DelaunayInfill.gcode import ProcessSettings, process_gcode  # noqa: E402
from DelaunayInfill.gcode.read import as_cura_list  # noqa: E402
from DelaunayInfill.gcode.stages import STAGES, StageClock  # noqa: E402

# Non-prismatic everyday cases (their layers change with height), as named in everyday.CASES.
DEFAULT_MODELS = ("dome", "sphere", "cone_up", "lofted_hull", "lobed_vase", "bushing", "engraved_text",
                  "arch", "pillars_fins", "perforated_plate")


def slice_case(case, density: float, version: str, folder: str) -> tuple[str, float]:
    """CuraEngine `version` slices `case` (its sparse slice only) into `folder`: (G-code path, wall s)."""
    from tests.engine import everyday
    from tests.engine.engines import engine

    chosen = engine(version)
    os.makedirs(folder, exist_ok=True)
    meshes = []
    for mesh_name, (model, offset) in zip(case.mesh_names(), case.models):
        path = os.path.join(folder, mesh_name)
        everyday.write_model_stl(path, everyday.placed_model(model, offset), mesh_name)
        meshes.append((path, {}))
    settings = {**case.settings, "infill_sparse_density": density}
    out = os.path.join(folder, "cura.gcode")
    start = time.perf_counter()
    done = curaengine.slice_models([(os.path.basename(p), s) for p, s in meshes], settings, out,
                                   engine=chosen.executable, resources=chosen.resources, cwd=folder)
    seconds = time.perf_counter() - start
    with open(done.path, "a", encoding="utf-8") as f:  # as Cura's GUI saves it
        f.write(everyday.cura_footer(settings))
    return done.path, seconds


def time_pass(path: str, out_path: str) -> tuple[float, float, object]:
    """(in-process s, whole CLI run s, report) for one G-code file."""
    with open(path, encoding="utf-8", newline="") as f:
        layers = as_cura_list(f.read())
    start = time.perf_counter()
    _, report = process_gcode(layers, ProcessSettings())
    in_process = time.perf_counter() - start
    exe = os.path.join(os.path.dirname(sys.executable), "delaunay-infill")
    command = [exe] if os.path.exists(exe) else [sys.executable, "-m", "DelaunayInfill.cli"]
    start = time.perf_counter()
    subprocess.run([*command, "process", path, "-o", out_path, "-q", "--keep-going"], check=False,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    whole = time.perf_counter() - start
    return in_process, whole, report


def run(models, engines, density: float, repeats: int, out: str, stages: bool):
    from tests.engine.everyday import CASES

    cases = {c.name: c for c in CASES}
    rows, stage_rows = [], []
    for version in engines:
        for name in models:
            case = cases[name]
            folder = os.path.join(out, f"{name}-{version}")
            slices, ins, wholes = [], [], []
            report = None
            for _ in range(repeats):
                path, s = slice_case(case, density, version, folder)
                p, w, report = time_pass(path, os.path.join(folder, "processed.gcode"))
                slices.append(s)
                ins.append(p)
                wholes.append(w)
            s, p, w = statistics.median(slices), statistics.median(ins), statistics.median(wholes)
            rows.append((name, version, report.layers_total, report.layers_processed, report.layers_repeated,
                         s, p, p / s, w, w / s))
            print(f"{name:18s} {version:>4s}  slice {s:6.2f} s  in-process {p:6.2f} s ({p / s:4.2f}x)  "
                  f"CLI {w:6.2f} s ({w / s:4.2f}x)", file=sys.stderr, flush=True)
            if stages:
                with open(path, encoding="utf-8", newline="") as f:
                    layers = as_cura_list(f.read())
                clock = StageClock()
                _, rep = process_gcode(layers, ProcessSettings(), stages=clock)
                stage_rows.append((name, version, rep.layers_processed, clock))
    return rows, stage_rows


def table(rows, stage_rows, density: float, repeats: int) -> str:
    out = [f"Everyday models at {density:g} %, medians of {repeats} (slice, pass) pairs; ratios to the slice "
           "of the same pairs", "",
           "| model | engine | layers | processed | written from an earlier layer | CuraEngine slice s | "
           "process_gcode s | ratio | whole CLI run s | ratio |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for name, version, total, processed, repeated, s, p, pr, w, wr in rows:
        out.append(f"| {name} | {version} | {total} | {processed} | {repeated} | {s:.2f} | {p:.2f} | {pr:.2f}x | "
                   f"{w:.2f} | {wr:.2f}x |")
    out.append("")
    for version in sorted({r[1] for r in rows}):
        mine = [r for r in rows if r[1] == version]
        ins, wholes = [r[7] for r in mine], [r[9] for r in mine]
        out.append(f"CuraEngine {version}: in-process median {statistics.median(ins):.2f}x (largest "
                   f"{max(ins):.2f}x, {max(mine, key=lambda r: r[7])[0]}); whole CLI run median "
                   f"{statistics.median(wholes):.2f}x (largest {max(wholes):.2f}x)")
    if stage_rows:
        names = [n for n in STAGES if any(n in c.seconds for *_, c in stage_rows)] + ["other"]
        out += ["", "One more in-process run split into the pass's stages, ms per processed layer:", "",
                "| model | engine | " + " | ".join(names) + " | total |",
                "|---|---|" + "---|" * (len(names) + 1)]
        for name, version, processed, clock in stage_rows:
            per = max(1, processed)
            timed = sum(clock.seconds.values())
            values = dict(clock.seconds)
            values["other"] = values.get("other", 0.0) + max(0.0, clock.total - timed)
            out.append(f"| {name} | {version} | " + " | ".join(f"{values.get(n, 0.0) / per * 1000:.1f}" for n in names)
                       + f" | {clock.total / per * 1000:.1f} |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--density", type=float, default=20.0, help="infill density, %% (default 20)")
    parser.add_argument("--engines", default="4.13,5.0", help="CuraEngine versions (default 4.13,5.0)")
    parser.add_argument("--models", default=",".join(DEFAULT_MODELS), help="everyday cases to run")
    parser.add_argument("--repeats", type=int, default=3, help="(slice, pass) pairs per model (default 3)")
    parser.add_argument("--out", default=None, help="folder for the slices (default: a temporary one)")
    parser.add_argument("--stages", action="store_true", help="also split one run per model into stages")
    args = parser.parse_args(argv)
    out = args.out or tempfile.mkdtemp(prefix="bench-everyday-")
    rows, stage_rows = run([m for m in args.models.split(",") if m], [e for e in args.engines.split(",") if e],
                           args.density, args.repeats, out, args.stages)
    print(table(rows, stage_rows, args.density, args.repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
