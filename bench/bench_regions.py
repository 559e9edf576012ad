"""Region densities measured whole, the change across a border, crowded nodes: issue 15's region targets.

For each case (an 80 x 80 mm part with one region, and the paper's Figure 10 star) and seed, the
default pattern is built and clipped to the part, then measured independently by clipping its lines
with shapely:

* **whole**: each region's density over all of itself, the band along its border included (line
  length inside x line width / area), and the rest of the part's;
* **sparse side, 0-2 mm**: the density in the 2 mm of the sparser zone along the border (a strip a
  third of a sparse spacing wide: whether a lattice row falls in it decides most of this figure);
* **across the border**: the density in bands one sparse spacing s = 2 sqrt(3) w / d_sparse wide (the
  sparse lattice's side) on either side of the border, all along it: the sparse side's first band
  [0, s) and the dense side's first band and the rest of the dense side beyond s.  Issue 15: the
  transition lies on the denser side and is at most one sparse spacing wide, so the sparse side's
  first band is at the sparse density and the dense side is at its density from s on (each within 2
  points); the dense side's first band is where the change is.  A dense region enclosed by the part
  is its own lattice in whole triangles, which reach past its border by up to their height h (session
  21): there the change lies in that reach, and a last column gives the sparse side's band [h, h + s).
  As controls, the same bands in uniform patterns of the sparse and of the dense density (a zone a few
  lattice sides across swings by itself);
* **max edges per node** (nodes inside the part) and **short edges**: edges with both ends inside the
  part shorter than a quarter of the local spacing (the triangular lattice's side 2 sqrt(3) w / d at
  the denser end's density).

A second table gives the density **across the border**; a third the **stiffness per region**: a 100 x 100 mm part with one square region
(30 or 36 mm), the frame model of `bench/stiffness.py` (rigid joints) in a window exactly over the
region (its border band inside), and in a window of the same size beside it on the part's side
(touching the border), each as C_min / rho against a uniform pattern of that side's density in the
same window with the same seed.

With ``--ideal`` a fourth table measures the same windows over the best junction two lattices can
have (`ideal_junction`: each density's exact lattice right up to the border, nothing between; the
densities are then whatever the lattices print there): what any sampler could reach at most.

With ``--junctions`` a fifth table puts three junctions side by side in three windows: the default
pattern, the ideal junction and a **border line** (`border_line_junction`: each density's exact
lattice clipped at the region's border, and one line along the border that both end on, as an infill
mesh with an infill wall; densities uncalibrated).  Besides the two windows above, a third of the
same size is centred on the region's lower border (**straddling**: half of it each density), given
as C_min / rho itself (a triangular lattice measures about 0.37 in a window this size).  A window
whose edge is the border is strained as the affine field there, so a line along that edge counts as
fully loaded: the straddling window is the fair test of a junction.

Targets (issue 15): every whole region within 2 points for regions two of their own spacings
across and more; no node over 8 edges; no short edge; each region's C_min / rho at least 0.95 of a
uniform pattern of its density.

Usage::

    python3 bench/bench_regions.py [--seeds 5] [--ideal] [--junctions]
    python3 bench/bench_regions.py --seeds 5 --plot border-profile.png   # the density across one border
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np
from shapely.geometry import MultiLineString, Point, box

from DelaunayInfill.density import LATTICE_SIDE
from DelaunayInfill.figures import star_polygon, star_regions
from DelaunayInfill.pattern import InfillPattern

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stiffness import stiffness, triangular_lattice  # noqa: E402  (bench/stiffness.py, beside this file)

WIDTH = 0.4  # mm
PART = box(0, 0, 80, 80)
CASES = {
    # name: (part, base density, [(region, density)])
    "box 20 mm at 60 % in 20 %": (PART, 0.2, [(box(30, 30, 50, 50), 0.6)]),
    "box 12 mm at 60 % in 20 %": (PART, 0.2, [(box(34, 34, 46, 46), 0.6)]),
    "disk 20 mm at 60 % in 20 %": (PART, 0.2, [(Point(40, 40).buffer(10, 32), 0.6)]),
    "disk 12 mm at 60 % in 20 %": (PART, 0.2, [(Point(40, 40).buffer(6, 32), 0.6)]),
    "box 16 mm at 40 % in 10 %": (PART, 0.1, [(box(32, 32, 48, 48), 0.4)]),
    "strip 8 mm at 60 % in 20 %": (PART, 0.2, [(box(36, 0, 44, 80), 0.6)]),
    "box 24 mm at 10 % in 40 %": (PART, 0.4, [(box(28, 28, 52, 52), 0.1)]),
    "strip 14 mm at 10 % in 40 %": (PART, 0.4, [(box(33, 0, 47, 80), 0.1)]),
    "Figure 10 star at 20 %": (star_polygon()[0], 0.2, star_regions()),
}


def density(segments: np.ndarray, zone) -> float:
    """Line length inside `zone` x line width / its area."""
    lines = MultiLineString([tuple(map(tuple, s)) for s in segments])
    return lines.intersection(zone).length * WIDTH / zone.area


def sparse_side(part, base: float, region, region_density: float):
    """The 2 mm of the sparser zone along the region's border."""
    if region_density > base:
        return part.difference(region).intersection(region.buffer(2.0))
    return region.difference(region.buffer(-2.0))


