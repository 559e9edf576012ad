"""Painted density sets for the Cura tool, in pure numpy (no Cura import).

A model's painting is a list of *painted sets*: each has a number, a density (%), a depth (mm)
and the indices of the painted triangles in the model's own mesh order (row ``i`` of the mesh's
index array, or vertices ``3i .. 3i+2`` of an unindexed mesh: the order Cura's 3MF writer keeps
and the snapshot's triangles follow).  Because they are indices into the node's own mesh, the
painting follows every move, rotation, scale and mirror of the model.  A face belongs to at most
one set: painting it into another set moves it there.

The Cura side (``paint_tool.py``) keeps a model's painting as JSON in the node's ``metadata``
(:data:`METADATA_KEY`), which Cura's 3MF writer saves with the object and its reader gives back.
This module has everything that can be tested without Cura: the JSON form, the brush (which
triangles a stroke at a point paints), the ray pick, the stroke's undo/redo state, the overlay's
geometry, the export for the command line and the conversion into the pass's ``PaintedRegion``.
"""

from __future__ import annotations

import json
import math
import os
import struct
from dataclasses import dataclass, field

import numpy as np

#: Key of a model node's painting in ``node.metadata`` (saved by Cura's 3MF writer as object metadata).
METADATA_KEY = "delaunay_infill_paint"
FORMAT_VERSION = 1

MODES = ("place", "paint", "erase")
MIN_BRUSH_MM, MAX_BRUSH_MM = 0.2, 500.0
MIN_DEPTH_MM, MAX_DEPTH_MM = 0.1, 500.0

#: One colour per set number (RGBA 0-1), repeating; chosen to stand out against Cura's yellow models.
PALETTE = (
    (0.85, 0.10, 0.10, 1.0),  # red
    (0.10, 0.35, 0.90, 1.0),  # blue
    (0.10, 0.65, 0.20, 1.0),  # green
    (0.60, 0.15, 0.75, 1.0),  # purple
    (0.95, 0.45, 0.05, 1.0),  # orange
    (0.05, 0.70, 0.75, 1.0),  # teal
    (0.85, 0.20, 0.55, 1.0),  # pink
    (0.45, 0.30, 0.15, 1.0),  # brown
)


def set_color(number: int) -> tuple:
    """The overlay colour (RGBA, 0-1) of painted set `number` (1-based)."""
    return PALETTE[(int(number) - 1) % len(PALETTE)]


def set_color_hex(number: int) -> str:
    """The same colour as ``#rrggbb`` for the panel."""
    r, g, b, _ = set_color(number)
    return "#{:02x}{:02x}{:02x}".format(*(int(round(c * 255)) for c in (r, g, b)))


def clamp(value, low: float, high: float, what: str) -> float:
    """`value` as a finite float clamped to [low, high]; ValueError when it is no number."""
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{what} must be a number, got {value!r}")
    return min(high, max(low, number))


def _faces(values) -> np.ndarray:
    return np.unique(np.asarray(values, dtype=np.int64).reshape(-1))


# -- the painted sets of one model ----------------------------------------------------------------


@dataclass
class PaintSet:
    """One painted set: `faces` (sorted unique triangle indices), `density` %, `depth` mm."""

    number: int
    density: float
    depth: float
    faces: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self):
        self.number = int(self.number)
        self.density = clamp(self.density, 0.0, 100.0, "density")
        self.depth = clamp(self.depth, MIN_DEPTH_MM, MAX_DEPTH_MM, "depth")
        self.faces = _faces(self.faces)

    def copy(self) -> PaintSet:
        return PaintSet(self.number, self.density, self.depth, self.faces.copy())

    def __eq__(self, other) -> bool:
        return (isinstance(other, PaintSet) and self.number == other.number and self.density == other.density
                and self.depth == other.depth and np.array_equal(self.faces, other.faces))


