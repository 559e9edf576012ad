"""The paper's figures, redrawn, with measured densities.

``delaunay-infill figures -o DIR`` writes

* ``figure2.png``: Poisson-disk samples and their Delaunay infill on a
  400 x 400 mm square at 10, 40 and 80 % (1.2 mm lines, as in the paper);
* ``figure10.png``: the five-point star split into five tips and the central
  pentagon at 30/30/20/50/50/10 %, in the paper's layout and in the seamless
  layout;
* ``figures.md`` (or ``--table PATH``): the measured density per region, the paper's Formula (6)
  calibration error next to ours, and triangle quality with and without
  relaxation.

matplotlib is an optional extra (``pip install DelaunayInfill[plot]``).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from shapely.geometry import Point, Polygon, box

from .pattern import InfillPattern, generate_infill

__all__ = ["star_polygon", "star_regions", "write_figures"]

FIGURE10_DENSITIES = (0.3, 0.3, 0.2, 0.5, 0.5, 0.1)


def star_polygon(diameter: float = 60.0, inner_ratio: float = 0.45, points: int = 5):
    """The paper's five-point star (the project's test model), centred at 0, 0.

    Returns
    -------
    (Polygon, tips, inner)
        The star, its tip vertices (points, 2) and inner vertices (points, 2).
    """
    outer = diameter / 2.0
    angles = math.pi / 2 + np.arange(2 * points) * math.pi / points
    radii = np.where(np.arange(2 * points) % 2 == 0, outer, outer * inner_ratio)
    ring = np.c_[radii * np.cos(angles), radii * np.sin(angles)]
    return Polygon(ring), ring[0::2], ring[1::2]


def star_regions(densities=FIGURE10_DENSITIES, **star_kwargs) -> list:
    """Figure 10's regions: tips 1-5 (triangles) then the central pentagon 6."""
    _, tips, inner = star_polygon(**star_kwargs)
    n = len(tips)
    triangles = [Polygon([inner[i - 1], tips[i], inner[i]]) for i in range(n)]
    return [(t, d) for t, d in zip(triangles, densities[:n])] + [(Polygon(inner), densities[n])]


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as error:
        raise SystemExit(
            "matplotlib is needed for pictures: pip install 'DelaunayInfill[plot]' (or pip install matplotlib)"
        ) from error
    return plt


def _draw_segments(ax, segments, width_mm, color="#1f5fa8"):
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(segments, colors=color, linewidths=max(0.25, width_mm * 0.6)))


def _outline(ax, polygon, **kw):
    for ring in [polygon.exterior, *polygon.interiors]:
        xy = np.asarray(ring.coords)
        ax.plot(xy[:, 0], xy[:, 1], **kw)


def figure2(out: Path, seed: int = 0) -> list[dict]:
    """400 x 400 square at 10/40/80 %, 1.2 mm lines; returns table rows."""
    plt = _pyplot()
    square = box(0, 0, 400, 400)
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    rows = []
    for ax, target in zip(axes, (0.1, 0.4, 0.8)):
        t0 = time.perf_counter()
        pattern = InfillPattern.build(square, target, 1.2, seed=seed)
        result = pattern.clip(square)
        seconds = time.perf_counter() - t0
        paper = generate_infill(square, target, 1.2, seed=seed, calibration="paper")
        _draw_segments(ax, result.segments, 0.5, color="#9bb7d4")
        inside = (pattern.points >= 0).all(axis=1) & (pattern.points <= 400).all(axis=1)
        pts = pattern.points[inside]
        ax.plot(pts[:, 0], pts[:, 1], ".", ms=1.5, color="#10294a")
        ax.set_title(f"{target:.0%} target, measured {result.density:.1%}\n{len(pts)} samples")
        ax.set_aspect("equal")
        ax.set_xlim(0, 400)
        ax.set_ylim(0, 400)
        rows.append(
            {
                "target": target,
                "ours": result.density,
                "paper": paper.density,
                "samples": len(pts),
                "seconds": seconds,
            }
        )
    fig.suptitle("Figure 2 redrawn: Poisson-disk samples and Delaunay infill, 400 x 400 mm, 1.2 mm lines")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return rows


def figure10(out: Path, line_width: float = 0.4, seed: int = 0) -> list[dict]:
    """The star with Figure 10's six regions, paper layout vs seamless; returns rows."""
    plt = _pyplot()
    star, _, _ = star_polygon()
    regions = star_regions()
    fig, axes = plt.subplots(1, 2, figsize=(12, 6.2))
    rows = []
    layouts = (("paper", "paper layout (convex parts, Bridson)"), ("seamless", "seamless layout (default)"))
    for ax, (layout, title) in zip(axes, layouts):
        result = generate_infill(star, 0.3, line_width, regions=regions, layout=layout, seed=seed)
        _draw_segments(ax, result.segments, line_width)
        for k, (poly, dens) in enumerate(regions, start=1):
            _outline(ax, poly, color="#d0483a", lw=0.8, ls="--")
            c = poly.representative_point() if k <= 5 else Point(0, 0)
            ax.text(c.x, c.y, f"{k}\n{dens:.0%}", ha="center", va="center", fontsize=9, color="#d0483a",
                    bbox=dict(facecolor="white", alpha=0.7, lw=0))
        _outline(ax, star, color="black", lw=1.2)
        ax.set_title(title)
        ax.set_aspect("equal")
        ax.axis("off")
        for k, ((_, target), got) in enumerate(zip(regions, result.region_densities[1:]), start=1):
            rows.append({"layout": layout, "region": k, "target": target, "measured": got})
    fig.suptitle(f"Figure 10 redrawn: five-point star, regions 1-6 at 30/30/20/50/50/10 %, {line_width} mm lines")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return rows


