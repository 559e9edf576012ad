"""Stiffness benchmark: in-plane stiffness per density of Cura's infill and of DelaunayInfill's, same run.

An 80 x 80 x 12 mm box is sliced by CuraEngine (Debian's 4.13) with Cura's
triangles, cubic and grid infill at each density; the grid G-code is then
processed by ``DelaunayInfill.gcode.process_gcode`` with the default settings,
with the Poisson sampler, with ``relax=8`` and with ``layout="paper"`` (seeds 0-4 each).  For 5 middle
layers the FILL lines in a 30 mm window at the box's centre go through the
frame model of ``bench/stiffness.py`` (rigid joints, affine strain on the
window border, bead modulus 1, bead width 0.4 mm); the stack's stiffness is
the mean of the layers' tensors.  Columns:

* C_min/rho: weakest-direction uniaxial-strain stiffness per area fraction
  (0.375 is the triangular lattice's, the bound for a line network);
* isotropy: C_min / C_max over directions (of the stack);
* E_min/rho: weakest-direction uniaxial-stress (tension) modulus per area fraction;
* rho: area fraction of the lines in the window;
* vs triangles: C_min/rho against Cura's triangles at that density.

"Poisson sampler" is the default pattern before the lattice seeding (patterns
built with ``sampler="fast"``), measured in the same run.

The "9 windows" columns do the same over nine windows (centres on a 3 x 3
grid 10 mm apart round the box's centre, closer where a large window would
reach the walls; the mean tensor of the nine windows and five layers): where a
pattern has few lines per window (10 %), how one window clips them moves the
single-window figures by a few percent.  ``--window 60`` holds four lattice
sides at 10 % (a 30 mm window two).

"Cura triangles, window turned" measures Cura's triangles in windows turned
by 0, 3, ..., 57 degrees round the centre (mean +- deviation over the turns;
only where turned windows stay inside the infill): Cura anchors its lines at
the box's centre, along the window's sides, while the default's lattice is
turned by the seed, so this is the like-for-like reference at 10 %.

Delaunay rows give the mean over the seeds, +- their standard deviation.
With ``--plot PATH`` a polar plot of C(theta)/rho and E(theta)/rho at 20 %
(Cura's triangles, grid, the Poisson sampler and the default) is saved.

Usage::

    python3 bench/bench_stiffness.py [--densities 10,20,40] [--seeds 5] [--plot docs/images/stiffness-polar.png]
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import statistics
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from bench.stiffness import fill_segments, from_tensor, stiffness  # noqa: E402
from DelaunayInfill import curaengine, models  # noqa: E402

CURA = ("triangles", "cubic", "grid")
OURS = (("Delaunay default", {}), ("Poisson sampler (the default before the lattice)", {"sampler": "fast"}),
        ("relax=8", {"relax": 8}), ('layout="paper"', {"layout": "paper"}))
WIDTH = 0.4
TURNED = "Cura triangles, window turned 0-57°"
TURNS = tuple(range(0, 60, 3))  # degrees: the triangles repeat every 60
BOX = 80.0  # mm, the box's side
INFILL_INSET = 0.8  # mm, the box's two walls: the infill's edge lies this far inside the box


def split_like_cura(text: str) -> list[str]:
    """Cura's in-memory form: one string before the first ;LAYER:, one per layer."""
    return [p for p in re.split(r"(?m)^(?=;LAYER:)", text) if p]


