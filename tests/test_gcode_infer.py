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