def border_bands(part, base: float, region, region_density: float) -> dict:
    """Bands one sparse spacing wide along the region's border, inside the part shrunk by one spacing
    (the part's own edge stays out of them): {"sparse 1-2", "sparse 0-1", "dense 0-1", "dense beyond 1",
    "sparse past the reach"}.  The last: beside a dense region, the sparse side's spacing beyond the
    region's lattice triangles (`enclosed_zones.lattice_patch`: they reach past its border by up to
    their height h); beside a sparse one, "sparse 0-1"."""
    s = LATTICE_SIDE * WIDTH / min(base, region_density)
    inner = part.buffer(-s)
    if region_density > base:  # dense inside the region: the sparse side is outside it
        sparse_near, sparse_far = region.buffer(s).difference(region), region.buffer(2 * s).difference(region.buffer(s))
        dense_near, dense_far = region.difference(region.buffer(-s)), region.buffer(-s)
        h = math.sqrt(3.0) / 2.0 * LATTICE_SIDE * WIDTH / region_density
        past = region.buffer(h + s).difference(region.buffer(h))
    else:
        sparse_near, sparse_far = region.difference(region.buffer(-s)), region.buffer(-s).difference(region.buffer(-2 * s))
        dense_near, dense_far = region.buffer(s).difference(region), part.difference(region.buffer(s))
        past = sparse_near
    bands = {"sparse 1-2": sparse_far, "sparse 0-1": sparse_near, "dense 0-1": dense_near, "dense beyond 1": dense_far,
             "sparse past the reach": past}
    return {k: v.intersection(inner) for k, v in bands.items()}


def node_figures(pattern) -> tuple[int, int]:
    """(max edges at a node inside the part, edges inside it under a quarter of the local spacing)."""
    segments = pattern.segments
    nodes, index, counts = np.unique(np.round(segments.reshape(-1, 2), 9), axis=0,
                                     return_inverse=True, return_counts=True)
    inside = np.array([pattern.footprint.contains(Point(*xy)) for xy in nodes])
    both = inside[index.reshape(-1, 2)].all(axis=1)
    dens = np.maximum(pattern.density_map.at(segments[:, 0]), pattern.density_map.at(segments[:, 1]))
    length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
    short = both & (length < 0.25 * LATTICE_SIDE * WIDTH / dens)
    return int(counts[inside].max()), int(short.sum())


def run(seeds: int) -> list[dict]:
    rows = []
    for name, (part, base, regions) in CASES.items():
        for seed in range(seeds):
            start = time.process_time()
            pattern = InfillPattern.build(part, base, WIDTH, regions=regions, seed=seed)
            seconds = time.process_time() - start
            printed = pattern.clip(part).segments
            zones = pattern.density_map.zones(part)
            errors = [density(printed, z) - d for z, d in zip(zones, pattern.density_map.densities) if z.area > 0]
            region, region_density = regions[0]
            band = sparse_side(part, base, region, region_density) if len(regions) == 1 else None
            most, short = node_figures(pattern)
            across = control = None
            control_dense = float("nan")
            if band is not None:
                bands = border_bands(part, base, region, region_density)
                across = {k: 100 * density(printed, z) if z.area > 1.0 else float("nan") for k, z in bands.items()}
                # the same band in a uniform pattern of the sparse density: how much a band this wide varies anyway
                uniform = InfillPattern.build(part, min(base, region_density), WIDTH, seed=seed).clip(part).segments
                control = 100 * density(uniform, bands["sparse 0-1"])
                if bands["dense beyond 1"].area > 1.0:  # ... and the dense side's rest in a uniform dense pattern
                    uniform = InfillPattern.build(part, max(base, region_density), WIDTH, seed=seed).clip(part).segments
                    control_dense = 100 * density(uniform, bands["dense beyond 1"])
            rows.append({
                "across": across, "control": control, "control_dense": control_dense, "dense": 100 * max(base, region_density),
                "case": name, "seed": seed, "worst_points": 100 * max(abs(e) for e in errors),
                "errors": errors, "sparse_side": None if band is None else 100 * density(printed, band),
                "sparse": 100 * min(base, region_density), "max_edges": most, "short": short, "ms": 1000 * seconds,
            })
    return rows


