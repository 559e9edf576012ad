"""``process_gcode`` and ``process_file``: Cura's FILL replaced by Delaunay infill.

Two passes over the chunks (one per ``;LAYER:``): a cheap survey (validity,
each mesh's footprint), then the rewrite, one chunk at a time, so a file is
never held in memory whole.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..combing import CombingArea
from ..geometry import (
    contains_xy,
    empty_area,
    multilinestring_of,
    polygons_of,
    to_multipolygon,
    unary_union,
)
from ..routing import TravelCost, order_paths, plan_runs
from .area import (
    carved_as_cura4,
    AreaCache,
    MeshLayer,
    closed_loops,
    fraction_inside,
    mesh_layer,
    piece_centres,
    sample_segments,
    segments_of,
    without_foreign,
    without_necks,
)
from .emit import EmitParams, emit_block
from .estimate import move_seconds, move_times
from .footer import read_footer
from .header import patch_header
from .infer import e_per_mm, family_spacings, skin_line_width, wall_line_width
from .read import (
    FILL,
    WALL_INNER,
    WALL_OUTER,
    GCodeError,
    HeaderInfo,
    LayerParse,
    MachineState,
    ProcessCancelled,
    RetractionModel,
    check_cura_gcode,
    iter_chunks,
    iter_file_chunks,
    parse_layer,
)
from .mesh_density import MeshDensities
from .patterns import PatternCache, RegionSoFar, shape_key
from .replay import (
    LayerRecord,
    LayerWords,
    RepeatCache,
    layer_words,
    record_layer,
    replay_layer,
    shifted_time_line,
    splice_blocks,
)
from .settings import MeshSettings, ProcessReport, ProcessSettings, Region, RegionReport
from .split import split_by_line_ends
from .stages import OFF
from .witness import (
    isolated_cura_lines,
    kd_tree,
    kept_cura_pieces,
    new_line_places,
    segment_polylines,
    witness_radius,
    witnessed,
)

__all__ = [
    "process_gcode",
    "process_file",
    "ProcessSettings",
    "MeshSettings",
    "Region",
    "ProcessReport",
    "GCodeError",
    "ProcessCancelled",
]

_TIME_ELAPSED = re.compile(r"^;TIME_ELAPSED:(-?[\d.]+)", re.M)
_M204 = re.compile(r"^M204 [^\n;]*?S(\d+\.?\d*)", re.M)
_LAYER_NUMBER = re.compile(r";LAYER:(-?\d+)")
_EXTRUDING_XY = re.compile(r"^G1 (?:F[\d.]+ )?X(-?[\d.]+) Y(-?[\d.]+) E", re.M)
_DEFAULT_LINE_WIDTH = 0.4
_RETRACT_TRAVEL_MM = 40.0  # a retraction and prime take about as long as this much travel
_NEGLIGIBLE_AREA = 1e-9  # share of an area below which what is left of it is rounding, not a zone
_NO_AREA_MM2 = 1e-9  # an infill area this small (mm²) is a sliver the cuts left, nothing to fill (`as_area` refuses it)
# the report's counters that a repeated layer adds to again (`_Run._totals`)
_COUNTED = ("layers_total", "layers_processed", "layers_kept", "infill_before_mm", "infill_after_mm",
            "infill_travel_mm", "infill_retractions", "blocks_replaced", "blocks_kept", "cura_infill_kept_mm",
            "layers_with_cura_infill_kept")


# ----------------------------------------------------------------------------- survey
@dataclass
class Survey:
    """First pass (cheap): validity facts and totals needed before the rewrite."""

    first_chunk: str = ""
    last_chunk: str = ""
    layer_chunks: int = 0
    acceleration: float | None = None
    last_time_elapsed: float | None = None
    meshes: set = field(default_factory=set)  # the ;MESH: names (NONMESH left out)
    # mesh -> [min x, min y, max x, max y] of its outer walls over the whole print, mm: where its
    # infill can ever be, so one pattern can serve all its layers (`PatternCache`)
    extents: dict = field(default_factory=dict)
    # mesh -> the last ;LAYER: number it prints in (`RegionSoFar.layers_left`)
    last_layers: dict = field(default_factory=dict)

    def add(self, text: str, index: int) -> None:
        if ";MESH:" in text:
            heads = _mesh_heads(text)
            names = {name for _, _, name in heads if name != "NONMESH"}
            self.meshes.update(names)
            if ";TYPE:WALL-OUTER" in text:
                self._add_extents(text, heads)
            number = _LAYER_NUMBER.match(text)
            if number:
                self.last_layers.update(dict.fromkeys(names, int(number.group(1))))
        if index == 0:
            self.first_chunk = text
        self.last_chunk = text
        if text.startswith(";LAYER:"):
            self.layer_chunks += 1
        if self.acceleration is None and "M204" in text:
            m = _M204.search(text)
            if m:
                self.acceleration = float(m.group(1))
        at = text.rfind(";TIME_ELAPSED:")
        if at >= 0:
            m = _TIME_ELAPSED.match(text, at)
            if m:
                self.last_time_elapsed = float(m.group(1))

    def _add_extents(self, text: str, heads: list) -> None:
        for k, (_, head_end, name) in enumerate(heads):
            if name == "NONMESH":
                continue
            end = heads[k + 1][0] if k + 1 < len(heads) else len(text)
            at = text.find(";TYPE:WALL-OUTER", head_end, end)
            while at >= 0:
                stop = text.find(";TYPE:", at + 16, end)
                stop = end if stop < 0 else stop
                xy = _EXTRUDING_XY.findall(text, at, stop)
                if xy:
                    pts = np.asarray(xy, dtype=float)
                    lo, hi = pts.min(axis=0), pts.max(axis=0)
                    box = self.extents.get(name)
                    self.extents[name] = ([lo[0], lo[1], hi[0], hi[1]] if box is None else
                                          [min(box[0], lo[0]), min(box[1], lo[1]), max(box[2], hi[0]), max(box[3], hi[1])])
                at = text.find(";TYPE:WALL-OUTER", stop, end)


def _mesh_heads(text: str) -> list[tuple[int, int, str]]:
    """The ``;MESH:`` lines of a chunk: (start, end of the line, the name without trailing space) each.

    What ``^;MESH:(.*?)\\s*$`` finds (multi-line), found with `str.find` (a chunk has a few of them
    among thousands of lines).
    """
    starts = [0] if text.startswith(";MESH:") else []
    at = text.find("\n;MESH:")
    while at >= 0:
        starts.append(at + 1)
        at = text.find("\n;MESH:", at + 7)
    heads = []
    for start in starts:
        end = text.find("\n", start)
        end = len(text) if end < 0 else end
        heads.append((start, end, text[start + 6 : end].rstrip()))
    return heads


def _printed_kinds(parse: LayerParse) -> set[int]:
    """``mesh index * 64 + kind`` of every feature the layer extrudes (remembered with the parse)."""
    hit = parse._derived.get("printed kinds")
    if hit is None:
        m, extruding = parse.moves, parse.extruding()
        hit = parse._derived["printed kinds"] = set(np.unique(m["mesh"][extruding] * 64 + m["kind"][extruding]).tolist())
    return hit


def _walled_meshes(parse: LayerParse) -> set[str]:
    """The meshes that print an outer wall in this layer, by ``;MESH:`` name and by file name."""
    names = {parse.meshes[code // 64] for code in _printed_kinds(parse) if code % 64 == WALL_OUTER}
    return set().union(*map(_names_of, names))


def _names_of(mesh: str) -> set[str]:
    """A ``;MESH:`` name and that name without its folders: a Region made from the mesh may be named either way."""
    return {mesh, mesh.replace("\\", "/").rsplit("/", 1)[-1]}


def _has_both_walls(parse: LayerParse, mesh: str) -> bool:
    """Whether `mesh` prints an outer and an inner wall in this layer (else `wall_line_width` is None)."""
    if mesh not in parse.meshes:
        return False
    base = parse.meshes.index(mesh) * 64  # kinds (TYPE_CODES) are below 64
    printed = _printed_kinds(parse)
    return base + WALL_OUTER in printed and base + WALL_INNER in printed


def _move_seconds(moves: dict, acceleration: float, jerk: float) -> np.ndarray:
    """Seconds of every FILL-block move of a layer, shape (n,) (0 for the other moves), each block
    timed on its own (`estimate.move_seconds`): it starts and ends at rest, as the new block does."""
    block = moves["block"]
    rows = np.flatnonzero(block >= 0)
    seconds = np.zeros(len(block))
    if len(rows):
        b = block[rows]
        breaks = (b[:-1] != b[1:]) | (rows[1:] != rows[:-1] + 1)
        seconds[rows] = move_seconds(moves["x1"][rows] - moves["x0"][rows], moves["y1"][rows] - moves["y0"][rows],
                                     moves["z1"][rows] - moves["z0"][rows], moves["de"][rows], moves["f"][rows],
                                     acceleration, jerk, breaks=breaks)
    return seconds


def _split_empty_regions(regions: list) -> tuple[list, object, list]:
    """Separate 0 % regions ("no infill there") from the density regions.

    Parameters
    ----------
    regions : list of (MultiPolygon, float, str)
        (area, density fraction, name) in order; later regions win where they overlap.

    Returns
    -------
    (list, MultiPolygon or None, list)
        The regions with density > 0 (same order); the area with no infill
        (each 0 % region minus the later regions that overlap it), None when
        there is none; and (part, name) of each 0 % region for the report.
    """
    if all(d > 0.0 for _, d, _ in regions):
        return regions, None, []
    kept, parts = [], []
    for k, (a, d, name) in enumerate(regions):
        if d > 0.0:
            kept.append((a, d, name))
            continue
        later = [b for b, dd, _ in regions[k + 1 :] if dd > 0.0]
        part = to_multipolygon(a.difference(unary_union(later))) if later else a
        if not part.is_empty:
            parts.append((part, name))
    empty = to_multipolygon(unary_union([p for p, _ in parts])) if parts else None
    return kept, empty, parts


# ----------------------------------------------------------------------------- the run
_NOTHING_LEARNED = (*(None,) * 5, frozenset())
# FILL extruding this much more per mm (against the walls) than before: infill combined over layers
_COMBINED_RATIO = 1.6


@dataclass
class _RegionTally:
    target: float
    length: float = 0.0
    area: float = 0.0  # summed over the layers, mm2
    target_area: float = 0.0  # target x area, summed: where the target changes, the report's is their mean
    mixed: bool = False  # a layer had another target
    layers: int = 0  # layers in which the region holds infill area
    last_chunk: int = -1


def _tally_added(before: tuple | None, target: float, length: float, area: float, target_area: float,
                 mixed: bool) -> tuple:
    """What a layer added to one region's tally: (target, length, area), its target the layer's mean
    where the region's target has changed."""
    if before is not None:
        length, area, target_area = length - before[1], area - before[2], target_area - before[3]
    return (target_area / area if mixed and area > 1e-9 else target), length, area