def middle_layers(path: str, count: int = 5) -> list[int]:
    with open(path, encoding="utf-8", errors="replace") as f:
        numbers = sorted({int(m) for m in re.findall(r"^;LAYER:(\d+)", f.read(), re.M)})
    mid = len(numbers) // 2
    return numbers[mid - count // 2: mid - count // 2 + count]


def nine_window_spread(window: float) -> float:
    """mm between the nine windows' centres: 10, or less where the outer windows would leave the infill."""
    return min(10.0, (BOX - 2.0 * INFILL_INSET - window) / 2.0 - 0.5)


def turned_fits(window: float, spread: float) -> bool:
    """Whether the nine windows, turned by any angle round the box's centre, stay inside its infill."""
    return math.sqrt(2.0) * (window / 2.0 + spread) <= BOX / 2.0 - INFILL_INSET


def stack_of(path: str, layers: list[int], window: float, centre, spread: float = 10.0, turn: float = 0.0):
    """Stiffness of the stack of layers in the central window, and over 3 x 3 windows.

    Each is a `Stiffness` of the mean tensor and density: of the layers in the
    window at `centre`; and of the layers in nine windows whose centres are
    `centre` moved by -spread, 0, +spread mm in x and y (a larger piece of the
    part: the clipping of a few lines by one window weighs less).  With `turn`
    (degrees) the windows are turned by it round `centre` (the lines turned back).
    """
    segments = [fill_segments(path, n) for n in layers]
    if turn:
        angle = math.radians(-turn)
        rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        segments = [(seg - centre) @ rotation.T + centre for seg in segments]
    central = [stiffness(seg, WIDTH, window=window, centre=centre) for seg in segments]
    offsets = [(dx, dy) for dx in (-spread, 0.0, spread) for dy in (-spread, 0.0, spread)]
    many = [stiffness(seg, WIDTH, window=window, centre=(centre[0] + dx, centre[1] + dy))
            for seg in segments for dx, dy in offsets]

    def mean(results):
        return from_tensor(np.mean([r.C for r in results], axis=0), float(np.mean([r.rho for r in results])))

    return mean(central), mean(many)


def run(densities, seeds: int, window: float, out: str):
    from DelaunayInfill.gcode.process import process_gcode
    from DelaunayInfill.gcode.settings import ProcessSettings

    stl = os.path.join(out, "box.stl")
    models.write_stl(stl, models.box(BOX, BOX, 12.0), name="box")
    rows = {}  # (density, name) -> dict
    for density in densities:
        paths = {}
        for pattern in CURA:
            path = os.path.join(out, f"box_{pattern}_{density:g}.gcode")
            curaengine.slice_models([(os.path.basename(stl), {})],
                                    {"infill_sparse_density": density, "infill_pattern": pattern}, path, cwd=out)
            paths[pattern] = path
        layers = middle_layers(paths["grid"])
        centre = (110.0, 110.0)  # the box's centre: model (0, 0) is printed at the bed's centre
        spread = nine_window_spread(window)
        for pattern in CURA:
            stack, nine = stack_of(paths[pattern], layers, window, centre, spread)
            rows[(density, f"Cura {pattern}")] = {"stacks": [stack], "spread": [nine]}
        if turned_fits(window, spread):
            # Cura anchors its lines at the box's centre, on the window's axes; the lattice is turned by the seed
            turned = [stack_of(paths["triangles"], layers, window, centre, spread, turn) for turn in TURNS]
            rows[(density, TURNED)] = {"stacks": [t[0] for t in turned], "spread": [t[1] for t in turned]}
        with open(paths["grid"], encoding="utf-8") as f:
            chunks = split_like_cura(f.read())
        for name, options in OURS:
            stacks, spreads, seconds = [], [], []
            options = dict(options)
            sampler = options.pop("sampler", None)
            for seed in range(seeds):
                start = time.process_time()
                with _sampler(sampler):
                    layers_out, report = process_gcode(chunks, ProcessSettings(seed=seed, **options))
                seconds.append(time.process_time() - start)
                if report.failed_layers or not report.blocks_replaced:
                    raise RuntimeError(f"{name}, {density:g} %, seed {seed}: process_gcode replaced "
                                       f"{report.blocks_replaced} blocks, layers failed: {report.failed_layers}")
                path = os.path.join(out, f"box_delaunay_{density:g}_{seed}.gcode")
                with open(path, "w", encoding="utf-8") as f:
                    f.write("".join(layers_out))
                stack, nine = stack_of(path, layers, window, centre, spread)
                stacks.append(stack)
                spreads.append(nine)
            rows[(density, name)] = {"stacks": stacks, "spread": spreads, "seconds": statistics.median(seconds)}
    return rows


@contextlib.contextmanager
def _sampler(name):
    """Patterns built with this sampler (`InfillPattern.build`'s keyword; the G-code pass has no
    setting for it): the Poisson-disk pattern that was the default before the lattice seeding."""
    if name is None:
        yield
        return
    from DelaunayInfill.pattern import InfillPattern

    original = InfillPattern.__dict__["build"]

    def build(cls, *args, **kwargs):
        return original.__func__(cls, *args, **{**kwargs, "sampler": kwargs.get("sampler") or name})

    InfillPattern.build = classmethod(build)
    try:
        yield
    finally:
        InfillPattern.build = original


def _cell(values, digits: int) -> str:
    mean = statistics.fmean(values)
    if len(values) > 1:
        return f"{mean:.{digits}f} ± {statistics.stdev(values):.{digits}f}"
    return f"{mean:.{digits}f}"


def format_table(rows, densities, seeds: int, window: float) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    out = [f"80 x 80 x 12 mm box, CuraEngine 4.13, 0.4 mm lines, {window:g} mm window at the centre "
           f"(9 windows {nine_window_spread(window):g} mm apart), "
           f"5 middle layers (stack = mean tensor), Delaunay rows: seeds 0-{seeds - 1}; load average {load:.2f}.", "",
           "| density | infill | C_min/rho | isotropy | E_min/rho | rho in window | vs Cura triangles (C_min/rho) "
           "| 9 windows: C_min/rho | isotropy | vs Cura triangles | process_gcode CPU (s) |",
           "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    names = [f"Cura {p}" for p in CURA] + [TURNED] + [name for name, _ in OURS]
    for density in densities:
        reference = statistics.fmean(s.c_min for s in rows[(density, "Cura triangles")]["stacks"])
        reference_9 = statistics.fmean(s.c_min for s in rows[(density, "Cura triangles")]["spread"])
        for name in names:
            if (density, name) not in rows:
                continue
            row = rows[(density, name)]
            stacks, spread = row["stacks"], row["spread"]
            c_min, c_min_9 = [s.c_min for s in stacks], [s.c_min for s in spread]
            seconds = f"{row['seconds']:.2f}" if "seconds" in row else ""
            out.append(f"| {density:g} % | {name} | {_cell(c_min, 3)} | {_cell([s.isotropy for s in stacks], 2)} | "
                       f"{_cell([s.e_min for s in stacks], 3)} | {_cell([100 * s.rho for s in stacks], 1)} % | "
                       f"{statistics.fmean(c_min) / reference:.3f} | {_cell(c_min_9, 3)} | "
                       f"{_cell([s.isotropy for s in spread], 2)} | {statistics.fmean(c_min_9) / reference_9:.3f} | "
                       f"{seconds} |")
    return "\n".join(out)


def polar_plot(rows, density, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    theta = np.radians(np.arange(0.0, 360.5, 1.0))
    fig, axes = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(10, 5.4))
    styles = {"Cura triangles": ("#1f77b4", "-"), "Cura grid": ("#7f7f7f", "--"),
              "Poisson sampler (the default before the lattice)": ("#ff7f0e", ":"), "Delaunay default": ("#d62728", "-")}
    for name, (colour, style) in styles.items():
        stacks = rows[(density, name)]["stacks"]
        for k, stack in enumerate(stacks):
            label = name if k == 0 else None
            alpha = 1.0 if len(stacks) == 1 else 0.6
            axes[0].plot(theta, stack.c_theta(theta), style, color=colour, label=label, alpha=alpha, lw=1.4)
            axes[1].plot(theta, stack.e_theta(theta), style, color=colour, label=label, alpha=alpha, lw=1.4)
    for ax, title in zip(axes, ("C(θ)/ρ, uniaxial strain", "E(θ)/ρ, uniaxial stress (tension)")):
        ax.set_title(title, pad=14)
        ax.set_rlim(0, 0.55)
        ax.set_rticks([0.1, 0.2, 0.3, 0.375, 0.5])
        ax.tick_params(labelsize=8)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(f"In-plane stiffness per density at {density:g} %, 80 mm box, 30 mm window (Delaunay: one curve per seed)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.93))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--densities", default="10,20,40", help="percent, comma-separated")
    parser.add_argument("--seeds", type=int, default=5, help="Delaunay seeds 0..N-1 (default 5)")
    parser.add_argument("--window", type=float, default=30.0, help="window side, mm")
    parser.add_argument("--plot", default=None, help="save the polar plot (20 %, or the first density) here")
    parser.add_argument("--out", default=None, help="keep the G-code files in this folder")
    args = parser.parse_args(argv)
    problem = curaengine.setup_problem()
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    densities = [float(v) for v in args.densities.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or tmp
        os.makedirs(out, exist_ok=True)
        rows = run(densities, args.seeds, args.window, out)
    print(format_table(rows, densities, args.seeds, args.window))
    if args.plot:
        polar_plot(rows, 20.0 if 20.0 in densities else densities[0], args.plot)
        print(f"\npolar plot: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
