"""Settings, density regions and the report of a G-code run."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..geometry import empty_area, polygons_of, to_multipolygon
from .estimate import DEFAULT_JERK

__all__ = ["MeshSettings", "ProcessSettings", "Region", "RegionReport", "ProcessReport"]


@dataclass
class MeshSettings:
    """Per-mesh settings, keyed by the ``;MESH:`` name in `ProcessSettings.meshes`.

    Densities are fractions 0-1, lengths mm, speeds mm/s; None = inferred.
    ``region_density`` marks a density-region mesh (a Cura ``infill_mesh``).
    """

    enabled: bool = True
    density: float | None = None
    line_width: float | None = None
    speed: float | None = None
    infill_overlap: float | None = None
    region_density: float | None = None


@dataclass
class ProcessSettings:
    """Settings of a G-code run (see docs/gcode.md).  None = inferred from the G-code."""

    density: float | None = None
    line_width: float | None = None
    infill_overlap: float | None = None
    speed: float | None = None
    flow: float = 1.0
    seed: int = 0
    layout: str = "seamless"
    relax: int = 0
    calibration: str = "measured"
    meshes: dict[str, MeshSettings] = field(default_factory=dict)
    process_unlisted_meshes: bool = True
    filament_diameter: float | None = None
    volumetric_e: bool | None = None
    relative_e: bool | None = None
    retraction_amount: float | None = None
    retraction_retract_speed: float | None = None
    retraction_prime_speed: float | None = None
    retraction_hop: float | None = None
    retraction_min_travel: float | None = None
    # travel round concave corners and holes inside the part instead of retracting (Cura's
    # retraction_combing); a combed travel longer than combing_max_distance mm retracts (0: no limit)
    combing: bool = True
    combing_max_distance: float = 0.0
    firmware_retraction: bool | None = None
    travel_speed: float | None = None
    acceleration: float = 3000.0
    jerk: float = DEFAULT_JERK  # mm/s, XY corner speed limit of the time estimate (Cura's machine_max_jerk_xy)
    feather: float = 0.0
    # a layer that repeats an earlier one (a prism's middle layers) is written from that layer's
    # result (gcode/replay.py); False processes every layer on its own (for tests: same output)
    repeat_layers: bool = True
    # Cura's infill pattern of the print (None: from the G-code's settings footer, if it has one);
    # lightning infill is kept as Cura made it
    infill_pattern: str | None = None
    # Cura's gradual_infill_steps (None: from the settings footer): the pass replaces gradual infill
    # with uniform infill at the full density, and says so
    gradual_infill_steps: int | None = None
    # how many layers Cura's infill is combined over (its Infill Layer Thickness over the layer height;
    # None: from the settings footer, and the G-code's own extrusion): 2 or more keeps Cura's infill
    infill_layers: int | None = None
    # Cura's Infill as Support (infill_support_enabled; None: from the settings footer): kept as Cura made it
    infill_support: bool | None = None
    # Cura's Infill Wall Line Count (None: from the settings footer): its walls round the infill stay
    infill_wall_lines: int | None = None

    def validate(self) -> None:
        """Raise ValueError with a clear message for impossible values."""
        if self.density is not None and not (0.0 < self.density <= 1.0):
            raise ValueError(f"density must be in (0, 100] %, got {self.density * 100:g} %")
        for name in ("line_width", "infill_overlap", "speed", "retraction_amount", "travel_speed", "filament_diameter"):
            v = getattr(self, name)
            if v is not None and (not math.isfinite(v) or v < 0 or (v == 0 and name in ("line_width", "speed"))):
                raise ValueError(f"{name} must be a positive number, got {v}")
        if self.line_width is not None and not (0.05 <= self.line_width <= 5.0):
            raise ValueError(f"line width {self.line_width} mm is outside 0.05-5 mm")
        if not (0.1 <= self.flow <= 3.0):
            raise ValueError(f"flow must be between 10 % and 300 %, got {self.flow * 100:g} %")
        if not (math.isfinite(self.jerk) and self.jerk >= 0.0):
            raise ValueError(f"jerk must be a speed >= 0 mm/s, got {self.jerk}")
        if not (math.isfinite(self.feather) and self.feather >= 0.0):
            raise ValueError(f"feather must be a width >= 0 mm, got {self.feather}")
        if not (isinstance(self.relax, int) and 0 <= self.relax <= 1000):
            raise ValueError(f"relax must be a whole number of steps, 0 to 1000, got {self.relax}")
        if self.layout not in ("seamless", "paper"):
            raise ValueError(f"layout must be 'seamless' or 'paper', got {self.layout!r}")
        for name, ms in self.meshes.items():
            for key in ("density", "region_density"):
                v = getattr(ms, key)
                # 0 % is allowed: a Cura infill_mesh at 0 % means "no infill there"
                if v is not None and not (0.0 <= v <= 1.0):
                    raise ValueError(f"mesh {name!r}: {key} must be in [0, 100] %, got {v * 100:g} %")

    def mesh(self, name: str) -> MeshSettings | None:
        """Settings of a ``;MESH:`` name: exact match first, then by file name (CLI paths vary)."""
        ms = self.meshes.get(name)
        if ms is None and self.meshes:
            base = name.replace("\\", "/").rsplit("/", 1)[-1]
            for key, value in self.meshes.items():
                if key.replace("\\", "/").rsplit("/", 1)[-1] == base:
                    return value
        return ms

    def enabled(self, name: str) -> bool:
        ms = self.mesh(name)
        return ms.enabled if ms is not None else self.process_unlisted_meshes


@dataclass
class Region:
    """A density region: a triangle mesh (sliced per layer) or a fixed polygon.

    ``triangles`` (n, 3, 3) mm in G-code coordinates; ``polygon`` a shapely
    area used for ``z_min <= z <= z_max``; ``density`` fraction 0-1, where 0
    means "no infill here" (the region is cut out of the infill area).
    """

    density: float
    triangles: np.ndarray | None = None
    polygon: object = None
    z_min: float = -math.inf
    z_max: float = math.inf
    name: str = ""

    def __post_init__(self):
        if not (0.0 <= float(self.density) <= 1.0):
            raise ValueError(f"region {self.name or ''} density must be in [0, 100] %, got {self.density * 100:g} %")
        if (self.triangles is None) == (self.polygon is None):
            raise ValueError("a Region needs exactly one of triangles= or polygon=")
        if self.triangles is not None:
            tri = np.asarray(self.triangles, dtype=float)
            if tri.ndim != 3 or tri.shape[1:] != (3, 3) or len(tri) == 0:
                raise ValueError(f"region triangles must have shape (n, 3, 3), got {tri.shape}")
            if not np.isfinite(tri).all():
                raise ValueError("region triangles have NaN or infinite coordinates")
            self.triangles = tri
            zs = tri[:, :, 2]
            self.z_min = max(self.z_min, float(zs.min()))
            self.z_max = min(self.z_max, float(zs.max()))
        self._cache: dict[float, object] = {}

    @classmethod
    def from_stl(cls, path, density: float, offset=(0.0, 0.0, 0.0), name: str | None = None) -> Region:
        """A region from an STL file, shifted by `offset` (mm) into G-code coordinates."""
        import os

        from ..meshslice import read_stl

        tri = read_stl(path) + np.asarray(list(offset) + [0.0] * (3 - len(offset)), dtype=float)[:3]
        return cls(density=density, triangles=tri, name=name or os.path.basename(os.fspath(path)))

    def at(self, z: float):
        """The region's area at height `z` (MultiPolygon, possibly empty)."""
        if not (self.z_min <= z <= self.z_max):
            return empty_area()
        if self.polygon is not None:
            return to_multipolygon(self.polygon)
        key = round(float(z), 4)
        hit = self._cache.get(key)
        if hit is None:
            from ..meshslice import slice_mesh

            hit = slice_mesh(self.triangles, z)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def bounds_xy(self):
        if self.polygon is not None:
            polys = polygons_of(self.polygon)
            return to_multipolygon(polys).bounds if polys else None
        pts = self.triangles.reshape(-1, 3)
        return (*pts[:, :2].min(axis=0), *pts[:, :2].max(axis=0))