@dataclass
class _MeshFacts:
    """What the run has learned of one mesh from its layers so far (None: not yet)."""

    line_width: float | None = None  # mm, from its walls (layers after the first)
    density: float | None = None  # its infill density, from its FILL lines
    region_density: float | None = None  # as an infill-mesh modifier: its region's density
    reach_density: float | None = None  # the first estimate, for the closing radius only
    cura_density: float | None = None  # Cura's own, from its FILL spacing
    extruder: int | None = None  # the extruder of its first block
    fill_wall_ratio: float | None = None  # smallest E per mm of its FILL over its walls' so far (one layer's infill)
    few_lines_mm: float = 0.0  # its FILL length in the layers with too few lines for families, summed ...
    few_lines_area: float = 0.0  # ... and its infill area there, mm2 (a part without modifiers)
    few_lines_chunk: int = -1  # the chunk they were last added for
    sections: tuple = ()  # combined infill: its last layers' rebuilt infill areas, newest last
    modifiers: frozenset = frozenset()  # as a host: its wall-less modifiers' names, from their FILL so far

    def learned(self) -> tuple:
        """What a layer's result depends on (the extruder only picks the footer's density, read anew)."""
        return (self.line_width, self.density, self.region_density, self.reach_density, self.cura_density,
                self.modifiers)


@dataclass
class _MeshStep:
    """One mesh in one layer: its rebuilt geometry and the widths it is processed with (mm)."""

    name: str
    geo: MeshLayer
    line_width: float
    overlap: float
    closing: float  # closing radius of a FILL hull: about Cura's line spacing


@dataclass
class _LayerRegions:
    """A host's density regions in one layer, as the pattern takes them."""

    regions: list  # (area, density fraction, name), later ones win: the modifiers' parts, then the user's
    covered_children: set  # modifiers whose area the host's seamless pattern fills
    split_parts_only: bool  # the regions are only the modifier split's parts (disjoint, inside the area)
    rimmed: list = field(default_factory=list)  # areas of wall-less infill meshes whose infill Cura insets


@dataclass
class _Nesting:
    """How a host meets the other hosts of its layer: a mesh with walls inside it (an infill mesh made with
    Per Model Settings), or its own part inside such a mesh."""

    inner_parts: list = field(default_factory=list)  # parts of the hosts inside this one (they fill them)
    lines_inside: object = None  # (k, 2, 2) Cura FILL of the outer host's modifiers inside this one, mm


@dataclass
class _FillArea:
    """Where a host's new infill goes in one layer, and what was cut out of its confirmed area for it."""

    area: object  # MultiPolygon, mm
    regions: list  # the density regions (area, density, name) but the 0 % ones, as the pattern takes them
    empty: object  # the 0 % regions' union (None: none)
    empty_parts: list  # (part, name) of each 0 % region, for the report
    before_empty: object  # the area before the 0 % cut (what a 0 % region's report counts)
    infill_walls: list  # Cura's infill walls, kept as printed (closed FILL loops), each (m, 2)
    in_walls: object  # which of the host's FILL segments are on them (None: no infill walls)
    pieces: object = None  # the islands of Cura's infill in `area` (CuraEngine 4.13's carving; None: its pieces)


@dataclass
class _HostInfill:
    """A mesh with its infill-mesh modifiers in one layer: what it prints, and into which of Cura's blocks."""

    mesh: _MeshStep
    blocks: list  # Cura's FILL blocks of the host and its modifiers (indices into parse.blocks)
    fill_blocks: list  # those that may carry new paths
    paths: list  # the new infill (and Cura's lines kept), in print order
    reach: float  # mm: a Cura line farther than this from new infill is not taken over
    empty: object  # the 0 % regions (None: none)
    covered_children: set  # modifiers whose area the host's seamless pattern fills
    travel_part: object  # where travel may go without leaving the part
    assigned: dict = field(default_factory=dict)  # block index -> its run of paths


@dataclass
class _LayerOut:
    """What the layer step has written so far: rewritten blocks, counters, the time added."""

    retraction: RetractionModel
    replaced: dict = field(default_factory=dict)  # block index -> its new lines
    stats: dict = field(default_factory=lambda: {
        "blocks_replaced": 0, "blocks_kept": 0, "infill_travel_mm": 0.0, "infill_retractions": 0,
        "cura_infill_kept_mm": 0.0, "layers_with_cura_infill_kept": 0})
    dt: float = 0.0
    old_times: object = None  # seconds of each of Cura's moves (computed at the first replaced block)
    layer_epm: dict = field(default_factory=dict)  # E per mm of a mesh's FILL (key: its name), all FILL (None)


