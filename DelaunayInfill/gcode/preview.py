"""Top view of one layer coloured by line type (matplotlib, an optional extra)."""

from __future__ import annotations

import os
import textwrap

import numpy as np

from .area import segments_of
from .read import TYPE_CODES, MachineState, RetractionModel, iter_file_chunks, parse_layer

__all__ = ["layer_segments", "layer_view", "region_outlines", "render_layer", "render_layers", "MATPLOTLIB_MISSING"]

MATPLOTLIB_MISSING = "the preview needs matplotlib: pip install 'DelaunayInfill[plot]' (or pip install matplotlib)"

# Colours close to Cura's "Line Type" scheme.
_STYLE = {
    "WALL-OUTER": ("#d62728", "outer wall"),
    "WALL-INNER": ("#2ca02c", "inner wall"),
    "SKIN": ("#e6c619", "skin"),
    "FILL": ("#ff7f0e", "infill"),
    "SUPPORT": ("#17becf", "support"),
    "SUPPORT-INTERFACE": ("#1f77b4", "support interface"),
    "SKIRT": ("#9edae5", "skirt/brim"),
    "PRIME-TOWER": ("#8c564b", "prime tower"),
}
_NAMES = {v: k for k, v in TYPE_CODES.items()}
_REGION_COLOURS = ("#000000", "#e377c2", "#7f7f7f", "#bcbd22", "#1f77b4")


def layer_segments(path, layer: int, *, occurrence: int = 0) -> dict[str, np.ndarray]:
    """The moves of layer `layer` of a G-code file, grouped by line type (see `layer_view`)."""
    return layer_view(path, layer, occurrence=occurrence)[0]


def layer_view(path, layer: int, *, occurrence: int = 0) -> tuple[dict[str, np.ndarray], float, float]:
    """The moves of layer `layer` of a G-code file, grouped by line type, with its heights.

    Parameters
    ----------
    path : path-like
    layer : int
        The ``;LAYER:`` number.
    occurrence : int
        Which of several layers with that number (one-at-a-time printing).

    Returns
    -------
    (dict, float, float)
        Type name (``"FILL"``, ``"travel"``, ...) -> segments, shape (k, 2, 2), mm; the layer's
        print height Z and the height it was sliced at (the middle of the layer), mm.

    Raises
    ------
    ValueError
        No such layer.
    """
    state, retraction = MachineState(), RetractionModel()
    seen = 0
    layers = []
    prev_z = None
    with open(path, encoding="utf-8", errors="replace", newline="") as f:
        for chunk in iter_file_chunks(f):
            parse = parse_layer(chunk, state, retraction)
            if parse.number is None:
                continue
            layers.append(parse.number)
            if parse.number == layer:
                if seen == occurrence:
                    # the slice height as the G-code pass takes it: half a layer below the print height
                    height = parse.z - prev_z if prev_z is not None and 0 < parse.z - prev_z < 2.0 else min(parse.z, 0.2)
                    return _group(parse), float(parse.z), float(parse.z - height / 2)
                seen += 1
            prev_z = parse.z
    if not layers:
        raise ValueError(f"{os.fspath(path)} has no ';LAYER:' lines")
    raise ValueError(f"{os.fspath(path)} has no layer {layer} (layers {min(layers)}..{max(layers)})")


def _group(parse) -> dict[str, np.ndarray]:
    m = parse.moves
    moved = (m["x1"] != m["x0"]) | (m["y1"] != m["y0"])
    ok = moved & np.isfinite(m["x0"]) & np.isfinite(m["y0"])
    extr = ok & (m["de"] > 0)
    segs = segments_of(m, slice(None))
    # a travel between a retraction (E-only move backwards) and the next prime is made retracted:
    # where the nozzle may string, so the view marks it apart
    e_only = ~moved & (m["de"] != 0)
    steps = np.where(e_only, np.sign(m["de"]), 0.0)
    retracted = np.cumsum(-steps) > 0
    travel = ok & ~extr
    out = {"travel": segs[travel & ~retracted], "travel, retracted": segs[travel & retracted]}
    for code in np.unique(m["kind"][extr]):
        out[_NAMES.get(int(code), "NONE")] = segs[extr & (m["kind"] == code)]
    return out


