"""Cura's infill density read off its FILL lines (`gcode/infer.py`)."""

import numpy as np
import pytest

from DelaunayInfill.gcode.infer import family_spacings, infill_density


def grid_lines(spacing: float, per_group: int, width: float, extent: float = 40.0, turn: float = 0.3) -> np.ndarray:
    """A grid of two families (turned by `turn` rad), each line printed `per_group` times a line width apart."""
    offsets = np.arange(-extent, extent, spacing)
    offsets = (offsets[:, None] + width * np.arange(per_group)[None]).ravel()
    lines = []
    for angle in (turn, turn + np.pi / 2):
        d = np.array([np.cos(angle), np.sin(angle)])
        n = np.array([-d[1], d[0]])
        for o in offsets:
            # pieces of each line, as Cura's lines are cut by holes and walls
            for a in np.arange(-extent, extent, 7.0):
                lines.append([o * n + a * d, o * n + (a + 5.0) * d])
    return np.array(lines)


@pytest.mark.parametrize("per_group", [1, 2, 3])
@pytest.mark.parametrize("density", [0.1, 0.2, 0.4])
def test_a_line_multiplier_reads_as_its_density(density, per_group):
    """Cura's infill line multiplier prints each line several times a line width apart: the density is
    the groups' (2 families x per_group x w / pitch), not the pair's own gap (a 40 % grid of pairs
    read as 200 % and the pass printed the everyday pillars at 69 % for 35 % with CuraEngine 5.0)."""
    w = 0.4
    pitch = 2 * w * per_group / density  # each family's share: per_group * w / pitch = density / 2
    fill = grid_lines(pitch, per_group, w)
    assert infill_density(fill, w) == pytest.approx(density, rel=0.03)
    assert len(family_spacings(fill, w)) == 2