def format_table(rows: list[dict]) -> str:
    out = ["| case | seeds | worst whole-region error (points) | mean | sparse side 0-2 mm (%) | sparse target (%) "
           "| max edges per node | short edges | build CPU ms (median) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name in CASES:
        mine = [r for r in rows if r["case"] == name]
        worst = max(r["worst_points"] for r in mine)
        mean = np.mean([100 * abs(e) for r in mine for e in r["errors"]])
        side = [r["sparse_side"] for r in mine if r["sparse_side"] is not None]
        side_text = f"{min(side):.1f}-{max(side):.1f}" if side else "-"
        out.append(f"| {name} | {len(mine)} | {worst:.2f} | {mean:.2f} | {side_text} | "
                   f"{mine[0]['sparse']:.0f} | {max(r['max_edges'] for r in mine)} | {sum(r['short'] for r in mine)} | "
                   f"{np.median([r['ms'] for r in mine]):.0f} |")
    worst = max(r["worst_points"] for r in rows)
    out.append("")
    out.append(f"worst whole-region error over every case and seed: {worst:.2f} points (target <= 2); "
               f"max edges per node {max(r['max_edges'] for r in rows)} (target <= 8); "
               f"short edges {sum(r['short'] for r in rows)} (target 0)")
    return "\n".join(out)


def _range(rows: list[dict], key: str) -> str:
    values = [r[key] for r in rows if not math.isnan(r[key])]
    return f"{min(values):.1f}-{max(values):.1f}" if values else "-"


def format_across(rows: list[dict]) -> str:
    """The density across each single region's border in bands one sparse spacing wide (min-max over seeds)."""
    keys = ("sparse 1-2", "sparse 0-1", "dense 0-1", "dense beyond 1", "sparse past the reach")
    out = ["| case | seeds | sparse side 1-2 spacings (%) | sparse side 0-1 spacing (%) | dense side 0-1 spacing (%) "
           "| dense side beyond 1 spacing (%) | sparse side, one spacing past a dense region's lattice (%) "
           "| targets (%) | band on the denser side, at most one sparse spacing "
           "| a uniform pattern of the sparse density, sparse side 0-1 spacing (%) "
           "| a uniform pattern of the dense density, dense side beyond 1 spacing (%) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|"]
    worst = 0.0
    for name in CASES:
        mine = [r for r in rows if r["case"] == name and r["across"] is not None]
        if not mine:
            continue
        cells = []
        for k in keys:
            values = [r["across"][k] for r in mine if not math.isnan(r["across"][k])]
            cells.append(f"{min(values):.1f}-{max(values):.1f}" if values else "-")
        misses = [max(abs(r["across"]["sparse 0-1"] - r["sparse"]),
                      0.0 if math.isnan(r["across"]["dense beyond 1"]) else abs(r["across"]["dense beyond 1"] - r["dense"]))
                  for r in mine]
        worst = max(worst, max(misses))
        out.append(f"| {name} | {len(mine)} | " + " | ".join(cells) + f" | {mine[0]['sparse']:.0f} / {mine[0]['dense']:.0f} "
                   f"| {'yes' if max(misses) <= 2.0 else 'no'} (worst {max(misses):.1f} points) "
                   f"| {min(r['control'] for r in mine):.1f}-{max(r['control'] for r in mine):.1f} | {_range(mine, 'control_dense')} |")
    past = max(abs(r["across"]["sparse past the reach"] - r["sparse"]) for r in rows if r["across"] is not None)
    out.append("")
    out.append(f"worst of the sparse side's first spacing and the dense side beyond one spacing against their "
               f"targets, every case and seed: {worst:.2f} points (target <= 2); of the sparse side's spacing past "
               f"a dense region's lattice: {past:.2f} points")
    return "\n".join(out)


# the region at the middle of a part wide enough that the window beside the largest (36 mm) region, its
# edge on the border, lies inside the part (in a 100 mm part it reached 4 mm past the part's free edge)
MIDDLE = 60.0  # mm
STIFFNESS_PART = box(0, 0, 2 * MIDDLE, 2 * MIDDLE)
STIFFNESS_CASES = {
    # name: (base density, region density, region side mm); the region is centred on the part
    "60 % region in 20 %": (0.2, 0.6, 30.0),
    "20 % region in 60 %": (0.6, 0.2, 30.0),
    "30 % region in 20 %": (0.2, 0.3, 30.0),
    "40 % region in 10 %": (0.1, 0.4, 36.0),
    "10 % region in 40 %": (0.4, 0.1, 36.0),
}


def run_stiffness(seeds: int) -> list[dict]:
    """C_min / rho over the region and beside it, each against a uniform pattern of its density."""
    centre = (MIDDLE, MIDDLE)
    rows = []
    for name, (base, inner, side) in STIFFNESS_CASES.items():
        region = box(MIDDLE - side / 2, MIDDLE - side / 2, MIDDLE + side / 2, MIDDLE + side / 2)
        beside = (MIDDLE, MIDDLE - side)  # the window below the region, its top edge on the border
        for seed in range(seeds):
            def uniform(d, seed=seed):
                return InfillPattern.build(STIFFNESS_PART, d, WIDTH, seed=seed).clip(STIFFNESS_PART).segments
            lines = InfillPattern.build(STIFFNESS_PART, base, WIDTH, regions=[(region, inner)],
                                        seed=seed).clip(STIFFNESS_PART).segments
            over = stiffness(lines, WIDTH, window=side, centre=centre)
            out = stiffness(lines, WIDTH, window=side, centre=beside)
            rows.append({
                "case": name, "seed": seed, "rho": over.rho,
                "region": over.c_min / stiffness(uniform(inner), WIDTH, window=side, centre=centre).c_min,
                "beside": out.c_min / stiffness(uniform(base), WIDTH, window=side, centre=beside).c_min,
            })
    return rows


def format_stiffness(rows: list[dict]) -> str:
    out = ["| case | seeds | window over the region: C_min/rho vs uniform (mean, min-max) | its density (%) "
           "| window beside it: vs uniform (mean, min-max) |", "|---|---:|---:|---:|---:|"]
    for name in STIFFNESS_CASES:
        mine = [r for r in rows if r["case"] == name]
        over = [r["region"] for r in mine]
        out_ = [r["beside"] for r in mine]
        out.append(f"| {name} | {len(mine)} | {np.mean(over):.3f} ({min(over):.3f}-{max(over):.3f}) | "
                   f"{100 * np.mean([r['rho'] for r in mine]):.1f} | {np.mean(out_):.3f} ({min(out_):.3f}-{max(out_):.3f}) |")
    worst = min(min(r["region"], r["beside"]) for r in rows)
    out.append("")
    out.append(f"weakest region or side against a uniform pattern of its density: {worst:.3f} (target >= 0.95)")
    return "\n".join(out)


def ideal_junction(base: float, inner: float, side: float, angle: float) -> np.ndarray:
    """The best junction a lattice pattern can have: each density's exact lattice (side 2 sqrt(3) w / d,
    one orientation, one origin: at ratios 3 and 4 the sparser lattice is a subset of the denser) right
    up to the region's border, no band of other samples, Delaunay across.  Segments (k, 2, 2)."""
    from scipy.spatial import Delaunay

    from DelaunayInfill.geometry import contains_xy

    region = box(MIDDLE - side / 2, MIDDLE - side / 2, MIDDLE + side / 2, MIDDLE + side / 2)
    points = []
    for density, inside in ((inner, True), (base, False)):
        lattice = triangular_lattice(LATTICE_SIDE * WIDTH / density, 2.2 * MIDDLE, angle)
        nodes = np.unique(np.round(lattice.reshape(-1, 2), 7), axis=0)
        nodes = nodes[(np.abs(nodes - MIDDLE) <= MIDDLE).all(axis=1)]
        points.append(nodes[contains_xy(region, nodes[:, 0], nodes[:, 1]) == inside])
    points = np.unique(np.round(np.concatenate(points), 7), axis=0)
    tri = Delaunay(points).simplices
    edges = np.unique(np.sort(np.concatenate((tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]])), axis=1), axis=0)
    return points[edges]


