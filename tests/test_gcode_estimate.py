"""The print-time model: trapezoids, jerk-limited corners between extrusion moves."""

import math

import numpy as np
import pytest

from DelaunayInfill.gcode.estimate import junction_speeds, move_seconds, move_times, moves_time

A = 3000.0  # mm/s²
F = 3000.0  # mm/min = 50 mm/s


def test_rest_to_rest_trapezoid_and_triangle():
    v = F / 60
    long, short = 10.0, 0.2
    assert move_times([long], [F], A)[0] == pytest.approx(long / v + v / A)
    assert move_times([short], [F], A)[0] == pytest.approx(2 * math.sqrt(short / A))
    # explicit zero corner speeds are the same model
    assert move_times([long, short], [F, F], A, entry=[0, 0], exit=[0, 0]) == pytest.approx(move_times([long, short], [F, F], A))


def test_a_straight_line_cut_in_pieces_takes_as_long_as_the_whole():
    pieces = np.full(8, 5.0)
    split = moves_time(pieces, np.zeros(8), np.zeros(8), np.full(8, 0.2), np.full(8, F), A)
    whole = moves_time([40.0], [0.0], [0.0], [1.6], [F], A)
    assert split == pytest.approx(whole)


@pytest.mark.parametrize(("turn_deg", "expected"), [(90, 20.0 / math.sqrt(2)), (180, 10.0), (60, 20.0)])
def test_corner_speed_follows_the_jerk_limit(turn_deg, expected):
    angle = math.radians(turn_deg)
    dx, dy = [10.0, 10.0 * math.cos(angle)], [0.0, 10.0 * math.sin(angle)]
    corner = junction_speeds(dx, dy, [F, F], A, 20.0, [True])[0]
    # |change of the velocity vector| = speed * 2 sin(turn / 2) <= jerk
    assert corner == pytest.approx(min(50.0, expected))
    assert junction_speeds(dx, dy, [F, F], A, 20.0, [False])[0] == 0.0


def test_corner_speeds_are_reachable_within_short_moves():
    # 0.1 mm segments: no move can reach 50 mm/s; the corner stays within sqrt(a * length)
    corner = junction_speeds([0.1, 0.1], [0.0, 0.0], [F, F], A, 20.0, [True])[0]
    assert corner == pytest.approx(math.sqrt(A * 0.1))


def test_corners_only_between_extrusion_moves_and_never_across_a_break():
    dx, dy, dz = np.array([10.0, 0.0, 10.0, 10.0]), np.array([0.0, 10.0, 0.0, 0.0]), np.zeros(4)
    de = np.array([0.5, 0.5, 0.0, 0.5])  # the third move is a travel
    f = np.full(4, F)
    joined = move_seconds(dx, dy, dz, de, f, A, 20.0)
    rest = move_times(np.full(4, 10.0), f, A)
    assert joined[0] < rest[0] and joined[1] < rest[1]  # the corner between the two extrusions
    assert joined[2] == pytest.approx(rest[2]) and joined[3] == pytest.approx(rest[3])  # a travel stops
    cut = move_seconds(dx, dy, dz, de, f, A, 20.0, breaks=[True, False, False])
    assert cut == pytest.approx(rest)


def test_many_short_chained_moves_are_cheaper_than_rest_to_rest_but_never_faster_than_cruising():
    rng = np.random.default_rng(1)
    angles = np.cumsum(rng.uniform(-0.6, 0.6, 200))
    lengths = rng.uniform(1.0, 4.0, 200)
    dx, dy = lengths * np.cos(angles), lengths * np.sin(angles)
    f = np.full(200, F)
    seconds = move_seconds(dx, dy, np.zeros(200), np.full(200, 0.1), f, A, 20.0)
    assert (seconds >= lengths / (F / 60) - 1e-12).all()
    assert seconds.sum() < 0.9 * move_times(lengths, f, A).sum()
