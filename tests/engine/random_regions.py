"""Random density regions on random everyday shapes, for the engine tier.

The plugin's own use: a user places denser and sparser regions on a model (the Density regions tool
makes each an ``infill_mesh`` modifier, a sphere, cube or cylinder with no walls or skin of its own;
Per Model Settings make them with the print's walls), slices and prints.  A seed draws a model of
``random_shapes`` (its settings too) and one to three regions over it: their shapes, sizes, places
(some reach past the model or overlap each other: the later one wins), densities (0 % is "no infill
here") and whether they have walls.  Each case is sliced by CuraEngine and processed twice, as the
command line does (the G-code alone) and as the plugin does (the modifiers' triangles given as
regions), and each result is judged by

* the corpus's checker (``everyday_check``): no new infill outside Cura's infill area, in mid-air or
  on skin or walls, Cura's infill places covered, no island without infill;
* the density of every region and of the rest, measured here from the files alone: the new FILL's
  length inside the region's section (``manifold3d``'s slice of the modifier, the later regions' cut
  out) and Cura's infill area (the dense reference slice's lines, buffered by half a line width with
  flat ends), times the line width, over that area, summed over the layers.  Cura's own FILL is
  measured the same way.

    python3 -m tests.engine.random_regions --seeds 0-39 --out /tmp/random-regions [--engine 5.0]
    python3 -m tests.engine.random_regions --seeds 0,3,7,9 --out /tmp/random-regions --pictures
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field

import numpy as np
from manifold3d import Manifold

from DelaunayInfill.density import LATTICE_SIDE

from .everyday import MODELS, SEGMENTS, EverydayCase, EverydaySlice, block, cylinder, section
from .random_shapes import _seeds, random_model, random_settings, sliced_or_none, summary

#: densities a region is drawn with, %
REGION_DENSITIES = (0, 5, 10, 30, 50, 60, 80)
#: a region (or the rest) is judged where Cura's infill area in it is at least this many of the
#: sparser side's line spacings across on average (the issue's "regions down to two line spacings wide")
MIN_SPACINGS_ACROSS = 2.0
#: the most a judged region's density may miss its target by, as a fraction (2 points) ...
DENSITY_TOLERANCE = 0.02
#: ... or, where Cura's own infill misses it by more, by Cura's miss and this much more
OVER_CURA_TOLERANCE = 0.01
#: a 0 % region may print this much (lines that end on its border reach into it by up to half a width)
ZERO_REGION_MAX = 0.005


@dataclass(frozen=True)
class RandomRegion:
    """One drawn density region: an ``infill_mesh`` modifier over the model.

    Attributes
    ----------
    name : str
        Its model name in ``everyday.MODELS`` (the STL is ``<name>.stl``).
    shape : str
        "sphere", "cube" or "cylinder".
    density : float
        %.
    walls : bool
        Made with Per Model Settings (the print's walls and skin) rather than the Density regions tool.
    """

    name: str
    shape: str
    density: float
    walls: bool

    def mesh_settings(self, order: int) -> dict:
        """Per-mesh Cura settings: the tool's (no walls, no skin) or Per Model Settings' (the print's)."""
        values = {"infill_mesh": True, "infill_sparse_density": float(self.density), "infill_mesh_order": order}
        if not self.walls:
            values.update(wall_thickness=0, wall_line_count=0, top_bottom_thickness=0, top_layers=0,
                          bottom_layers=0)
        return values


@dataclass(frozen=True)
class RegionsCase:
    """A random shape with its drawn regions: the everyday case to slice, and its density (%)."""

    case: EverydayCase
    density: float
    regions: tuple = field(default=())


def _region_solid(rng: np.random.Generator, shape: str, model: Manifold) -> Manifold:
    """A region's solid of `shape` somewhere over `model` (model coordinates, mm)."""
    (lo_x, lo_y, lo_z, hi_x, hi_y, hi_z) = model.bounding_box()
    size = float(rng.uniform(6.0, 0.8 * max(8.0, min(hi_x - lo_x, hi_y - lo_y))))
    x, y = rng.uniform(lo_x + 0.1 * (hi_x - lo_x), hi_x - 0.1 * (hi_x - lo_x)), \
        rng.uniform(lo_y + 0.1 * (hi_y - lo_y), hi_y - 0.1 * (hi_y - lo_y))
    if shape == "sphere":
        z = float(rng.uniform(lo_z, hi_z))
        return Manifold.sphere(size / 2, SEGMENTS).translate((x, y, z))
    # a cube or cylinder: as tall as the model, or from a random height up or to a random height
    low, high = sorted(rng.uniform(lo_z - 2.0, hi_z + 2.0, 2))
    if rng.random() < 0.4:
        low, high = lo_z - 1.0, hi_z + 1.0
    height = max(2.0, high - low)
    if shape == "cube":
        solid = block(size, float(rng.uniform(0.5, 1.5)) * size, height, x=x, y=y, z=low)
        return solid.rotate((0.0, 0.0, float(rng.uniform(0, 90)))) if rng.random() < 0.5 else solid
    return cylinder(size, height, x=x, y=y, z=low)


def random_regions_case(seed: int) -> RegionsCase:
    """The model of random shape `seed` with one to three drawn regions (their solids registered in
    ``everyday.MODELS``), its settings and density."""
    rng = np.random.default_rng(20_000 + seed)
    model_name = f"random_{seed}"
    MODELS.setdefault(model_name, lambda seed=seed: random_model(seed))
    model = MODELS[model_name]()
    settings, density = random_settings(seed)
    regions = []
    for k in range(int(rng.integers(1, 4))):
        shape = str(rng.choice(("sphere", "cube", "cylinder")))
        name = f"region_{seed}_{k + 1}"
        solid = _region_solid(rng, shape, model)
        MODELS.setdefault(name, lambda solid=solid: solid)
        regions.append(RandomRegion(name, shape, float(rng.choice(REGION_DENSITIES)), bool(rng.random() < 0.25)))
    models = ((model_name, (0.0, 0.0)), *((r.name, (0.0, 0.0)) for r in regions))
    mesh_settings = ({}, *(r.mesh_settings(order) for order, r in enumerate(regions, start=1)))
    what = ", ".join(f"{r.shape} {r.density:g} %{' with walls' if r.walls else ''}" for r in regions)
    case = EverydayCase(f"regions_{seed}", models, settings, f"random shape {seed} with {what}", mesh_settings)
    return RegionsCase(case, density, tuple(regions))


# --------------------------------------------------------------------------- measuring


@dataclass
class ZoneDensity:
    """What one zone (a region, or the rest of the model) prints, summed over the layers.

    Lengths in mm, area in mm² (summed over the layers), density as a fraction.
    """

    name: str
    target: float
    area_mm2: float = 0.0
    layers: int = 0
    new_mm: float = 0.0
    cura_mm: float = 0.0
    line_width: float = 0.4

    @property
    def new(self) -> float:
        return self.new_mm * self.line_width / self.area_mm2 if self.area_mm2 else math.nan

    @property
    def cura(self) -> float:
        return self.cura_mm * self.line_width / self.area_mm2 if self.area_mm2 else math.nan

    def wide_enough(self, sparsest: float) -> bool:
        """Whether the zone is at least MIN_SPACINGS_ACROSS line spacings across on average: its mean area
        per layer against a square of that side, the spacing being the Delaunay pattern's (a triangular
        lattice's side) at the sparser of the zone's density and `sparsest` (the rest's, fraction)."""
        if self.layers == 0 or self.target <= 0:
            return False
        spacing = LATTICE_SIDE * self.line_width / min(self.target, sparsest)
        return self.area_mm2 / self.layers >= (MIN_SPACINGS_ACROSS * spacing) ** 2

    def judged(self, sparsest: float) -> str | None:
        """A problem with this zone's density (regions judged where `wide_enough`), or None."""
        if self.target <= 0:  # "no infill here": at most what lines ending at its border poke in
            return None if not self.area_mm2 or self.new <= ZERO_REGION_MAX else \
                f"{self.name}: a 0 % region prints {100 * self.new:.2f} %"
        if not self.wide_enough(sparsest):
            return None
        miss = abs(self.new - self.target)
        allowed = max(DENSITY_TOLERANCE, abs(self.cura - self.target) + OVER_CURA_TOLERANCE)
        if miss > allowed:
            return (f"{self.name}: {100 * self.new:.1f} % for {100 * self.target:g} % (Cura's {100 * self.cura:.1f} %, "
                    f"{self.area_mm2 / max(self.layers, 1):.0f} mm² a layer over {self.layers} layers)")
        return None

    def row(self, sparsest: float) -> str:
        return (f"{self.name:16s} {100 * self.target:5.1f} {100 * self.new:6.1f} {100 * self.cura:6.1f}"
                f" {self.area_mm2 / max(self.layers, 1):8.0f} {self.layers:5d}"
                f" {'' if self.wide_enough(sparsest) or self.target <= 0 else 'narrow'}")


def zone_densities(done: EverydaySlice, drawn: RegionsCase, processed: str) -> list[ZoneDensity]:
    """Every region's density and the rest's, in the processed file and in Cura's (see the module)."""
    from shapely.affinity import translate
    from shapely.ops import unary_union

    from .everyday_check import _inside, _layer_heights, extract_layers, lines_buffer, sample_segments

    with open(done.cura_gcode, encoding="utf-8") as f:
        original = extract_layers(f.read())
    with open(done.reference_gcode, encoding="utf-8") as f:
        reference = extract_layers(f.read())
    new = extract_layers(processed)
    heights = _layer_heights(original)
    lw = done.line_width
    solids = [MODELS[r.name]() for r in drawn.regions]
    zones = [ZoneDensity("rest", drawn.density / 100.0, line_width=lw),
             *(ZoneDensity(r.name, r.density / 100.0, line_width=lw) for r in drawn.regions)]
    step = 0.1
    for key, layer in original.items():
        ref = reference.get(key)
        if ref is None or not len(ref.fill) or not np.isfinite(layer.z):
            continue
        z = layer.z - heights.get(key, 0.2) / 2
        # (flat ends: Cura's infill area ends where its lines do; square ends read half a line width more
        # along every wall, 4 % of a small region's area: random regions 81, a 94 mm² region at 80 %)
        area = lines_buffer(ref.fill, lw / 2 + 0.01, ends="flat")
        sections = [translate(section(s, round(z, 4)), *done.bed_offset) for s in solids]
        # a region is what the later ones (higher infill_mesh_order) leave of it; the rest is what none covers
        pieces = [sec.difference(unary_union(sections[k + 1:])) if k + 1 < len(sections) else sec
                  for k, sec in enumerate(sections)]
        # (Cura's area holds no part of a 0 % region: its place is the model's section, a line width in)
        material = done.section_at(layer.z - heights.get(key, 0.2) / 2)
        pieces = [area.difference(unary_union(sections)),
                  *(p.buffer(-lw).intersection(material) if r.density <= 0 else p.intersection(area)
                    for p, r in zip(pieces, drawn.regions, strict=True))]
        new_fill = new[key].fill if key in new else np.zeros((0, 2, 2))
        new_points, new_w = sample_segments(new_fill, step)
        cura_points, cura_w = sample_segments(layer.fill, step)
        for zone, piece in zip(zones, pieces, strict=True):
            if piece.is_empty or piece.area < lw * lw:
                continue
            zone.area_mm2 += piece.area
            zone.layers += 1
            zone.new_mm += float(new_w[_inside(piece, new_points)].sum()) if len(new_points) else 0.0
            zone.cura_mm += float(cura_w[_inside(piece, cura_points)].sum()) if len(cura_points) else 0.0
    return zones


# --------------------------------------------------------------------------- running


def plugin_settings(done: EverydaySlice, drawn: RegionsCase):
    """``(ProcessSettings, [Region])`` as the plugin makes them in Cura: its adapter
    (``cura.adapter.build_settings``) on a scene snapshot of the case, every mesh's values those the
    engine resolved for the slice, the regions' triangles in G-code coordinates."""
    from DelaunayInfill import curaengine
    from DelaunayInfill.cura.adapter import build_settings
    from DelaunayInfill.cura.snapshot import MeshSnapshot, SceneSnapshot

    from .engines import engine
    from .everyday import mesh_triangles

    case = drawn.case
    per_mesh = list(case.mesh_settings) or [{}] * len(case.models)
    resolved = curaengine.resolve_settings({**case.settings, "infill_sparse_density": drawn.density},
                                           list(zip(case.mesh_names(), per_mesh, strict=True)),
                                           resources=engine(done.version).resources)
    base = {**resolved.global_values, **resolved.extruder_values}
    offset = np.array([*done.bed_offset, 0.0])
    meshes = []
    for (name, values), (model, _) in zip(resolved.meshes, case.models, strict=True):
        region = bool(values.get("infill_mesh"))
        meshes.append(MeshSnapshot(name=name, values={**base, **values}, enabled=True, is_region=region,
                                   triangles=mesh_triangles(MODELS[model]()) + offset if region else None))
    return build_settings(SceneSnapshot(global_values=dict(resolved.global_values),
                                        extruder_values={0: dict(resolved.extruder_values)}, meshes=meshes))


def process_and_judge(done: EverydaySlice, drawn: RegionsCase, as_plugin: bool):
    """Process `done` as the plugin does (`as_plugin`: its settings and regions from Cura's values,
    `plugin_settings`) or as the command line does (the G-code alone, but for the 0 % modifiers, which
    leave no trace in it, and those drawn over them: the README has them given with ``--modifier``);
    judge it: (report, checker result, zones, problems)."""
    import os

    from DelaunayInfill import process_gcode
    from DelaunayInfill.gcode.read import as_cura_list
    from DelaunayInfill.gcode.settings import Region

    from .everyday import add_failed_layers, mesh_triangles
    from .everyday_check import check_everyday

    with open(done.cura_gcode, encoding="utf-8") as f:
        original = f.read()
    with open(done.reference_gcode, encoding="utf-8") as f:
        reference = f.read()
    if as_plugin:
        settings, regions = plugin_settings(done, drawn)
    else:  # the 0 % ones, and the later ones that win over them (given regions win over the G-code's)
        zero = [k for k, r in enumerate(drawn.regions) if r.density <= 0]
        offset = np.array([*done.bed_offset, 0.0])
        settings, regions = None, [
            Region(r.density / 100.0, triangles=mesh_triangles(MODELS[r.name]()) + offset, name=f"{r.name}.stl")
            for r in (drawn.regions[zero[0]:] if zero else ())]
    layers, report = process_gcode(as_cura_list(original), settings, regions=regions)
    processed = "".join(layers)
    with open(os.path.join(done.folder, f"processed-{'plugin' if as_plugin else 'cli'}.gcode"), "w",
              encoding="utf-8") as f:
        f.write(processed)
    # coverage is judged at the line spacing of the sparsest density the print has
    sparsest = min(d for d in (drawn.density, *(r.density for r in drawn.regions)) if d > 0) / 100.0
    result = check_everyday(original, processed, reference, done.section_at, spacing=2.0 * done.line_width / sparsest,
                            line_width=done.line_width)
    add_failed_layers(result, report)
    zones = zone_densities(done, drawn, processed)
    # (from the G-code alone a modifier's density and border are read off its lines: judged as the
    # plugin prints them; the command line's are shown, and a 0 % region must stay empty in both)
    problems = [p for z in zones for p in [z.judged(drawn.density / 100.0)] if p and (as_plugin or z.target <= 0)]
    return report, result, zones, problems


def pictures(out_dir: str, seeds: list[int], version: str = "4.13") -> str:
    """For each seed, the layer where its regions cover most of the model: Cura's G-code above, the plugin's
    processed one below, the regions' sections dashed (their density in the legend).  A PNG."""
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from shapely.affinity import translate

    from DelaunayInfill.gcode.preview import layer_segments

    from .everyday import EverydaySliceCache
    from .everyday_check import extract_layers

    cache = EverydaySliceCache(out_dir)
    colours = {"WALL-OUTER": "#d62728", "WALL-INNER": "#2ca02c", "SKIN": "#e6c619", "FILL": "#ff7f0e"}
    region_colours = ("#1f77b4", "#9467bd", "#17becf")
    figure, axes = plt.subplots(2, len(seeds), figsize=(3.4 * len(seeds), 7.0), squeeze=False)
    for column, seed in enumerate(seeds):
        drawn = random_regions_case(seed)
        done = cache.get(drawn.case, drawn.density, version)
        process_and_judge(done, drawn, as_plugin=True)
        layers = extract_layers(open(done.cura_gcode, encoding="utf-8").read())
        solids = [MODELS[r.name]() for r in drawn.regions]

        def covered(z):
            model = done.section_at(z)
            return sum(translate(section(s, z), *done.bed_offset).intersection(model).area for s in solids)

        candidates = [(number, moves.z) for (number, occurrence), moves in layers.items()
                      if occurrence == 0 and len(moves.fill) and number % 4 == 2]
        layer, z = max(candidates, key=lambda c: covered(c[1] - 0.1))
        for row, path in enumerate((done.cura_gcode, os.path.join(done.folder, "processed-plugin.gcode"))):
            ax = axes[row][column]
            groups = layer_segments(path, layer)
            for kind, colour in colours.items():
                segments = groups.get(kind)
                if segments is not None and len(segments):
                    ax.add_collection(LineCollection(segments, colors=colour, linewidths=0.6))
            for k, (r, s) in enumerate(zip(drawn.regions, solids, strict=True)):
                sec = translate(section(s, round(z - 0.1, 4)), *done.bed_offset)
                for n, poly in enumerate(getattr(sec, "geoms", [])):
                    ax.plot(*poly.exterior.xy, ls="--", lw=1.0, color=region_colours[k % 3],
                            label=f"{r.shape} {r.density:g} %" if n == 0 and row == 0 else None)
            ax.set_aspect("equal")
            ax.autoscale_view()
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"regions {seed} ({drawn.density:g} %), layer {layer}: {'Cura' if row == 0 else 'Delaunay'}",
                         fontsize=8)
            if row == 0:
                ax.legend(fontsize=6, loc="lower left")
    figure.tight_layout()
    path = os.path.join(out_dir, "random-regions.png")
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main(argv=None) -> int:
    from .everyday import EverydaySliceCache, report_row

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0-19", help="seeds, e.g. 0-59 or 3,7,11 (default 0-19)")
    parser.add_argument("--engine", default="4.13", help="CuraEngine version (default 4.13)")
    parser.add_argument("--out", required=True, help="folder for the slices")
    parser.add_argument("--cli-only", action="store_true", help="process as the command line does only")
    parser.add_argument("--plugin-only", action="store_true", help="process as the plugin does only")
    parser.add_argument("--pictures", action="store_true",
                        help="draw one layer of each seed (Cura's and the plugin's) into OUT/random-regions.png and stop")
    args = parser.parse_args(argv)
    if args.pictures:
        print(pictures(args.out, _seeds(args.seeds), args.engine))
        return 0
    cache = EverydaySliceCache(args.out)
    failed, unsliced = [], []
    for seed in _seeds(args.seeds):
        drawn = random_regions_case(seed)
        done = sliced_or_none(cache, drawn.case, drawn.density, args.engine, unsliced, seed)
        if done is None:
            continue
        for as_plugin in (False,) if args.cli_only else (True,) if args.plugin_only else (False, True):
            report, result, zones, problems = process_and_judge(done, drawn, as_plugin)
            how = "plugin" if as_plugin else "cli"
            ok = result.ok and not problems
            print(f"{report_row(done, report, result)} [{how}] {drawn.case.exercises}; {drawn.case.settings}",
                  flush=True)
            for zone in zones:
                print("    " + zone.row(drawn.density / 100.0), flush=True)
            if not ok:
                failed.append(f"{seed}/{how}")
                if not result.ok:
                    print(result.report(), flush=True)
                for p in problems:
                    print("  - density: " + p, flush=True)
    return summary(failed, unsliced)


if __name__ == "__main__":
    sys.exit(main())
