"""Print time and material in Cura's UI after the Delaunay pass.

Cura's print-information panel shows CuraEngine's estimates, made for Cura's
own infill.  The G-code pass patches the header of the processed G-code
(``;TIME:``, ``;Filament used:``; Griffin ``;PRINT.TIME:`` and
``;EXTRUDER_TRAIN.n.MATERIAL.VOLUME_USED:``) from the project's estimate;
this module makes the UI show the same figures by re-emitting the backend's
``printDurationMessage`` (per-feature seconds, mm³ per extruder), which is
what Cura's ``PrintInformation`` listens to.

The first half is pure Python (header parsing and the arithmetic); the
second half hooks into the extension's processed-G-code callbacks.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

_TIME = re.compile(r"^;TIME:(\d+(?:\.\d+)?)", re.M)
_PRINT_TIME = re.compile(r"^;PRINT\.TIME:(\d+(?:\.\d+)?)", re.M)
_FILAMENT_USED = re.compile(r"^;Filament used:(.*)$", re.M)
_VOLUME_USED = re.compile(r"^;EXTRUDER_TRAIN\.(\d+)\.MATERIAL\.VOLUME_USED:(\d+(?:\.\d+)?)", re.M)
_AMOUNT = re.compile(r"([-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)\s*(mm3|m)?")

#: Cura's (and a re-emission's) tolerance: figures closer than this are left alone.
RELATIVE_TOLERANCE = 0.005


@dataclass
class HeaderTotals:
    """Print time and material as written in a G-code header.

    Attributes
    ----------
    time_s : float or None
        Whole print, seconds.
    filament_m : list of float
        Per extruder: metres of filament (``;Filament used: 1.2m, 0m``).
    volume_mm3 : list of float
        Per extruder: mm³ (Griffin ``VOLUME_USED``, or ``;Filament used: 123mm3``
        in volumetric flavours).
    """

    time_s: float | None = None
    filament_m: list = field(default_factory=list)
    volume_mm3: list = field(default_factory=list)

    def volumes_mm3(self, diameters_mm) -> list:
        """Material per extruder in mm³ (filament lengths converted with `diameters_mm`)."""
        if self.volume_mm3:
            return list(self.volume_mm3)
        out = []
        for index, metres in enumerate(self.filament_m):
            diameter = float(diameters_mm[index] if index < len(diameters_mm) else diameters_mm[-1])
            out.append(metres * 1000.0 * math.pi * (diameter / 2.0) ** 2)
        return out


def header_totals(header: str) -> HeaderTotals:
    """Parse the time and material figures of a Cura G-code header (``gcode_list[0]``)."""
    totals = HeaderTotals()
    match = _TIME.search(header) or _PRINT_TIME.search(header)
    if match:
        totals.time_s = float(match.group(1))
    volumes = {int(n): float(v) for n, v in _VOLUME_USED.findall(header)}
    if volumes:
        totals.volume_mm3 = [volumes.get(i, 0.0) for i in range(max(volumes) + 1)]
    match = _FILAMENT_USED.search(header)
    if match:
        for number, unit in _AMOUNT.findall(match.group(1)):
            if unit == "mm3":
                totals.volume_mm3.append(float(number))
            else:
                totals.filament_m.append(float(number))
    return totals


def times_matching_total(times_per_feature: dict, total_s: float) -> dict:
    """Per-feature seconds whose sum is `total_s`, changing only the infill where possible.

    The difference between the new total and Cura's goes to ``"infill"`` (the
    only feature the pass changes); if that would make infill negative, all
    features are scaled instead.
    """
    times = {key: (0.0 if value != value else float(value)) for key, value in times_per_feature.items()}
    other = sum(value for key, value in times.items() if key != "infill")
    infill = float(total_s) - other
    if infill >= 0.0:
        times["infill"] = infill
        return times
    scale = float(total_s) / other if other > 0 else 0.0
    return {key: (0.0 if key == "infill" else value * scale) for key, value in times.items()}


def needs_update(shown_time_s, shown_volumes, total_s, volumes, tolerance: float = RELATIVE_TOLERANCE) -> bool:
    """True when the UI's figures differ from the processed G-code's by more than `tolerance`."""
    def off(a, b):
        return abs(float(a) - float(b)) > tolerance * max(1.0, abs(float(b)))

    if total_s is not None and (shown_time_s is None or off(shown_time_s, total_s)):
        return True
    return any(off(a, b) for a, b in zip(shown_volumes or [], volumes or []))


def corrected_estimates(times_per_feature: dict, material_amounts: list, header: str, diameters_mm):
    """Cura's estimates corrected to the processed G-code's header.

    Parameters
    ----------
    times_per_feature : dict
        CuraEngine's per-feature seconds for this slice.
    material_amounts : list of float
        CuraEngine's mm³ per extruder.
    header : str
        The processed G-code's header (``gcode_list[0]``).
    diameters_mm : sequence of float
        Filament diameter per extruder.

    Returns
    -------
    (dict, list) or None
        Times and material for ``printDurationMessage``; None when the header
        has no figures.
    """
    totals = header_totals(header)
    if totals.time_s is None:
        return None
    times = times_matching_total(times_per_feature or {"infill": 0.0}, totals.time_s)
    volumes = totals.volumes_mm3(list(diameters_mm) or [1.75])
    amounts = list(material_amounts)
    for index, volume in enumerate(volumes):
        if index < len(amounts):
            amounts[index] = volume
        elif volume > 0:
            amounts.extend([0.0] * (index - len(amounts)) + [volume])
    return times, amounts


# -- Cura side --------------------------------------------------------------------------------


class EstimatesUpdater:
    """After each write-back, make Cura's print information match the processed header."""

    def __init__(self, application, extension):
        self._application = application
        self._extension = extension

    def onProcessed(self, plate, gcode_list, report=None) -> None:
        from UM.Logger import Logger

        original = self._extension.getLastEstimates(plate) if hasattr(self._extension, "getLastEstimates") else None
        if not original or not gcode_list:
            return
        stack = self._application.getGlobalContainerStack()
        diameters = []
        for extruder in (stack.extruderList if stack is not None else []):
            try:
                diameters.append(float(extruder.getProperty("material_diameter", "value")))
            except (TypeError, ValueError):
                diameters.append(1.75)
        corrected = corrected_estimates(original[0], original[1], gcode_list[0], diameters or [1.75])
        if corrected is None:
            return
        times, amounts = corrected
        info = self._application.getPrintInformation()
        shown_time = None
        try:
            shown_time = float(int(info.currentPrintTime))
        except Exception:
            pass
        shown_volumes = getattr(info, "_material_amounts", None)
        if not needs_update(shown_time, shown_volumes, sum(times.values()), amounts):
            return
        backend = self._application.getBackend()
        # The extension records every printDurationMessage as Cura's own; keep the real ones.
        backend.printDurationMessage.emit(plate, times, amounts)
        restore = getattr(self._extension, "_last_estimates", None)
        if isinstance(restore, dict):
            restore[plate] = original
        Logger.log("i", "DelaunayInfill: print information set to %.0f s, %s mm³", sum(times.values()),
                   ", ".join(f"{a:.0f}" for a in amounts))


_updater = None


def install(extension) -> None:
    """Hook the estimate correction into the extension's processed-G-code callbacks."""
    global _updater
    from UM.Application import Application

    _updater = EstimatesUpdater(Application.getInstance(), extension)
    extension.addProcessedCallback(_updater.onProcessed)
