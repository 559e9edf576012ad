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