class _Run:
    def __init__(
        self,
        settings: ProcessSettings,
        regions: Sequence[Region],
        info: HeaderInfo,
        survey: Survey,
        clock=OFF,
    ):
        self.clock = clock  # `stages.StageClock` with --stages, else a no-op
        self.s = settings
        self.user_regions = list(regions)
        self.info = info
        # CuraEngine 4 opens infill areas and insets wall-less modifiers by half a line width; 5 does neither
        self.cura4 = info.engine_version is None or info.engine_version < (5, 0)
        self.survey = survey
        self.state = MachineState()
        self.retraction = RetractionModel()
        self.report = ProcessReport(volumetric=info.volumetric)
        self.patterns = PatternCache(settings, extents=survey.extents)
        self.last_layers = survey.last_layers
        self.area_cache = AreaCache()
        self.meshes: dict[str, _MeshFacts] = {}  # by ;MESH: name
        self.first_lw: float | None = None  # the first line width learned from any mesh's walls
        self.tally: dict[str, _RegionTally] = {}
        self.chunks_seen = 0  # the layers' per-region tally counts a region once per chunk
        self.zone_areas: dict[tuple, tuple] = {}
        self.clips: dict[tuple, object] = {}
        self.result_memo: dict[int, tuple] = {}
        self.modifier_areas: dict[tuple, object] = {}
        self.shares: dict[tuple, tuple] = {}
        self.grown: dict[tuple, tuple] = {}
        self.inside_memo: dict[tuple, tuple] = {}
        self.witnessed_memo: dict[tuple, tuple] = {}
        self.xy_words: dict[int, tuple] = {}
        self._combing: dict[int, CombingArea] = {}  # id(part) -> its combing area (parts repeat on prisms)
        self.e_before: dict[int, float] = {}
        self.e_delta: dict[int, float] = {}
        self.time_delta = 0.0
        self.acceleration = survey.acceleration or settings.acceleration
        self.prev_z: float | None = None
        self.repeats = RepeatCache() if settings.repeat_layers else None
        self.footer = read_footer(survey.last_chunk)
        # Lightning infill shows only where it supports a top skin, not where infill may go: no witness
        # confirms the area, so Cura's infill stays.
        patterns = {settings.infill_pattern} if settings.infill_pattern else {
            self.footer.infill_pattern(e) for e in range(max(1, len(self.footer.extruder_values)))}
        self.keep_cura = "lightning" in patterns
        if self.keep_cura:
            self.report.warnings.append(
                "Cura's lightning infill kept: its lines do not show where infill may go. Choose another "
                "infill pattern (grid, for one) in Cura to have it replaced")
        # Infill as Support likewise prints infill only under the top surfaces it holds up: its lines
        # confirm a band a line spacing wide beyond that region, inside the part over nothing.
        support = settings.infill_support
        if support is None:
            support = any((self.footer.value("infill_support_enabled", e) or "").strip().lower() == "true"
                          for e in range(max(1, len(self.footer.extruder_values))))
        if support and not self.keep_cura:
            self.keep_cura = True
            self.report.warnings.append(
                "Cura's infill kept: Infill as Support prints infill only under the top surfaces it holds up, "
                "and its lines do not show how far that reaches. Turn Infill as Support off in Cura to have "
                "it replaced")
        steps = settings.gradual_infill_steps
        if steps is None:
            steps = self._footer_count("gradual_infill_steps")
        self.densities = MeshDensities(settings, self.footer, steps, self._facts)
        # Cura's Infill Wall Line Count: its closed FILL loops are kept
        self.infill_walls = (settings.infill_wall_lines if settings.infill_wall_lines is not None
                             else self._footer_count("infill_wall_line_count"))
        if steps > 0 and not self.keep_cura:
            self.report.warnings.append(
                f"Cura's gradual infill ({steps} step{'s' if steps > 1 else ''}) is replaced by uniform infill at its "
                "full density, which uses more material than Cura's: set Gradual Infill Steps to 0, or a "
                "lower infill density")
        # how many layers Cura's infill is combined over (Infill Layer Thickness): 1, none
        self.infill_layers = settings.infill_layers if settings.infill_layers is not None else self._footer_infill_layers()
        self.combined_kept = 0  # mesh layers that kept Cura's combined infill
        self.layer_sections: dict[str, object] = {}  # this layer's infill area of each mesh (combined infill only)
        self.lw_warned = False
        self.any_lw: float | None = None
        self.skin_lw: float | None = None  # the skin lines' spacing, while no walls have told the line width
        self.measured_lw: float | None = None

    def _footer_count(self, key: str) -> int:
        """The largest whole-number value of a setting over the footer's extruders (0: not there)."""
        found = [self.footer.number(key, e) for e in range(max(1, len(self.footer.extruder_values)))]
        return int(max([v for v in found if v is not None], default=0))

    # ------------------------------------------------------------------ combined infill layers
    # Cura's Infill Layer Thickness (N layers): Cura moves the infill that N layers share up into the top
    # one of the group, as a line N layers high, and leaves single lines where their sections differ.
    # A top layer whose infill area lies inside the areas of the layers below it in its group (a
    # prism's, a dome's: all of its infill is shared) is replaced, with lines as high as Cura's; every
    # other layer keeps Cura's infill (a growing section's top layer has single lines of its own).
    def _footer_infill_layers(self) -> int:
        """How many layers the footer's Infill Layer Thickness combines Cura's infill over (1: none)."""
        most = 1
        for e in range(max(1, len(self.footer.extruder_values))):
            thickness = self.footer.number("infill_sparse_thickness", e)
            height = self.footer.number("layer_height", e) or self.info.layer_height
            if thickness and height and height > 0:
                most = max(most, int(round(thickness / height)))
        return most

    def _fill_wall_ratio(self, parse: LayerParse, mesh: str) -> float | None:
        """E per mm of a mesh's FILL over its walls' in this layer (None: it has no FILL or no walls here)."""
        own = parse.extruding() & parse.mesh_mask(mesh)
        fill = own & parse.kind_mask(FILL)
        walls = own & (parse.kind_mask(WALL_INNER) | parse.kind_mask(WALL_OUTER))
        if not fill.any() or not walls.any():
            return None
        fill_rate, wall_rate = e_per_mm(parse, fill), e_per_mm(parse, walls)
        return fill_rate / wall_rate if fill_rate and wall_rate else None

    def _layers_high(self, parse: LayerParse, mesh: str) -> float | None:
        """How many layers high a mesh's FILL in this layer is: its E per mm against its walls' over the
        lowest such ratio of its layers so far (this one's included; None: no FILL or no walls here)."""
        ratio = self._fill_wall_ratio(parse, mesh)
        if ratio is None:
            return None
        facts = self._facts(mesh)
        facts.fill_wall_ratio = ratio if facts.fill_wall_ratio is None else min(facts.fill_wall_ratio, ratio)
        return ratio / facts.fill_wall_ratio

    def _combined_infill_in(self, parse: LayerParse) -> int:
        """How many layers high the highest FILL of this layer is, against the layers before (1: none)."""
        most = 1
        for mesh in parse.meshes:
            high = self._layers_high(parse, mesh)
            if high is not None and high > _COMBINED_RATIO:
                most = max(most, int(round(high)))
        return most

    def _combined_hosts(self, parse: LayerParse, steps: dict, hosts: list) -> list:
        """The hosts whose infill this layer replaces under combined infill: a top layer (its FILL as high
        as the group) whose infill area the layers below it in the group hold too."""
        n = self.infill_layers
        allowed = []
        for name, st in steps.items():
            facts = self._facts(name)
            high = self._layers_high(parse, name)
            top = high is not None and high > _COMBINED_RATIO
            area = st.geo.area
            below = facts.sections[-(n - 1):]
            if name in hosts:
                # (a tenth of a line width out is within the infill's own overlap into the walls)
                reach = 0.1 * st.line_width
                if top and len(below) == n - 1 and all(
                        area.difference(b.buffer(reach, 2)).area <= reach * reach for b in below):
                    allowed.append(name)
                elif top:  # (a layer below a top one has Cura's single lines only where it differs: they stay)
                    self.combined_kept += 1
            self._add_section(name, area)
            self.layer_sections[name] = area
        return allowed

    def _add_section(self, mesh: str, area) -> None:
        """A layer's infill area joins the mesh's recent ones (also for a layer written from an earlier one)."""
        facts = self._facts(mesh)
        facts.sections = (*facts.sections, area)[-(self.infill_layers - 1):]

    # ------------------------------------------------------------------ helpers
    def _facts(self, mesh: str) -> _MeshFacts:
        facts = self.meshes.get(mesh)
        if facts is None:
            facts = self.meshes[mesh] = _MeshFacts()
        return facts

    def _line_width(self, parse: LayerParse, mesh: str) -> float:
        ms = self.s.mesh(mesh)
        if self.measured_lw is None and _has_both_walls(parse, mesh) and parse.number is not None and parse.number >= 1:
            # the file's own width, for the report (an override far from it is worth a word)
            self.measured_lw = wall_line_width(parse, mesh) or None
        if ms is not None and ms.line_width:
            return ms.line_width
        if self.s.line_width:
            return self.s.line_width
        facts = self._facts(mesh)
        if facts.line_width is not None:
            return facts.line_width
        w = wall_line_width(parse, mesh) if _has_both_walls(parse, mesh) else None
        if w is not None:
            # The first layer may use its own (wider) line width: remember only later layers.
            if parse.number is not None and parse.number >= 1:
                facts.line_width = w
                self.first_lw = self.first_lw or w
            self.any_lw = self.any_lw or w
            return w
        if self.first_lw is not None:
            return self.first_lw
        if self.any_lw is None:
            for other in parse.meshes:
                w = wall_line_width(parse, other) if other != mesh and _has_both_walls(parse, other) else None
                if w is not None:
                    self.any_lw = w
                    break
        if self.any_lw is not None:
            return self.any_lw
        if self.skin_lw is not None:
            self.measured_lw = self.measured_lw or self.skin_lw
            return self.skin_lw
        if not self.lw_warned:
            self.report.warnings.append(f"line width not found from walls; using {_DEFAULT_LINE_WIDTH} mm (give --line-width)")
            self.lw_warned = True
        return _DEFAULT_LINE_WIDTH

    def _retraction(self) -> RetractionModel:
        r = RetractionModel(**vars(self.retraction))
        s = self.s
        if s.retraction_amount is not None:
            r.amount = s.retraction_amount
            r.seen = r.seen or s.retraction_amount > 0
        if s.retraction_retract_speed is not None:
            r.retract_f = s.retraction_retract_speed * 60
        if s.retraction_prime_speed is not None:
            r.prime_f = s.retraction_prime_speed * 60
        if s.retraction_hop is not None:
            r.hop = s.retraction_hop
        if s.firmware_retraction is not None:
            r.firmware = s.firmware_retraction
        return r

    def _tally(self, name: str, target: float, length: float, area: float) -> None:
        t = self.tally.get(name)
        if t is None:
            t = self.tally[name] = _RegionTally(target)
        t.length += length
        t.area += area
        t.target_area += target * area
        t.mixed |= target != t.target
        if area > 0 and t.last_chunk != self.chunks_seen:
            t.layers += 1
            t.last_chunk = self.chunks_seen

    # ------------------------------------------------------------------ per chunk
    def process_chunk(self, text: str) -> str:
        self.chunks_seen += 1
        self.layer_sections = {}
        words = layer_words(text) if self.repeats is not None and text.startswith(";LAYER:") else None
        repeat_key = None
        if words is not None:
            repeat_key = self._repeat_key(words)
            record = self.repeats.get(repeat_key)
            if record is not None:
                with self.clock("repeated layers"):
                    out = self._replay(text, words, record)
                if out is not None:
                    return out
            state_before, totals_before = self.state.copy(), self._totals()
        with self.clock("parse"):
            parse = parse_layer(text, self.state, self.retraction)
        m = parse.moves
        # Net E per extruder (retractions and primes included): what Cura's filament figure counts.
        has_e = m["de"] != 0
        if has_e.any():
            exts = m["ext"][has_e]
            if (exts == exts[0]).all():  # one extruder (the usual case): one sum, the same figure
                ext = int(exts[0])
                self.e_before[ext] = self.e_before.get(ext, 0.0) + float(m["de"][has_e].sum())
            else:
                for ext in np.unique(exts):
                    self.e_before[int(ext)] = self.e_before.get(int(ext), 0.0) + float(m["de"][has_e & (m["ext"] == ext)].sum())
        fill_len = parse.xy_length()[parse.extruding() & parse.kind_mask(FILL)].sum()
        self.report.infill_before_mm += float(fill_len)
        self.report.infill_after_mm += float(fill_len)
        lines = parse.lines
        time_lines = parse.time_elapsed_lines
        changed = False
        failed = False
        edits: list = []
        if parse.number is not None:
            self.report.layers_total += 1
            if not self.keep_cura and self.s.infill_layers is None and self.infill_layers < 2:
                found = self._combined_infill_in(parse)
                if found >= 2:
                    self.infill_layers = found
                    # (what earlier layers recorded was decided without the groups: not to be repeated,
                    # nor is this layer, decided before its group was known)
                    if self.repeats is not None:
                        self.repeats = RepeatCache()
                    words = None
                    self.report.warnings.append(
                        f"layer {parse.number} prints infill {found} layers high (Cura's Infill Layer Thickness): "
                        "only layers whose group of layers has one section are replaced")
            if self.skin_lw is None and self.first_lw is None and self.any_lw is None and not self.s.line_width \
                    and parse.number >= 1 and not self.keep_cura \
                    and not any(_has_both_walls(parse, mesh) for mesh in parse.meshes):
                # no walls to tell the line width: the skin's lines (the skin layers under the infill
                # come before any layer asks for it)
                with self.clock("areas"):
                    self.skin_lw = skin_line_width(parse)
            todo = [b for b in parse.blocks if b.has_moves and self.s.enabled(b.mesh)] if not self.keep_cura else []
            if not todo:
                self.report.layers_kept += 1
            else:
                try:
                    new_lines, dt, stats = self._layer(parse)
                except ProcessCancelled:
                    raise
                except Exception as exc:  # a failing layer keeps Cura's infill
                    failed = True
                    self.report.failed_layers.append(parse.number)
                    self.report.failure_messages.append(f"layer {parse.number}: {type(exc).__name__}: {exc}")
                else:
                    for key, value in stats.items():
                        setattr(self.report, key, getattr(self.report, key) + value)
                    if new_lines is None:
                        self.report.layers_kept += 1
                    else:
                        self.report.layers_processed += 1
                        lines, time_lines, edits = new_lines
                        changed = True
                        self.time_delta += dt
            # the regions' sections the layer was processed with (at its slice height, from the layer below)
            sections = self._region_sections(parse.z) if words is not None and self.user_regions else None
            self.prev_z = parse.z
        if words is not None and parse.number is not None and not failed:
            with self.clock("repeat records"):
                self._record(repeat_key, text, words, parse, state_before, totals_before, edits, sections)
        if time_lines and self.time_delta != 0.0:
            if not changed:
                lines = list(lines)
            for i in time_lines:
                lines[i] = shifted_time_line(lines[i], self.time_delta)
            changed = True
        return "\n".join(lines) if changed else text

    # ------------------------------------------------------------------ repeated layers (replay.py)
    def _repeat_key(self, words: LayerWords) -> tuple:
        """What a layer's result depends on: its text (but Z and E numbers) and what this run remembers."""
        st = self.state
        # (the feature type before the layer only matters up to its first ;TYPE: line; Cura starts with one)
        type_before = None if words.key.startswith("\n;TYPE:") else st.type
        return (
            words.key,
            (st.x, st.y, st.f, st.depth, st.fw_retracted, st.extruder, type_before, st.mesh, st.relative_e,
             st.relative_xyz, st.e_mode_relative),
            *self._learned(),
        )

    def _learned(self) -> tuple:
        """What this run has learned so far that a layer's result depends on (retraction, per-mesh figures)."""
        combined = (self.infill_layers, tuple((name, tuple(_digest(a) for a in facts.sections))
                                              for name, facts in self.meshes.items() if facts.sections)
                    ) if self.infill_layers >= 2 else ()
        return (
            combined,
            tuple(vars(self.retraction).values()),
            self.any_lw,
            self.skin_lw,
            tuple((name, facts.learned()) for name, facts in self.meshes.items() if facts.learned() != _NOTHING_LEARNED),
        )

    def _totals(self) -> tuple:
        """The report's running totals (what a layer adds to them is what its repeats add again)."""
        r = self.report
        return (tuple(getattr(r, name) for name in _COUNTED), dict(self.e_before), dict(self.e_delta),
                {name: (t.target, t.length, t.area, t.target_area, t.mixed) for name, t in self.tally.items()}, self.time_delta)

    def _region_sections(self, z: float) -> list:
        z_slice = self._slice_z(z)
        return [r.at(z_slice).wkb for r in self.user_regions]

    def _record(self, key, text, words, parse: LayerParse, state_before: MachineState, totals_before: tuple,
                edits: list, sections: list | None) -> None:
        record = record_layer(text, words, parse.lines, state_before, parse.end_state, parse.z, edits,
                              parse.time_elapsed_lines, RetractionModel(**vars(self.retraction)))
        if record is None:
            return
        counted0, e_before0, e_delta0, tally0, time0 = totals_before
        counted1, e_before1, e_delta1, tally1, time1 = self._totals()
        record.extra["added"] = (
            tuple(b - a for a, b in zip(counted0, counted1, strict=True)),
            {k: v - e_before0.get(k, 0.0) for k, v in e_before1.items()},
            {k: v - e_delta0.get(k, 0.0) for k, v in e_delta1.items()},
            {k: _tally_added(tally0.get(k), *now) for k, now in tally1.items()},
            time1 - time0,
        )
        record.extra["regions"] = sections
        record.extra["sections"] = dict(self.layer_sections)
        self.repeats.put(key, record)
        # The layer has taught the run its retraction and per-mesh figures (each learned once, from
        # this layer's own lines, and used by it): the same layer met again with them gives this result.
        learned = (*key[:2], *self._learned())
        if learned != key:
            self.repeats.put(learned, record)

    def _replay(self, text: str, words: LayerWords, record: LayerRecord) -> str | None:
        """`text` written from the record of the layer it repeats; None when it does not repeat it after all."""
        added = record.extra["added"]
        if self.user_regions:
            layer_z = round(record.layer_z + (self.state.z - record.z_start), 6)
            if self._region_sections(layer_z) != record.extra["regions"]:
                return None
        done = replay_layer(text, words, record, self.state, self.time_delta + added[4])
        if done is None:
            return None
        out, self.state, self.prev_z = done
        counted, e_before, e_delta, tally, dt = added
        r = self.report
        if counted[_COUNTED.index("layers_processed")]:
            r.layers_repeated += 1  # repeats of layers that kept Cura's infill are not news
        for name, value in zip(_COUNTED, counted, strict=True):
            if value:
                setattr(r, name, getattr(r, name) + value)
        for k, v in e_before.items():
            self.e_before[k] = self.e_before.get(k, 0.0) + v
        for k, v in e_delta.items():
            self.e_delta[k] = self.e_delta.get(k, 0.0) + v
        for name, (target, length, area) in tally.items():
            self._tally(name, target, length, area)
        self.time_delta += dt
        vars(self.retraction).update(vars(record.retraction_after))
        for mesh, section in record.extra["sections"].items():
            self._add_section(mesh, section)
        if not record.blocks and not (record.time_lines and self.time_delta != 0.0):
            return text
        return out

    def _slice_z(self, z: float) -> float:
        h = None
        if self.prev_z is not None and 0 < z - self.prev_z < 2.0:
            h = z - self.prev_z
        if h is None:
            h = self.info.layer_height or min(z, 0.2)
        return z - h / 2

    def _layer(self, parse: LayerParse):
        """Cura's FILL of one parsed layer replaced: areas, density regions, patterns, routes, emit."""
        self.densities.new_layer(self.chunks_seen)
        clock = self.clock
        with clock("areas"):
            steps = self._mesh_steps(parse)
        parent_of = self._modifiers_of(steps)
        hosts = [n for n in steps if self.s.enabled(n) and n not in parent_of]
        if self.infill_layers >= 2:
            hosts = self._combined_hosts(parse, steps, hosts)
        if not hosts:
            return None, 0.0, {}
        for name in hosts:
            if not steps[name].geo.has_walls:  # a mesh of its own without walls: its area is its FILL hull
                st = steps[name]
                with clock("areas"):
                    st.geo = mesh_layer(parse, name, st.line_width, st.overlap, st.closing, self.area_cache,
                                        cura4_opening=self.cura4)
        out = _LayerOut(retraction=self._retraction())
        children_of = {name: [steps[c] for c, p in parent_of.items() if p == name] for name in hosts}
        nesting = self._nesting(steps, hosts, children_of)
        for name in hosts:
            host = self._host_infill(parse, steps[name], children_of[name], out, nesting.get(name))
            if host is None:
                continue
            with clock("routes"):
                self._route(parse, host, out)
            with clock("emit"):
                self._emit_host(parse, host, out)
        with clock("emit"):
            return self._splice(parse, out)

    def _nesting(self, steps: dict, hosts: list, children_of: dict) -> dict[str, _Nesting]:
        """Hosts with walls that lie inside another host's part (an infill mesh with walls of its own):
        {host: _Nesting}, only for the hosts concerned.

        The inner one fills its part (`without_foreign` cuts it out of the outer one's area).  A wall-less
        modifier of the outer host may reach into it (Cura lets a modifier of higher order win there): its
        Cura lines inside are the inner host's to confirm and to keep where its new infill does not take
        over, never the outer host's (random regions 96: they were kept beside the inner host's new
        infill, which printed that place twice).
        """
        parts = {n: steps[n].geo.part for n in hosts if steps[n].geo.has_walls and steps[n].geo.part is not None}
        if len(parts) < 2:
            return {}
        out: dict[str, _Nesting] = {}
        for outer, outer_part in parts.items():
            grown = self._grown(outer_part, steps[outer].line_width)
            fills = [c.geo.fill for c in children_of[outer] if len(c.geo.fill)]
            fill = np.concatenate(fills) if fills else None
            middle = fill.mean(axis=1) if fill is not None else None
            for inner, inner_part in parts.items():
                if inner == outer or inner_part.difference(grown).area > 0.1 * inner_part.area:
                    continue
                out.setdefault(outer, _Nesting()).inner_parts.append(inner_part)
                if fill is None:
                    continue
                inside = fill[contains_xy(inner_part, middle[:, 0], middle[:, 1])]
                if len(inside):
                    nest = out.setdefault(inner, _Nesting())
                    nest.lines_inside = inside if nest.lines_inside is None else np.concatenate([nest.lines_inside, inside])
        return out

    def _mesh_steps(self, parse: LayerParse) -> dict:
        """Every mesh with FILL in the layer: its line width, overlap and rebuilt area (`mesh_layer`)."""
        s = self.s
        is_fill = parse.kind_mask(FILL)
        steps: dict[str, _MeshStep] = {}
        for b in parse.blocks:
            if not b.has_moves or b.mesh in steps:
                continue
            name = b.mesh
            facts = self._facts(name)
            if facts.extruder is None:
                facts.extruder = b.extruder
            lw = self._line_width(parse, name)
            ms = s.mesh(name)
            overlap = ms.infill_overlap if ms is not None and ms.infill_overlap is not None else s.infill_overlap
            if overlap is None:
                overlap = 0.1 * lw
            guess = facts.density or facts.region_density or facts.reach_density
            if guess is None:
                # Cura's own density of this mesh sets how far apart its FILL lines are.
                sel = parse.mesh_mask(name) & is_fill & (parse.moves["de"] > 0)
                guess = self.densities.of_lines(segments_of(parse.moves, sel), lw)
                if guess is not None:
                    facts.reach_density = guess  # only sets a closing radius: the first estimate will do
                guess = guess or 0.2
            closing = min(25.0, max(2 * lw, 1.5 * lw / max(guess, 0.04)))
            geo = mesh_layer(parse, name, lw, overlap, closing, self.area_cache, hull_without_walls=False,
                             cura4_opening=self.cura4)
            steps[name] = _MeshStep(name, geo, lw, overlap, closing)
        return steps

    def _modifiers_of(self, steps: dict) -> dict[str, str]:
        """Which meshes are density regions inside another (Cura infill_mesh modifiers): {modifier: host}."""
        s = self.s
        hosts = [st for st in steps.values() if s.enabled(st.name) and st.geo.has_walls and st.geo.part is not None]
        parent_of: dict[str, str] = {}
        for st in steps.values():
            # A mesh with walls here prints its own infill inside them (Cura cuts it out of the mesh around it,
            # and so does `without_foreign`): a host of its own, even when it is a density region.
            if st.geo.has_walls:
                continue
            for host in hosts:
                if host.name == st.name:
                    continue
                grown = self._grown(host.geo.part, host.line_width)
                if self._fraction_inside(st.geo.fill, grown, host.line_width) >= 0.9:
                    parent_of[st.name] = host.name
                    break
        return parent_of

    def _host_infill(self, parse: LayerParse, st: _MeshStep, children: list, out: _LayerOut,
                     nesting: _Nesting | None = None):
        """The new infill of a host mesh and its modifiers (None: none, Cura's stays): its area confirmed by
        Cura's lines, its density regions, the pattern's paths, and Cura's lines where those do not take over.
        `nesting`: the hosts inside this one, or the outer host's modifier lines inside this one."""
        nesting = nesting or _Nesting()
        lw = st.line_width
        clock = self.clock
        with clock("areas"):  # other meshes' walls and skin, and an infill mesh with walls inside this one
            st.geo = without_foreign(parse, st.geo, lw, self.area_cache)
        if not st.geo.used_hull:  # (a hull is made of the lines: witnessed already)
            with clock("areas"):
                st.geo = self._witnessed(parse, st.geo, [c.geo.fill for c in children], lw, nesting.lines_inside)
        g = st.geo
        area = g.area
        zones = self._layer_regions(parse, st, children)
        if area.is_empty:
            if len(g.fill):  # nothing confirmed: Cura's infill of this mesh stays, and is counted
                out.stats["cura_infill_kept_mm"] += float(np.hypot(*(g.fill[:, 1] - g.fill[:, 0]).T).sum())
                out.stats["layers_with_cura_infill_kept"] = 1
            return None
        # (Cura's lines of a mesh with modifiers cover only part of its area: their length says nothing)
        density = self.densities.mesh(st.name, g.fill, lw, area, alone=not children)
        if density <= 0.0:
            return None  # a 0 % mesh has no infill (Cura made none)
        fill = self._fill_area(g, area, zones, lw, [g.fill, *(c.geo.fill for c in children)])
        area, region_list, empty = fill.area, fill.regions, fill.empty
        my_blocks, fill_blocks, start, end = _host_blocks(parse.blocks, {st.name, *(c.name for c in children)})
        # (all of it 0 %: Cura's lines there go, nothing replaces them; or the cuts left a sliver without
        # area, random regions 264: Cura's lines stay where no new line takes over)
        if area.is_empty or not area.area > _NO_AREA_MM2:
            paths, used_regions = [], []
        else:
            with clock("patterns"):
                pattern, _, used_regions = self.patterns.get(st.name, area, density, lw, region_list,
                                                             self._so_far(st.name, density, parse.number))
                # Lines run to the area's edge, as Cura's own do (CuraEngine 4.13 and 5.0 end them on the
                # inner wall's edge grown by the infill overlap: the same infill length per area); the
                # stubs a clip leaves across a narrow stroke or in a sharp tip are left out below.
                result = self._clip(pattern, area, start, end)
                paths = self._paths(result, min_length=lw)  # (a stub under a line width prints a blob)
            with clock("density report"):
                self._measure(result, paths, area, density, used_regions, lw, disjoint=zones.split_parts_only,
                              base_name=self._base_name(st.name, density))
        reach = 2.5 * lw / min([density, *(d for _, d, _ in used_regions)])
        with clock("Cura's lines kept"):
            # (Cura's own lines that graze a 0 % region's border stay: its section of the region and ours
            # differ by the slicing's tolerance, and a small island's line lay a third inside ours, random
            # regions 276)
            empty_core = None if empty is None else to_multipolygon(empty.buffer(-lw / 2, 4))
            not_kept = empty_core if not nesting.inner_parts else to_multipolygon(
                unary_union([*nesting.inner_parts, *([empty_core] if empty_core is not None else [])]))
            paths = self._with_cura_kept(st, children, area, paths, reach, not_kept, start, out, fill.infill_walls,
                                         fill.in_walls, end, nesting.lines_inside, fill.pieces)
        for part, zname in fill.empty_parts:
            self._tally(zname, 0.0, 0.0, part.intersection(fill.before_empty).area)
        travel_part = g.part if g.part is not None else area.buffer(lw / 2)
        return _HostInfill(st, my_blocks, fill_blocks, paths, reach, empty, zones.covered_children, travel_part)

    def _fill_area(self, g: MeshLayer, area, zones: _LayerRegions, lw: float, cura_fills: list) -> _FillArea:
        """Where the new infill goes in a host's confirmed `area`: inside Cura's infill walls, outside the 0 %
        regions, and (CuraEngine 4.13) clear of what its carving of wall-less modifiers leaves empty
        (`cura_fills`: Cura's FILL of the host and of its modifiers, each (k, 2, 2) mm: where it runs stays)."""
        # Cura's Infill Wall Line Count: closed FILL loops round the infill area stay as Cura printed
        # them, and the new infill fills what they enclose
        infill_walls, in_walls = closed_loops(g.fill) if self.infill_walls > 0 else ([], None)
        if infill_walls:
            with self.clock("areas"):
                area = to_multipolygon(area.difference(multilinestring_of(infill_walls).buffer(lw / 2 + 1e-3, 4)))
        # 0 % regions are "no infill there": cut out of the area, not given to the engine
        before_empty = area
        regions, empty, empty_parts = _split_empty_regions(zones.regions)
        if empty is not None:
            area = to_multipolygon(area.difference(empty))
            # (a 0 % region's border within a line width of a wall leaves a neck where Cura prints nothing:
            # through it a pocket with Cura's line would count as part of the rest, random regions 81)
            with self.clock("areas"):
                area = without_necks(area, lw, self.cura4)
        pieces = None
        if zones.rimmed and not area.is_empty:  # (after the 0 % cut: a modifier's lines stop short of it too)
            with self.clock("areas"):
                carved = carved_as_cura4(area, zones.rimmed, lw, np.concatenate(cura_fills))
                area, pieces = carved.area, carved.pieces
                if zones.split_parts_only:  # (the split's parts are taken as parts of the area: cut them too;
                    # a part all in the rim is no region here)
                    cut = [(to_multipolygon(a.intersection(area)), d, name) for a, d, name in regions]
                    regions = [(a, d, name) for a, d, name in cut if not a.is_empty]
        return _FillArea(area, regions, empty, empty_parts, before_empty, infill_walls, in_walls, pieces)

    def _infill_mesh(self, name: str) -> bool:
        """Whether the settings name `name` a Cura infill mesh (the plugin's density regions)."""
        ms = self.s.mesh(name)
        return ms is not None and ms.region_density is not None

    def _layer_regions(self, parse: LayerParse, st: _MeshStep, children: list) -> _LayerRegions:
        """The density regions of a host in this layer: its modifiers' parts, then the user's at its slice height.

        The user's win where they overlap (a modifier's part is read off its lines, and the split gives
        a 0 % modifier's empty place to its neighbour: the command line's ``--modifier FILE.stl:0`` must
        hold there).
        """
        # (a region that is another mesh with walls here is cut out of this one's area with its walls: its
        # density is that mesh's, and in this one's pattern it would only thin the infill round it)
        others = _walled_meshes(parse) - _names_of(st.name)
        given = [(a, r.density, r.name or f"region {k + 1}") for k, r in enumerate(self.user_regions)
                 if not (r.name and r.name in others) for a in [r.at(self._slice_z(parse.z))] if not a.is_empty]
        # Without user regions here, the regions are the modifier split's parts: disjoint, inside the area.
        zones = _LayerRegions([], set(), split_parts_only=not given)
        # (the modifiers' parts are pieces of the host's area: `_modifier_areas` splits it)
        with self.clock("areas"):
            parts = self._modifier_areas(st, children) if children else []
        # CuraEngine 4.13 carves every wall-less infill mesh out of its host's area, one without lines in this
        # layer too (a later one took all its share: random regions 1): the given regions that are this
        # host's modifiers in any layer so far, in order
        facts = self._facts(st.name)
        facts.modifiers = facts.modifiers | {c.name for c in children}
        modifiers = set().union(*map(_names_of, facts.modifiers))
        # (a 0 % region prints no line to show it a modifier of the model, but carves as one: a later region
        # over it is inset twice, random regions 163; so does a region the plugin knows as an infill mesh before
        # it prints its first line, or if it never does, its share all slivers along the walls: random regions
        # 267; a region with walls is no modifier's host, seed 30, but a wall-less one that fills a layer of
        # its own, its model printing no FILL there, is the model's modifier still, and so are the others
        # beside it: random regions 289)
        walled_region = st.geo.has_walls and any(r.name and r.name in _names_of(st.name) for r in self.user_regions)
        rimmed = [(k, a) for k, (a, d, name) in enumerate(given)
                  if name in modifiers or (not walled_region and (d <= 0 or self._infill_mesh(name)))
                  ] if self.cura4 else []
        for c, ca in zip(children, parts, strict=True):
            if ca.is_empty:
                continue
            zones.covered_children.add(c.name)
            mine = any(name in _names_of(c.name) for _, _, name in given)
            if self.cura4 and not mine:
                rimmed.append((len(given) + len(rimmed), ca))
            if mine:
                continue  # the caller gave this modifier's exact mesh as a Region: keep that one only
            zones.regions.append((ca, self.densities.region(c.name, c.geo.fill, c.line_width, ca),
                                  f"mesh {c.name}"))
        # (in CuraEngine's mesh order, as the given regions are: a later modifier takes from the earlier ones)
        zones.rimmed = [a for _, a in sorted(rimmed, key=lambda item: item[0])]
        zones.regions.extend(given)
        return zones

    def _with_cura_kept(self, st: _MeshStep, children: list, area, paths: list, reach: float, not_kept, start,
                        out: _LayerOut, infill_walls: list = (), in_walls=None, end=None, lines_inside=None,
                        pieces=None) -> list:
        """`paths` with Cura's lines where the new infill does not take over, all in print order.

        Those lines (a part not confirmed, an island too small for the pattern, Cura's infill walls)
        are printed as Cura printed them, on the route with the new paths; `out` counts them.  None is
        kept in `not_kept` (0 % regions, the hosts inside this one); `lines_inside` are Cura lines of an
        outer host's modifier inside this one, kept as its own are; `pieces` the islands of Cura's infill in
        `area` when they are not its pieces.
        """
        own = st.geo.fill if in_walls is None else st.geo.fill[~in_walls]
        child_fills, apart = self._modifier_lines_apart(children, paths, st.line_width, reach, not_kept)
        cura_fill = np.concatenate([own, *child_fills, *([lines_inside] if lines_inside is not None else [])])
        kept = [*kept_cura_pieces(cura_fill, area, paths, st.line_width, reach, not_kept, pieces=pieces), *apart,
                *infill_walls]
        if kept:
            paths, _ = order_paths([*paths, *kept], start, end=end)
        out.stats["cura_infill_kept_mm"] += float(sum(np.hypot(*np.diff(k, axis=0).T).sum() for k in kept))
        out.stats["layers_with_cura_infill_kept"] = 1
        return paths

    def _route(self, parse: LayerParse, host: _HostInfill, out: _LayerOut) -> None:
        """The host's paths shared among its FILL blocks (`host.assigned`)."""
        host.assigned = {i: [] for i in host.blocks}
        if host.paths and len(host.fill_blocks) == 1:
            host.assigned[host.fill_blocks[0]] = list(host.paths)
        elif host.paths:
            # The host's and its modifiers' FILL blocks share the layer's route in runs of
            # consecutive paths, cut where the least travel is added (`plan_runs`): the route
            # keeps its order, Cura's blocks keep theirs.  A travel that leaves the part is
            # retracted (when Cura retracts): it costs about as much as this much more travel.
            penalty = _RETRACT_TRAVEL_MM if out.retraction.seen else 0.0
            self._share_paths(host.paths, host.fill_blocks, parse.blocks, host.travel_part, penalty, host.assigned,
                              _block_anchors(parse, host.fill_blocks))

    def _emit_host(self, parse: LayerParse, host: _HostInfill, out: _LayerOut) -> None:
        """Each of the host's FILL blocks rewritten with its paths, or kept as Cura's."""
        m, extr = parse.moves, parse.extruding()
        new_tree = None
        for bi in host.blocks:
            blk = parse.blocks[bi]
            mask = m["block"] == bi
            had_fill = bool((mask & extr).any())
            new_paths = host.assigned.get(bi, [])
            if had_fill and not new_paths and host.paths and blk.mesh in host.covered_children:
                # The host's seamless pattern fills this modifier's area (printed from other
                # blocks): keeping Cura's lines here would print it twice.
                had_fill = False
            elif not blk.unsupported and not new_paths and had_fill and (host.paths or host.empty is not None):
                # A block that got no new path keeps Cura's infill only where the new pattern leaves a gap.
                probe = sample_segments(segments_of(m, mask & extr), 2.0)
                covered = np.zeros(len(probe), dtype=bool)
                if host.paths:
                    if new_tree is None:
                        new_tree = kd_tree(np.concatenate([sample_segments(np.stack([p[:-1], p[1:]], axis=1),
                                                                           host.mesh.line_width) for p in host.paths]))
                    covered |= new_tree.query(probe)[0] <= host.reach
                if host.empty is not None:  # places of a 0 % region need no infill
                    covered |= contains_xy(host.empty, probe[:, 0], probe[:, 1])
                had_fill = float(covered.mean()) < 0.9
            if blk.unsupported or (not new_paths and had_fill):
                out.stats["blocks_kept"] += 1
                continue
            self._emit_block(parse, host, bi, new_paths, had_fill, out)

    def _emit_block(self, parse: LayerParse, host: _HostInfill, bi: int, new_paths: list, had_fill: bool,
                    out: _LayerOut) -> None:
        """One FILL block rewritten: Cura's E per mm and speeds, travels combed, Cura's state handed back."""
        s = self.s
        m, extr, moved = parse.moves, parse.extruding(), parse.moved()
        is_fill = parse.kind_mask(FILL)
        blk = parse.blocks[bi]
        mask = m["block"] == bi
        extrudes = bool((mask & extr).any())
        lw = host.mesh.line_width
        # a block that extrudes nothing takes its mesh's FILL rate, else the layer's (both
        # remembered for the layer: a modifier's travel-only blocks ask again and again)
        layer_epm = out.layer_epm
        epm = _block_rate(parse, mask & extr, blk.mesh, extr & is_fill, layer_epm) if extrudes else None
        if epm is None:
            if blk.mesh not in layer_epm:
                layer_epm[blk.mesh] = e_per_mm(parse, extr & is_fill & parse.mesh_mask(blk.mesh))
            epm = layer_epm[blk.mesh]
        if epm is None:
            if None not in layer_epm:
                layer_epm[None] = e_per_mm(parse, extr & is_fill)
            epm = layer_epm[None]
        if epm is None:
            if new_paths:
                out.stats["blocks_kept"] += 1
                return
            epm = 0.0
        ms = s.mesh(blk.mesh)
        speed = ms.speed if ms is not None and ms.speed else s.speed
        if speed:
            print_f = speed * 60.0
        elif had_fill:
            print_f = float(m["f"][mask & extr][0])
        else:
            fills = m["f"][extr & is_fill]
            print_f = float(fills[0]) if fills.size else blk.before.f
        g0 = m["f"][mask & ~extr & moved]
        retraction = out.retraction
        travel_f = s.travel_speed * 60.0 if s.travel_speed else (retraction.travel_f or (float(g0.max()) if g0.size else 9000.0))
        params = EmitParams(
            e_per_mm=epm * s.flow,
            print_f=print_f,
            travel_f=travel_f,
            retraction=retraction,
            part=host.travel_part,
            min_travel=s.retraction_min_travel if s.retraction_min_travel is not None else 2 * lw,
            layer_z=parse.z,
            xy_words=self.xy_words,
            comb=self._combing_area(host.travel_part, lw) if s.combing else None,
            comb_max=s.combing_max_distance,
            acceleration=self.acceleration,
            jerk=s.jerk,
        )
        written = emit_block(new_paths, blk.before, blk.after, params, blk.extra_lines)
        out.replaced[bi] = written.lines
        if out.old_times is None:
            with self.clock("estimate"):
                out.old_times = _move_seconds(m, self.acceleration, s.jerk)
        with self.clock("estimate"):
            old_t = float(out.old_times[mask].sum())
            new_t = written.seconds + (float(move_times(np.concatenate(written.dist), np.concatenate(written.feed),
                                                        self.acceleration).sum()) if written.dist else 0.0)
        out.dt += new_t - old_t
        # Net change of the filament used: every E move of the new block minus those of Cura's.
        old_net = float(m["de"][mask].sum())  # not after.e - before.e: Cura may G92 E0 inside
        self.e_delta[blk.extruder] = self.e_delta.get(blk.extruder, 0.0) + written.net_e - old_net
        old_len = float(parse.xy_length()[mask & extr & is_fill].sum())
        self.report.infill_after_mm += written.extrude_mm - old_len
        out.stats["blocks_replaced"] += 1
        out.stats["infill_travel_mm"] += written.travel_mm
        out.stats["infill_retractions"] += written.retractions

    def _splice(self, parse: LayerParse, out: _LayerOut):
        """The layer's lines with the rewritten blocks in place, where its ;TIME_ELAPSED: lines went, the edits."""
        stats = out.stats
        if not out.replaced:
            return None, 0.0, {k: stats[k] for k in ("blocks_kept", "cura_infill_kept_mm", "layers_with_cura_infill_kept")}
        if not math.isfinite(out.dt):
            raise ValueError("the print-time estimate of the new moves is not finite")
        blocks, replaced = parse.blocks, out.replaced
        order = sorted(replaced, key=lambda i: blocks[i].start)
        out_lines = splice_blocks(parse.lines, [(blocks[bi].start, blocks[bi].stop, replaced[bi]) for bi in order])
        # (start, stop, new lines, state before, state after) of each replaced block
        edits = [(blocks[bi].start, blocks[bi].stop, replaced[bi], blocks[bi].before, blocks[bi].after) for bi in order]
        shifts = [(stop, len(new) - (stop - start - 1)) for start, stop, new, _, _ in edits]  # (stop, lines added)
        # ;TIME_ELAPSED: lines end blocks (never inside one): each moves by what the blocks before it add
        time_lines = [t + sum(added for stop, added in shifts if t >= stop) for t in parse.time_elapsed_lines]
        if not all(out_lines[t].startswith(";TIME_ELAPSED:") for t in time_lines):
            time_lines = _time_lines(out_lines)
        return (out_lines, time_lines, edits), out.dt, stats

    def _modifier_lines_apart(self, children: list, paths: list, lw: float, reach: float,
                              not_kept) -> tuple[list, list]:
        """The modifiers' Cura lines, less the groups of them that no new line comes near for that modifier's
        own density (`isolated_cura_lines`), and those groups as polylines to keep (none in `not_kept`).
        A modifier no denser than the host's sparsest zone (whose `reach` `kept_cura_pieces` uses) is left
        to that."""
        fills, apart, places = [], [], None
        for c in children:
            fill = c.geo.fill
            if len(fill) == 0:
                continue
            spacing = lw / self.densities.cura(c.name, fill, lw)
            if 2.5 * spacing >= reach:
                fills.append(fill)
                continue
            if places is None:
                places = new_line_places(paths, lw)
            alone = isolated_cura_lines(fill, places, lw, link=2.0 * spacing, reach=2.5 * spacing)
            if alone.any() and not_kept is not None and not not_kept.is_empty:
                middle = fill[alone].mean(axis=1)
                alone[np.flatnonzero(alone)[contains_xy(not_kept, middle[:, 0], middle[:, 1])]] = False
            fills.append(fill[~alone])
            if not alone.any():
                continue
            # (as `kept_cura_pieces`: a piece under a line width prints a blob)
            apart.extend(p for p in segment_polylines(fill[alone]) if np.hypot(*np.diff(p, axis=0).T).sum() >= lw)
        return fills, apart

    def _witnessed(self, parse: LayerParse, g, child_fills: list, lw: float, lines_inside=None):
        """`g` with its area cut to what Cura's FILL lines of it and its modifiers (and `lines_inside`, an outer
        host's modifier lines inside it, (k, 2, 2)) confirm (remembered)."""
        fills = [g.fill, *child_fills, *([lines_inside] if lines_inside is not None else [])]
        h = hashlib.blake2b(digest_size=16)
        for f in fills:
            h.update(np.round(f, 3).tobytes() + b"|")
        key = (id(g.area), h.digest(), round(lw, 4))
        hit = self.witnessed_memo.get(key)
        if hit is not None and hit[0] is g.area:
            return hit[1]
        spacing = None
        for f in fills:
            if len(f) == 0:
                continue
            found = family_spacings(f, lw, quantile=0.9)
            if found is None:
                # no families of parallel lines (gyroid, concentric, ...): twice the spacing their length
                # gives (their lines wander, and a line multiplier doubles the length)
                d = self.densities.of_lines(f, lw, g.area.area) if not g.area.is_empty else None
                if d is None and not g.area.is_empty:
                    # too few lines to tell their pattern (gradual infill's sparsest steps print two or
                    # three): their length still tells how far apart they are
                    d = float(np.hypot(*(f[:, 1] - f[:, 0]).T).sum() * lw / g.area.area)
                found = [2.0 * lw / d] if d else None
            if found:
                spacing = max(spacing or 0.0, *found)
        # (each mesh's FILL lines in the order printed: `witnessed` joins them into runs only if it must)
        area = witnessed(g.area, np.concatenate(fills), lw, witness_radius(spacing, lw))
        out = replace(g, area=area)
        if len(self.witnessed_memo) >= 32:
            self.witnessed_memo.pop(next(iter(self.witnessed_memo)))
        self.witnessed_memo[key] = (g.area, out)
        return out

    def _share_paths(self, paths, fill_blocks: list[int], blocks, part, penalty: float, assigned: dict,
                     anchors: np.ndarray | None = None) -> None:
        """Cut the layer's route into one run of consecutive paths per Cura FILL block (`plan_runs`).

        Remembered per clip result (a prism's layers share their paths and blocks).
        """
        ends = tuple((blocks[b].before.x, blocks[b].before.y, blocks[b].after.x, blocks[b].after.y) for b in fill_blocks)
        key = (id(paths), id(part), penalty, tuple(fill_blocks), tuple(round(v, 2) for e in ends for v in e))
        hit = self.shares.get(key)
        if hit is None or hit[0] is not paths or hit[1] is not part:
            runs = _island_runs(paths, np.array(ends, dtype=float), anchors, part) if anchors is not None else None
            if runs is None:
                runs = plan_runs(list(paths), np.array(ends, dtype=float), TravelCost(part, penalty))
            hit = (paths, part, runs)
            if len(self.shares) >= 16:
                self.shares.pop(next(iter(self.shares)))
            self.shares[key] = hit
        for bi, run in zip(fill_blocks, hit[2], strict=True):
            assigned[bi] = list(run)

    def _fraction_inside(self, fill: np.ndarray, area, step: float) -> float:
        """`fraction_inside`, remembered for the last few (lines, area) pairs (prisms repeat them)."""
        # the lines' bytes in the key: modifiers with as many lines must not evict each other
        key = (id(area), fill.shape, fill.tobytes(), round(step, 6))
        hit = self.inside_memo.get(key)
        if hit is not None and hit[0] is area:
            return hit[1]
        value = fraction_inside(fill, area, step)
        if len(self.inside_memo) >= 32:
            self.inside_memo.pop(next(iter(self.inside_memo)))
        self.inside_memo[key] = (area, value)
        return value

    def _grown(self, area, by: float):
        """`area` buffered by `by` mm, remembered (the same part object comes back layer after layer)."""
        key = (id(area), round(by, 6))
        hit = self.grown.get(key)
        if hit is None or hit[0] is not area:
            hit = (area, area.buffer(by))
            if len(self.grown) >= 64:
                self.grown.pop(next(iter(self.grown)))
            self.grown[key] = hit
        return hit[1]

    def _modifier_areas(self, host: _MeshStep, children: list) -> list:
        """Areas of a host's infill-mesh modifiers in this layer (one split of the host's area).

        Cura ends infill lines half a line width minus the infill overlap
        inside their area, so the modifiers' borders are found from where
        their lines end (`split_by_line_ends`).
        """
        meshes = [host, *children]
        lw, overlap = host.line_width, host.overlap
        # The host's area (inside its walls) holds its modifiers' parts: Cura cuts them out of it.
        area = host.geo.area
        h = hashlib.blake2b(digest_size=16)
        for st in meshes:
            h.update(st.name.encode() + b"|" + np.round(st.geo.fill, 3).tobytes() + b"|")
        h.update(np.array([lw, overlap]).tobytes())
        key = (h.digest(), shape_key(area))
        hit = self.modifier_areas.get(key)
        if hit is not None:
            return hit
        spacings = [lw / self.densities.cura(st.name, st.geo.fill, lw) for st in meshes]
        end_inset = max(0.0, lw / 2 - overlap)
        parts = split_by_line_ends(area, [st.geo.fill for st in meshes], spacings, end_inset, step=max(lw, 0.25))[1:]
        if len(self.modifier_areas) > 64:
            self.modifier_areas.clear()
        self.modifier_areas[key] = parts
        return parts

    def _clip(self, pattern, area, start, end=None):
        """`pattern.clip`, remembered: a prism's layers clip the same area from and to the same nozzle positions."""
        key = (id(pattern), *shape_key(area), *(None if at is None else (round(at[0], 2), round(at[1], 2))
                                                 for at in (start, end)))
        hit = self.clips.get(key)
        if hit is None or hit[0] is not pattern:  # ids are reused once a pattern is freed
            hit = (pattern, pattern.clip(area, start=start, end=end))
            if len(self.clips) >= 8:
                self.clips.pop(next(iter(self.clips)))
            self.clips[key] = hit
        return hit[1]

    def _combing_area(self, part, lw: float) -> CombingArea | None:
        """The combing area of `part` (kept while the same part object comes back, as on prisms)."""
        if part is None or part.is_empty:
            return None
        hit = self._combing.get(id(part))
        if hit is None or hit.source is not part:
            if len(self._combing) >= 16:
                self._combing.pop(next(iter(self._combing)))
            hit = self._combing[id(part)] = CombingArea(part, margin=lw, tolerance=lw / 4)
        return hit

    def _paths(self, result, min_length: float = 0.0) -> list[np.ndarray]:
        """The result's paths as float arrays, the same objects for a remembered clip result.

        Pieces shorter than `min_length` (mm) are left out: a clip can leave a
        stub in a sharp corner or across a narrow stroke, which prints nothing
        useful yet costs a travel (and often a retraction) to reach.
        """
        hit = self.result_memo.get(id(result))
        if hit is None or hit[0] is not result or hit[3] != min_length:
            arrays = [np.asarray(p, dtype=float) for p in result.paths if len(p) >= 2]
            kept = arrays
            if arrays and min_length > 0:
                # every path's length at once: its steps' lengths summed (the steps between paths left out)
                points = np.concatenate(arrays)
                step = np.r_[np.hypot(*np.diff(points, axis=0).T), 0.0]
                heads = np.cumsum([0] + [len(a) for a in arrays[:-1]])
                step[heads[1:] - 1] = 0.0  # (the step from one path's end to the next path's start)
                lengths = np.add.reduceat(step, heads)
                kept = [a for a, n in zip(arrays, lengths.tolist(), strict=True) if n >= min_length]
            hit = (result, kept, {}, min_length)
            if len(self.result_memo) >= 16:
                self.result_memo.pop(next(iter(self.result_memo)))
            self.result_memo[id(result)] = hit
        return hit[1]

    def _zones(self, area, regions, lw, disjoint: bool = False):
        """Each zone and its area: index k regions[k], last the base (cached per area and regions).

        Zones are measured whole, the bands along their borders included (the
        pattern is calibrated on whole zones too: a region prints its density
        over all of itself).  `disjoint`: the regions are disjoint parts of
        `area` (a modifier split's), each its own part.
        """
        key = (*shape_key(area), tuple(id(r) for r in regions), round(lw, 4), disjoint)
        hit = self.zone_areas.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], regions, strict=True)):
            return hit[1]
        owns = [None] * len(regions)
        later = None  # the union of regions[k + 1:]
        for k in range(len(regions) - 1, -1, -1):
            a = regions[k][0]
            if disjoint:
                owns[k] = to_multipolygon(a)
                continue
            own = a.intersection(area)
            if later is not None:
                own = own.difference(later)
            if k > 0:  # (the union of them all is for the base zone only, when it has one)
                later = a if later is None else later.union(a)
            owns[k] = to_multipolygon(own)
        if not regions:
            owns.append(to_multipolygon(area))
        elif area.area - sum(own.area for own in owns) <= _NEGLIGIBLE_AREA * max(area.area, 1.0):
            # The regions' parts (disjoint, inside `area`) cover it: no base zone.  Said from their
            # areas, as the difference would say it: when the regions tile the part (modifiers),
            # `area` and their union share every border, and that difference is the slowest overlay.
            owns.append(empty_area())
        else:
            every = unary_union([r[0] for r in regions]) if disjoint else (
                regions[0][0] if later is None else later.union(regions[0][0]))
            owns.append(to_multipolygon(area.difference(every)))
        zones = (owns, [z.area for z in owns])
        if len(self.zone_areas) > 256:
            self.zone_areas.clear()
        self.zone_areas[key] = ([r for r in regions], zones)  # holding them keeps the ids valid
        return zones

    def _zone_lengths(self, result, paths, zones, lw) -> np.ndarray:
        """New infill length inside each zone, remembered per clip result and zones."""
        memo = self.result_memo[id(result)][2]
        key = (id(zones), lw)
        hit = memo.get(key)
        if hit is not None and hit[0] is zones:
            return hit[1]
        points = np.concatenate(paths)
        steps = np.ones(len(points) - 1, dtype=bool)  # point i to i + 1, but from one path to the next
        steps[np.cumsum([len(p) for p in paths[:-1]], dtype=np.int64) - 1] = False
        segs = np.stack([points[:-1][steps], points[1:][steps]], axis=1)
        pts, weight = piece_centres(segs, max(lw / 2, 0.1))  # (not the ends: a clipped line ends on the border)
        owner = np.full(len(pts), len(zones))  # len(zones): in no zone
        for k, zone in enumerate(zones):
            free = owner == len(zones)
            if zone.area > 0 and free.any():
                idx = np.flatnonzero(free)
                owner[idx[contains_xy(zone, pts[idx, 0], pts[idx, 1])]] = k
        lengths = np.bincount(owner, weights=weight, minlength=len(zones) + 1)[: len(zones)]
        memo[key] = (zones, lengths)
        return lengths

    def _measure(self, result, paths, area, base_density, regions, lw, disjoint: bool = False,
                 base_name: str = "base") -> None:
        """Accumulate new infill length x line width and area per density region (later regions win)."""
        if not paths:
            return
        zones, areas = self._zones(area, regions, lw, disjoint)
        lengths = self._zone_lengths(result, paths, zones, lw)
        for k, (_, dens, name) in enumerate(regions):
            self._tally(name, dens, float(lengths[k]) * lw, areas[k])
        self._tally(base_name, base_density, float(lengths[-1]) * lw, areas[-1])

    def _so_far(self, mesh: str, density: float, number: int | None) -> RegionSoFar | None:
        """What the region of a mesh's own `density` has printed so far, and the mesh's layers above `number`."""
        last = self.last_layers.get(mesh)
        if number is None or last is None:
            return None
        t = self.tally.get(self._base_name(mesh, density))
        return RegionSoFar(t.length, t.area, last - number) if t is not None else RegionSoFar(0.0, 0.0, last - number)

    def _base_name(self, mesh: str, density: float) -> str:
        """The report's name of a mesh's own `density`: "base", or "mesh NAME" when the mesh has a density
        of its own (a per-model setting, or lines that disagree with the footer's density)."""
        ms = self.s.mesh(mesh)
        if ms is not None and ms.density is not None:
            return f"mesh {mesh}"
        footer = self.footer.infill_density(self._facts(mesh).extruder or 0)
        if self.s.density is None and footer is not None and density != footer and not self.densities.gradual_steps:
            return f"mesh {mesh}"
        return "base"

    # ------------------------------------------------------------------ header
    def finish(self, header: str) -> str:
        r = self.report
        r.meshes = sorted(self.survey.meshes)
        r.line_width_found = self.measured_lw
        before = sum(self.e_before.values())
        r.filament_before_mm = before
        r.filament_after_mm = before + sum(self.e_delta.values())
        r.time_before_s = self.survey.last_time_elapsed or 0.0
        r.time_after_s = r.time_before_s + self.time_delta
        if self.combined_kept:
            r.warnings.append(
                f"Cura's infill kept in {self.combined_kept} layer(s): Cura's Infill Layer Thickness prints it "
                f"{self.infill_layers} layers high, and there the section grows over the layers below (new infill "
                "would lie over their walls). Set Infill Layer Thickness to the layer height to have it replaced "
                "everywhere")
        names = ["base", *[n for n in self.tally if n != "base"]]
        for name in names:
            t = self.tally.get(name)
            if t is None or ((name == "base" or name.startswith("mesh ")) and t.area <= 1e-6 and len(self.tally) > 1):
                continue  # regions tile the whole part (or the mesh, given as a region too): no zone of its own
            measured = t.length / t.area if t.area > 1e-9 else float("nan")
            target = t.target_area / t.area if t.mixed and t.area > 1e-9 else t.target
            r.regions.append(RegionReport(name, target, measured, t.area, t.layers))
        return patch_header(header, self.time_delta, self.e_before, self.e_delta, self.s, volumetric=self.info.volumetric,
                            layers=(r.layers_processed, r.layers_kept, len(r.failed_layers)))


