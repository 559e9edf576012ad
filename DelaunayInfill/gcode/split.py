"""Splitting a host's infill area between it and its infill-mesh modifiers, from the G-code alone.

Cura cuts every infill-mesh modifier's part out of its host's infill area and clips each mesh's
infill lines to its own part, so the lines' ends mark the borders between meshes:

* each modifier holds the area between its neighbouring parallel lines, grown by how far inside its
  part Cura ends a line, plus the other meshes' line ends on its border (their convex hull where
  that hull is mostly filled already); later modifiers win where two hold the same place;
* the gap no modifier holds is shared out on a grid: to the host where its lines are nearer (in
  line spacings), else to the modifier whose held part is nearest (`_GapOwner`, `_gap_owners`);
* patterns without families of parallel lines (gyroid, concentric) are measured to their lines.

`split_by_lines` is the older nearest-line split of the whole area (borders up to half a spacing
off), kept for a host alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from shapely.geometry import MultiPolygon, Polygon

from ..geometry import (
    boundary_segments,
    boxes_meet,
    contains_xy,
    convex_hull_of,
    distances,
    empty_area,
    points_on_surface,
    polygonize_segments,
    polygons_from,
    polygons_of,
    to_multipolygon,
    unary_union,
)
from .area import direction_peaks, sample_segments, valid_area

__all__ = ["split_by_lines", "split_by_line_ends", "line_families", "between_lines", "span_pieces"]

_GAP_COARSE = 4  # the gap's owners are asked first on cells this many grid steps wide


@dataclass
class _OwnerGrid:
    """Which mesh's lines are nearest (in units of its spacing) at the centres of a grid's cells.

    ``owner`` (rows, cols): mesh index, -1 away from the area; cell (i, j) spans
    x from ``x0 + j * step``, y from ``y0 + i * step``.  ``centred`` (rows,
    cols): whether the cell's centre lies in the area (None: where ``owner``
    is set).  Cells next to such a cell have an owner too: the area's border
    runs through them.
    """

    x0: float
    y0: float
    step: float
    owner: np.ndarray
    centred: np.ndarray | None = None

    def _cells(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row and column of the cell under each point (p, 2), and whether it lies on the grid."""
        j = np.floor((pts[:, 0] - self.x0) / self.step).astype(np.int64)
        i = np.floor((pts[:, 1] - self.y0) / self.step).astype(np.int64)
        rows, cols = self.owner.shape
        return i, j, (i >= 0) & (i < rows) & (j >= 0) & (j < cols)

    def at(self, pts: np.ndarray) -> np.ndarray:
        """Owner at points (p, 2); -1 outside the grid or in a cell whose centre is outside the area."""
        i, j, ok = self._cells(pts)
        if self.centred is not None:
            ok[ok] = self.centred[i[ok], j[ok]]
        out = np.full(len(pts), -1, dtype=np.int64)
        out[ok] = self.owner[i[ok], j[ok]]
        return out

    def centres(self) -> np.ndarray:
        """Cell centres, shape (rows, cols, 2)."""
        rows, cols = self.owner.shape
        gx, gy = np.meshgrid(self.x0 + (np.arange(cols) + 0.5) * self.step, self.y0 + (np.arange(rows) + 0.5) * self.step)
        return np.stack([gx, gy], axis=-1)

    def polygon(self, mask: np.ndarray):
        """The cells where `mask` (rows, cols) holds, as one area (exactly those cells, corners on the grid)."""
        if not mask.any():
            return empty_area()
        return self.regions(np.where(mask, 0, -1), 1)[0][0]

    def regions(self, labels: np.ndarray, count: int) -> tuple[list, object]:
        """The cells of each label as one area each, and the free cells' area, in one pass.

        The borders between cells of different labels are traced on the grid
        lines (straight runs merged, broken where more than two border edges
        meet) inside a frame one cell beyond the grid, and their faces are
        built once; each face is the cells of one label.  Far cheaper than a
        union of rectangles per label.

        Parameters
        ----------
        labels : ndarray of int, shape (rows, cols)
            Label per cell, 0 .. count - 1, or -1 for a free cell.
        count : int

        Returns
        -------
        parts : list of MultiPolygon
            One per label (empty where it has no cell), mm.
        free : MultiPolygon
            The free cells and the ring of cells round the grid (the frame).
        """
        rows, cols = labels.shape
        cell = np.pad(labels, 1, constant_values=-1)  # cell[i + 1, j + 1] is labels[i, j]
        across = cell[1:, :] != cell[:-1, :]  # border edges on horizontal grid lines (rows + 1, cols + 2)
        along = cell[:, 1:] != cell[:, :-1]  # border edges on vertical grid lines (rows + 2, cols + 1)
        # Border edges meeting at each grid corner (rows + 1, cols + 1): a straight run goes on only
        # through a corner where it is alone.
        meeting = (across[:, :-1].astype(np.int8) + across[:, 1:] + along[:-1, :] + along[1:, :])
        single = meeting == 2
        segments = []
        for axis, (edge, through) in enumerate(((across, single), (along.T, single.T))):
            joined = np.zeros_like(edge)
            joined[:, 1:] = edge[:, 1:] & edge[:, :-1] & through
            goes_on = np.zeros_like(edge)
            goes_on[:, :-1] = joined[:, 1:]
            line, first = np.nonzero(edge & ~joined)
            _, last = np.nonzero(edge & ~goes_on)  # row-major: the i-th end closes the i-th run
            # grid-corner indices (x, y) of the run's ends; the padded first column/row is index -1
            ends = np.stack([np.stack([first - 1, line], axis=1), np.stack([last, line], axis=1)], axis=1)
            segments.append(ends if axis == 0 else ends[..., ::-1])
        frame = np.array([[-1, -1], [cols + 1, -1], [cols + 1, rows + 1], [-1, rows + 1]])
        segments.append(np.stack([frame, np.roll(frame, -1, axis=0)], axis=1))
        corners = np.concatenate(segments)
        xy = np.empty(corners.shape)
        xy[..., 0] = self.x0 + corners[..., 0] * self.step
        xy[..., 1] = self.y0 + corners[..., 1] * self.step
        faces = polygonize_segments(xy)
        # Each face holds the cells of one label: a point inside it tells which.
        i, j, ok = self._cells(points_on_surface(faces))
        face_label = np.full(len(faces), -1, dtype=np.int64)
        face_label[ok] = labels[i[ok], j[ok]]
        groups: list[list] = [[] for _ in range(count + 1)]  # the last: free
        for face, label in zip(faces, face_label.tolist(), strict=True):
            groups[label].append(face)
        return [MultiPolygon(g) for g in groups[:-1]], MultiPolygon(groups[-1])


