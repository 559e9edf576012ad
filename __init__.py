"""Cura entry point of the DelaunayInfill plugin.

Cura imports this folder as the package ``DelaunayInfill``; the engine is the
subpackage ``DelaunayInfill.DelaunayInfill``.  Importing it does no heavy
work: numpy, scipy and shapely are imported only when a slice is processed.
"""

from UM.Logger import Logger


def _region_tool_module():
    """Task D's density-region tool module, or None when it is not there."""
    try:
        from .DelaunayInfill.cura import region_tool
    except ModuleNotFoundError as error:
        if error.name and error.name.endswith("region_tool"):
            return None
        Logger.logException("e", "DelaunayInfill: the density region tool could not be loaded")
        return None
    except Exception:
        Logger.logException("e", "DelaunayInfill: the density region tool could not be loaded")
        return None
    return region_tool


def getMetaData():
    module = _region_tool_module()
    if module is None:
        return {}
    try:
        return {"tool": module.tool_metadata()}
    except Exception:
        Logger.logException("e", "DelaunayInfill: the density region tool has no usable metadata")
        return {}


def register(app):
    from .DelaunayInfill.cura.extension import DelaunayInfillExtension

    objects = {"extension": DelaunayInfillExtension()}
    module = _region_tool_module()
    if module is not None and "tool" in getMetaData():  # a tool without metadata would break the toolbar
        try:
            objects["tool"] = module.DensityRegionTool()
        except Exception:
            Logger.logException("e", "DelaunayInfill: the density region tool could not be created")
    return objects