def _digest(area) -> bytes:
    """A short digest of an area's geometry (its vertices to 0.001 mm)."""
    parts = [np.round(np.asarray(ring.coords), 3).tobytes() for p in polygons_of(area)
             for ring in (p.exterior, *p.interiors)]
    return hashlib.blake2b(b"|".join(parts), digest_size=16).digest()


def _host_blocks(blocks: list, names: set) -> tuple[list[int], list[int], tuple | None, tuple | None]:
    """A host's FILL blocks (its and its modifiers', `names`), those that may carry new paths, where the
    first starts and, when it is the only one, where it ends.

    Every FILL block of the host and its modifiers may carry new paths, travel-only ones too (Cura's
    hops between its blocks): a path printed on the way costs no travel.  Returns (indices into
    `blocks`, the supported ones among them, the first of those's start (x, y) mm or None, the
    single one's end (x, y) mm or None: the route is planned to end near it; several blocks share
    the route by `plan_runs`, which knows every block's ends).
    """
    mine = [i for i, b in enumerate(blocks) if b.has_moves and b.mesh in names]
    fill_blocks = [bi for bi in mine if not blocks[bi].unsupported] or mine[:1]
    first = blocks[fill_blocks[0]].before
    last = blocks[fill_blocks[0]].after if len(fill_blocks) == 1 else None
    return (mine, fill_blocks, (first.x, first.y) if math.isfinite(first.x) else None,
            (last.x, last.y) if last is not None and math.isfinite(last.x) else None)