def encode_ranges(faces) -> list:
    """Sorted unique indices as ``[[start, stop), ...]`` runs (compact for painted patches)."""
    f = _faces(faces)
    if len(f) == 0:
        return []
    breaks = np.flatnonzero(np.diff(f) != 1) + 1
    starts = f[np.r_[0, breaks]]
    stops = f[np.r_[breaks - 1, len(f) - 1]] + 1
    return [[int(a), int(b)] for a, b in zip(starts, stops)]


def decode_ranges(ranges) -> np.ndarray:
    """The indices of ``[[start, stop), ...]`` runs; ValueError for anything else."""
    if not isinstance(ranges, list):
        raise ValueError("painted faces must be a list of [start, stop] runs")
    parts = []
    for run in ranges:
        if (not isinstance(run, list) or len(run) != 2 or not all(isinstance(v, int) and not isinstance(v, bool)
                                                                   for v in run) or not 0 <= run[0] < run[1]):
            raise ValueError(f"bad run of painted faces {run!r}")
        parts.append(np.arange(run[0], run[1], dtype=np.int64))
    return _faces(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)


class PaintData:
    """All painted sets of one model, in creation order (later sets win where their regions overlap).

    Parameters
    ----------
    face_count : int
        How many triangles the model's mesh has (a painting saved for another mesh is refused).
    sets : list of PaintSet
    """

    def __init__(self, face_count: int, sets=None):
        self.face_count = int(face_count)
        self.sets: list[PaintSet] = [s.copy() for s in (sets or [])]
        for s in self.sets:
            self._check(s.faces)

    def _check(self, faces: np.ndarray) -> None:
        if len(faces) and (faces[0] < 0 or faces[-1] >= self.face_count):
            raise ValueError(f"face {int(faces[-1] if faces[-1] >= self.face_count else faces[0])} is not one of "
                             f"the model's {self.face_count} triangles")

    def copy(self) -> PaintData:
        return PaintData(self.face_count, self.sets)

    def __eq__(self, other) -> bool:
        return isinstance(other, PaintData) and self.face_count == other.face_count and self.sets == other.sets

    def __bool__(self) -> bool:
        return any(len(s.faces) for s in self.sets)

    def get(self, number) -> PaintSet | None:
        return next((s for s in self.sets if s.number == int(number)), None)

    def next_number(self) -> int:
        return max((s.number for s in self.sets), default=0) + 1

    def add_set(self, density: float, depth: float, number: int | None = None) -> PaintSet:
        new = PaintSet(self.next_number() if number is None else number, density, depth)
        if self.get(new.number) is not None:
            raise ValueError(f"painted set {new.number} exists already")
        self.sets.append(new)
        return new

    def remove_set(self, number) -> bool:
        before = len(self.sets)
        self.sets = [s for s in self.sets if s.number != int(number)]
        return len(self.sets) != before

    def paint(self, number, faces) -> int:
        """Add `faces` to set `number` (taking them from any other set); returns how many were new to it."""
        target = self.get(number)
        if target is None:
            raise ValueError(f"no painted set {number}")
        faces = _faces(faces)
        self._check(faces)
        new = np.setdiff1d(faces, target.faces, assume_unique=True)
        if len(new) == 0:
            return 0
        for s in self.sets:
            if s is not target and len(s.faces):
                s.faces = np.setdiff1d(s.faces, new, assume_unique=True)
        target.faces = np.union1d(target.faces, new)
        return int(len(new))

    def erase(self, faces) -> int:
        """Remove `faces` from every set; returns how many painted faces were erased."""
        faces = _faces(faces)
        erased = 0
        for s in self.sets:
            keep = np.setdiff1d(s.faces, faces, assume_unique=True)
            erased += len(s.faces) - len(keep)
            s.faces = keep
        return int(erased)

    def drop_empty(self) -> None:
        self.sets = [s for s in self.sets if len(s.faces)]

    def set_of_face(self, face) -> int:
        """The number of the set face `face` is painted in, or 0 when it is not painted."""
        face = int(face)
        return next((s.number for s in self.sets
                     if len(s.faces) and s.faces[min(np.searchsorted(s.faces, face), len(s.faces) - 1)] == face), 0)

    def painted_faces(self) -> np.ndarray:
        return _faces(np.concatenate([s.faces for s in self.sets])) if self.sets else np.zeros(0, dtype=np.int64)

    # -- the saved form (node metadata, 3MF) --
    def to_json(self) -> str:
        return json.dumps({
            "version": FORMAT_VERSION,
            "face_count": self.face_count,
            "sets": [{"number": s.number, "density": s.density, "depth": s.depth, "faces": encode_ranges(s.faces)}
                     for s in self.sets],
        }, separators=(",", ":"))

    @classmethod
    def from_json(cls, text, face_count: int | None = None) -> PaintData:
        """Read :meth:`to_json`'s form; ValueError when it is not one, or was saved for another mesh."""
        try:
            doc = json.loads(text)
        except (TypeError, ValueError) as error:
            raise ValueError(f"the painting is not JSON ({error})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("sets"), list):
            raise ValueError("the painting has no list of sets")
        if int(doc.get("version", 0)) > FORMAT_VERSION:
            raise ValueError(f"the painting was saved by a newer plugin (format {doc.get('version')})")
        saved_count = int(doc.get("face_count", -1))
        if face_count is not None and saved_count != int(face_count):
            raise ValueError(f"the painting was made on a mesh of {saved_count} triangles, this one has {face_count}")
        sets = []
        for entry in doc["sets"]:
            if not isinstance(entry, dict):
                raise ValueError(f"bad painted set {entry!r}")
            sets.append(PaintSet(entry.get("number"), entry.get("density"), entry.get("depth"),
                                 decode_ranges(entry.get("faces", []))))
        if len({s.number for s in sets}) != len(sets):
            raise ValueError("two painted sets share a number")
        return cls(saved_count, sets)


class PaintEdit:
    """The undo/redo state of one change of a model's painting (a stroke, an edit, a deletion).

    `apply(data)` is called with a copy of the painting to show: the one after the change on
    :meth:`redo`, the one before it on :meth:`undo` (the Cura operation wraps this).
    """

    def __init__(self, before: PaintData | None, after: PaintData | None, apply, description: str = ""):
        self.before = before.copy() if before is not None else None
        self.after = after.copy() if after is not None else None
        self._apply = apply
        self.description = description

    @property
    def changes(self) -> bool:
        return self.before != self.after

    def redo(self) -> None:
        self._apply(self.after.copy() if self.after is not None else None)

    def undo(self) -> None:
        self._apply(self.before.copy() if self.before is not None else None)


# -- geometry ---------------------------------------------------------------------------------------


def mesh_triangles(vertices, indices=None) -> np.ndarray:
    """(n, 3, 3) triangles of a mesh in its face order (index rows, or vertex triples when unindexed)."""
    v = np.asarray(vertices, dtype=float).reshape(-1, 3)
    if indices is not None and len(indices):
        return v[np.asarray(indices, dtype=np.int64).reshape(-1, 3)]
    return v[: len(v) // 3 * 3].reshape(-1, 3, 3)


def transform_triangles(matrix, triangles) -> np.ndarray:
    """Triangles (n, 3, 3) through a 4 x 4 affine matrix."""
    m = np.asarray(matrix, dtype=float)
    t = np.asarray(triangles, dtype=float)
    return t @ m[:3, :3].T + m[:3, 3]


def signed_volume(triangles) -> float:
    """The signed volume (mm3) a closed mesh's triangles enclose: > 0 when their normals point outwards."""
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def outward(triangles) -> np.ndarray:
    """The triangles with their corners ordered so that their normals point out of the mesh.

    Same rows (face indices hold); corners 1 and 2 swapped throughout when the mesh encloses a
    negative volume, as after a mirror whose mesh was not re-wound (Cura's mirror re-winds the
    mesh, but a copy made by Multiply Selected shares the mesh, so mirroring one re-winds both).
    """
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    return t[:, [0, 2, 1]] if signed_volume(t) < 0.0 else t


def unit_normals(triangles) -> np.ndarray:
    t = np.asarray(triangles, dtype=float)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]


def ray_hit(origin, direction, triangles):
    """The first triangle a ray hits: ``(face index, distance along the unit ray, point)`` or None.

    Möller–Trumbore over all triangles at once (both sides count).
    """
    o = np.asarray(origin, dtype=float).reshape(3)
    d = np.asarray(direction, dtype=float).reshape(3)
    d = d / max(np.linalg.norm(d), 1e-300)
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    if len(t) == 0:
        return None
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - t[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    dist = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1.0 + 1e-9) & (dist > 1e-9)
    if not hit.any():
        return None
    candidates = np.flatnonzero(hit)
    face = int(candidates[np.argmin(dist[candidates])])
    return face, float(dist[face]), o + dist[face] * d


def triangle_distances(point, triangles) -> np.ndarray:
    """3-D distance from `point` to each triangle, shape (n,)."""
    x = np.asarray(point, dtype=float).reshape(1, 3)
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    a, b, c = t[:, 0], t[:, 1], t[:, 2]

    def segment(p, q):
        pq = q - p
        s = np.clip(np.einsum("ij,ij->i", x - p, pq) / np.maximum(np.einsum("ij,ij->i", pq, pq), 1e-300), 0.0, 1.0)
        return np.linalg.norm(x - (p + s[:, None] * pq), axis=1)

    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=1)
    n = normal / np.maximum(length, 1e-300)[:, None]
    height = np.einsum("ij,ij->i", x - a, n)
    foot = x - height[:, None] * n
    inside = length > 0.0
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(q - p, foot - p), n) >= 0.0
    return np.where(inside, np.minimum(np.abs(height), edges), edges)


