"""The G-code pipeline: Cura's ``;TYPE:FILL`` replaced by Delaunay infill.

See docs/gcode.md.  ``process_gcode`` works on Cura's in-memory list of
strings; ``process_file`` streams a file.
"""

from .process import process_file, process_gcode
from .read import GCodeError, ProcessCancelled
from .settings import MeshSettings, ProcessReport, ProcessSettings, Region, RegionReport

__all__ = [
    "process_gcode",
    "process_file",
    "ProcessSettings",
    "MeshSettings",
    "Region",
    "RegionReport",
    "ProcessReport",
    "GCodeError",
    "ProcessCancelled",
]
