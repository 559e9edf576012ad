"""Print-time estimate: a trapezoid motion model, one move at a time.

Every move accelerates from rest to its feedrate and decelerates back to
rest (junction speed zero), or reaches only a triangle profile when it is too
short.  The same model times Cura's original FILL moves and the new ones, so
the difference is what is added to ``;TIME_ELAPSED`` and the header.
"""

from __future__ import annotations

import numpy as np

__all__ = ["move_times", "moves_time"]


def move_times(distance, feedrate, acceleration: float) -> np.ndarray:
    """Seconds per move.

    Parameters
    ----------
    distance : array_like, shape (n,)
        Path length of each move, mm (for E-only moves: the E distance).
    feedrate : array_like, shape (n,)
        G-code F, mm/min.
    acceleration : float
        mm/s².

    Returns
    -------
    ndarray, shape (n,)
    """
    d = np.abs(np.asarray(distance, dtype=float))
    v = np.maximum(np.asarray(feedrate, dtype=float) / 60.0, 1e-3)
    a = max(float(acceleration), 1e-3)
    full = d >= v * v / a
    return np.where(full, d / v + v / a, 2.0 * np.sqrt(d / a))


def moves_time(dx, dy, dz, de, feedrate, acceleration: float) -> float:
    """Total seconds of G0/G1 moves given as per-move deltas (mm) and F (mm/min)."""
    dx, dy, dz, de = (np.asarray(a, dtype=float) for a in (dx, dy, dz, de))
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    dist = np.where(dist > 0, dist, np.abs(de))
    return float(move_times(dist, feedrate, acceleration).sum())