def _block_anchors(parse: LayerParse, fill_blocks: list[int]) -> np.ndarray | None:
    """Per FILL block, the middle of its first FILL line, shape (b, 2) mm (None: a block prints none)."""
    m = parse.moves
    fill = parse.extruding() & parse.kind_mask(FILL)
    rows = np.flatnonzero(fill & np.isin(m["block"], fill_blocks))
    blocks, first = np.unique(m["block"][rows], return_index=True)  # each block's first FILL line
    if len(blocks) < len(fill_blocks):
        return None
    at = rows[first[np.searchsorted(blocks, fill_blocks)]]
    return np.c_[(m["x0"][at] + m["x1"][at]) / 2, (m["y0"][at] + m["y1"][at]) / 2]


def _island_runs(paths: list[np.ndarray], ends: np.ndarray, anchors: np.ndarray, part) -> list[list[np.ndarray]] | None:
    """One run per FILL block when each block fills an island of its own (None: they do not).

    CuraEngine 5.0 writes one FILL block per island (a pillar, a letter): a block's run is then the
    paths of its island, routed from where the block starts to where it ends, and no route needs sharing
    (`routing.plan_runs` costs every cut of a shared route, which grows with blocks x paths).
    Each block's Cura lines (`anchors`) must lie in a piece of `part` of its own, and every path must
    start in one of those pieces.

    Parameters
    ----------
    paths : list of ndarray, each (m, 2)
    ends : ndarray, shape (b, 4)
        Per block in print order: start x, y and end x, y, mm.
    anchors : ndarray, shape (b, 2)
        A point of each block's own FILL lines (`_block_anchors`), mm.
    part : (Multi)Polygon or None
        The islands (the mesh's part), mm.
    """
    if part is None or len(ends) < 2 or not paths or not np.isfinite(ends).all():
        return None
    pieces = polygons_of(part)
    if len(pieces) < len(ends):
        return None
    heads = np.array([p[0] for p in paths], dtype=float)
    block_piece = np.full(len(ends), -1)
    path_piece = np.full(len(paths), -1)
    for k, piece in enumerate(pieces):
        block_piece[contains_xy(piece, anchors[:, 0], anchors[:, 1])] = k
        path_piece[contains_xy(piece, heads[:, 0], heads[:, 1])] = k
    if (block_piece < 0).any() or len(set(block_piece.tolist())) < len(ends) or not np.isin(path_piece, block_piece).all():
        return None
    return [order_paths([paths[i] for i in np.flatnonzero(path_piece == k)], (b[0], b[1]), end=(b[2], b[3]))[0]
            if (path_piece == k).any() else [] for k, b in zip(block_piece, ends)]


