"""DelaunayInfill: Delaunay-triangulated Poisson-disk variable-density infill.

The engine is pure Python on numpy, scipy and shapely.  Names are imported
lazily so that importing the package (as Cura does at plugin load) is cheap.
"""

__version__ = "0.1.0"

_EXPORTS = {
    "sample_poisson_disk": ".sampling",
    "generate_infill": ".pattern",
    "InfillPattern": ".pattern",
    "InfillResult": ".pattern",
    "process_gcode": ".gcode.process",
    "process_file": ".gcode.process",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value