def region_outlines(regions, z: float) -> list[tuple[np.ndarray, str]]:
    """The outlines of density regions at height `z`.

    Parameters
    ----------
    regions : sequence of Region
        Density regions (`settings.Region`: a mesh or a polygon with a density fraction).
    z : float
        The slice height, mm.

    Returns
    -------
    list of (ndarray, str)
        Each ring as points, shape (n, 2), mm, with its region's label (name and density in %).
    """
    rings = []
    for region in regions:
        label = f"{region.name} {region.density * 100:g} %"
        for poly in region.at(z).geoms:
            for ring in (poly.exterior, *poly.interiors):
                rings.append((np.asarray(ring.coords)[:, :2], label))
    return rings


def _draw(ax, groups, title, line_width, outlines=()):
    from matplotlib.collections import LineCollection

    handles = []
    if len(groups.get("travel", [])):
        lc = LineCollection(groups["travel"], colors="#606060", linewidths=0.6, linestyles="dotted", label="travel")
        ax.add_collection(lc)
        handles.append(lc)
    if len(groups.get("travel, retracted", [])):
        lc = LineCollection(groups["travel, retracted"], colors="#9467bd", linewidths=1.2, linestyles="dashed",
                            label="travel, retracted")
        ax.add_collection(lc)
        handles.append(lc)
    for name, (colour, label) in _STYLE.items():
        segs = groups.get(name)
        if segs is None or not len(segs):
            continue
        lc = LineCollection(segs, colors=colour, linewidths=line_width, capstyle="round", label=label)
        ax.add_collection(lc)
        handles.append(lc)
    for k, label in enumerate(dict.fromkeys(lbl for _, lbl in outlines)):
        rings = [ring for ring, lbl in outlines if lbl == label]
        lc = LineCollection(rings, colors=_REGION_COLOURS[k % len(_REGION_COLOURS)], linewidths=1.4,
                            linestyles="dashdot", label=f"region {label}")
        ax.add_collection(lc)
        handles.append(lc)
    ax.set_aspect("equal")
    ax.autoscale_view()
    # long file names wrap: a title never runs past its panel
    ax.set_title("\n".join(textwrap.wrap(title, 48)) or title, fontsize=10)
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    return handles


def render_layers(panels, out_path, *, dpi: int = 150, line_width: float = 1.0, window=None) -> str:
    """Draw one or more layer views side by side into a PNG.

    Parameters
    ----------
    panels : sequence of (groups, title) or (groups, title, outlines)
        `layer_segments` results with their titles, and optionally `region_outlines` to draw.
    out_path : path-like
    window : (x0, y0, x1, y1), optional
        The part of the bed to show, mm (default: everything the layer prints).

    Returns
    -------
    str
        The written path.

    Raises
    ------
    ImportError
        matplotlib is not installed (message: `MATPLOTLIB_MISSING`).
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(MATPLOTLIB_MISSING) from exc
    fig, axes = plt.subplots(1, len(panels), figsize=(6.4 * len(panels), 6.4), squeeze=False)
    handles = []
    for ax, (groups, title, *outlines) in zip(axes[0], panels, strict=True):
        handles = _draw(ax, groups, title, line_width, *outlines) or handles
        if window is not None:
            ax.set_xlim(window[0], window[2])
            ax.set_ylim(window[1], window[3])
    by_label = {h.get_label(): h for ax in axes[0] for h in ax.collections}
    fig.legend(by_label.values(), by_label.keys(), loc="lower center", ncol=min(5, len(by_label)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    out_path = os.fspath(out_path)
    tmp = out_path + ".tmp.png"
    # bbox "tight": titles, labels and the legend stay on the canvas whatever the part's shape
    fig.savefig(tmp, dpi=dpi, bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)
    os.replace(tmp, out_path)
    return out_path


def render_layer(path, layer: int, out_path, *, before=None, occurrence: int = 0, dpi: int = 150, window=None,
                 regions=()) -> str:
    """PNG top view of one layer; with `before`, the original on the left for comparison; `window`
    (x0, y0, x1, y1) mm zooms in; `regions` (`settings.Region`) are drawn as outlines at the layer's
    slice height."""
    panels = []
    for source in ([before] if before is not None else []) + [path]:
        groups, z, z_slice = layer_view(source, layer, occurrence=occurrence)
        title = f"{os.path.basename(os.fspath(source))} — layer {layer} (Z {z:g} mm)"
        panels.append((groups, title, region_outlines(regions, z_slice)))
    return render_layers(panels, out_path, dpi=dpi, window=window)