def brush_faces(triangles, centre, radius: float, *, view_direction=None, hit_face: int | None = None) -> np.ndarray:
    """The triangles a brush of `radius` mm at `centre` paints: every one with a point within the radius.

    With `view_direction` (the camera ray) only the triangles facing the camera are painted, so a
    brush on one side of a thin wall does not paint the other side.  `hit_face` (the picked
    triangle) is always painted.  Returns sorted indices.
    """
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    if len(t) == 0:
        return np.zeros(0, dtype=np.int64)
    c = np.asarray(centre, dtype=float).reshape(3)
    r = max(0.0, float(radius))
    lo, hi = t.min(axis=1), t.max(axis=1)
    near = np.all((lo <= c + r) & (hi >= c - r), axis=1)  # bounding boxes first
    idx = np.flatnonzero(near)
    if len(idx):
        idx = idx[triangle_distances(c, t[idx]) <= r]
    if view_direction is not None and len(idx):
        d = np.asarray(view_direction, dtype=float).reshape(3)
        idx = idx[unit_normals(t[idx]) @ d < 0.0]
    if hit_face is not None:
        idx = np.union1d(idx, [int(hit_face)])
    return np.unique(idx.astype(np.int64))


def stroke_points(start, end, radius: float) -> np.ndarray:
    """Points from `start` to `end` no more than half a brush radius apart (a fast drag leaves no gaps)."""
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    steps = int(np.ceil(np.linalg.norm(b - a) / max(radius * 0.5, 1e-6)))
    steps = min(max(steps, 1), 200)
    return a + (b - a) * (np.arange(1, steps + 1) / steps)[:, None]


