"""The infill density each mesh asks for, read from the user's settings, Cura's settings footer and its FILL lines.

Cura does not write a mesh's density into the G-code beside its lines, and the footer holds the print's
settings, not per-model ones: `MeshDensities` weighs the footer against what the lines' spacing (or, for
too few lines, their length over the area) says, and remembers per mesh what it has learned
(`_MeshFacts` in ``process.py``).  Densities are fractions.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numpy as np

from .footer import CuraFooter
from .infer import family_spacings, infill_density
from .settings import ProcessSettings

# A density read from the lines' spacing this much over what their length gives (in an area at least
# this many spacings across, where lines cut short at the border hardly count) is not the density
# (line patterns measure 0.86-1.09 on the everyday models; gradual infill's steps are denser in part
# of the area, so it is not asked there)
_SPACING_OVER_LENGTH = 1.2
_WIDE_AREA_SPACINGS = 4.0
# Cura patterns whose lines in one layer do not show their density as a spacing (lines in pairs whose
# gap changes from layer to layer): the footer's density holds even where their spacing disagrees
_PAIRED_LINE_PATTERNS = frozenset({"tetrahedral", "quarter_cubic", "cross", "cross_3d"})
#: a part with too few lines for families takes the footer's density while its lines' length over its
#: area, summed over the layers, lies within this factor of it (a 10 % cutting mesh in a 20 % print
#: reads 11-12 %)
_FEW_LINES_AGREE = 0.7
#: lines a mesh needs in a layer for their spacing to be remembered as its density
_FAMILY_LINES = 12
#: the density taken where nothing tells one
_FALLBACK = 0.2


class MeshDensities:
    """Each mesh's density for a run: the host's, a modifier's region's, and Cura's own.

    Parameters
    ----------
    settings : ProcessSettings
        The user's densities (per mesh, or for the print) win over everything read.
    footer : CuraFooter
        Cura's settings footer of the file (empty without one).
    gradual_steps : int
        Cura's Gradual Infill Steps (its sparser steps are not a density of their own).
    facts : callable
        ``facts(mesh)``: the run's `_MeshFacts` record of a mesh, made on first use.
    """

    def __init__(self, settings: ProcessSettings, footer: CuraFooter, gradual_steps: int, facts: Callable):
        self.s = settings
        self.footer = footer
        self.gradual_steps = gradual_steps
        self.facts = facts
        self.chunk = 0  # the chunk (layer) being processed: few-lines sums count each once
        self.layer_answers: dict[tuple, tuple] = {}  # this layer's `infill_density` answers
        self.few_lines: dict[tuple, float] = {}  # a modifier's density from one layer's few lines

    def new_layer(self, chunk: int) -> None:
        """Forget the last layer's answers (they are the lines' own, asked again within one layer)."""
        self.chunk = chunk
        self.layer_answers = {}

    def mesh(self, mesh: str, fill: np.ndarray, lw: float, area, alone: bool = False) -> float:
        """The density a host mesh's infill is to be printed at.

        `fill` (k, 2, 2) its FILL segments in this layer, mm; `area` its infill area (or None); `alone`:
        no modifier takes part of the area (its lines' length over the area then tells the density too).
        """
        ms = self.s.mesh(mesh)
        if ms is not None and ms.density is not None:
            return ms.density
        if self.s.density is not None:
            return self.s.density
        facts = self.facts(mesh)
        wanted, paired = self._footer(facts)
        if paired:
            return wanted
        if wanted is not None:
            spacings = family_spacings(fill, lw) if len(fill) >= _FAMILY_LINES else None
            # this layer's few lines counted first: the footer is taken while their sum agrees
            counted = spacings is None and self._count_few_lines(
                facts, fill, lw, wanted, area.area if area is not None and alone else None)
            if self._lines_agree(facts, wanted, spacings, counted, lw):
                return wanted
        if len(fill) < _FAMILY_LINES and facts.few_lines_chunk == self.chunk and facts.density is None:
            return facts.few_lines_mm * lw / facts.few_lines_area  # what its lines said so far, not one layer's few
        d = facts.density
        if d is None:
            d = self.of_lines(fill, lw, area.area if area is not None else None, by_length=alone)
            if d is None:
                return _FALLBACK
            if len(fill) >= _FAMILY_LINES:
                facts.density = d
        elif len(fill) >= _FAMILY_LINES:
            # Cura made this mesh's infill denser from here on (gradual infill's steps under a top
            # surface): never print less than it does.
            here = self.of_lines(fill, lw)
            # (and their length says so too: paired lines read as a spacing print no denser)
            here_whole = self.of_lines(fill, lw, area.area if area is not None else None, by_length=alone)
            if (here is not None and here > 1.25 * d and here_whole is not None and here_whole > 1.25 * d
                    and family_spacings(fill, lw) is not None):
                d = facts.density = here
        return d

    def region(self, mesh: str, fill: np.ndarray, lw: float, area) -> float:
        """The density of the region an infill-mesh modifier makes (its FILL `fill`, its part `area`)."""
        ms = self.s.mesh(mesh)
        if ms is not None and ms.region_density is not None:
            return ms.region_density
        if ms is not None and ms.density is not None:
            return ms.density
        facts = self.facts(mesh)
        d = facts.region_density
        if d is None:
            # Too few lines to trust for every layer: remembered for this layer's very lines only.
            key = (mesh, lw, hashlib.blake2b(np.round(fill, 3).tobytes(), digest_size=12).digest(),
                   None if area is None else round(area.area, 3))
            d = self.few_lines.get(key)
            if d is None:
                d = self.of_lines(fill, lw, area.area if area is not None else None) or _FALLBACK
                if len(self.few_lines) >= 256:
                    self.few_lines.clear()
                self.few_lines[key] = d
            if len(fill) >= _FAMILY_LINES:
                facts.region_density = d
        return d

    def cura(self, mesh: str, fill: np.ndarray, lw: float) -> float:
        """Cura's own density of a mesh (from its FILL spacing), remembered."""
        facts = self.facts(mesh)
        d = facts.cura_density
        if d is None:
            d = self.of_lines(fill, lw) or _FALLBACK
            if len(fill) >= _FAMILY_LINES:
                facts.cura_density = d
        return d

    def of_lines(self, fill: np.ndarray, lw: float, area: float | None = None,
                 by_length: bool = False) -> float | None:
        """`infill_density`, remembered for the layer by the lines themselves.

        A mesh's lines are asked up to four times in its layer (the closing reach, the modifier
        split, the mesh's and the region's density).  With families found the area plays no part,
        so one look at the lines answers every area; only the fallback (no families) uses it, and
        `by_length` (the lines are all of `area`'s: no modifier takes part of it), where the spacing
        reads far denser than the length.
        """
        key = (fill.dtype.str, fill.shape, fill.tobytes(), lw)
        hit = self.layer_answers.get(key)
        if hit is None:
            hit = self.layer_answers[key] = (infill_density(fill, lw),)
        if hit[0] is None and area:
            return infill_density(fill, lw, area)
        if (by_length and hit[0] is not None and area and not self.gradual_steps
                and area >= (_WIDE_AREA_SPACINGS * lw / hit[0]) ** 2):
            # Octet, quarter cubic and cross infill pair their lines up at varying gaps: the gaps
            # read as a spacing print far denser than the lines' length over the area says they do
            by_length = float(np.hypot(*(fill[:, 1] - fill[:, 0]).T).sum() * lw / area)
            if hit[0] > _SPACING_OVER_LENGTH * by_length:
                return by_length
        return hit[0]

    def _footer(self, facts) -> tuple[float | None, bool]:
        """Cura's ``infill_sparse_density`` from the file's settings footer (None: none), and whether it
        holds whatever the lines say (a pattern whose lines pair up: their gaps tell no density)."""
        extruder = facts.extruder or 0
        wanted = self.footer.infill_density(extruder)
        if wanted is None or wanted <= 0.0:
            return None, False
        return wanted, (self.s.infill_pattern or self.footer.infill_pattern(extruder)) in _PAIRED_LINE_PATTERNS

    def _lines_agree(self, facts, wanted: float, spacings: list | None, counted: bool, lw: float) -> bool:
        """Whether a mesh's lines agree with the footer's density `wanted`.

        The footer holds the print's settings, not per-model ones: a mesh whose
        lines form clear families at another density (more than a quarter off)
        has a per-model density of its own, which its lines tell; so does a
        part with too few lines for families (`counted`) whose lines' length
        over its area, summed over such layers so far (`_count_few_lines`), is
        off the footer's by more than a factor 1.4 (a 10 % cutting mesh in a
        20 % print: Cura's lines there read 12 %).
        """
        if spacings is not None:
            return abs(sum(lw / sp for sp in spacings) - wanted) <= 0.25 * wanted
        if counted:
            by_length = facts.few_lines_mm * lw / facts.few_lines_area
            return _FEW_LINES_AGREE * wanted <= by_length <= wanted / _FEW_LINES_AGREE
        return True

    def _count_few_lines(self, facts, fill: np.ndarray, lw: float, wanted: float, area: float | None) -> bool:
        """Add this layer's lines and area to the mesh's few-lines sums (once a chunk); False: not such a part.

        Only parts over two line spacings square count (a small island's few clipped lines say little),
        and not with gradual infill (its sparser steps are replaced at the full density: not a density of
        its own).
        """
        if not len(fill) or not area or area < (4.0 * lw / wanted) ** 2 or self.gradual_steps:
            return False
        if facts.few_lines_chunk != self.chunk:
            facts.few_lines_chunk = self.chunk
            facts.few_lines_mm += float(np.hypot(*(fill[:, 1] - fill[:, 0]).T).sum())
            facts.few_lines_area += area
        return True