def run_ideal(angles=(0.1, 0.4, 0.7)) -> list[dict]:
    """`ideal_junction` measured as `run_stiffness` measures the pattern (three lattice turns)."""
    rows = []
    for name, (base, inner, side) in STIFFNESS_CASES.items():
        for angle in angles:
            lines = ideal_junction(base, inner, side, angle)
            uniform = triangular_lattice(LATTICE_SIDE * WIDTH / inner, 2.2 * MIDDLE, angle)
            over = stiffness(lines, WIDTH, window=side, centre=(MIDDLE, MIDDLE))
            rows.append({"case": name, "seed": angle, "rho": over.rho, "region": over.c_min / stiffness(
                uniform, WIDTH, window=side, centre=(MIDDLE, MIDDLE)).c_min, "beside": float("nan")})
    return rows


def format_ideal(rows: list[dict]) -> str:
    out = ["| case | turns | ideal junction, window over the region: C_min/rho vs uniform (mean, min-max) "
           "| its density (%) |", "|---|---:|---:|---:|"]
    for name in STIFFNESS_CASES:
        over = [r["region"] for r in rows if r["case"] == name]
        rho = [r["rho"] for r in rows if r["case"] == name]
        out.append(f"| {name} | {len(over)} | {np.mean(over):.3f} ({min(over):.3f}-{max(over):.3f}) "
                   f"| {100 * np.mean(rho):.1f} |")
    return "\n".join(out)


