"""Binary STL input/output and the project's test models.

All models are closed, outward-oriented triangle meshes centred on X/Y = 0
with z >= 0.  That is what CuraEngine's command line expects: unless
``machine_center_is_zero`` is set it shifts every mesh by
(machine_width / 2, machine_depth / 2), so model (0, 0) lands at the bed centre.

Besides the meshes, the outlines are available as (n, 2) arrays so that tests
can reason about the part's geometry without re-reading the STL, and the
five-point star's Figure 10 regions (Qiao et al. 2022) are available both as 2D
polygons and as prisms that can be sliced as ``infill_mesh`` modifiers.
"""

from __future__ import annotations

import math
import os
import struct
import tempfile

import numpy as np
from shapely.geometry import Polygon

__all__ = [
    "write_stl",
    "read_stl",
    "triangulate_polygon",
    "prism",
    "box",
    "cube",
    "h_bracket",
    "star",
    "cube_outline",
    "h_bracket_outline",
    "star_outline",
    "star_regions",
    "star_region_prisms",
    "STAR_FIGURE10_DENSITIES",
    "write_test_models",
]

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])

# Figure 10 of the paper: tip regions 1-5 (counter-clockwise from the +Y tip)
# and the central pentagon 6, as fill fractions.
STAR_FIGURE10_DENSITIES = {
    "tip1": 0.30,
    "tip2": 0.30,
    "tip3": 0.20,
    "tip4": 0.50,
    "tip5": 0.50,
    "centre": 0.10,
}


# --------------------------------------------------------------------------- STL I/O