def test_touching_lines_are_not_read_as_groups():
    """Lines a line width apart everywhere (one family at 100 %) are plain lines: every gap narrow."""
    w = 0.4
    fill = grid_lines(w, 1, w, extent=10.0)
    one_family = fill[: len(fill) // 2]
    assert infill_density(one_family, w) == pytest.approx(1.0, rel=0.03)


def _walls_layer(walls: int, width: float = 0.4, side: float = 30.0) -> str:
    """One Cura layer of a square part: its outer wall, then `walls - 1` inner walls a width apart each."""
    lines, e = [";LAYER:3", "G0 F6000 X0 Y0 Z0.8"], 0.0
    for k in range(walls):
        kind = "WALL-OUTER" if k == 0 else "WALL-INNER"
        inset = width / 2 + k * width
        corners = [(inset, inset), (side - inset, inset), (side - inset, side - inset), (inset, side - inset)]
        lines += [f";TYPE:{kind}", ";MESH:part.stl", f"G0 F6000 X{corners[0][0]:.3f} Y{corners[0][1]:.3f}"]
        for x, y in corners[1:] + corners[:1]:
            e += 0.03
            lines.append(f"G1 F1500 X{x:.3f} Y{y:.3f} E{e:.5f}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("walls", [2, 3, 4, 6])
def test_the_line_width_is_the_first_inner_wall_s_distance_however_many_walls(walls):
    """The inner walls lie one, two, ... widths inside the outer one: with four walls the median of all
    their distances read 0.8 mm for 0.4 mm lines (and the CLI printed the cup's 20 % as 40 %)."""
    from DelaunayInfill.gcode.infer import wall_line_width
    from DelaunayInfill.gcode.read import MachineState, RetractionModel, parse_layer

    parse = parse_layer(_walls_layer(walls), MachineState(), RetractionModel())
    assert wall_line_width(parse, "part.stl") == pytest.approx(0.4, abs=0.01)


def _skin_layer(width: float, side: float = 20.0, ironing: bool = False, turn: float = 0.4) -> str:
    """One Cura layer of skin: a zigzag of lines `width` apart across a square, turned by `turn` rad,
    with one outer wall only (no inner wall to measure from); optionally ironing lines 0.1 mm apart
    at a tenth of the flow over it, as Cura types them too (SKIN)."""
    lines, e = [";LAYER:2", "G0 F6000 X0 Y0 Z0.6", ";MESH:part.stl", ";TYPE:WALL-OUTER"], 0.0
    for x, y in ((0, 0), (side, 0), (side, side), (0, side), (0, 0)):
        e += 0.03 * side
        lines.append(f"G1 F1500 X{x:.3f} Y{y:.3f} E{e:.5f}")
    c, s = np.cos(turn), np.sin(turn)

    def at(u, v):  # the square's centre, turned
        return side / 2 + c * u - s * v, side / 2 + s * u + c * v

    def zigzag(gap, rate):
        nonlocal e
        out, prev = [], None
        for k, v in enumerate(np.arange(-side / 3, side / 3, gap)):
            ends = (-side / 3, side / 3) if k % 2 == 0 else (side / 3, -side / 3)
            for u in ends:
                x, y = at(u, v)
                if prev is not None:
                    e += rate * float(np.hypot(x - prev[0], y - prev[1]))
                out.append(f"G1 X{x:.3f} Y{y:.3f} E{e:.5f}")
                prev = (x, y)
        return out

    lines += [";TYPE:SKIN", "G0 X{:.3f} Y{:.3f}".format(*at(-side / 3, -side / 3))] + zigzag(width, 0.05)
    if ironing:
        lines += ["G0 X{:.3f} Y{:.3f}".format(*at(-side / 3, -side / 3))] + zigzag(0.1, 0.005)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("width", [0.4, 0.6, 0.8])
@pytest.mark.parametrize("ironing", [False, True], ids=["skin", "ironed"])
def test_with_one_wall_the_line_width_is_the_skin_lines_spacing(width, ironing):
    """A 0.6 mm nozzle with Cura's 0.8 mm wall thickness prints one wall: no inner wall tells the line
    width (the CLI took 0.4 mm and printed 20 % as 24 %, 1-2 mm of it on skin); the skin's lines lie one
    line width apart, the ironing's at a tenth of the flow is left out."""
    from DelaunayInfill.gcode.infer import skin_line_width, wall_line_width
    from DelaunayInfill.gcode.read import MachineState, RetractionModel, parse_layer

    parse = parse_layer(_skin_layer(width, ironing=ironing), MachineState(), RetractionModel())
    assert wall_line_width(parse, "part.stl") is None
    assert skin_line_width(parse) == pytest.approx(width, abs=0.005)


def test_no_skin_lines_tell_no_line_width():
    from DelaunayInfill.gcode.infer import skin_line_width
    from DelaunayInfill.gcode.read import MachineState, RetractionModel, parse_layer

    parse = parse_layer(_walls_layer(1), MachineState(), RetractionModel())
    assert skin_line_width(parse) is None


@pytest.mark.parametrize("seed", range(4))
def test_nearest_other_move_is_the_exact_point_to_segment_distance(seed):
    """The tree of samples only finds the candidates; the distance is exact, a left-out move never
    counts, and nothing beyond the reach does (checked against every point x move pair)."""
    from DelaunayInfill.gcode.infer import _nearest_other_move

    rng = np.random.default_rng(seed)
    start = rng.uniform(0, 20, (300, 2))
    moves = np.stack([start, start + rng.normal(0, 3, (300, 2))], axis=1)
    points = rng.uniform(0, 20, (80, 2))
    left_out = np.stack([rng.integers(0, 300, 80), rng.integers(-1, 300, 80)], axis=1)
    got = _nearest_other_move(points, moves, left_out, 2.0)
    a, d = moves[:, 0], moves[:, 1] - moves[:, 0]
    rel = points[:, None] - a[None]
    t = np.clip((rel * d).sum(-1) / (d * d).sum(-1), 0, 1)
    dist = np.hypot(*np.moveaxis(rel - t[..., None] * d, -1, 0))
    dist[(np.arange(300)[None, None, :] == left_out[:, :, None]).any(axis=1)] = np.inf  # (-1 is none)
    want = dist.min(axis=1)
    want = np.where(want < 2.0, want, np.inf)
    assert np.isfinite(got).sum() > 40
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