@dataclass
class RegionReport:
    """Target and measured density of one region (fractions), over all processed layers."""

    name: str
    target: float
    measured: float
    area_mm2: float  # summed over the layers it holds infill in
    layers: int = 0

    @property
    def area_per_layer_mm2(self) -> float:
        return self.area_mm2 / self.layers if self.layers else 0.0


def _shown_region_name(name: str) -> str:
    """A region's name for the summary: a mesh's or an STL's file name without its folders."""
    head, sep, rest = name.partition(" ")
    if head == "mesh" and sep:
        return f"mesh {os.path.basename(rest.replace(chr(92), '/')) or rest}"
    return os.path.basename(name.replace(chr(92), "/")) or name


@dataclass
class ProcessReport:
    """What a run did (see docs/gcode.md)."""

    layers_total: int = 0
    layers_processed: int = 0
    layers_kept: int = 0
    layers_repeated: int = 0  # of the processed and kept ones: written from an earlier layer they repeat
    failed_layers: list[int] = field(default_factory=list)
    failure_messages: list[str] = field(default_factory=list)
    regions: list[RegionReport] = field(default_factory=list)
    filament_before_mm: float = 0.0
    filament_after_mm: float = 0.0
    time_before_s: float = 0.0
    time_after_s: float = 0.0
    infill_before_mm: float = 0.0
    infill_after_mm: float = 0.0
    infill_travel_mm: float = 0.0
    infill_retractions: int = 0
    blocks_replaced: int = 0
    blocks_kept: int = 0
    # Cura's own lines printed where the new infill does not take over (`witness.kept_cura_pieces`)
    cura_infill_kept_mm: float = 0.0
    layers_with_cura_infill_kept: int = 0
    already_processed: bool = False
    written: bool = False  # the output was written (process_file), or the list returned (process_gcode)
    meshes: list[str] = field(default_factory=list)  # the file's ;MESH: names
    line_width_found: float | None = None  # the line width read from the walls, mm
    volumetric: bool = False
    seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed_layers

    def format_table(self) -> str:
        """A plain-text summary for the CLI."""
        if self.already_processed:
            return "already processed by DelaunayInfill (marker found): nothing changed"
        unit = "mm3" if self.volumetric else "mm"

        def pct(a, b):
            return f"{(a / b - 1) * 100:+.1f} %" if b else "n/a"

        def hms(s):
            s = int(round(s))
            return f"{s // 3600}h{s % 3600 // 60:02d}m{s % 60:02d}s"

        kept_failed = len(self.failed_layers)
        out = [f"layers {self.layers_total}: {self.layers_processed} processed"
               + (f" ({self.layers_repeated} of them written from an earlier layer they repeat)"
                  if self.layers_repeated else "")
               + f", {self.layers_kept} left as Cura's (no infill to replace)"
               + (f", {kept_failed} kept Cura's infill after a FAILURE" if kept_failed else ""),
               ""]
        rows = [
            ("FILL blocks", "", f"{self.blocks_replaced} replaced", f"{self.blocks_kept} left as Cura's"),
            (f"filament ({unit})", f"{self.filament_before_mm:.1f}", f"{self.filament_after_mm:.1f}", pct(self.filament_after_mm, self.filament_before_mm)),
            ("print time", hms(self.time_before_s), hms(self.time_after_s), pct(self.time_after_s, self.time_before_s)),
            ("infill path (mm)", f"{self.infill_before_mm:.0f}", f"{self.infill_after_mm:.0f}", pct(self.infill_after_mm, self.infill_before_mm)),
            ("infill travel (mm)", "", f"{self.infill_travel_mm:.0f}", f"{self.infill_retractions} retractions"),
        ]
        if self.cura_infill_kept_mm > 0:
            rows.append(("  Cura's lines kept", "", f"{self.cura_infill_kept_mm:.0f} mm",
                         f"in {self.layers_with_cura_infill_kept} layers"))
        out.append(f"{'':20s} {'before':>12s} {'after':>16s} {'change':>24s}")
        out += [f"{a:20s} {b:>12s} {c:>16s} {d:>24s}" for a, b, c, d in rows]
        if self.regions:
            names = [_shown_region_name(r.name) for r in self.regions]
            width = max(20, *(len(n) for n in names))
            out.append("")
            out.append(f"{'region':{width}s} {'target':>8s} {'measured':>9s} {'mm2 per layer':>14s} {'layers':>7s}")
            for name, r in zip(names, self.regions):
                meas = "n/a" if not math.isfinite(r.measured) else f"{r.measured * 100:.1f} %"
                out.append(f"{name:{width}s} {r.target * 100:6.1f} % {meas:>9s} {r.area_per_layer_mm2:14.0f} {r.layers:7d}")
        if self.failed_layers:
            shown = ", ".join(str(n) for n in self.failed_layers[:20])
            more = " ..." if len(self.failed_layers) > 20 else ""
            out.append("")
            out.append(f"{len(self.failed_layers)} layer(s) kept Cura's infill because processing failed: {shown}{more}")
            for msg in self.failure_messages[:3]:
                out.append(f"  {msg}")
        for w in self.warnings:
            out.append(f"warning: {w}")
        out.append(f"done in {self.seconds:.2f} s")
        return "\n".join(out)