def _lines(segments: np.ndarray) -> MultiLineString:
    return MultiLineString([tuple(map(tuple, s)) for s in segments])


def _segments(lines) -> np.ndarray:
    """Segments (k, 2, 2) of a (Multi)LineString or a collection of them."""
    pieces = []
    for line in getattr(lines, "geoms", [lines]):
        if line.is_empty:
            continue
        if hasattr(line, "geoms"):
            pieces.append(_segments(line))
            continue
        coords = np.asarray(line.coords)
        if len(coords) >= 2:
            pieces.append(np.stack((coords[:-1], coords[1:]), axis=1))
    return np.concatenate(pieces) if pieces else np.zeros((0, 2, 2))


def border_line_junction(base: float, inner: float, side: float, angle: float) -> np.ndarray:
    """Each density's exact lattice clipped at the region's border and one line along the border (the
    lattices' lines end on it), clipped to `STIFFNESS_PART`: segments (k, 2, 2), densities uncalibrated."""
    from shapely.ops import unary_union

    region = box(MIDDLE - side / 2, MIDDLE - side / 2, MIDDLE + side / 2, MIDDLE + side / 2)
    lattice = {d: _lines(triangular_lattice(LATTICE_SIDE * WIDTH / d, 2.2 * MIDDLE, angle)) for d in (base, inner)}
    return _segments(unary_union([lattice[inner].intersection(region),
                                  lattice[base].intersection(STIFFNESS_PART.difference(region)), region.exterior]))


def run_junctions(angles=(0.1, 0.4, 0.7)) -> list[dict]:
    """The default pattern (seeds 0, 1, 2), the ideal junction and the border line (three lattice turns)
    in the windows over the region, beside it and straddling its border."""
    rows = []
    for name, (base, inner, side) in STIFFNESS_CASES.items():
        region = box(MIDDLE - side / 2, MIDDLE - side / 2, MIDDLE + side / 2, MIDDLE + side / 2)
        below = box(MIDDLE - side / 2, MIDDLE - 1.5 * side, MIDDLE + side / 2, MIDDLE - side / 2)
        windows = {"over": (MIDDLE, MIDDLE), "beside": (MIDDLE, MIDDLE - side), "straddling": (MIDDLE, MIDDLE - side / 2)}
        for k, angle in enumerate(angles):
            def lattice(d, angle=angle):
                lines = _lines(triangular_lattice(LATTICE_SIDE * WIDTH / d, 2.2 * MIDDLE, angle))
                return _segments(lines.intersection(STIFFNESS_PART))

            def pattern(d, seed=k):
                return InfillPattern.build(STIFFNESS_PART, d, WIDTH, seed=seed).clip(STIFFNESS_PART).segments

            default = InfillPattern.build(STIFFNESS_PART, base, WIDTH, regions=[(region, inner)],
                                          seed=k).clip(STIFFNESS_PART).segments
            for junction, lines, uniform in (("default pattern", default, pattern),
                                             ("ideal junction", ideal_junction(base, inner, side, angle), lattice),
                                             ("border line", border_line_junction(base, inner, side, angle), lattice)):
                got = {w: stiffness(lines, WIDTH, window=side, centre=c) for w, c in windows.items()}
                rows.append({
                    "case": name, "junction": junction, "turn": k,
                    "over": got["over"].c_min / stiffness(uniform(inner), WIDTH, window=side, centre=windows["over"]).c_min,
                    "beside": got["beside"].c_min / stiffness(uniform(base), WIDTH, window=side,
                                                              centre=windows["beside"]).c_min,
                    "straddling": got["straddling"].c_min,
                    "region": density(lines, region), "below": density(lines, below),
                })
    return rows