def calibration_rows(seed: int = 0) -> list[dict]:
    """Measured density against target for our calibration and the paper's Formula (6)."""
    from shapely.geometry import Point as P

    shapes = {
        "square 50 mm": box(0, 0, 50, 50),
        "star 60 mm": star_polygon()[0],
        "annulus 60/24 mm": P(0, 0).buffer(30, 32).difference(P(0, 0).buffer(12, 32)),
    }
    rows = []
    for name, shape in shapes.items():
        for width in (0.4, 1.2):
            for target in (0.05, 0.2, 0.5, 0.8):
                ours = generate_infill(shape, target, width, seed=seed).density
                paper = generate_infill(shape, target, width, seed=seed, calibration="paper").density
                rows.append({"shape": name, "width": width, "target": target, "ours": ours, "paper": paper})
    return rows


def quality_rows(seed: int = 0) -> list[dict]:
    """Triangle quality of a 100 x 100 mm, 20 % pattern with and without relaxation."""
    rows = []
    for steps in (0, 8):
        pattern = InfillPattern.build(box(0, 0, 100, 100), 0.2, 0.4, seed=seed, relax=steps)
        rows.append({"relax": steps, **pattern.quality(), "density": pattern.calibrated_densities[0]})
    return rows


def write_figures(out_dir: Path, seed: int = 0, table: Path | None = None) -> str:
    """Write the figures into `out_dir` and the tables to `table` (default out_dir/figures.md).

    Returns the markdown.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    f2 = figure2(out_dir / "figure2.png", seed=seed)
    f10 = figure10(out_dir / "figure10.png", seed=seed)
    cal = calibration_rows(seed=seed)
    qual = quality_rows(seed=seed)
    lines = ["# Figures and measured densities", "",
             "Printed by `delaunay-infill figures -o docs/images --table docs/figures.md` (in the repository).", ""]
    lines += ["## Figure 2: 400 x 400 mm square, 1.2 mm lines", "",
              "| target | measured (ours) | measured with Formula (6) | samples | seconds |", "|---|---|---|---|---|"]
    lines += [f"| {r['target']:.0%} | {r['ours']:.2%} | {r['paper']:.2%} | {r['samples']} | {r['seconds']:.2f} |" for r in f2]
    lines += ["", "## Figure 10: star regions (0.4 mm lines)", "",
              "| layout | region | target | measured |", "|---|---|---|---|"]
    lines += [f"| {r['layout']} | {r['region']} | {r['target']:.0%} | {r['measured']:.1%} |" for r in f10]
    lines += ["", "## Calibration: measured density, ours vs the paper's Formula (6)", "",
              "| shape | line width | target | ours | error | Formula (6) | error |", "|---|---|---|---|---|---|---|"]
    lines += [
        f"| {r['shape']} | {r['width']} mm | {r['target']:.0%} | {r['ours']:.2%} | {100 * (r['ours'] - r['target']):+.2f} pt "
        f"| {r['paper']:.2%} | {100 * (r['paper'] - r['target']):+.2f} pt |"
        for r in cal
    ]
    worst_ours = max(abs(r["ours"] - r["target"]) for r in cal)
    worst_paper = max(abs(r["paper"] - r["target"]) for r in cal)
    lines += ["", f"Worst error: ours {100 * worst_ours:.2f} points, Formula (6) {100 * worst_paper:.2f} points.", ""]
    lines += ["## Triangle quality, 100 x 100 mm at 20 %, 0.4 mm lines", "",
              "| relaxation steps | LOP violations | min angle | mean smallest angle | triangles with an angle < 40 deg | edges < half the mean | density |",
              "|---|---|---|---|---|---|---|"]
    lines += [
        f"| {r['relax']} | {r['lop_violations']} | {r['min_angle_deg']:.1f} deg | {r['mean_min_angle_deg']:.1f} deg | "
        f"{r['sharp_triangle_share']:.1%} | {r['short_edge_share']:.1%} | {r['density']:.2%} |"
        for r in qual
    ]
    text = "\n".join(lines) + "\n"
    table = table or out_dir / "figures.md"
    table.parent.mkdir(parents=True, exist_ok=True)
    table.write_text(text, encoding="utf-8")
    return text