def _inside_lattice(area, xs: np.ndarray, ys: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Whether each lattice point (xs[j], ys[i]) lies inside `area`, shape (len(ys), len(xs)).

    Even-odd rule along each row of points: the border's edges are cut by
    every row they span (half-open in y) and a point is inside when an odd
    number of cuts lie left of it.  The few points within `tol` of a cut, a
    horizontal edge or a corner (where rounding could tip the count, and a
    grid's points can fall on a box's edges) are tested by shapely, so the
    answer is shapely's point-in-area test.  `xs`, `ys` increasing, mm.
    """
    inside = np.zeros((len(ys), len(xs)), dtype=bool)
    edges = boundary_segments(area)
    if len(edges) == 0 or len(xs) == 0 or len(ys) == 0:
        return inside
    (xa, ya), (xb, yb) = edges[:, 0].T, edges[:, 1].T
    first = np.searchsorted(ys, np.minimum(ya, yb), side="left")  # rows with min(ya, yb) <= y < max(ya, yb)
    count = np.searchsorted(ys, np.maximum(ya, yb), side="left") - first
    edge = np.repeat(np.arange(len(edges)), count)
    row = np.repeat(first, count) + np.arange(edge.size) - np.repeat(np.cumsum(count) - count, count)
    y = ys[row]
    x = xa[edge] + (y - ya[edge]) * (xb[edge] - xa[edge]) / (yb[edge] - ya[edge])
    col = np.searchsorted(xs, x, side="right")  # the first point right of the cut
    flips = np.bincount(row * (len(xs) + 1) + col, minlength=len(ys) * (len(xs) + 1)).reshape(len(ys), len(xs) + 1)
    inside = (np.cumsum(flips[:, :-1], axis=1) & 1).astype(bool)
    # Points the count cannot settle: next to a cut, or on a row through a horizontal edge or a corner.
    unsure = np.zeros((len(ys), len(xs) + 1), dtype=np.int64)
    for side in (col - 1, col):
        close = (side >= 0) & (side < len(xs))
        close[close] = np.abs(xs[side[close]] - x[close]) <= tol
        unsure[row[close], side[close]] += 1
        unsure[row[close], side[close] + 1] -= 1
    level = np.r_[ya[ya == yb], ya]  # horizontal edges, then every corner
    lo = np.r_[np.minimum(xa, xb)[ya == yb], xa]
    hi = np.r_[np.maximum(xa, xb)[ya == yb], xa]
    rows_from = np.searchsorted(ys, level - tol, side="left")
    rows_to = np.searchsorted(ys, level + tol, side="right")
    for offset in range(int((rows_to - rows_from).max(initial=0))):  # rows within tol of a level: at most a few
        on = rows_from + offset < rows_to
        r = rows_from[on] + offset
        np.add.at(unsure, (r, np.searchsorted(xs, lo[on] - tol, side="left")), 1)
        np.add.at(unsure, (r, np.searchsorted(xs, hi[on] + tol, side="right")), -1)
    check_row, check_col = np.nonzero(np.cumsum(unsure[:, :-1], axis=1) > 0)
    if check_row.size:
        inside[check_row, check_col] = contains_xy(area, xs[check_col], ys[check_row])
    return inside


def _in_box(pts: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Indices of the points (p, 2) inside the box from corner `lo` (2,) to `hi` (2,), borders included."""
    return np.flatnonzero((pts[:, 0] >= lo[0]) & (pts[:, 0] <= hi[0]) & (pts[:, 1] >= lo[1]) & (pts[:, 1] <= hi[1]))


def _owner_grid(area, fills: list[np.ndarray], spacings: list[float], step: float) -> _OwnerGrid | None:
    """The nearest-line owner grid of `split_by_lines` (None: no area or no lines).

    Every cell whose centre lies in `area`, or next to one that does, gets
    the mesh whose lines are nearest its centre (in line spacings).
    """
    if area.is_empty or not any(len(f) for f in fills):
        return None
    minx, miny, maxx, maxy = area.bounds
    step = max(step, np.sqrt((maxx - minx) * (maxy - miny) / 60000.0))
    xs, ys = np.arange(minx + step / 2, maxx, step), np.arange(miny + step / 2, maxy, step)
    centred = _inside_lattice(area, xs, ys)
    # The cells round those too (the area's border runs through them): owned cells reach past the
    # border, so cutting them to the area leaves no staircase of free cells along it (a host sliver
    # at every step, each cut out and handed to a modifier in turn).
    owned = _grown(centred).ravel()
    grid = np.full((len(ys), len(xs)), -1, dtype=np.int64)
    rows, cols = np.divmod(np.flatnonzero(owned), len(xs))
    pts = np.column_stack([xs[cols], ys[rows]])
    if len(pts):
        # Distances in line spacings.  A first pass looks no further than `bound` spacings (far
        # cheaper); only where no mesh's lines are that near are all distances measured in full.
        # Nearer than the bound beats anything beyond it, so the owners are those of a full search.
        bound = 1.0
        dist = np.full((len(fills), len(pts)), np.inf)
        samples = [sample_segments(fill, step / 2) for fill in fills]
        trees = [cKDTree(s) if len(s) else None for s in samples]
        for k, (tree, spacing) in enumerate(zip(trees, spacings, strict=True)):
            if tree is not None:
                # Points beyond the bound from the lines' bounding box are beyond it from the lines.
                reach = bound * spacing
                lo, hi = samples[k].min(axis=0) - reach, samples[k].max(axis=0) + reach
                near = _in_box(pts, lo, hi)
                dist[k, near] = tree.query(pts[near], distance_upper_bound=reach)[0] / spacing
        far = ~(dist.min(axis=0) < 0.99 * bound)  # 0.99: clear of rounding at the bound
        if far.any():
            for k, (tree, spacing) in enumerate(zip(trees, spacings, strict=True)):
                if tree is not None:
                    dist[k, far] = tree.query(pts[far])[0] / spacing
        grid.ravel()[owned] = np.argmin(dist, axis=0)
    return _OwnerGrid(minx, miny, step, grid, centred)


def split_by_lines(area, fills: list[np.ndarray], spacings: list[float], step: float = 0.5) -> list:
    """Split `area` among meshes by whose FILL lines are nearest, in units of each one's line spacing.

    Cura cuts infill-mesh modifiers out of their host's infill, so the lines of
    neighbouring meshes end on their common border; comparing distances in
    units of line spacing puts the border between them.  Evaluated on a grid of
    `step` mm (coarser for large areas: at most ~60k probes).

    Parameters
    ----------
    area : (Multi)Polygon
        The host's infill area (includes the modifiers' parts).
    fills : list of ndarray, each shape (k, 2, 2)
        Cura's FILL segments per mesh, mm (may be empty).
    spacings : list of float
        Line spacing per mesh (line width / Cura's density), mm.

    Returns
    -------
    list of MultiPolygon
        One per mesh, in the order given.
    """
    grid = _owner_grid(area, fills, spacings, step)
    if grid is None:
        return [empty_area() for _ in fills]
    parts, _ = grid.regions(grid.owner, len(fills))
    return [to_multipolygon(p.intersection(area)) if not p.is_empty else empty_area() for p in parts]


def line_families(fill: np.ndarray, min_share: float = 0.12, max_families: int = 4) -> list[tuple[float, np.ndarray]]:
    """Families of parallel lines among FILL segments (lines, grid, triangles patterns).

    Parameters
    ----------
    fill : ndarray, shape (k, 2, 2)
        Segments, mm.
    min_share : float
        A family holds at least this share of the total length.

    Returns
    -------
    list of (float, ndarray of bool)
        Per family its direction (radians, in [0, pi)) and which segments
        belong to it; empty when the segments form no clear families (gyroid,
        concentric: fewer than 85 % of the length in families).
    """
    if len(fill) < 4:
        return []
    length, ang, peaks, total = direction_peaks(fill, min_share)
    if total <= 0:
        return []
    out = []
    covered = np.zeros(len(fill), dtype=bool)
    for fam in peaks:
        delta = np.abs(np.mod(ang - 2.0 * fam + 90.0, 180.0) - 90.0)
        member = (delta <= 3.5) & ~covered
        if not member.any():
            continue
        covered |= member
        # Mean direction of the members (doubled angles: 179 and 1 degrees average to 0).
        doubled = np.radians(2.0 * ang[member])
        theta = 0.5 * np.arctan2((length[member] * np.sin(doubled)).sum(), (length[member] * np.cos(doubled)).sum())
        out.append((float(np.mod(theta, np.pi)), member))
    if not out or len(out) > max_families or length[covered].sum() < 0.85 * total:
        return []
    return out


def span_pieces(fills: list[np.ndarray], max_gap_factor: float = 1.6) -> list[list | None]:
    """The pieces of `between_lines` of several meshes at once, not yet united.

    All families of all meshes are handled in one pass of array operations
    (a mesh's lines are a few dozen segments: per-call overhead would
    dominate).  Per mesh a list of polygons whose union is its
    `between_lines` (the runs and quadrilaterals may overlap), an empty list
    when its families span nothing, or None when its lines form no clear
    families (or it has none).

    Parameters
    ----------
    fills : list of ndarray, each shape (k, 2, 2)
        FILL segments per mesh, mm.
    max_gap_factor : float
        Neighbouring lines at most this many times their family's spacing apart span an area.

    Returns
    -------
    list of (list of Polygon or None)
        One entry per mesh, mm.
    """
    out: list[list | None] = [None] * len(fills)
    chosen, theta = [], []
    for m, fill in enumerate(fills):
        families = line_families(fill) if len(fill) else []
        if families:
            out[m] = []
        for angle, member in families:
            chosen.append((m, np.flatnonzero(member)))
            theta.append(angle)
    if not chosen:
        return out
    mesh_of_family = np.array([m for m, _ in chosen])
    seg = np.concatenate([fills[m][idx] for m, idx in chosen])
    family = np.repeat(np.arange(len(chosen)), [len(idx) for _, idx in chosen])
    u_all = np.column_stack([np.cos(theta), np.sin(theta)])
    u, n = u_all[family], np.column_stack([-u_all[family, 1], u_all[family, 0]])
    offset = 0.5 * ((seg[:, 0, 0] + seg[:, 1, 0]) * n[:, 0] + (seg[:, 0, 1] + seg[:, 1, 1]) * n[:, 1])
    along_a = seg[:, 0, 0] * u[:, 0] + seg[:, 0, 1] * u[:, 1]
    along_b = seg[:, 1, 0] * u[:, 0] + seg[:, 1, 1] * u[:, 1]
    lo, hi = np.minimum(along_a, along_b), np.maximum(along_a, along_b)
    order = np.lexsort((lo, offset, family))
    offset, lo, hi, family = offset[order], lo[order], hi[order], family[order]
    # Pieces on one line share its family and offset (within 0.05 mm).
    new_line = np.ones(len(offset), dtype=bool)
    new_line[1:] = (family[1:] != family[:-1]) | (offset[1:] - offset[:-1] > 0.05)
    starts = np.flatnonzero(new_line)
    counts = np.diff(np.append(starts, len(offset)))
    line_off, line_family = offset[starts], family[starts]
    gaps = line_off[1:] - line_off[:-1]
    within = line_family[1:] == line_family[:-1]  # gap i lies between lines i and i + 1 of one family
    # Each family's spacing: the median of its gaps (as `median_of`: the mean of the two middle ones).
    gap_family = line_family[:-1][within]
    ordered = np.lexsort((gaps[within], gap_family))
    sorted_gaps = gaps[within][ordered]
    per_family = np.bincount(gap_family, minlength=len(chosen))
    first = np.cumsum(per_family) - per_family
    has = per_family > 0
    spacing = np.full(len(chosen), np.inf)
    spacing[has] = 0.5 * (sorted_gaps[(first + (per_family - 1) // 2)[has]] + sorted_gaps[(first + per_family // 2)[has]])
    # Every pair of pieces on neighbouring lines (close enough), line by line, row-major within a pair of lines.
    pairs = np.flatnonzero(within & (gaps <= max_gap_factor * spacing[line_family[:-1]]))
    per_pair = counts[pairs] * counts[pairs + 1]
    line = np.repeat(pairs, per_pair)
    rank = np.arange(per_pair.sum()) - np.repeat(np.cumsum(per_pair) - per_pair, per_pair)
    ia = starts[line] + rank // counts[line + 1]
    ib = starts[line + 1] + rank % counts[line + 1]
    # Pieces of the two lines whose along-ranges overlap face each other.
    facing = (lo[ia] < hi[ib]) & (lo[ib] < hi[ia])
    ia, ib, line = ia[facing], ib[facing], line[facing]
    if ia.size == 0:
        return out
    u_line, n_line = u_all[line_family], np.column_stack([-u_all[line_family, 1], u_all[line_family, 0]])
    # Where neighbouring lines are one piece each, consecutive quadrilaterals share a whole side: a
    # run of them is one polygon, up one end of the lines and down the other.  A run never leaves
    # its family (pairs are within one).
    single = (counts[line] == 1) & (counts[line + 1] == 1) & (hi[ia] - lo[ia] > 1e-9) & (hi[ib] - lo[ib] > 1e-9)
    chained = line[single]
    if chained.size:
        run_start = np.flatnonzero(np.r_[True, chained[1:] != chained[:-1] + 1])
        run_stop = np.r_[run_start[1:], chained.size]
        for a, b in zip(chained[run_start].tolist(), (chained[run_stop - 1] + 2).tolist(), strict=True):
            at = starts[a:b]
            uu, nn, off = u_line[a], n_line[a], line_off[a:b, None]
            up = lo[at, None] * uu + off * nn
            down = hi[at, None] * uu + off * nn
            out[mesh_of_family[line_family[a]]].append(Polygon(np.concatenate([up[:1], down, up[:0:-1]])))
    ia, ib, line = ia[~single], ib[~single], line[~single]
    if ia.size:
        uu, nn = u_line[line][:, None, :], n_line[line][:, None, :]
        oa, ob = line_off[line][:, None, None], line_off[line + 1][:, None, None]
        ends = np.stack([lo[ia], hi[ia], hi[ib], lo[ib]], axis=1)[:, :, None]  # (q, 4, 1)
        side = np.stack([oa[:, 0], oa[:, 0], ob[:, 0], ob[:, 0]], axis=1)  # (q, 4, 1)
        corners = ends * uu + side * nn
        for mesh, quad in zip(mesh_of_family[line_family[line]].tolist(), polygons_from(corners), strict=True):
            out[mesh].append(quad)
    return out


def _united(pieces: list):
    """The union of polygons as a MultiPolygon (None for None)."""
    if pieces is None:
        return None
    if not pieces:
        return None
    # two pieces (one run per family, the usual case): a plain union is cheaper than a cascaded one
    return to_multipolygon(pieces[0].union(pieces[1]) if len(pieces) == 2 else unary_union(pieces))


def between_lines(fill: np.ndarray, max_gap_factor: float = 1.6):
    """The area swept between neighbouring parallel lines, bounded by chords through their ends.

    Cura clips each family of parallel infill lines to the infill area, so
    the ends of neighbouring lines lie on the area's border: the chord
    between them follows a straight border exactly (where the nearest-line
    split of `split_by_lines` is biased by the spacings).  For each family,
    every pair of overlapping pieces on neighbouring lines (at most
    `max_gap_factor` x the family's spacing apart) spans a quadrilateral;
    the union of all of them is returned (`span_pieces`, united).

    Parameters
    ----------
    fill : ndarray, shape (k, 2, 2)
        One mesh's FILL segments, mm.

    Returns
    -------
    MultiPolygon or None
        None when the lines form no clear families (or span nothing).
    """
    return _united(span_pieces([fill], max_gap_factor)[0])


def _distance_to(area, pts: np.ndarray, step: float = 0.1) -> np.ndarray:
    """Distance (mm) from points (p, 2) to `area`: 0 inside, else to its boundary (to within `step`)."""
    edges = boundary_segments(area)
    if len(edges) == 0:
        return np.full(len(pts), np.inf)
    dist = cKDTree(sample_segments(edges, step)).query(pts)[0]
    return np.where(contains_xy(area, pts[:, 0], pts[:, 1]), 0.0, dist)


def _squared_distances(pts: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Squared distance (mm^2) from each point (p, 2) to each segment (k, 2, 2), shape (p, k)."""
    start = segments[:, 0]
    d = segments[:, 1] - start
    length2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    rel_x, rel_y = pts[:, 0, None] - start[:, 0], pts[:, 1, None] - start[:, 1]  # (p, k)
    t = np.clip((rel_x * d[:, 0] + rel_y * d[:, 1]) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    ex, ey = rel_x - t * d[:, 0], rel_y - t * d[:, 1]
    return ex * ex + ey * ey


def _segment_distances(pts: np.ndarray, segments: np.ndarray, sample_step: float) -> np.ndarray:
    """Distance (mm) from each point (p, 2) to the nearest of `segments` (k, 2, 2), shape (p,).

    Exact, point by segment, for up to a few million pairs; beyond that to
    the nearest of the segments' samples `sample_step` mm apart (a tree).
    """
    if len(pts) * len(segments) > 2_000_000:
        return cKDTree(sample_segments(segments, sample_step)).query(pts)[0]
    return np.sqrt(_squared_distances(pts, segments).min(axis=1))


def _nearest_mesh(pts: np.ndarray, fills: list[np.ndarray], spacings: list[float], sample_step: float,
                  bound: float = 2.0) -> np.ndarray:
    """Index of the mesh whose lines are nearest each point (p, 2), in units of its line spacing; -1: no lines.

    Few points and lines are measured all at once.  Otherwise a first pass
    measures each mesh's distances only at the points within `bound`
    spacings of its lines' bounding box, and where no mesh is that near,
    all distances are measured: nearer than the bound beats anything beyond
    it, so the owners are those of a full search.  Ties go to the first mesh.
    """
    owner = np.full(len(pts), -1, dtype=np.int64)
    meshes = [k for k, fill in enumerate(fills) if len(fill)]
    if len(pts) == 0 or not meshes:
        return owner
    sizes = [len(fills[k]) for k in meshes]
    if len(pts) * sum(sizes) <= 8_000:
        scaled = _squared_distances(pts, np.concatenate([fills[k] for k in meshes]))
        scaled *= np.repeat([1.0 / spacings[k] ** 2 for k in meshes], sizes)
        per_mesh = np.minimum.reduceat(scaled, np.cumsum(sizes) - sizes, axis=1)
        return np.asarray(meshes)[np.argmin(per_mesh, axis=1)]
    best = np.full(len(pts), np.inf)

    def closer(k: int, at: np.ndarray) -> None:
        dist = _segment_distances(pts[at], fills[k], sample_step) / spacings[k]
        near = dist < best[at]
        best[at[near]], owner[at[near]] = dist[near], k

    for k in meshes:
        reach = bound * spacings[k]
        lo, hi = fills[k].min(axis=(0, 1)) - reach, fills[k].max(axis=(0, 1)) + reach
        closer(k, _in_box(pts, lo, hi))
    far = np.flatnonzero(~(best < 0.99 * bound))  # 0.99: clear of rounding at the bound
    if far.size:
        best[far], owner[far] = np.inf, -1
        for k in meshes:
            closer(k, far)
    return owner


def _border_ends(fills: list[np.ndarray], spacings: list[float], owns: list, area, end_inset: float,
                 probe: float, sample_step: float) -> list[np.ndarray]:
    """Per mesh k >= 1: the line ends of the other meshes that lie on its border, mm (p, 2).

    Each line is continued `probe` mm beyond its end; ends whose continuation
    leaves `area` lie on its outer border and are never counted.  The host's
    lines (j = 0) end only on its outer border or on a modifier's border:
    such an end goes to the modifier whose lines' span (`owns`) is nearest,
    within its line spacing.  A modifier's line end goes to modifier k when
    k's lines are the nearest to its continuation (in line spacings,
    `_nearest_mesh`); it ends `end_inset` before the border and is moved there.
    """
    out = [np.zeros((0, 2)) for _ in fills]
    segments = np.concatenate(fills)
    source = np.repeat(np.arange(len(fills)), [len(f) for f in fills])
    d = segments[:, 1] - segments[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    ok = length > 1e-6
    u = d[ok] / length[ok, None]
    ends = np.concatenate([segments[ok, 1], segments[ok, 0]])
    outward = np.concatenate([u, -u])
    source = np.concatenate([source[ok], source[ok]])
    beyond = ends + probe * outward
    inside = contains_xy(area, beyond[:, 0], beyond[:, 1])
    ends, outward, beyond, source = ends[inside], outward[inside], beyond[inside], source[inside]
    hosts = source == 0
    if hosts.any():
        dist = np.full((len(fills), int(hosts.sum())), np.inf)
        for k in range(1, len(fills)):
            if owns[k] is not None and not owns[k].is_empty:
                dist[k] = _distance_to(owns[k], beyond[hosts])
                dist[k][dist[k] > spacings[k]] = np.inf
        best = np.argmin(dist, axis=0)
        found = np.isfinite(dist[best, np.arange(len(best))])
        for k in range(1, len(fills)):
            out[k] = ends[hosts][found & (best == k)]
    if (~hosts).any():
        border = ends[~hosts] + end_inset * outward[~hosts]
        owner = _nearest_mesh(beyond[~hosts], fills, spacings, sample_step)
        for k in range(1, len(fills)):
            hit = (owner == k) & (source[~hosts] != k)
            if hit.any():
                out[k] = np.concatenate([out[k], border[hit]])
    return out


def _grid_step(area, step: float) -> float:
    """The nearest-line grid's step, mm: `step`, coarser for large areas (at most ~60k cells)."""
    minx, miny, maxx, maxy = area.bounds
    return max(step, float(np.sqrt((maxx - minx) * (maxy - miny) / 60000.0)))


class _GapOwner:
    """Which mesh a point of the gap between the held parts goes to.

    The host or a modifier as the nearest lines say (in line spacings,
    `_nearest_mesh`): the host's sparse lines reach into the corners its
    span cuts.  Among the modifiers, the one whose held part is nearest in
    its line spacings, within one spacing: a sparse modifier's hull misses
    more of its corners than a dense one's.  A modifier whose lines form no
    families (nothing held) is measured to its lines.  Without host lines,
    a point no held part is that near goes to the nearest in spacings.

    Parameters
    ----------
    fills : list of ndarray, each shape (k, 2, 2)
        FILL segments per mesh, index 0 the host, mm.
    spacings : list of float
        Line spacing per mesh, mm.
    held : list of MultiPolygon
        What each modifier holds (index 0 unused), mm.
    sample_step : float
        Borders and lines are measured to samples this far apart, mm.
    """

    def __init__(self, fills: list[np.ndarray], spacings: list[float], held: list, sample_step: float):
        self.fills, self.spacings, self.sample_step = fills, spacings, sample_step
        self.modifiers, self.trees = [], []
        for k in range(1, len(fills)):
            if not held[k].is_empty:
                samples = sample_segments(boundary_segments(held[k]), sample_step)
            elif len(fills[k]):
                samples = sample_segments(fills[k], sample_step)
            else:
                continue
            self.modifiers.append(k)
            self.trees.append(cKDTree(samples))

    def __call__(self, pts: np.ndarray) -> np.ndarray:
        """Owner (mesh index) of each point (p, 2), shape (p,)."""
        host_has_lines = len(self.fills[0]) > 0
        owner = _nearest_mesh(pts, self.fills, self.spacings, self.sample_step) if host_has_lines else None
        ask = np.flatnonzero(owner >= 1) if host_has_lines else np.arange(len(pts))
        found = np.zeros(ask.size, dtype=bool)
        if ask.size and self.trees:
            at = pts[ask]
            dist = np.full((len(self.trees), ask.size), np.inf)
            for row, (tree, k) in enumerate(zip(self.trees, self.modifiers, strict=True)):
                # only the points within reach of the samples' box can be within reach of them
                reach = self.spacings[k]
                lo, hi = tree.mins - reach, tree.maxes + reach
                near = _in_box(at, lo, hi)
                if near.size:
                    dist[row, near] = tree.query(at[near], distance_upper_bound=reach)[0] / reach
            best = np.argmin(dist, axis=0)
            found = np.isfinite(dist[best, np.arange(ask.size)])
        if owner is None:  # no host lines: a point no held part is near goes to the nearest one
            owner = np.empty(len(pts), dtype=np.int64)
            rest = ask[~found]
            if rest.size and self.trees:
                far = np.stack([tree.query(pts[rest])[0] / self.spacings[k] for tree, k in zip(self.trees, self.modifiers, strict=True)])
                owner[rest] = np.asarray(self.modifiers)[np.argmin(far, axis=0)]
            elif rest.size:
                owner[rest] = _nearest_mesh(pts[rest], self.fills, self.spacings, self.sample_step)
        if found.any():
            owner[ask[found]] = np.asarray(self.modifiers)[best[found]]
        return owner


def _gap_owners(gap, owner_of, x0: float, y0: float, step: float, coarse: int = 4) -> _OwnerGrid:
    """The owners of the cells over `gap`, on the lattice of corner (`x0`, `y0`) and `step` (mm).

    The owners are found first on cells `coarse` times larger: those that
    meet `gap` (holding a point of its border, sampled every half step, or
    its centre) get ``owner_of`` their centre; the other large cells take
    the owner of the nearest one that does (cut to the gap most add
    nothing, and each owner's cells come out as a few large pieces with
    short borders).  Where neighbouring large cells differ, the border
    between owners runs near: there each `step` cell that meets `gap` is
    asked on its own.  Cut to `gap`, the cells of each mesh are its share.

    Parameters
    ----------
    gap : (Multi)Polygon
        mm.
    owner_of : callable
        Points (p, 2) mm -> mesh index of each, shape (p,) (`_GapOwner`).
    x0, y0, step : float
        The lattice, mm.
    coarse : int
        Large cells are this many steps wide.

    Returns
    -------
    _OwnerGrid
        Cells of `step` mm, an owner (mesh index) in every one; ``centred`` None.
    """
    big = coarse * step
    minx, miny, maxx, maxy = gap.bounds
    j0, j1 = int(np.floor((minx - x0) / big)) - 1, int(np.ceil((maxx - x0) / big)) + 1
    i0, i1 = int(np.floor((miny - y0) / big)) - 1, int(np.ceil((maxy - y0) / big)) + 1
    xs, ys = x0 + (np.arange(j0, j1) + 0.5) * big, y0 + (np.arange(i0, i1) + 0.5) * big
    edges = boundary_segments(gap)
    meets = _inside_lattice(gap, xs, ys)
    border = sample_segments(edges, step / 2)
    meets[np.floor((border[:, 1] - ys[0]) / big + 0.5).astype(np.int64),
          np.floor((border[:, 0] - xs[0]) / big + 0.5).astype(np.int64)] = True
    owner = np.full(meets.shape, -1, dtype=np.int64)
    rows, cols = np.nonzero(meets)
    owner[rows, cols] = owner_of(np.column_stack([xs[cols], ys[rows]]))
    if 0 < len(rows) < owner.size:
        # (a k-d tree, not scipy.ndimage's distance transform: frozen Cura builds may lack ndimage)
        _, nearest = cKDTree(np.column_stack([rows, cols])).query(np.argwhere(~meets))
        owner[~meets] = owner[rows[nearest], cols[nearest]]
    fine = np.repeat(np.repeat(owner, coarse, axis=0), coarse, axis=1)
    if coarse == 1:
        return _OwnerGrid(x0 + j0 * big, y0 + i0 * big, step, fine)
    # Large cells next to one of another owner: the border between them runs near.
    padded = np.pad(owner, 1, mode="edge")
    mixed = np.zeros(owner.shape, dtype=bool)
    for di in range(3):
        for dj in range(3):
            other = padded[di:di + owner.shape[0], dj:dj + owner.shape[1]]
            mixed |= other != owner
    mixed &= _grown(meets)
    if mixed.any():
        fxs = x0 + (j0 * coarse + np.arange(fine.shape[1]) + 0.5) * step
        fys = y0 + (i0 * coarse + np.arange(fine.shape[0]) + 0.5) * step
        candidate = np.repeat(np.repeat(mixed, coarse, axis=0), coarse, axis=1)
        ask = np.zeros(fine.shape, dtype=bool)
        rows, cols = np.nonzero(candidate)
        ask[rows, cols] = contains_xy(gap, fxs[cols], fys[rows])
        ask[np.floor((border[:, 1] - fys[0]) / step + 0.5).astype(np.int64),
            np.floor((border[:, 0] - fxs[0]) / step + 0.5).astype(np.int64)] = True
        ask &= candidate
        rows, cols = np.nonzero(ask)
        fine[rows, cols] = owner_of(np.column_stack([fxs[cols], fys[rows]]))
    return _OwnerGrid(x0 + j0 * big, y0 + i0 * big, step, fine)


def _grown(mask: np.ndarray) -> np.ndarray:
    """`mask` (rows, cols) and the cells round each of its cells (8 neighbours)."""
    by_rows = mask.copy()
    by_rows[1:] |= mask[:-1]
    by_rows[:-1] |= mask[1:]
    out = by_rows.copy()
    out[:, 1:] |= by_rows[:, :-1]
    out[:, :-1] |= by_rows[:, 1:]
    return out


def split_by_line_ends(area, fills: list[np.ndarray], spacings: list[float], end_inset: float,
                       step: float = 0.5, convex_fill: float = 0.8) -> list:
    """Split `area` between a host (index 0) and its infill-mesh modifiers by where their lines end.

    Cura clips every mesh's infill lines to its own area, so line ends mark
    the borders between meshes; a nearest-line split (`split_by_lines`)
    puts the border up to half a spacing off, which biases a region's
    density.  Each modifier holds:

    * where its lines end: the area between its neighbouring lines
      (`between_lines`) grown by `end_inset` (Cura ends infill lines that far
      inside their area: half a line width minus the infill overlap), plus
      the ends of the other meshes' lines that meet its border
      (`_border_ends`);
    * the convex hull of those (inside `area`) when the area between its
      lines fills at least `convex_fill` of it: sparse lines cut a convex
      corner by up to a spacing, the hull does not.

    Later modifiers win where what they hold overlaps.  The gap no modifier
    holds and the host's lines do not span goes, cell by cell of a `step` mm
    grid (cut to the gap exactly, `_gap_owners`), to the host or a modifier
    as the nearest lines say, and among modifiers to the one whose held part
    is nearest in line spacings (`_GapOwner`): this is all a modifier whose
    lines form no families (gyroid, concentric) gets.  The host gets the rest, less strips
    narrower than its line spacing, which go to the nearest modifier.

    Parameters
    ----------
    area : (Multi)Polygon
        The host's infill area (includes the modifiers' parts).
    fills : list of ndarray, each shape (k, 2, 2)
        Cura's FILL segments per mesh, index 0 the host, mm.
    spacings : list of float
        Line spacing per mesh, mm.
    end_inset : float
        How far inside its area a line ends, mm.
    step : float
        Grid step of the nearest-line split of the gap, mm (coarser for
        large areas: at most ~60k cells over `area`).
    convex_fill : float
        Share of its hull the lines must span for the hull to be taken.

    Returns
    -------
    list of MultiPolygon
        One per mesh, in the order given (index 0 the host's part); they
        do not overlap and together make `area`.
    """
    if len(fills) < 2:
        return split_by_lines(area, fills, spacings, step=step)
    if area.is_empty or not any(len(f) for f in fills):
        return [empty_area() for _ in fills]
    step = _grid_step(area, step)
    pieces = span_pieces(fills)
    # A modifier's span is needed only grown (the buffer of its overlapping pieces is that of their
    # union); the host's only as it is.
    owns = [None] + [to_multipolygon(MultiPolygon(p).buffer(end_inset, 4)) if p else None for p in pieces[1:]]
    host_span = _united(pieces[0])
    ends = _border_ends(fills, spacings, owns, area, end_inset, probe=max(4 * end_inset, 2 * step),
                        sample_step=step / 2)
    held: list = [empty_area()] * len(fills)
    for k in range(1, len(fills)):
        own = owns[k]
        if own is None or own.is_empty:
            continue
        corners = np.concatenate([np.concatenate([np.asarray(p.exterior.coords) for p in polygons_of(own)]), ends[k]])
        hull = to_multipolygon(convex_hull_of(corners).intersection(area))
        held[k] = hull if own.area >= convex_fill * hull.area else to_multipolygon(own.intersection(area))
    # Later modifiers win where they overlap: each loses what later ones whose boxes meet its box hold.
    claimed = list(held)
    for k in range(1, len(fills)):
        part = held[k]
        for later in held[k + 1:]:
            if not part.is_empty and not later.is_empty and boxes_meet(part.bounds, later.bounds):
                part = part.difference(later)
        claimed[k] = to_multipolygon(part)
    holding = [h for h in held[1:] if not h.is_empty]
    free = to_multipolygon(area.difference(unary_union(holding))) if holding else to_multipolygon(area)
    gap = free if host_span is None else to_multipolygon(free.difference(host_span))
    rests = [empty_area()] * len(fills)
    if not gap.is_empty:
        grid = _gap_owners(gap, _GapOwner(fills, spacings, held, step / 2), *area.bounds[:2], step, _GAP_COARSE)
        cells, _ = grid.regions(grid.owner, len(fills))
        rests = [to_multipolygon(c.intersection(gap)) if not c.is_empty else empty_area() for c in cells]
    if host_span is None:
        host = rests[0]
    else:
        held_span = free.intersection(host_span)
        host = to_multipolygon(held_span.union(rests[0]) if not rests[0].is_empty else held_span)
    children = [to_multipolygon(c.union(r)) if not r.is_empty else c for c, r in zip(claimed[1:], rests[1:], strict=True)]
    # Strips of the host narrower than its line spacing left between modifiers are
    # estimation slivers, not a zone the host's density could fill: the nearest modifier takes each.
    width = 0.5 * spacings[0]
    core = _opened_round(host, width)
    try:
        slivers = [p for p in polygons_of(host.difference(core) if not core.is_empty else host) if p.area > 1e-9]
    except Exception:  # noqa: BLE001 - GEOS can fail on nearly touching borders; the slivers then stay the host's
        slivers = []
    if slivers and any(not c.is_empty for c in children):
        owner = _nearest_within(slivers, children, 1e-6 + 0.1 * width)
        for k, child in enumerate(children):
            extra = [piece for piece, o in zip(slivers, owner.tolist(), strict=True) if o == k]
            if extra:
                # the slivers are disjoint pieces of the host: one union with all of them at once
                children[k] = to_multipolygon(child.union(MultiPolygon(extra)))
        # What the modifiers did not take stays the host's.
        kept = [piece for piece, o in zip(slivers, owner.tolist(), strict=True) if o < 0]
        host = to_multipolygon(unary_union([core, *kept])) if kept else core
    return [host, *children]


def _opened_round(area, width: float):
    """`area` shrunk by `width` and grown back, inside `area` (mm): without the strips narrower than 2 x `width`.

    GEOS can grow the shrunk area back into a polygon that crosses itself, and the overlay with `area` then
    fails (random regions 176: "TopologyException: found non-noded intersection", a failed layer): it is
    made valid first.
    """
    return to_multipolygon(valid_area(area.buffer(-width, 4).buffer(width, 4)).intersection(area))


def _nearest_within(pieces: list, targets: list, limit: float) -> np.ndarray:
    """Index of the target nearest to each piece when within `limit` mm, else -1; shape (n,).

    Only pairs whose bounding boxes lie within `limit` are measured (the
    rest are farther); ties go to the first target, as with ``argmin``.
    """
    box_of = np.array([p.bounds for p in pieces]).reshape(-1, 4)
    dist = np.full((len(targets), len(pieces)), np.inf)
    for k, target in enumerate(targets):
        if target.is_empty:
            continue
        tx0, ty0, tx1, ty1 = target.bounds
        gap_x = np.maximum(0.0, np.maximum(tx0 - box_of[:, 2], box_of[:, 0] - tx1))
        gap_y = np.maximum(0.0, np.maximum(ty0 - box_of[:, 3], box_of[:, 1] - ty1))
        close = np.flatnonzero(np.hypot(gap_x, gap_y) <= limit)
        if close.size:
            dist[k, close] = distances([pieces[i] for i in close.tolist()], target)
    nearest = np.argmin(dist, axis=0)
    return np.where(dist[nearest, np.arange(len(pieces))] <= limit, nearest, -1)