def format_junctions(rows: list[dict]) -> str:
    out = ["| case | junction | over the region: vs uniform | beside it: vs uniform | straddling the border: C_min/rho "
           "| region density (%) | density below it (%) |", "|---|---|---:|---:|---:|---:|---:|"]
    for name in STIFFNESS_CASES:
        for junction in ("default pattern", "ideal junction", "border line"):
            mine = [r for r in rows if r["case"] == name and r["junction"] == junction]
            cells = [f"{np.mean([r[key] for r in mine]):.3f} ({min(r[key] for r in mine):.3f})"
                     for key in ("over", "beside", "straddling")]
            out.append(f"| {name} | {junction} | " + " | ".join(cells) + f" | {100 * np.mean([r['region'] for r in mine]):.1f} "
                       f"| {100 * np.mean([r['below'] for r in mine]):.1f} |")
    return "\n".join(out)


PROFILE_CASE = "box 20 mm at 60 % in 20 %"


def border_profile(seeds: int, bins: int = 6) -> tuple[np.ndarray, list[np.ndarray]]:
    """Density against distance from the region's border, in bins half a sparse spacing wide.

    Returns (bin centres in sparse spacings, negative on the sparse side; one density array in % per seed).
    """
    part, base, regions = CASES[PROFILE_CASE]
    region, region_density = regions[0]
    s = LATTICE_SIDE * WIDTH / min(base, region_density)
    inner = part.buffer(-s)
    edges = 0.5 * s * np.arange(-bins, bins + 1)  # signed distance: outside the region (sparse) negative
    centres = 0.5 * (edges[:-1] + edges[1:]) / s
    out = []
    for seed in range(seeds):
        printed = InfillPattern.build(part, base, WIDTH, regions=regions, seed=seed).clip(part).segments
        values = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            # signed distance d (inside the region positive): between region.buffer(-lo) and region.buffer(-hi)
            band = region.buffer(-lo, 8).difference(region.buffer(-hi, 8)).intersection(inner)
            values.append(100 * density(printed, band) if band.area > 1.0 else float("nan"))
        out.append(np.array(values))
    return centres, out


def plot_profile(path: str, seeds: int) -> None:
    """`border_profile` drawn: one line per seed, the two targets dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    centres, per_seed = border_profile(seeds)
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=110)
    for seed, values in enumerate(per_seed):
        ax.plot(centres, values, marker="o", ms=3, lw=1, label=f"seed {seed}")
    ax.axvline(0, color="k", lw=0.8)
    ax.axhline(20, color="0.5", ls="--", lw=0.8)
    ax.axhline(60, color="0.5", ls="--", lw=0.8)
    ax.axvspan(-1, 0, color="tab:blue", alpha=0.06)
    ax.set_xlabel("distance from the region's border, sparse spacings (20 % side negative)")
    ax.set_ylabel("printed density, % (bins of half a spacing)")
    ax.set_title(f"{PROFILE_CASE}: the change lies on the denser side", fontsize=10)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5, help="seeds per case (default 5)")
    parser.add_argument("--ideal", action="store_true",
                        help="also measure the ideal junction of two exact lattices (no band) the same way")
    parser.add_argument("--junctions", action="store_true",
                        help="also compare the default pattern, the ideal junction and a border line in three windows")
    parser.add_argument("--plot", metavar="PNG", help="draw the density across the border of one case, per seed, and stop")
    args = parser.parse_args(argv)
    if args.plot:
        plot_profile(args.plot, args.seeds)
        print(f"wrote {args.plot}")
        return 0
    rows = run(args.seeds)
    print(format_table(rows))
    print()
    print(format_across(rows))
    print()
    print(format_stiffness(run_stiffness(args.seeds)))
    if args.ideal:
        print()
        print(format_ideal(run_ideal()))
    if args.junctions:
        print()
        print(format_junctions(run_junctions()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