def overlay_triangles(triangles, faces, offset: float) -> np.ndarray:
    """The painted triangles moved `offset` along their normals (drawn just above the surface)."""
    t = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)[_faces(faces)]
    return t + unit_normals(t)[:, None, :] * float(offset)


# -- slicing and export -----------------------------------------------------------------------------


@dataclass
class PaintedSnapshot:
    """A painted set as plain data for the background job (G-code coordinates)."""

    model: str  # the model's name (its ;MESH: name)
    number: int
    density: float  # percent
    depth: float  # mm
    faces: np.ndarray
    triangles: np.ndarray  # the model's whole mesh, (n, 3, 3) G-code mm, in the node's face order


def painted_snapshots(model_name: str, data: PaintData, gcode_triangles) -> list:
    """The :class:`PaintedSnapshot` of each non-empty set of one model."""
    tri = np.asarray(gcode_triangles, dtype=float).reshape(-1, 3, 3)
    if len(tri) != data.face_count:
        raise ValueError(f"{model_name}: the painting has {data.face_count} triangles, the mesh {len(tri)}")
    return [PaintedSnapshot(model_name, s.number, s.density, s.depth, s.faces.copy(), tri)
            for s in data.sets if len(s.faces)]


def painted_regions(snapshots, enabled_models, lift: float = 0.0) -> list:
    """The pass's ``PaintedRegion`` of each painted set of an enabled model, in scene order then set order."""
    from ..painting import PaintedRegion

    out = []
    for item in snapshots:
        if item.model not in enabled_models or len(item.faces) == 0:
            continue
        tri = np.array(item.triangles, dtype=float)
        tri[..., 2] += float(lift)
        out.append(PaintedRegion(tri, item.faces, float(item.density) / 100.0, float(item.depth),
                                 name=f"painted {item.model} #{item.number}"))
    return out


