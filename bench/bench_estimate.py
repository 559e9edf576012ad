"""The pipeline's print-time model against CuraEngine's own estimate, same run.

    python3 bench/bench_estimate.py [--patterns grid,gyroid,...] [--density 20,50]

Slices the project's cube with real CuraEngine 4.13 in several of Cura's infill patterns and times
every move of each G-code with ``DelaunayInfill.gcode.estimate``: from rest to rest (the model before
corners were added) and with jerk-limited corners between extrusion moves (the model the G-code pass
uses). CuraEngine's figure is the file's last ``;TIME_ELAPSED``. Patterns of short segments (gyroid)
show why corners matter: the new infill's time is a difference of two such estimates.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from DelaunayInfill import curaengine, models  # noqa: E402
from DelaunayInfill.gcode.estimate import DEFAULT_JERK, move_seconds, move_times  # noqa: E402
from DelaunayInfill.gcode.read import MachineState, RetractionModel, as_cura_list, iter_chunks, parse_layer  # noqa: E402

ACCELERATION = 3000.0  # mm/s², fdmprinter's machine_acceleration (what CuraEngine times with here)


def file_moves(text: str) -> dict:
    """Every move of a G-code file in order (the pipeline's parser), keys as ``LayerParse.moves``."""
    state, retraction = MachineState(), RetractionModel()
    parts = [parse_layer(chunk, state, retraction).moves for chunk in iter_chunks(as_cura_list(text))]
    moves = {key: np.concatenate([p[key] for p in parts]) for key in ("x0", "y0", "z0", "x1", "y1", "z1", "de", "f")}
    known = np.isfinite(moves["x0"]) & np.isfinite(moves["y0"]) & np.isfinite(moves["z0"])
    return {key: value[known] for key, value in moves.items()}


def estimates(text: str) -> tuple[float, float, float]:
    """(CuraEngine's seconds, rest-to-rest seconds, with corners seconds)."""
    engine = float(re.findall(r"^;TIME_ELAPSED:([\d.]+)", text, re.M)[-1])
    m = file_moves(text)
    dx, dy, dz = m["x1"] - m["x0"], m["y1"] - m["y0"], m["z1"] - m["z0"]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    rest = float(move_times(np.where(dist > 0, dist, np.abs(m["de"])), m["f"], ACCELERATION).sum())
    corners = float(move_seconds(dx, dy, dz, m["de"], m["f"], ACCELERATION, DEFAULT_JERK).sum())
    return engine, rest, corners


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patterns", default="grid,lines,triangles,zigzag,concentric,gyroid")
    parser.add_argument("--density", default="20,50", help="percent, comma separated")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        model = models.write_test_models(folder)["cube"]
        for pattern in args.patterns.split(","):
            for density in (float(d) for d in args.density.split(",")):
                out = os.path.join(folder, f"cube_{pattern}_{density:g}.gcode")
                settings = {"infill_sparse_density": density, "infill_pattern": pattern}
                curaengine.slice_models([(os.path.basename(model), {})], settings, out, cwd=folder)
                with open(out, encoding="utf-8") as f:
                    rows.append((pattern, density, *estimates(f.read())))
    print(f"Cube 20 mm, 0.2 mm layers, sliced by CuraEngine in this run; "
          f"model: acceleration {ACCELERATION:g} mm/s², jerk {DEFAULT_JERK:g} mm/s.\n")
    print("| pattern | density | CuraEngine (min) | rest to rest (min) | vs CuraEngine | with corners (min) | vs CuraEngine |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for pattern, density, engine, rest, corners in rows:
        print(f"| {pattern} | {density:g} % | {engine / 60:.2f} | {rest / 60:.2f} | {rest / engine:.3f}x | "
              f"{corners / 60:.2f} | {corners / engine:.3f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