def _block_rate(parse: LayerParse, moves: np.ndarray, mesh: str, fill: np.ndarray, rates: dict) -> float | None:
    """E per mm of path for a FILL block's new lines (E units/mm; None: the block prints nothing).

    Cura's rate for the layer's FILL (all of it, else the block's mesh's) when the block's own moves
    print at it to Cura's rounding (1e-5 E per move), else the block's own.  A rate taken from more
    moves carries less of that rounding: a block with a few short lines of its own would otherwise
    pass their rounding on to every new line, differently from layer to layer.

    Parameters
    ----------
    parse : LayerParse
    moves : ndarray of bool, shape (n,)
        The block's extruding moves.
    mesh : str
        The block's mesh.
    fill : ndarray of bool, shape (n,)
        The layer's extruding FILL moves.
    rates : dict
        The layer's rates by mesh (None: all FILL), filled in as they are asked for.
    """
    de = parse.moves["de"][moves]
    length = parse.xy_length()[moves]
    ok = (length > 1e-6) & (de > 0)
    own_length = float(length[ok].sum())
    if not ok.any() or own_length < 1e-3:
        return None
    own_e = float(de[ok].sum())
    slack = 1e-5 * int(ok.sum())
    for key in (None, mesh):
        if key not in rates:
            rates[key] = e_per_mm(parse, fill if key is None else fill & parse.mesh_mask(key))
        rate = rates[key]
        if rate is not None and abs(own_e - rate * own_length) <= slack:
            return rate
    return own_e / own_length