def write_binary_stl(path, triangles, name: str = "DelaunayInfill painted model") -> None:
    """A binary STL of `triangles` (n, 3, 3), in their order (FACES.json indexes it)."""
    tri = np.asarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
    normals = unit_normals(tri.astype(float)).astype(np.float32)
    rows = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rows["n"], rows["v"] = normals, tri
    with open(path, "wb") as stream:
        stream.write(name.encode("ascii", "replace")[:80].ljust(80, b" "))
        stream.write(struct.pack("<I", len(tri)))
        stream.write(rows.tobytes())


def export_painting(stl_path, faces_path, gcode_triangles, faces) -> tuple:
    """Write MODEL.stl (the model in G-code coordinates) and FACES.json for ``delaunay-infill process --paint``.

    The STL is in G-code millimetres as CuraEngine places the model, so ``--paint`` needs no
    ``--modifier-offset`` for G-code Cura sliced.  Returns the two paths.
    """
    faces = _faces(faces)
    if len(faces) == 0:
        raise ValueError("nothing is painted in this set")
    write_binary_stl(stl_path, gcode_triangles)
    with open(faces_path, "w", encoding="utf-8") as stream:
        json.dump({"faces": [int(f) for f in faces]}, stream)
        stream.write("\n")
    return os.fspath(stl_path), os.fspath(faces_path)


def local_path(chosen) -> str:
    """A file dialog's choice (a ``file:`` URL, as QML's FileDialog gives it, or a plain path) as a local path."""
    from urllib.parse import unquote, urlparse

    text = os.fspath(chosen) if not isinstance(chosen, str) else chosen
    text = text.strip()
    if not text:
        raise ValueError("no file chosen")
    if text.lower().startswith("file:"):
        parsed = urlparse(text)
        path = unquote(parsed.path)
        if parsed.netloc and parsed.netloc != "localhost":
            path = f"//{parsed.netloc}{path}"
        if len(path) > 2 and path[0] == "/" and path[2] == ":":  # file:///C:/... on Windows
            path = path[1:]
        return os.path.normpath(path)
    return os.path.normpath(os.path.expanduser(text))


def export_paths(stem) -> tuple:
    """MODEL.stl and FACES.json paths for a chosen path `stem` (an .stl or .json suffix is dropped)."""
    stem = os.fspath(stem)
    base, ext = os.path.splitext(stem)
    if ext.lower() in (".stl", ".json"):
        stem = base
    return stem + ".stl", stem + ".faces.json"
