"""In-plane stiffness of one layer's infill line network: a frame model, solved with scipy.sparse.

What is computed
----------------
The lines (segments, mm) are clipped to a square window.  Crossings and
T-junctions split them into pieces; piece ends closer than `tol` are one node.
Every piece is a plane frame element (Euler-Bernoulli beam with axial and
bending stiffness) of bead modulus E = 1, cross-section width = the line width
w (in the plane) and thickness t = 1 (out of the plane): EA = w, EI = w^3 / 12.
Joints are rigid (``joints="rigid"``: the pieces at a node share its
rotation) or pinned (``joints="pin"``: EI is 1e-9 of the rigid value, so the
network is a truss; a tiny EI keeps mechanisms solvable).

Nodes within `tol` of the window border are given the affine displacement
u = eps . (x - centre) of a unit strain; every other node (and every rotation)
is free and in equilibrium.  For the three unit strains (eps_xx, eps_yy,
gamma_xy) the interior is solved (sparse LU) and the effective stiffness
tensor is the energy form C_ij = u_i^T K u_j / A (3 x 3 Voigt, engineering
shear strain, A the window's area).  Pieces not connected to the border carry
nothing and are left out of the solve (not of the density).

Figures (all divided by the network's area fraction rho = clipped line length
x w / A, so a bar of the bead's own material along the strain gives 1):

``C(theta)``
    Uniaxial-strain stiffness in direction theta: the normal stress along d =
    (cos theta, sin theta) under the strain d (x) d, e^T C e with
    e = (cos^2, sin^2, 2 cos sin).  ``C_min`` / ``C_max`` are its minimum /
    maximum over theta (0.5 deg steps); ``isotropy`` = C_min / C_max.
    A stretch-dominated triangular lattice gives 3/8 in every direction, the
    upper bound of C_min / rho for any line network in the truss limit.
``E(theta)``
    Uniaxial-stress (tension) modulus in direction theta: 1 / (s^T S s),
    S = C^-1, s = (cos^2, sin^2, cos sin).  ``E_min`` is its minimum.  A square
    grid with pinned joints has E(45 deg) = 0 (it shears freely).

Command line::

    python3 bench/stiffness.py FILE.gcode [--layers 20,21] [--window 30] [--centre X,Y] [--joints rigid]
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, identity
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

__all__ = ["Stiffness", "clip_to_window", "network", "stiffness", "directional", "from_tensor",
           "triangular_lattice", "square_grid", "fill_segments"]

_ANGLES = np.radians(np.arange(0.0, 180.0, 0.5))  # directions theta of C(theta), E(theta)
_PIN = 1e-9  # pinned joints: EI as a fraction of the rigid value


@dataclass
class Stiffness:
    """Effective in-plane stiffness of a line network in a window.

    Attributes
    ----------
    C : ndarray (3, 3)
        Voigt stiffness (eps_xx, eps_yy, gamma_xy), bead modulus 1.
    rho : float
        Area fraction: clipped line length x line width / window area.
    nodes, pieces : int
        Size of the frame model.
    """

    C: np.ndarray
    rho: float
    nodes: int = 0
    pieces: int = 0

    @property
    def normalised(self) -> np.ndarray:
        """C / rho."""
        return self.C / self.rho

    def c_theta(self, angles=_ANGLES) -> np.ndarray:
        """Uniaxial-strain stiffness C(theta) / rho for each angle (radians)."""
        return directional(self.C, angles)[0] / self.rho

    def e_theta(self, angles=_ANGLES) -> np.ndarray:
        """Uniaxial-stress modulus E(theta) / rho for each angle (radians)."""
        return directional(self.C, angles)[1] / self.rho

    @property
    def c_min(self) -> float:
        return float(self.c_theta().min())

    @property
    def c_max(self) -> float:
        return float(self.c_theta().max())

    @property
    def isotropy(self) -> float:
        c = self.c_theta()
        return float(c.min() / c.max())

    @property
    def e_min(self) -> float:
        return float(self.e_theta().min())

    def summary(self) -> dict:
        return {"C_min/rho": self.c_min, "isotropy": self.isotropy, "E_min/rho": self.e_min, "rho": self.rho,
                "C_max/rho": self.c_max}


def directional(C: np.ndarray, angles=_ANGLES) -> tuple[np.ndarray, np.ndarray]:
    """(C(theta), E(theta)) of a Voigt stiffness (3, 3) for each angle (radians); not normalised."""
    c, s = np.cos(angles), np.sin(angles)
    strain = np.stack((c * c, s * s, 2.0 * c * s), axis=1)
    stress = np.stack((c * c, s * s, c * s), axis=1)
    c_theta = np.einsum("ai,ij,aj->a", strain, C, strain)
    try:
        S = np.linalg.inv(C)
        e_theta = 1.0 / np.einsum("ai,ij,aj->a", stress, S, stress)
    except np.linalg.LinAlgError:
        e_theta = np.zeros(len(angles))
    e_theta = np.where(np.isfinite(e_theta) & (e_theta > 0), e_theta, 0.0)
    return c_theta, e_theta


def from_tensor(C: np.ndarray, rho: float) -> Stiffness:
    """A `Stiffness` of a given tensor and area fraction (e.g. the mean of several layers')."""
    return Stiffness(np.asarray(C, dtype=float), float(rho))


# --------------------------------------------------------------------------- geometry
def clip_to_window(segments: np.ndarray, centre, half: float) -> np.ndarray:
    """Segments (k, 2, 2) clipped to the square |x - cx|, |y - cy| <= half (Liang-Barsky, vectorized)."""
    seg = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if len(seg) == 0:
        return seg
    p, d = seg[:, 0] - np.asarray(centre, float), seg[:, 1] - seg[:, 0]
    t0, t1 = np.zeros(len(seg)), np.ones(len(seg))
    keep = np.ones(len(seg), dtype=bool)
    for axis in (0, 1):
        for sign in (-1.0, 1.0):  # the half-planes sign * x <= half
            num = half - sign * p[:, axis]
            den = sign * d[:, axis]
            parallel = np.abs(den) < 1e-15
            keep &= ~(parallel & (num < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(parallel, np.nan, num / np.where(parallel, 1.0, den))
            entering, leaving = (den < 0) & ~parallel, (den > 0) & ~parallel
            t0 = np.where(entering, np.maximum(t0, t), t0)
            t1 = np.where(leaving, np.minimum(t1, t), t1)
    keep &= t1 > t0 + 1e-12
    a = p[keep] + d[keep] * t0[keep, None]
    b = p[keep] + d[keep] * t1[keep, None]
    out = np.stack((a, b), axis=1) + np.asarray(centre, float)
    return out


def network(segments: np.ndarray, tol: float = 1e-3):
    """Nodes and pieces of a line network: segments split at crossings and T-junctions, ends merged.

    Parameters
    ----------
    segments : ndarray (k, 2, 2)
    tol : float
        Ends (and a line end and a line it touches) closer than this are joined, mm.

    Returns
    -------
    (nodes (n, 2), pieces (m, 2) of node indices)
    """
    seg = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    length = np.hypot(*(seg[:, 1] - seg[:, 0]).T)
    seg = seg[length > tol]
    length = length[length > tol]
    k = len(seg)
    if k == 0:
        return np.zeros((0, 2)), np.zeros((0, 2), np.intp)
    mid = seg.mean(axis=1)
    # Two segments that meet have midpoints within half their lengths' sum (+ tol).
    pairs = cKDTree(mid).query_pairs(float(length.max()) + tol, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    p, r = seg[i, 0], seg[i, 1] - seg[i, 0]
    q, s = seg[j, 0], seg[j, 1] - seg[j, 0]
    den = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    ok = np.abs(den) > 1e-12 * length[i] * length[j]
    safe = np.where(ok, den, 1.0)
    qp = q - p
    t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / safe
    u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / safe
    ti, uj = tol / length[i], tol / length[j]  # the tolerance as a parameter on each
    meet = ok & (t >= -ti) & (t <= 1 + ti) & (u >= -uj) & (u <= 1 + uj)
    seg_id = [np.arange(k), np.arange(k), i[meet], j[meet]]
    param = [np.zeros(k), np.ones(k), np.clip(t[meet], 0, 1), np.clip(u[meet], 0, 1)]
    # Collinear neighbours (parallel): an end of one lying on the other splits it there.
    par = ~ok
    if par.any():
        for a, b in ((i[par], j[par]), (j[par], i[par])):
            for end in (0, 1):
                e = seg[a, end]
                base, dirv = seg[b, 0], seg[b, 1] - seg[b, 0]
                tt = np.einsum("ij,ij->i", e - base, dirv) / (length[b] ** 2)
                dist = np.hypot(*(base + dirv * tt[:, None] - e).T)
                on = (dist <= tol) & (tt > 0) & (tt < 1)
                seg_id.append(b[on])
                param.append(tt[on])
    seg_id, param = np.concatenate(seg_id), np.concatenate(param)
    order = np.lexsort((param, seg_id))
    seg_id, param = seg_id[order], param[order]
    points = seg[seg_id, 0] + (seg[seg_id, 1] - seg[seg_id, 0]) * param[:, None]
    # Merge points within tol: connected components of the close pairs.
    close = cKDTree(points).query_pairs(tol, output_type="ndarray")
    graph = coo_matrix((np.ones(len(close)), (close[:, 0], close[:, 1])), shape=(len(points), len(points)))
    _, label = connected_components(graph, directed=False)
    count = np.bincount(label)
    nodes = np.stack((np.bincount(label, points[:, 0]) / count, np.bincount(label, points[:, 1]) / count), axis=1)
    same = seg_id[1:] == seg_id[:-1]
    a, b = label[:-1][same], label[1:][same]
    real = a != b
    pieces = np.stack((a[real], b[real]), axis=1)
    return nodes, pieces


# --------------------------------------------------------------------------- model
def stiffness(segments: np.ndarray, line_width: float, *, window: float = 30.0, centre=None,
              joints: str = "rigid", tol: float | None = None) -> Stiffness:
    """Effective in-plane stiffness of the lines (k, 2, 2) in a square window (see the module's docstring).

    Parameters
    ----------
    segments : ndarray (k, 2, 2)
        mm.
    line_width : float
        Bead width, mm (the cross-section's in-plane width; thickness 1, modulus 1).
    window : float
        Side of the square window, mm.
    centre : (x, y), optional
        Window centre; default the centre of the segments' bounding box.
    joints : {"rigid", "pin"}
    tol : float, optional
        Node merging tolerance, mm; default a tenth of the line width.
    """
    if joints not in ("rigid", "pin"):
        raise ValueError(f"joints must be 'rigid' or 'pin', got {joints!r}")
    seg = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if centre is None:
        lo, hi = seg.reshape(-1, 2).min(axis=0), seg.reshape(-1, 2).max(axis=0)
        centre = 0.5 * (lo + hi)
    centre = np.asarray(centre, dtype=float)
    half = 0.5 * window
    tol = 0.1 * line_width if tol is None else tol
    clipped = clip_to_window(seg, centre, half)
    nodes, pieces = network(clipped, tol)
    area = window * window
    vec = nodes[pieces[:, 1]] - nodes[pieces[:, 0]]
    length = np.hypot(vec[:, 0], vec[:, 1])
    rho = float(length.sum()) * line_width / area
    if len(pieces) == 0:
        return Stiffness(np.zeros((3, 3)), max(rho, 1e-300), len(nodes), 0)
    # Only what is connected to the border carries load.
    n = len(nodes)
    border = (np.abs(nodes - centre) >= half - tol).any(axis=1)
    graph = coo_matrix((np.ones(len(pieces)), (pieces[:, 0], pieces[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    loaded = np.zeros(comp.max() + 1, dtype=bool)
    loaded[comp[border]] = True
    live = loaded[comp[pieces[:, 0]]]
    pieces, vec, length = pieces[live], vec[live], length[live]
    K = _assemble(nodes, pieces, vec, length, line_width, _PIN if joints == "pin" else 1.0)
    # Prescribed: both displacements of the border nodes; free: the rest (rotations all free).
    dof_fixed = np.zeros(3 * n, dtype=bool)
    dof_fixed[3 * np.flatnonzero(border)] = True
    dof_fixed[3 * np.flatnonzero(border) + 1] = True
    used = np.zeros(n, dtype=bool)
    used[pieces.ravel()] = True
    dof_used = np.repeat(used, 3)
    free = np.flatnonzero(dof_used & ~dof_fixed)
    fixed = np.flatnonzero(dof_used & dof_fixed)
    x = nodes - centre
    U = np.zeros((3 * n, 3))
    # unit strains: eps_xx, eps_yy, gamma_xy (u = (gamma / 2) y, v = (gamma / 2) x)
    U[0::3, 0] = x[:, 0]
    U[1::3, 1] = x[:, 1]
    U[0::3, 2] = 0.5 * x[:, 1]
    U[1::3, 2] = 0.5 * x[:, 0]
    U[~dof_fixed] = 0.0
    K = K.tocsr()
    if free.size:
        Kff = K[free][:, free].tocsc()
        # A node on a dangling, unbraced chain (a mechanism) would make the solve singular: a spring
        # of 1e-12 of the mean stiffness to ground holds it and changes nothing else measurably.
        Kff = Kff + identity(len(free), format="csc") * (1e-12 * float(Kff.diagonal().mean()))
        Kfp = K[free][:, fixed]
        U[free] = splu(Kff).solve(-(Kfp @ U[fixed]))
    C = U.T @ (K @ U) / area
    C = 0.5 * (C + C.T)
    return Stiffness(C, rho, int(used.sum()), len(pieces))


def _assemble(nodes, pieces, vec, length, width: float, bending: float):
    """Global stiffness (3 n x 3 n, COO) of plane frame elements, EA = w, EI = bending * w^3 / 12."""
    n = len(nodes)
    c, s = vec[:, 0] / length, vec[:, 1] / length
    ea = width / length
    ei = bending * width**3 / 12.0
    L = length
    kl = np.zeros((len(L), 6, 6))  # local: (u1, v1, t1, u2, v2, t2)
    kl[:, 0, 0] = kl[:, 3, 3] = ea
    kl[:, 0, 3] = kl[:, 3, 0] = -ea
    b12, b6, b4, b2 = 12 * ei / L**3, 6 * ei / L**2, 4 * ei / L, 2 * ei / L
    for (r, q), v in {(1, 1): b12, (1, 2): b6, (1, 4): -b12, (1, 5): b6, (2, 2): b4, (2, 4): -b6, (2, 5): b2,
                      (4, 4): b12, (4, 5): -b6, (5, 5): b4}.items():
        kl[:, r, q] = v
        kl[:, q, r] = v
    T = np.zeros((len(L), 6, 6))
    for o in (0, 3):
        T[:, o, o] = c
        T[:, o, o + 1] = s
        T[:, o + 1, o] = -s
        T[:, o + 1, o + 1] = c
        T[:, o + 2, o + 2] = 1.0
    kg = np.einsum("eji,ejk,ekl->eil", T, kl, T)
    dofs = np.concatenate((3 * pieces[:, :1] + np.arange(3), 3 * pieces[:, 1:] + np.arange(3)), axis=1)
    rows = np.repeat(dofs, 6, axis=1).ravel()
    cols = np.tile(dofs, (1, 6)).ravel()
    return coo_matrix((kg.ravel(), (rows, cols)), shape=(3 * n, 3 * n))


# --------------------------------------------------------------------------- reference networks
def triangular_lattice(spacing: float, extent: float, angle: float = 0.0, offset=(0.0, 0.0)) -> np.ndarray:
    """Edges (k, 2, 2) of an equilateral triangular lattice covering |x|, |y| <= extent (rotated by `angle`)."""
    n = int(math.ceil(2 * extent / spacing)) + 3
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
    a1, a2 = np.array([1.0, 0.0]), np.array([0.5, math.sqrt(3) / 2])
    pts = spacing * (i.ravel()[:, None] * a1 + j.ravel()[:, None] * a2)
    steps = spacing * np.array([a1, a2, a2 - a1])
    segs = np.concatenate([np.stack((pts, pts + st), axis=1) for st in steps])
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    segs = segs @ rot.T + np.asarray(offset, float)
    near = (np.abs(segs).max(axis=(1, 2)) <= extent + spacing)
    return segs[near]


def square_grid(spacing: float, extent: float, offset=(0.0, 0.0)) -> np.ndarray:
    """Edges (k, 2, 2) of a square grid of lines covering |x|, |y| <= extent, as whole lines."""
    c = np.arange(-extent, extent + spacing, spacing) + 0.5 * spacing
    h = np.stack((np.stack((np.full_like(c, -extent), c), 1), np.stack((np.full_like(c, extent), c), 1)), 1)
    v = h[:, :, ::-1]
    return np.concatenate((h, v)) + np.asarray(offset, float)


# --------------------------------------------------------------------------- G-code
def fill_segments(path, layer: int) -> np.ndarray:
    """The ``;TYPE:FILL`` extrusions (k, 2, 2) of one layer of a G-code file (the project's reader)."""
    from DelaunayInfill.gcode.preview import layer_segments

    return layer_segments(path, layer).get("FILL", np.zeros((0, 2, 2)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="In-plane stiffness of a layer's infill (frame model)")
    parser.add_argument("gcode")
    parser.add_argument("--layers", default=None, help="comma-separated ;LAYER: numbers (default: the middle one)")
    parser.add_argument("--window", type=float, default=30.0, help="square window side, mm (default 30)")
    parser.add_argument("--centre", default=None, help="X,Y of the window centre (default: the FILL lines' box centre)")
    parser.add_argument("--line-width", type=float, default=0.4)
    parser.add_argument("--joints", choices=("rigid", "pin"), default="rigid")
    args = parser.parse_args(argv)
    if args.layers is None:
        import re

        with open(args.gcode, encoding="utf-8", errors="replace") as f:
            numbers = [int(m) for m in re.findall(r"^;LAYER:(-?\d+)", f.read(), re.M)]
        layers = [numbers[len(numbers) // 2]]
    else:
        layers = [int(v) for v in args.layers.split(",")]
    centre = None if args.centre is None else [float(v) for v in args.centre.split(",")]
    Cs, rhos = [], []
    print("| layer | rho | C_min/rho | C_max/rho | isotropy | E_min/rho | nodes | pieces |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for layer in layers:
        seg = fill_segments(args.gcode, layer)
        res = stiffness(seg, args.line_width, window=args.window, centre=centre, joints=args.joints)
        Cs.append(res.C)
        rhos.append(res.rho)
        print(f"| {layer} | {res.rho:.4f} | {res.c_min:.4f} | {res.c_max:.4f} | {res.isotropy:.3f} | {res.e_min:.4f} "
              f"| {res.nodes} | {res.pieces} |")
    if len(layers) > 1:
        stack = from_tensor(np.mean(Cs, axis=0), float(np.mean(rhos)))
        print(f"| stack | {stack.rho:.4f} | {stack.c_min:.4f} | {stack.c_max:.4f} | {stack.isotropy:.3f} "
              f"| {stack.e_min:.4f} | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