def _time_lines(lines: list[str]) -> list[int]:
    return [i for i, line in enumerate(lines) if line.startswith(";TIME_ELAPSED:")]


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


# ----------------------------------------------------------------------------- API
def _check_regions(regions) -> list[Region]:
    out = []
    for r in regions or ():
        if not isinstance(r, Region):
            raise TypeError(f"regions must be DelaunayInfill.gcode.Region objects, got {type(r).__name__}")
        out.append(r)
    return out


def process_gcode(
    layers: Sequence[str],
    settings: ProcessSettings | None = None,
    *,
    regions: Iterable[Region] = (),
    progress: Callable[[float], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    stages=None,
) -> tuple[list[str], ProcessReport]:
    """Replace Cura's sparse infill in Cura's in-memory G-code list.

    Parameters
    ----------
    layers : sequence of str
        ``scene.gcode_dict[plate]``: header, start, one string per ``;LAYER:``, end.
    settings : ProcessSettings, optional
    regions : iterable of Region
        Density regions (G-code coordinates).
    progress : callable(float), optional
        Called with the fraction done.
    cancel : callable() -> bool, optional
        Polled between layers; True raises ProcessCancelled.
    stages : stages.StageClock, optional
        Times the run's stages (``--stages``).

    Returns
    -------
    (list of str, ProcessReport)
        The new list (same split as the input) and what was done.  An already
        processed input comes back unchanged with ``report.already_processed``.

    Raises
    ------
    GCodeError
        Not complete Cura G-code.
    """
    t0 = time.perf_counter()
    settings = settings or ProcessSettings()
    settings.validate()
    regions = _check_regions(regions)
    layers = list(layers)
    if not layers or not any(layers):
        raise GCodeError("the input is empty")
    survey = Survey()
    chunks = list(iter_chunks(layers))
    for i, chunk in enumerate(chunks):
        survey.add(chunk, i)
    info = check_cura_gcode(layers[0] + (layers[1] if len(layers) > 1 else ""), chunks[-1] if len(chunks) > 1 else "", survey.layer_chunks)
    if info.processed:
        return layers, ProcessReport(already_processed=True, seconds=time.perf_counter() - t0)
    run = _Run(settings, regions, info, survey, clock=stages or OFF)
    out = []
    total = len(chunks)
    for i, chunk in enumerate(chunks):
        if cancel is not None and cancel():
            raise ProcessCancelled("cancelled")
        out.append(run.process_chunk(chunk))
        if progress is not None:  # every layer: Cura's message moves layer by layer
            progress((i + 1) / total)
    out[0] = run.finish(out[0])
    run.report.written = True
    if len(out) != len(layers):
        # The caller's list was not split at layers: hand back one string per chunk (still Cura's form).
        pass
    run.report.seconds = time.perf_counter() - t0
    if stages is not None:
        stages.total = run.report.seconds
    return out, run.report


def process_file(
    in_path,
    out_path=None,
    settings: ProcessSettings | None = None,
    *,
    regions: Iterable[Region] = (),
    in_place: bool = False,
    progress: Callable[[float], None] | None = None,
    cancel: Callable[[], bool] | None = None,
    write_unchanged: bool = True,
    keep_going: bool = True,
    stages=None,
) -> ProcessReport:
    """Process a G-code file, streaming layer by layer; write `out_path` atomically.

    The body goes to a temporary file first; then header (with the new totals)
    and body are written to a temporary file next to `out_path` and renamed over
    it.  Nothing is written when the input is refused, already processed, or
    processing raises; nor when no layer was processed and `write_unchanged`
    is False, nor when a layer failed and `keep_going` is False
    (``report.written`` says which).  `stages` (a `stages.StageClock`) times
    the run's stages, as for `process_gcode`.

    Raises
    ------
    GCodeError
        Not complete Cura G-code (nothing written).
    FileNotFoundError, ValueError
        Missing input, or neither `out_path` nor `in_place`.
    """
    t0 = time.perf_counter()
    settings = settings or ProcessSettings()
    settings.validate()
    regions = _check_regions(regions)
    in_path = os.fspath(in_path)
    if out_path is None:
        if not in_place:
            raise ValueError("give an output path, or in_place=True to replace the input")
        out_path = in_path
    out_path = os.fspath(out_path)
    if not os.path.isfile(in_path):
        raise FileNotFoundError(f"no such file: {in_path}")
    if os.path.abspath(out_path) == os.path.abspath(in_path) and not in_place:
        raise ValueError("the output would overwrite the input; use in_place=True for that")
    size = max(os.path.getsize(in_path), 1)

    def chunks():
        try:
            with open(in_path, encoding="utf-8", newline="") as f:
                yield from iter_file_chunks(f)
        except UnicodeDecodeError as exc:
            raise GCodeError(f"not a text G-code file ({exc.reason} at byte {exc.start})") from None

    survey = Survey()
    for i, chunk in enumerate(chunks()):
        survey.add(chunk, i)
    info = check_cura_gcode(survey.first_chunk, survey.last_chunk if survey.layer_chunks else "", survey.layer_chunks)
    if info.processed:
        return ProcessReport(already_processed=True, seconds=time.perf_counter() - t0)
    run = _Run(settings, regions, info, survey, clock=stages or OFF)
    out_dir = os.path.dirname(os.path.abspath(out_path))
    body_fd, body_path = tempfile.mkstemp(prefix=".delaunay-body-", suffix=".gcode", dir=out_dir)
    final_path = None
    try:
        header_out = None
        done = 0
        with os.fdopen(body_fd, "w", encoding="utf-8", newline="") as body:
            for i, chunk in enumerate(chunks()):
                if cancel is not None and cancel():
                    raise ProcessCancelled("cancelled")
                text = run.process_chunk(chunk)
                done += len(chunk)
                if i == 0:
                    header_out = text
                else:
                    body.write(text)
                if progress is not None:
                    progress(min(1.0, done / size))
        header_out = run.finish(header_out or "")
        if (not write_unchanged and run.report.layers_processed == 0) or (not keep_going and run.report.failed_layers):
            run.report.seconds = time.perf_counter() - t0
            if stages is not None:
                stages.total = run.report.seconds
            return run.report  # (the body's temporary file goes below)
        final_fd, final_path = tempfile.mkstemp(prefix=".delaunay-out-", suffix=".gcode", dir=out_dir)
        with os.fdopen(final_fd, "w", encoding="utf-8", newline="") as out, open(body_path, encoding="utf-8", newline="") as body:
            out.write(header_out)
            shutil.copyfileobj(body, out, 1 << 20)
            out.flush()
            os.fsync(out.fileno())
        # mkstemp makes 0600 files: give the output the mode an ordinary new file gets (or the old file's)
        if os.path.exists(out_path):
            shutil.copymode(out_path, final_path)
        else:
            os.chmod(final_path, 0o666 & ~_umask())
        os.replace(final_path, out_path)
        final_path = None
        run.report.written = True
    finally:
        if os.path.exists(body_path):
            os.unlink(body_path)
        if final_path is not None and os.path.exists(final_path):
            os.unlink(final_path)
    if progress is not None:
        progress(1.0)
    run.report.seconds = time.perf_counter() - t0
    if stages is not None:
        stages.total = run.report.seconds
    return run.report
