"""The G-code header after processing: time and filament figures moved by what the pass changed, the marker."""

from __future__ import annotations

import math
import re

from .read import MARKER
from .settings import ProcessSettings

__all__ = ["patch_header"]


def _filament_area(settings: ProcessSettings) -> float | None:
    """Cross-section of the filament, mm², when its diameter is known."""
    d = settings.filament_diameter
    return math.pi * d * d / 4.0 if d else None


def _add_delta(value: float, ext: int, e_net: dict, e_delta: dict, per_e: float | None) -> float:
    """A header figure plus the net change of extrusion of extruder `ext`.

    `per_e` converts E units to the figure's unit; None: the figure's own ratio
    to the file's net E (Cura's conversion, read back from its numbers).
    """
    delta = e_delta.get(ext, 0.0)
    if per_e is None:
        net = e_net.get(ext, 0.0)
        if net <= 0:
            return value
        per_e = value / net
    return value + delta * per_e


def patch_header(
    header: str,
    time_delta: float,
    e_net: dict,
    e_delta: dict,
    settings: ProcessSettings,
    volumetric: bool = False,
    layers: tuple[int, int, int] | None = None,
) -> str:
    """Header with updated time and filament figures and the processed marker.

    Parameters
    ----------
    header : str
        Cura's header chunk.
    time_delta : float
        s added to the print time.
    e_net, e_delta : dict[int, float]
        Per extruder: the input's net E and the net change made (E units:
        mm of filament, mm³ when `volumetric`).
    settings : ProcessSettings
        For the filament diameter and the marker.
    volumetric : bool
        E is mm³ (UltiGCode, RepRap volumetric).
    layers : (int, int, int), optional
        Layers processed, kept as Cura's, failed: written into the marker.

    Notes
    -----
    Each figure becomes Cura's figure plus the net change in extrusion (new
    minus old), so it stays consistent with the file's net E: metres of
    filament get delta / 1000 (non-volumetric), mm³ get delta (volumetric) or
    delta × filament area; without a known conversion the figure's own ratio
    to the file's net E is used.
    """
    area = _filament_area(settings)
    to_m = None if volumetric else 1e-3
    if volumetric and area:
        to_m = 1e-3 / area
    to_mm3 = 1.0 if volumetric else area

    def time_sub(mo):
        return f"{mo.group(1)}{max(0, int(round(float(mo.group(2)) + time_delta)))}"

    header = re.sub(r"^(;TIME:)(\d+(?:\.\d+)?)", time_sub, header, count=1, flags=re.M)
    header = re.sub(r"^(;PRINT\.TIME:)(\d+(?:\.\d+)?)", time_sub, header, count=1, flags=re.M)

    def filament_sub(mo):
        items = mo.group(2).split(",")
        out = []
        for ext, item in enumerate(items):
            im = re.match(r"\s*(-?[\d.]+)(\D*)$", item)
            if not im:
                out.append(item)
                continue
            per_e = to_m if im.group(2).strip() == "m" else None
            val = max(0.0, _add_delta(float(im.group(1)), ext, e_net, e_delta, per_e))
            lead = item[: len(item) - len(item.lstrip())]
            out.append(f"{lead}{val:.5g}{im.group(2)}")
        return mo.group(1) + ",".join(out)

    header = re.sub(r"^(;Filament used:)(.*)$", filament_sub, header, count=1, flags=re.M)

    def volume_sub(mo):
        ext = int(mo.group(2))
        val = max(0.0, _add_delta(float(mo.group(4)), ext, e_net, e_delta, to_mm3))
        return f"{mo.group(1)}{ext}{mo.group(3)}{val:.0f}"

    header = re.sub(r"^(;EXTRUDER_TRAIN\.)(\d+)(\.MATERIAL\.VOLUME_USED:)([\d.]+)", volume_sub, header, flags=re.M)

    def ulti_sub(mo):  # UltiGCode: ;MATERIAL: (extruder 0) and ;MATERIAL2: (extruder 1), mm³
        ext = 1 if mo.group(2) else 0
        return f"{mo.group(1)}{max(0.0, _add_delta(float(mo.group(3)), ext, e_net, e_delta, to_mm3)):.0f}"

    header = re.sub(r"^(;MATERIAL(2?):)([\d.]+)", ulti_sub, header, flags=re.M)
    from .. import __version__

    marker = (
        f"{MARKER} version={__version__} layout={settings.layout} seed={settings.seed}"
        + (f" density={settings.density * 100:g}%" if settings.density is not None else "")
        # how many layers got Delaunay infill, kept Cura's (nothing to replace), failed (kept Cura's)
        + (f" layers_processed={layers[0]} layers_kept={layers[1]} layers_failed={layers[2]}" if layers else "")
    )
    m = re.search(r"^;Generated with", header, re.M)
    if m:
        return header[: m.start()] + marker + "\n" + header[m.start() :]
    if header and not header.endswith("\n"):
        header += "\n"
    return header + marker + "\n"
