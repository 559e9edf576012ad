"""How much Cura's own patterns print in a small square, against where it stands: their phase.

Issue 15 asks for filament within +-2 % of Cura's grid.  CuraEngine anchors its line patterns to the
middle of the mesh's bounding box, shifted by ``infill_offset_x`` / ``infill_offset_y``: across a
square a few spacings wide a line pattern prints a whole number of lines, so what it prints there
depends on where its lines fall (its phase), and with no offset a line of every direction runs
through the part's middle, where lines are longest.  This script slices a W x W x 20 mm box (W = 20
by default, ``bench_gcode.py``'s cube) with ``infill_offset_x`` = 0, 1, ... mm (one period of the
45-degree grid at 10 % is 8 mm x sqrt(2) = 11.3 mm along X) with the real CuraEngine (Debian 4.13)
with Cura's grid, triangles and lines at one density, processes the grid G-code with
``process_gcode`` and prints, per offset:

* each pattern's infill density: its ``;TYPE:FILL`` extrusion length (mm, mean over the layers that
  have infill) times the line width, over the square inside the walls ((W - 2 x wall thickness)^2);
* the whole print's filament against Cura's grid (as ``bench_gcode.py``).

The last rows give the mean, smallest and largest over the offsets.  ``--plot PATH`` draws the
densities against the offset.

Usage::

    python3 bench/bench_cube_places.py [--density PCT] [--width MM] [--offsets 0-11] [--out DIR] [--plot PATH]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

from DelaunayInfill import curaengine, models

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_gcode import PATTERNS, _engine_version, gcode_stats, split_like_cura  # noqa: E402

HEIGHT = 20.0  # mm
LINE_WIDTH = 0.4  # mm, the engine defaults' infill line width
WALL_THICKNESS = 0.8  # mm, the engine defaults' two walls


def fill_length_per_layer(text: str) -> float:
    """Mean extruding ``;TYPE:FILL`` XY length per layer that has any, mm (absolute E, as CuraEngine writes)."""
    lengths, current = [], 0.0
    x = y = e = 0.0
    fill = False
    for line in text.split("\n"):
        if line.startswith(";LAYER:"):
            if current > 0:
                lengths.append(current)
            current, fill = 0.0, False
        elif line.startswith(";TYPE:"):
            fill = line == ";TYPE:FILL"
        elif line.startswith(";MESH:NONMESH"):
            fill = False
        elif line.startswith("G92"):
            for word in line.split()[1:]:
                if word.startswith("E"):
                    e = float(word[1:])
        elif line.startswith(("G0", "G1")):
            words = {w[0]: float(w[1:]) for w in line.split(";")[0].split()[1:] if w[0] in "XYE"}
            nx, ny, ne = words.get("X", x), words.get("Y", y), words.get("E", e)
            if fill and ne > e:
                current += float(np.hypot(nx - x, ny - y))
            x, y, e = nx, ny, ne
    if current > 0:
        lengths.append(current)
    return float(np.mean(lengths)) if lengths else 0.0


def run(width: float, offsets: list[float], density: float, out: str) -> list[tuple]:
    """Per ``infill_offset_x`` (mm): (offset, {pattern: density %}, {pattern: filament vs grid %})."""
    from DelaunayInfill import process_gcode

    stl = os.path.join(out, "box.stl")
    models.write_stl(stl, models.box(width, width, HEIGHT), name="box")
    rows = []
    for offset in offsets:
        texts = {}
        for pattern in PATTERNS:
            path = os.path.join(out, f"box_{offset:g}_{pattern}.gcode")
            settings = {"infill_sparse_density": density, "infill_pattern": pattern, "infill_offset_x": offset}
            curaengine.slice_models([(os.path.basename(stl), {})], settings, path, cwd=out)
            with open(path, encoding="utf-8") as f:
                texts[pattern] = f.read()
        layers, _ = process_gcode(split_like_cura(texts["grid"]))
        texts["delaunay"] = "".join(layers)
        with open(os.path.join(out, f"box_{offset:g}_delaunay.gcode"), "w", encoding="utf-8") as f:
            f.write(texts["delaunay"])
        inner = (width - 2 * WALL_THICKNESS) ** 2
        printed = {p: 100 * fill_length_per_layer(t) * LINE_WIDTH / inner for p, t in texts.items()}
        filament = {p: gcode_stats(t)["filament_m"] for p, t in texts.items()}
        versus = {p: 100 * (f / filament["grid"] - 1) for p, f in filament.items()}
        rows.append((offset, printed, versus))
    return rows


def format_table(rows: list[tuple], width: float, density: float) -> str:
    names = (*PATTERNS, "delaunay")
    out = [f"A {width:g} x {width:g} x {HEIGHT:g} mm box, infill_offset_x 0, 1, ... mm, at {density:g} %, CuraEngine {_engine_version()}: infill density over the "
           "square inside the walls (FILL length x line width / area), and the whole print's filament against Cura's grid",
           "",
           "| infill_offset_x (mm) | " + " | ".join(f"{n} density" for n in names) + " | "
           + " | ".join(f"{n} filament vs grid" for n in names[1:]) + " |",
           "|---:|" + "---:|" * (2 * len(names) - 1)]
    for offset, printed, versus in rows:
        out.append(f"| {offset:g} | " + " | ".join(f"{printed[n]:.2f} %" for n in names) + " | "
                   + " | ".join(f"{versus[n]:+.1f} %" for n in names[1:]) + " |")
    for label, reduce in (("mean", np.mean), ("smallest", np.min), ("largest", np.max)):
        out.append(f"| {label} | " + " | ".join(f"{reduce([r[1][n] for r in rows]):.2f} %" for n in names) + " | "
                   + " | ".join(f"{reduce([r[2][n] for r in rows]):+.1f} %" for n in names[1:]) + " |")
    return "\n".join(out)


def density_plot(rows: list[tuple], width: float, density: float, path: str) -> None:
    """Each pattern's infill density against ``infill_offset_x``, saved as an image at `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    offsets = [r[0] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for name, style in (("grid", "o-"), ("triangles", "s-"), ("lines", "^-"), ("delaunay", "D-")):
        ax.plot(offsets, [r[1][name] for r in rows], style, label="Delaunay (default)" if name == "delaunay"
                else f"Cura {name}", lw=2.2 if name == "delaunay" else 1.2, ms=4)
    ax.axhline(density, color="0.5", lw=0.8, ls=":")
    ax.set_xlabel("infill_offset_x (mm): where Cura's lines fall")
    ax.set_ylabel("infill density printed (%)")
    ax.set_title(f"{width:g} mm cube at {density:g} %: FILL length x line width / area inside the walls", fontsize=9)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _offsets(text: str) -> list[float]:
    first, _, last = text.partition("-")
    return [float(w) for w in range(int(first), int(last or first) + 1)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--density", type=float, default=10.0, help="infill density, %% (default 10)")
    parser.add_argument("--width", type=float, default=20.0, help="the box's width, mm (default 20)")
    parser.add_argument("--offsets", default="0-11", help="infill_offset_x values, mm, FIRST-LAST in steps of 1 (default 0-11)")
    parser.add_argument("--out", help="keep the slices in this folder (default: a temporary one)")
    parser.add_argument("--plot", help="save a plot of the densities against the offset here")
    args = parser.parse_args(argv)
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        rows = run(args.width, _offsets(args.offsets), args.density, args.out)
    else:
        with tempfile.TemporaryDirectory() as out:
            rows = run(args.width, _offsets(args.offsets), args.density, out)
    print(format_table(rows, args.width, args.density))
    if args.plot:
        density_plot(rows, args.width, args.density, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
