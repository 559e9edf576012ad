"""Print-time estimate: a trapezoid motion model with jerk-limited corners.

Every move accelerates from its entry speed to its feedrate and decelerates to its exit speed, or
reaches only a triangle profile when it is too short. Between two consecutive extrusion moves the
nozzle keeps the speed that a classic XY jerk limit allows at that corner (Marlin's "jerk", which
CuraEngine's own estimate models too), bounded so that both moves can reach and leave it; travels,
retractions and Z moves start and end at rest. The same model times Cura's original FILL moves and
the new ones, so the difference is what is added to ``;TIME_ELAPSED`` and the header.

Why corners matter: a rest-to-rest model charges every segment a full stop, which overstates the
time of patterns made of short segments (Cura's gyroid by about 55 % against CuraEngine's own
figure, Delaunay chains less so) while long straight lines barely change (`bench/bench_estimate.py`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_JERK", "junction_speeds", "move_seconds", "move_times", "moves_time"]

#: mm/s: fdmprinter's ``machine_max_jerk_xy``, the corner speed limit CuraEngine's estimate uses
DEFAULT_JERK = 20.0


def move_times(distance, feedrate, acceleration: float, entry=None, exit=None) -> np.ndarray:
    """Seconds per move.

    Parameters
    ----------
    distance : array_like, shape (n,)
        Path length of each move, mm (for E-only moves: the E distance).
    feedrate : array_like, shape (n,)
        G-code F, mm/min.
    acceleration : float
        mm/s².
    entry, exit : array_like, shape (n,), optional
        Speed at the start and at the end of each move, mm/s (default 0: from rest to rest). Each
        must be reachable within its move (`junction_speeds` gives such speeds).

    Returns
    -------
    ndarray, shape (n,)
    """
    d = np.abs(np.asarray(distance, dtype=float))
    v = np.maximum(np.asarray(feedrate, dtype=float) / 60.0, 1e-3)
    a = max(float(acceleration), 1e-3)
    if entry is None and exit is None:
        full = d >= v * v / a
        return np.where(full, d / v + v / a, 2.0 * np.sqrt(d / a))
    v0 = np.minimum(np.zeros_like(d) if entry is None else np.asarray(entry, dtype=float), v)
    v1 = np.minimum(np.zeros_like(d) if exit is None else np.asarray(exit, dtype=float), v)
    cruise = d - (2.0 * v * v - v0 * v0 - v1 * v1) / (2.0 * a)
    peak = np.minimum(np.sqrt(np.maximum(a * d + (v0 * v0 + v1 * v1) / 2.0, 0.0)), v)
    trapezoid = (2.0 * v - v0 - v1) / a + np.maximum(cruise, 0.0) / v
    triangle = (2.0 * peak - v0 - v1) / a
    return np.where(cruise >= 0.0, trapezoid, triangle)


def junction_speeds(dx, dy, feedrate, acceleration: float, jerk: float, joined) -> np.ndarray:
    """Speed at each corner between consecutive moves, mm/s.

    Parameters
    ----------
    dx, dy : array_like, shape (n,)
        XY components of each move, mm.
    feedrate : array_like, shape (n,)
        G-code F, mm/min.
    acceleration : float
        mm/s².
    jerk : float
        Largest instant change of the XY velocity vector at a corner, mm/s.
    joined : array_like of bool, shape (n - 1,)
        Whether move i + 1 follows move i without a stop (else the corner speed is 0).

    Returns
    -------
    ndarray, shape (n - 1,)
        At most both moves' speeds, at most what the jerk allows for the turn, and at most
        sqrt(acceleration * length) of the shorter move, so that every move can reach both of its
        corner speeds from each other (no look-ahead over several moves needed).
    """
    dx = np.asarray(dx, dtype=float)
    dy = np.asarray(dy, dtype=float)
    joined = np.asarray(joined, dtype=bool)
    if len(dx) < 2:
        return np.zeros(0)
    length = np.hypot(dx, dy)
    moving = length > 0
    safe = np.where(moving, length, 1.0)
    ux, uy = dx / safe, dy / safe  # unit directions (0 for a move without XY)
    v = np.maximum(np.asarray(feedrate, dtype=float) / 60.0, 1e-3)
    corner = np.minimum(v[:-1], v[1:])
    turn = np.hypot(ux[1:] - ux[:-1], uy[1:] - uy[:-1])  # |change of direction|, 0 straight on .. 2 reversing
    corner = np.where(turn * corner > jerk, jerk / np.maximum(turn, 1e-12), corner)
    corner = np.minimum(corner, np.sqrt(max(float(acceleration), 1e-3) * np.minimum(length[:-1], length[1:])))
    return np.where(joined & moving[:-1] & moving[1:], corner, 0.0)


def move_seconds(dx, dy, dz, de, feedrate, acceleration: float, jerk: float = DEFAULT_JERK, breaks=None) -> np.ndarray:
    """Seconds of each move of a sequence, corners between extrusion moves at their jerk-limited speed.

    Parameters
    ----------
    dx, dy, dz, de : array_like, shape (n,)
        Per-move deltas, mm (E in E units).
    feedrate : array_like, shape (n,)
        G-code F, mm/min.
    acceleration : float
        mm/s².
    jerk : float
        mm/s, see `junction_speeds`.
    breaks : array_like of bool, shape (n - 1,), optional
        Corners where the sequence is cut anyway (e.g. between two FILL blocks timed apart).

    Returns
    -------
    ndarray, shape (n,)
    """
    dx, dy, dz, de = (np.asarray(a, dtype=float) for a in (dx, dy, dz, de))
    dxy = np.hypot(dx, dy)
    dist = np.sqrt(dxy * dxy + dz * dz)
    dist = np.where(dist > 0, dist, np.abs(de))
    if len(dist) < 2:
        return move_times(dist, feedrate, acceleration)
    extruding = (de > 0) & (dxy > 0) & (dz == 0)
    joined = extruding[:-1] & extruding[1:]
    if breaks is not None:
        joined &= ~np.asarray(breaks, dtype=bool)
    if not joined.any():  # e.g. Cura's grid: every extrusion line alone between travels
        return move_times(dist, feedrate, acceleration)
    corner = junction_speeds(dx, dy, feedrate, acceleration, jerk, joined)
    return move_times(dist, feedrate, acceleration, *_corner_ends(corner))


def _corner_ends(corner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit speeds of n moves from their n - 1 corner speeds (at rest at both ends)."""
    entry = np.zeros(len(corner) + 1)
    exit = np.zeros(len(corner) + 1)
    entry[1:] = corner
    exit[:-1] = corner
    return entry, exit


def moves_time(dx, dy, dz, de, feedrate, acceleration: float, jerk: float = DEFAULT_JERK) -> float:
    """Total seconds of G0/G1 moves given in order as per-move deltas (mm) and F (mm/min)."""
    return float(move_seconds(dx, dy, dz, de, feedrate, acceleration, jerk).sum())
