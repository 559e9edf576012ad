"""Inferring what the G-code does not state: line width, Cura's infill density, flow."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .area import direction_peaks, median_of, runs_of, sample_segments, segment_samples
from .read import SKIN, WALL_INNER, WALL_OUTER, LayerParse

__all__ = ["wall_line_width", "skin_line_width", "infill_density", "family_spacings", "e_per_mm", "nearest_sample_distance"]


def _segments_of(runs: list[np.ndarray]) -> np.ndarray:
    if not runs:
        return np.zeros((0, 2, 2))
    return np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in runs])


def nearest_sample_distance(segments: np.ndarray, step: float, pts: np.ndarray, upper: float) -> np.ndarray:
    """Distance from each point to the nearest of ``sample_segments(segments, step)``; inf from `upper` on.

    A segment's samples are evenly spaced, so its nearest one to a point is
    one of the two either side of the point's projection: found per segment
    in closed form, the same distances as a tree of all the samples gives
    (thousands of them for walls sampled every 0.02 mm), far cheaper.  A tree
    is used when points x segments are many.

    Parameters
    ----------
    segments : ndarray, shape (k, 2, 2)
        mm.
    step : float
        Sample spacing, mm.
    pts : ndarray, shape (p, 2)
        mm.
    upper : float
        Distances from this on are inf, mm.

    Returns
    -------
    ndarray, shape (p,)
    """
    if len(segments) == 0 or len(pts) == 0:
        return np.full(len(pts), np.inf)
    if len(pts) * len(segments) > 250_000:
        tree = cKDTree(sample_segments(segments, step), balanced_tree=False, compact_nodes=False)  # (faster to build)
        return tree.query(pts, distance_upper_bound=upper)[0]
    start = segments[:, 0]
    d = segments[:, 1] - start
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step).astype(np.int64))
    length2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    # the projection of each point on each segment, in sample steps, shape (p, k)
    rel_x, rel_y = pts[:, 0, None] - start[:, 0], pts[:, 1, None] - start[:, 1]
    at = (rel_x * d[:, 0] + rel_y * d[:, 1]) / np.where(length2 > 0, length2, 1.0) * n
    nearest = np.full(len(pts), np.inf)
    for index in (np.floor(at), np.ceil(at)):
        t = np.clip(index, 0, n) / n  # as sample_segments places its samples
        dx = pts[:, 0, None] - (start[:, 0] + d[:, 0] * t)
        dy = pts[:, 1, None] - (start[:, 1] + d[:, 1] * t)
        nearest = np.minimum(nearest, np.sqrt(dx * dx + dy * dy).min(axis=1))
    return np.where(nearest < upper, nearest, np.inf)


def wall_line_width(parse: LayerParse, mesh: str) -> float | None:
    """Centre distance between the outer wall and the first inner wall, mm.

    Cura puts the first inner wall (w0 + wx) / 2 inside the outer one; with
    equal widths that is the line width.  None without both walls.  Measured
    from the outer wall's samples to the nearest inner wall.
    """
    m = parse.moves
    in_mesh = parse.mesh_mask(mesh)
    moved = (m["x1"] != m["x0"]) | (m["y1"] != m["y0"])
    extr = in_mesh & moved & (m["de"] > 0)
    outer = _segments_of(runs_of(parse, extr & (m["kind"] == WALL_OUTER)))
    inner = _segments_of(runs_of(parse, extr & (m["kind"] == WALL_INNER)))
    if len(outer) == 0 or len(inner) == 0:
        return None
    # From the outer wall's samples to the nearest inner wall: that is the first inner wall however many
    # walls lie further in (from the inner walls' samples out, the median read 0.8 mm for 4 walls of 0.4
    # mm), and a fuzzy-skin outer wall's jitter evens out round it
    d = nearest_sample_distance(inner, 0.02, sample_segments(outer, 0.5), 3.0)
    d = d[np.isfinite(d)]
    if d.size < 5:
        return None
    w = float(np.median(d))
    return w if 0.05 <= w <= 3.0 else None


_SKIN_LINE_WIDTH_MAX = 2.0  # mm: skin lines further apart do not tell a line width
_SKIN_SAMPLE_STEP = 0.5  # mm between the samples that find a midpoint's nearby moves


def _nearest_other_move(points: np.ndarray, moves: np.ndarray, left_out: np.ndarray, reach: float) -> np.ndarray:
    """Distance from each point to the nearest move not left out for it; inf from `reach` on.

    The moves near each point are found through a tree of their samples
    (`_SKIN_SAMPLE_STEP` apart, so a move within `reach` has a sample within
    ``reach + step``), then measured exactly: memory grows with the pairs
    found, not with points x moves (a curved bottom skin has tens of thousands
    of moves: a points x moves matrix would take hundreds of MB).

    Parameters
    ----------
    points : ndarray, shape (p, 2)
        mm.
    moves : ndarray, shape (k, 2, 2)
        mm.
    left_out : ndarray of int, shape (p, j)
        Indices into `moves` each point does not measure to (-1: none).
    reach : float
        mm.

    Returns
    -------
    ndarray, shape (p,)
    """
    nearest = np.full(len(points), np.inf)
    if len(points) == 0 or len(moves) == 0:
        return nearest
    samples, owner = segment_samples(moves, _SKIN_SAMPLE_STEP)
    pairs = cKDTree(points).sparse_distance_matrix(
        cKDTree(samples, balanced_tree=False, compact_nodes=False), reach + _SKIN_SAMPLE_STEP, output_type="ndarray")
    if len(pairs) == 0:
        return nearest
    key = np.unique(pairs["i"].astype(np.int64) * len(moves) + owner[pairs["j"]])
    point, move = key // len(moves), key % len(moves)
    keep = ~(left_out[point] == move[:, None]).any(axis=1)
    point, move = point[keep], move[keep]
    a = moves[move, 0]
    d = moves[move, 1] - a
    rel = points[point] - a
    t = np.clip((rel * d).sum(axis=1) / np.maximum((d * d).sum(axis=1), 1e-12), 0.0, 1.0)
    np.minimum.at(nearest, point, np.hypot(*(rel - t[:, None] * d).T))
    return np.where(nearest < reach, nearest, np.inf)


def skin_line_width(parse: LayerParse, most: int = 400) -> float | None:
    """Centre distance between neighbouring skin lines, mm: the line width where walls cannot tell it.

    Cura fills top and bottom skin with lines one skin line width apart (and concentric loops the
    same); with a single wall (a 0.6 mm nozzle and Cura's 0.8 mm wall thickness) there is no inner
    wall to measure from.  Measured from the midpoints of up to `most` skin moves of at least 1.5 mm
    (their own ends and the moves joined to them left out) to the nearest other skin move.  Moves
    extruding under 0.6 of the highest E per mm of the long ones (ironing) are left out.  None when fewer than
    10 midpoints agree, or the nearest distances do not cluster (half of them within 10 % of the
    median).

    Parameters
    ----------
    parse : LayerParse
        One layer, every mesh's skin together.
    most : int
        Midpoints measured from at most.

    Returns
    -------
    float or None
        mm.
    """
    m = parse.moves
    dx, dy = m["x1"] - m["x0"], m["y1"] - m["y0"]
    length = np.hypot(dx, dy)
    skin = np.flatnonzero((m["kind"] == SKIN) & (m["de"] > 0) & (length > 1e-6))
    if skin.size < 12:
        return None
    rate = m["de"][skin] / length[skin]
    long_rate = rate[length[skin] >= 1.5]
    if long_rate.size == 0:
        return None
    # (ironing's lines, a tenth of the flow, can outnumber the skin's: the long moves' highest rate is the skin's)
    skin = skin[rate >= 0.6 * float(long_rate.max())]
    start = np.column_stack([m["x0"][skin], m["y0"][skin]])
    end = np.column_stack([m["x1"][skin], m["y1"][skin]])
    long_moves = np.flatnonzero(length[skin] >= 1.5)
    if long_moves.size < 10:
        return None
    chosen = long_moves[np.linspace(0, long_moves.size - 1, min(most, long_moves.size)).astype(np.int64)]
    mid = 0.5 * (start[chosen] + end[chosen])
    # left out for each midpoint: its own move and the moves joined to it in the file (a zigzag's
    # turn, a loop's next piece)
    order = skin[chosen]
    before, after = chosen - 1, chosen + 1
    before = np.where((before >= 0) & (skin[np.maximum(before, 0)] == order - 1), before, -1)
    after = np.where((after < len(skin)) & (skin[np.minimum(after, len(skin) - 1)] == order + 1), after, -1)
    nearest = _nearest_other_move(mid, np.stack([start, end], axis=1), np.stack([chosen, before, after], axis=1),
                                  _SKIN_LINE_WIDTH_MAX)
    nearest = nearest[np.isfinite(nearest) & (nearest >= 0.05)]
    if nearest.size < 10:
        return None
    w = median_of(nearest)
    if not 0.1 <= w <= _SKIN_LINE_WIDTH_MAX or np.mean(np.abs(nearest - w) <= 0.1 * w) < 0.5:
        return None
    return w


def e_per_mm(parse: LayerParse, mask: np.ndarray) -> float | None:
    """Extrusion per mm of path of the masked extruding moves (E units/mm)."""
    m = parse.moves
    dx = m["x1"][mask] - m["x0"][mask]
    dy = m["y1"][mask] - m["y0"][mask]
    length = np.hypot(dx, dy)
    de = m["de"][mask]
    ok = (length > 1e-6) & (de > 0)
    if not ok.any() or length[ok].sum() < 1e-3:
        return None
    return float(de[ok].sum() / length[ok].sum())


def family_spacings(fill: np.ndarray, line_width: float, quantile: float = 0.5) -> list[float] | None:
    """Spacing of each family of parallel lines in Cura's FILL, mm; None when the lines form no clear families.

    Line patterns (lines, grid, triangles, cubic, ...) print one to four
    families of parallel lines; gyroid, concentric and lightning do not.

    Parameters
    ----------
    fill : ndarray, shape (k, 2, 2)
        FILL segments, mm.
    line_width : float
        mm.
    quantile : float
        Which of a family's gaps between neighbouring lines: the median (its
        spacing), or a larger one (0.9: the wide gaps, where lines come in
        groups, as with Cura's infill line multiplier, or spacings differ, as
        with gradual infill).
    """
    if len(fill) < 4:
        return None
    length, ang, families, total = direction_peaks(fill, 0.12)
    members = []
    for fam in families:
        delta = np.abs(np.mod(ang - 2.0 * fam + 90.0, 180.0) - 90.0)
        members.append(delta <= 3.5)
    covered = length[np.any(members, axis=0)].sum() / total if members and total > 0 else 0.0
    if not (covered > 0.85 and 1 <= len(families) <= 4):
        return None
    spacings = []
    for sel in members:
        weight = length[sel]
        theta = np.radians((ang[sel] * weight).sum() / weight.sum())  # np.average, without its overhead
        normal = np.array([-np.sin(theta), np.cos(theta)])
        mid = 0.5 * (fill[sel, 0] + fill[sel, 1])
        off = np.sort(np.round(mid @ normal, 2))
        off = off[np.concatenate(([True], off[1:] != off[:-1]))]  # np.unique
        gaps = np.diff(off)
        gaps = gaps[gaps > 0.5 * line_width]
        if gaps.size < 2:
            return None
        spacings.append(_grouped_spacing(gaps, line_width) if quantile == 0.5 else _quantile(gaps, quantile))
    return spacings


def _grouped_spacing(gaps: np.ndarray, line_width: float) -> float:
    """A family's spacing from the gaps (mm) between its neighbouring lines: their median, or for lines
    in groups (Cura's infill line multiplier m prints each line m times a line width apart) the group's
    pitch over m, so that ``line_width / spacing`` is still the family's share of the density.

    Groups show as gaps of about a line width (m - 1 per group) among wide ones (one per group); the
    median alone would read a pair's own gap as the spacing (a 40 % grid of pairs as 200 %).
    """
    narrow = gaps <= 1.25 * line_width
    n_narrow, n_wide = int(np.count_nonzero(narrow)), int(np.count_nonzero(~narrow))
    if n_wide < 2 or n_narrow < 0.3 * n_wide:  # plain lines (or 100 %: every gap a line width)
        return median_of(gaps)
    # lines in a group: all the lines over the groups (one wide gap fewer than groups)
    per_group = max(2, int(round((n_narrow + n_wide + 1) / (n_wide + 1))))
    pitch = median_of(gaps[~narrow]) + (per_group - 1) * median_of(gaps[narrow])
    return pitch / per_group


def infill_density(fill: np.ndarray, line_width: float, area: float | None = None) -> float | None:
    """Cura's infill density from its FILL lines (fraction).

    A family of parallel lines with spacing s adds ``line_width / s`` to the
    density (`family_spacings`).  When no clear families exist,
    ``length * line_width / area`` is used.

    Parameters
    ----------
    fill : ndarray, shape (k, 2, 2)
        FILL segments, mm.
    line_width : float
    area : float, optional
        Infill area mm² for the fallback.
    """
    if len(fill) < 4:
        return None
    spacings = family_spacings(fill, line_width)
    if spacings is not None:
        density = sum(line_width / s for s in spacings)
        if 0.0 < density <= 1.0:
            return float(density)
    if area and area > 0:
        d = fill[:, 1] - fill[:, 0]
        return float(min(1.0, np.hypot(d[:, 0], d[:, 1]).sum() * line_width / area))
    return None


def _quantile(values: np.ndarray, q: float) -> float:
    """``np.quantile(values, q)`` (linear interpolation) of a 1-d array, without its overhead."""
    ordered = np.sort(values)
    at = q * (len(ordered) - 1)
    lo = int(math.floor(at))
    hi = min(lo + 1, len(ordered) - 1)
    a, b, t = float(ordered[lo]), float(ordered[hi]), at - lo
    # (as numpy interpolates: from the nearer end, so the value is exact at both)
    return b - (b - a) * (1.0 - t) if t >= 0.5 else a + (b - a) * t