def write_stl(path: str | os.PathLike, triangles, *, name: str = "DelaunayInfill") -> int:
    """Write a binary STL atomically.

    Parameters
    ----------
    path : path-like
        Output file.
    triangles : array_like, shape (n, 3, 3)
        Triangle vertices in mm, counter-clockwise seen from outside
        (facet normals are computed from this winding).
    name : str
        Header text (at most 80 bytes are kept).

    Returns
    -------
    int
        Number of triangles written.
    """
    tris = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    records = np.zeros(len(tris), dtype=_STL_RECORD)
    records["normal"] = normals
    records["vertices"] = tris
    header = name.encode("ascii", "replace")[:80].ljust(80, b" ")
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".stl-", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(header)
            f.write(struct.pack("<I", len(tris)))
            f.write(records.tobytes())
        _chmod_like_open(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return len(tris)


def _chmod_like_open(path: str) -> None:
    """Give a mkstemp file (mode 0600) the mode a plain open() would have given it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def read_stl(path: str | os.PathLike) -> np.ndarray:
    """Read a binary STL.

    Returns
    -------
    ndarray, shape (n, 3, 3), float64
        Triangle vertices in file units (mm).

    Raises
    ------
    ValueError
        If the file is not a complete binary STL.
    """
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 84:
        raise ValueError(f"{os.fspath(path)}: too short for a binary STL ({len(data)} bytes)")
    (count,) = struct.unpack_from("<I", data, 80)
    expected = 84 + count * _STL_RECORD.itemsize
    if len(data) < expected:
        raise ValueError(
            f"{os.fspath(path)}: binary STL announces {count} triangles but holds only "
            f"{(len(data) - 84) // _STL_RECORD.itemsize} (ASCII STL is not supported here)"
        )
    records = np.frombuffer(data, dtype=_STL_RECORD, count=count, offset=84)
    return records["vertices"].astype(np.float64)


# --------------------------------------------------------------------------- meshes


def _signed_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def triangulate_polygon(outline) -> np.ndarray:
    """Triangulate a simple polygon by ear clipping.

    Parameters
    ----------
    outline : array_like, shape (n, 2)
        Vertices in order, not repeating the first one; either orientation.

    Returns
    -------
    ndarray of int, shape (n - 2, 3)
        Vertex index triples, counter-clockwise.
    """
    pts = np.asarray(outline, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not Polygon(pts).is_valid:
        raise ValueError("outline must be a simple polygon of at least 3 (x, y) vertices")
    order = list(range(len(pts)))
    if _signed_area(pts) < 0:
        order.reverse()
    out = []
    while len(order) > 3:
        ring = pts[order]
        prev, nxt = np.roll(ring, 1, axis=0), np.roll(ring, -1, axis=0)
        convex = ((ring[:, 0] - prev[:, 0]) * (nxt[:, 1] - prev[:, 1])
                  - (ring[:, 1] - prev[:, 1]) * (nxt[:, 0] - prev[:, 0])) > 1e-12
        for k in np.flatnonzero(convex):
            a, b, c = prev[k], ring[k], nxt[k]
            others = np.delete(ring, [(k - 1) % len(ring), k, (k + 1) % len(ring)], axis=0)
            # an ear holds no other vertex (boundary included, which rejects touching vertices)
            d1 = (b[0] - a[0]) * (others[:, 1] - a[1]) - (b[1] - a[1]) * (others[:, 0] - a[0])
            d2 = (c[0] - b[0]) * (others[:, 1] - b[1]) - (c[1] - b[1]) * (others[:, 0] - b[0])
            d3 = (a[0] - c[0]) * (others[:, 1] - c[1]) - (a[1] - c[1]) * (others[:, 0] - c[0])
            if np.any((d1 >= 0) & (d2 >= 0) & (d3 >= 0)):
                continue
            n = len(order)
            out.append((order[(k - 1) % n], order[k], order[(k + 1) % n]))
            del order[k]
            break
        else:
            raise ValueError("polygon cannot be triangulated (self-intersecting or degenerate)")
    out.append(tuple(order))
    return np.asarray(out, dtype=np.int64)


def prism(outline, height: float, z0: float = 0.0) -> np.ndarray:
    """Extrude a simple polygon into a closed mesh.

    Parameters
    ----------
    outline : array_like, shape (n, 2)
        Polygon vertices in mm (either orientation, first vertex not repeated).
    height : float
        Extrusion height in mm (> 0).
    z0 : float
        Bottom face height in mm.

    Returns
    -------
    ndarray, shape (4n - 4, 3, 3)
        Triangles, counter-clockwise seen from outside.
    """
    if not height > 0:
        raise ValueError(f"prism height must be > 0, got {height}")
    ring = np.asarray(outline, dtype=np.float64)
    if _signed_area(ring) < 0:
        ring = ring[::-1]
    z1 = z0 + height
    caps = triangulate_polygon(ring)
    lo = np.c_[ring, np.full(len(ring), z0)]
    hi = np.c_[ring, np.full(len(ring), z1)]
    top = hi[caps]
    bottom = lo[caps[:, ::-1]]
    nxt = np.roll(np.arange(len(ring)), -1)
    side_a = np.stack([lo, lo[nxt], hi[nxt]], axis=1)
    side_b = np.stack([lo, hi[nxt], hi], axis=1)
    return np.concatenate([top, bottom, side_a, side_b])


def _rectangle(sx: float, sy: float, cx: float = 0.0, cy: float = 0.0) -> np.ndarray:
    hx, hy = sx / 2.0, sy / 2.0
    return np.array([(cx - hx, cy - hy), (cx + hx, cy - hy), (cx + hx, cy + hy), (cx - hx, cy + hy)])


def box(sx: float, sy: float, sz: float, cx: float = 0.0, cy: float = 0.0, z0: float = 0.0) -> np.ndarray:
    """An axis-aligned box, shape (12, 3, 3): size (sx, sy, sz) mm, centred on (cx, cy), from z0 up."""
    return prism(_rectangle(sx, sy, cx, cy), sz, z0)


def cube_outline(size: float = 20.0) -> np.ndarray:
    """The cube's footprint, shape (4, 2), mm, CCW."""
    return _rectangle(size, size)


def cube(size: float = 20.0) -> np.ndarray:
    """A cube of edge `size` mm, shape (12, 3, 3)."""
    return box(size, size, size)


def h_bracket_outline(width: float = 60.0, depth: float = 40.0, leg: float = 15.0, bar: float = 10.0) -> np.ndarray:
    """The H-bracket's footprint, shape (12, 2), mm, CCW.

    Two legs `leg` wide along Y at both ends of X, joined by a bar `bar` deep along X.
    """
    w, d, b = width / 2.0, depth / 2.0, bar / 2.0
    return np.array([
        (-w, -d), (-w + leg, -d), (-w + leg, -b), (w - leg, -b), (w - leg, -d), (w, -d),
        (w, d), (w - leg, d), (w - leg, b), (-w + leg, b), (-w + leg, d), (-w, d),
    ])


def h_bracket(width: float = 60.0, depth: float = 40.0, height: float = 10.0) -> np.ndarray:
    """The H-bracket, 60 x 40 x 10 mm by default."""
    return prism(h_bracket_outline(width, depth), height)


def star_outline(outer_diameter: float = 60.0, points: int = 5, inner_ratio: float = 0.45) -> np.ndarray:
    """A star's footprint, shape (2 * points, 2), mm, CCW.

    Vertex 0 is the tip on +Y; tips (even indices) lie on the outer circle,
    inner vertices (odd indices) on a circle `inner_ratio` times as large.
    """
    k = np.arange(2 * points)
    radius = np.where(k % 2 == 0, outer_diameter / 2.0, outer_diameter / 2.0 * inner_ratio)
    angle = math.pi / 2 + k * math.pi / points
    return np.c_[radius * np.cos(angle), radius * np.sin(angle)]


def star(outer_diameter: float = 60.0, height: float = 10.0, points: int = 5, inner_ratio: float = 0.45) -> np.ndarray:
    """The five-point star, diameter 60 mm, 10 mm high, inner ratio 0.45 by default."""
    return prism(star_outline(outer_diameter, points, inner_ratio), height)


def star_regions(outer_diameter: float = 60.0, points: int = 5, inner_ratio: float = 0.45) -> dict[str, Polygon]:
    """The star split as in the paper's Figure 10.

    Returns
    -------
    dict
        ``"tip1"`` ... ``"tipN"``: the tip triangles (a tip and its two
        neighbouring inner vertices), counter-clockwise from the +Y tip;
        ``"centre"``: the polygon of the inner vertices.  Model coordinates,
        mm; together they tile the star exactly.
    """
    ring = star_outline(outer_diameter, points, inner_ratio)
    n = len(ring)
    regions = {}
    for i in range(points):
        tip = 2 * i
        regions[f"tip{i + 1}"] = Polygon([ring[(tip - 1) % n], ring[tip], ring[tip + 1]])
    regions["centre"] = Polygon(ring[1::2])
    return regions


def star_region_prisms(height: float = 10.0, margin: float = 1.0, **star_kwargs) -> dict[str, np.ndarray]:
    """The Figure 10 regions as prisms for use as ``infill_mesh`` modifiers.

    Each prism spans z = 0 .. height + margin so it covers every layer of a
    star of that height.  Keys as in :func:`star_regions`; values shape (m, 3, 3).
    """
    return {
        name: prism(np.asarray(poly.exterior.coords)[:-1], height + margin)
        for name, poly in star_regions(**star_kwargs).items()
    }


def write_test_models(folder: str | os.PathLike) -> dict[str, str]:
    """Write cube.stl, hbracket.stl and star.stl into `folder`.

    Returns
    -------
    dict
        Model name -> file path.
    """
    os.makedirs(folder, exist_ok=True)
    out = {}
    for name, tris in (("cube", cube()), ("hbracket", h_bracket()), ("star", star())):
        path = os.path.join(os.fspath(folder), f"{name}.stl")
        write_stl(path, tris, name=name)
        out[name] = path
    return out
