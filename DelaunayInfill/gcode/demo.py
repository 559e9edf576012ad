"""``delaunay-infill demo``: the embedded default run on bundled CuraEngine output.

Two jobs:

* ``star_fig10``: the paper's five-point star (Ø60 x 10 mm) with the Figure 10
  densities (tips 1, 2: 30 %, tip 3: 20 %, tips 4, 5: 50 %, centre pentagon:
  10 %), one seamless triangulation across the region borders;
* ``hbracket_modifier``: the H-bracket (60 x 40 x 10 mm) with a Cura
  ``infill_mesh`` modifier box at 60 % over its +X half, taken over as a
  density region at the modifier's own density.

The G-code was made by CuraEngine 4.13 from the bundled STLs
(`DelaunayInfill.curaengine.DEFAULT_SETTINGS`: 0.4 mm nozzle, 0.2 mm layers,
20 % grid, 220 x 220 bed, model centred at (110, 110)).  ``--reslice``
slices the STLs again with the installed CuraEngine first.
"""

from __future__ import annotations

import gzip
import os
import shutil
import sys
from dataclasses import dataclass

from .process import process_file
from .settings import ProcessSettings, Region

__all__ = ["DATA_DIR", "DemoJob", "demo_jobs", "make_demo_gcode", "run_demo"]

DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
BED_CENTRE = (110.0, 110.0)  # where CuraEngine puts model (0, 0) with the demo settings

# Figure 10 densities, tips counted counter-clockwise from the +Y tip.
FIG10_DENSITIES = {"tip1": 0.30, "tip2": 0.30, "tip3": 0.20, "tip4": 0.50, "tip5": 0.50, "centre": 0.10}


@dataclass
class DemoJob:
    name: str
    gcode: str  # bundled file name in DATA_DIR (gzip)
    models: list  # (stl file name, per-mesh settings) for --reslice
    layer: int  # layer shown in the PNG
    settings: ProcessSettings
    regions: list


def star_fig10_regions() -> list[Region]:
    """The Figure 10 regions in G-code coordinates (five tip triangles, then the centre pentagon)."""
    from shapely import affinity

    from ..models import star_regions

    out = []
    for name, polygon in star_regions().items():
        out.append(Region(FIG10_DENSITIES[name], polygon=affinity.translate(polygon, *BED_CENTRE), name=name))
    return out


def demo_jobs() -> list[DemoJob]:
    from ..curaengine import infill_modifier_settings

    return [
        DemoJob(
            "star_fig10",
            "star.gcode.gz",
            [("star.stl", {})],
            25,
            ProcessSettings(density=0.10, seed=1),
            star_fig10_regions(),
        ),
        DemoJob(
            "hbracket_modifier",
            "hbracket_modifier.gcode.gz",
            [("hbracket.stl", {}), ("hbracket_box.stl", infill_modifier_settings(60))],
            25,
            ProcessSettings(seed=1),
            [],
        ),
    ]


def make_demo_gcode(folder: str, job: DemoJob, stl_dir: str = DATA_DIR) -> str:
    """Slice a job's bundled STLs with CuraEngine into `folder`; returns the G-code path.

    The engine runs inside `folder` with relative model names, so ``;MESH:``
    lines carry the file names (``star.stl``), as Cura's would carry node names.
    """
    from ..curaengine import slice_models

    os.makedirs(folder, exist_ok=True)
    for stl, _ in job.models:
        shutil.copyfile(os.path.join(stl_dir, stl), os.path.join(folder, stl))
    out = os.path.join(folder, job.name + "_cura.gcode")
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        slice_models(list(job.models), {}, os.path.basename(out))
    finally:
        os.chdir(cwd)
    return out


def _unpack(name: str, target: str) -> str:
    with gzip.open(os.path.join(DATA_DIR, name), "rb") as src, open(target + ".tmp", "wb") as dst:
        shutil.copyfileobj(src, dst)
    os.replace(target + ".tmp", target)
    return target


def run_demo(out_dir: str = "delaunay-demo", *, reslice: bool = False, log=print) -> int:
    """Run the demo jobs; write G-code, PNGs and summary.txt into `out_dir`.  Returns an exit status."""
    os.makedirs(out_dir, exist_ok=True)
    summary = []
    have_plot = True
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        have_plot = False
        log("note: matplotlib is not installed, so no PNGs (pip install 'DelaunayInfill[plot]')")
    for job in demo_jobs():
        if reslice:
            src = make_demo_gcode(os.path.join(out_dir, "cura"), job)
            log(f"{job.name}: sliced with CuraEngine -> {src}")
        else:
            src = _unpack(job.gcode, os.path.join(out_dir, job.name + "_cura.gcode"))
        dst = os.path.join(out_dir, job.name + "_delaunay.gcode")
        report = process_file(src, dst, job.settings, regions=job.regions)
        table = report.format_table()
        summary.append(f"== {job.name}: {os.path.basename(src)} -> {os.path.basename(dst)}\n{table}\n")
        log(summary[-1])
        if have_plot:
            from .preview import render_layer

            png = os.path.join(out_dir, f"{job.name}_layer{job.layer}.png")
            render_layer(dst, job.layer, png, before=src)
            log(f"wrote {png}")
    with open(os.path.join(out_dir, "summary.txt"), "w", encoding="utf-8") as f:
        f.write("\n".join(summary))
    log(f"demo output in {os.path.abspath(out_dir)}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run_demo())
