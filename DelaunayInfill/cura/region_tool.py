"""The "Density regions" tool: place, edit and delete density regions on a model.

A density region is an ``infill_mesh`` modifier node (walls and skins zero,
its own ``infill_sparse_density``) parented to the model it was placed on, so
it moves with the model.  CuraEngine treats it as an ordinary Cura infill
modifier (so it also works with Delaunay infill off); the Delaunay pipeline
reads it back with :func:`collect_scene_regions` and builds one seamless
triangulation with the region's density inside it.

Regions made with Cura's own Per Model Settings (any ``infill_mesh``) are
listed and collected the same way.

Python API (used by the panel through ``UM.ActiveTool`` and by the GUI tests):
``addRegion``, ``addRegionAtCentre``, ``removeRegion``, ``editRegion``,
``selectRegion`` and :func:`collect_scene_regions`.
"""

from __future__ import annotations

import os

import numpy as np

try:  # Cura 5 (Qt 6) first, Cura 4.13 (Qt 5) as fallback
    from PyQt6.QtCore import Qt, QTimer

    QT_MAJOR = 6
except ImportError:  # pragma: no cover - depends on the host Cura
    from PyQt5.QtCore import Qt, QTimer

    QT_MAJOR = 5

from UM.Application import Application
from UM.Event import Event, MouseEvent
from UM.Logger import Logger
from UM.Math.Vector import Vector
from UM.Mesh.MeshBuilder import MeshBuilder
from UM.Operations.AddSceneNodeOperation import AddSceneNodeOperation
from UM.Operations.GroupedOperation import GroupedOperation
from UM.Operations.Operation import Operation
from UM.Operations.RemoveSceneNodeOperation import RemoveSceneNodeOperation
from UM.Operations.TranslateOperation import TranslateOperation
from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator
from UM.Scene.Selection import Selection
from UM.Settings.SettingInstance import SettingInstance
from UM.Tool import Tool

from .region_shapes import (
    SHAPES,
    SceneRegion,
    clamp_density_percent,
    clamp_size_mm,
    infer_shape,
    next_region_number,
    order_regions,
    region_name,
    region_number,
    scene_to_gcode,
    shape_triangles,
)
from .paint_tool import PaintToolMixin

PLUGIN_FOLDER = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

PREF_SHAPE = "delaunay_infill/region_shape"
PREF_SIZE = "delaunay_infill/region_size_mm"
PREF_DENSITY = "delaunay_infill/region_density"
PREF_FEATHER = "delaunay_infill/region_feather_mm"

MESH_TYPE_KEYS = ("infill_mesh", "cutting_mesh", "support_mesh", "anti_overhang_mesh")

# What Cura's Per Model Settings tool sets on an infill mesh so it prints no walls or skin.
INFILL_MESH_OVERRIDES = {
    "top_bottom_thickness": 0,
    "top_thickness": "=top_bottom_thickness",
    "bottom_thickness": "=top_bottom_thickness",
    "top_layers": "=0 if infill_sparse_density == 100 else math.ceil(round(top_thickness / resolveOrValue('layer_height'), 4))",
    "bottom_layers": "=0 if infill_sparse_density == 100 else math.ceil(round(bottom_thickness / resolveOrValue('layer_height'), 4))",
    "wall_thickness": 0,
    "wall_line_count": "=max(1, round((wall_thickness - wall_line_width_0) / wall_line_width_x) + 1) if wall_thickness != 0 else 0",
}


def tool_metadata() -> dict:
    """The ``"tool"`` entry of the plugin's metadata (panel chosen by the Qt major version)."""
    return {
        "name": "Density regions",
        "description": "Click the model to add a denser or sparser region of Delaunay infill.",
        "icon": "qml/density_regions.svg",
        "tool_panel": f"qml/qt{QT_MAJOR}/DensityRegionsPanel.qml",
        "weight": 5,
    }


# -- scene helpers (main thread only) --------------------------------------------------------


def _app():
    return Application.getInstance()


def _scene():
    return _app().getController().getScene()


def _stack(node):
    return node.callDecoration("getStack") if node is not None else None


def is_region_node(node) -> bool:
    """True for an ``infill_mesh`` modifier node (ours or from Per Model Settings)."""
    stack = _stack(node)
    if not stack or not node.callDecoration("isSliceable"):
        return False
    try:
        return bool(stack.getProperty("infill_mesh", "value"))
    except Exception:  # a stack without the key (no global stack yet)
        return False


def is_model_node(node) -> bool:
    """True for a normal printable mesh (not a modifier, not a group)."""
    if node is None or not node.callDecoration("isSliceable") or node.callDecoration("isGroup"):
        return False
    stack = _stack(node)
    if not stack:
        return True
    return not any(stack.getProperty(key, "value") for key in MESH_TYPE_KEYS)


def region_nodes() -> list:
    """Every infill-mesh node in the scene, in scene order."""
    return [node for node in DepthFirstIterator(_scene().getRoot()) if is_region_node(node)]


def _machine_frame():
    stack = _app().getGlobalContainerStack()
    if stack is None:
        return 0.0, 0.0, True
    return (
        float(stack.getProperty("machine_width", "value")),
        float(stack.getProperty("machine_depth", "value")),
        bool(stack.getProperty("machine_center_is_zero", "value")),
    )


def _world_triangles(node) -> np.ndarray:
    """(k, 3, 3) triangles of `node`'s mesh in scene world coordinates (mm)."""
    mesh = node.getMeshData()
    if mesh is None:
        return np.zeros((0, 3, 3))
    world = mesh.getTransformed(node.getWorldTransformation())
    vertices = np.asarray(world.getVertices(), dtype=float)
    if world.hasIndices():
        return vertices[np.asarray(world.getIndices(), dtype=np.int64)]
    return vertices[: len(vertices) // 3 * 3].reshape(-1, 3, 3)


def _node_density_percent(node) -> float:
    stack = _stack(node)
    try:
        return float(stack.getProperty("infill_sparse_density", "value"))
    except (TypeError, ValueError, AttributeError):
        return float("nan")


def _world_scale(node) -> float:
    """The node's uniform world scale (cube root of the transform's determinant)."""
    matrix = np.asarray(node.getWorldTransformation().getData(), dtype=float)[:3, :3]
    scale = abs(float(np.linalg.det(matrix))) ** (1.0 / 3.0)
    return scale if scale > 1e-9 else 1.0


def _node_shape_and_size(node) -> tuple[str, float]:
    """(shape, size in world mm): the size follows the model when the user scales it."""
    shape = getattr(node, "_delaunay_region_shape", None)
    local_size = getattr(node, "_delaunay_region_size", None)  # mesh size in the node's own axes
    if shape is None or local_size is None:  # restored from a project file: infer from the mesh
        mesh = node.getMeshData()
        count = 0
        vertices = np.zeros((0, 3))
        if mesh is not None:
            count = mesh.getFaceCount() if mesh.hasIndices() else mesh.getVertexCount() // 3
            vertices = np.asarray(mesh.getVertices(), dtype=float).reshape(-1, 3)
        shape = infer_shape(count) if region_number(node.getName()) is not None else "mesh"
        local_size = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    return shape, float(local_size) * _world_scale(node)


def _node_mesh_order(node) -> int:
    try:
        return int(_stack(node).getProperty("infill_mesh_order", "value"))
    except (TypeError, ValueError, AttributeError):
        return 1


def scene_region(node) -> SceneRegion:
    """The :class:`SceneRegion` of an infill-mesh node (triangles in G-code coordinates)."""
    width, depth, centred = _machine_frame()
    shape, size = _node_shape_and_size(node)
    parent = node.getParent()
    parent_name = parent.getName() if parent is not None and is_model_node(parent) else ""
    return SceneRegion(
        name=node.getName(),
        density=_node_density_percent(node) / 100.0,
        triangles=scene_to_gcode(_world_triangles(node), width, depth, centred),
        number=region_number(node.getName()),
        shape=shape,
        size=size,
        parent=parent_name,
        mesh_order=_node_mesh_order(node),
    )


def collect_scene_regions() -> list[SceneRegion]:
    """All density regions in the scene, in the order the pipeline applies them (later wins).

    Call on Qt's main thread (it reads the scene graph); the result is plain
    numpy data that a background job may use.
    """
    regions = []
    for node in region_nodes():
        try:
            region = scene_region(node)
        except Exception:  # one odd node must not stop the others
            Logger.logException("w", "DelaunayInfill: cannot read density region %s", node.getName())
            continue
        if region.triangles.size and np.isfinite(region.density):
            regions.append(region)
    return order_regions(regions)


def region_feather_mm() -> float:
    """The feather width (mm) the user chose for region borders (0: sharp borders)."""
    try:
        return max(0.0, float(_app().getPreferences().getValue(PREF_FEATHER)))
    except (TypeError, ValueError):
        return 0.0


def _set_setting(node, key: str, value, *, user_state: bool) -> None:
    """Set a per-object setting on `node`'s own container.

    `user_state` False mirrors Cura's tools for mesh-type flags; True is
    required for ``infill_sparse_density`` (a non-user state would make the
    per-object stack read the extruder's value instead).
    """
    stack = _stack(node)
    top = stack.getTop()
    if isinstance(value, str) and value.startswith("="):
        from UM.Settings.SettingFunction import SettingFunction

        value = SettingFunction(value[1:])
    instance = top.getInstance(key)
    if instance is None:
        instance = SettingInstance(stack.getSettingDefinition(key), top)
        instance.setProperty("value", value)
        if not user_state:
            instance.resetState()
        top.addInstance(instance)
    else:
        instance.setProperty("value", value)
        if not user_state:
            instance.resetState()
    stack.propertyChanged.emit(key, "value")


class _SetRegionMeshOperation(Operation):
    """Undoable change of a region's shape and size (its mesh)."""

    def __init__(self, node, shape: str, size: float):
        super().__init__()
        self._node = node
        scale = _world_scale(node)  # the region scales with its model: size is in world mm
        old_shape, old_size = _node_shape_and_size(node)
        self._old = (node.getMeshData(), old_shape, old_size / scale)
        self._new = (_build_mesh(shape, size / scale), shape, size / scale)

    def _apply(self, mesh, shape, local_size):
        self._node.setMeshData(mesh)
        self._node._delaunay_region_shape = shape
        self._node._delaunay_region_size = local_size
        self._node.calculateBoundingBoxMesh()
        _scene().sceneChanged.emit(self._node)

    def undo(self):
        self._apply(*self._old)

    def redo(self):
        self._apply(*self._new)


_REGION_NODE_CLASS = None


def region_node_class():
    """The scene-node class of the tool's regions (made once, inside Cura).

    A region prints nothing of its own, so it must not count in the size Cura reports: under the
    object list Cura shows the extent of every ``CuraSceneNode`` that has a mesh
    (``CuraApplication.updatePlatformActivity``, Cura 4.13 to 5.x), modifiers included, so a 16 mm
    region on the top face of a 12 mm slab made it "23.1 mm" tall. A region is therefore a plain
    Uranium ``SceneNode`` (the model's own box already leaves it out: it is a non-printing mesh),
    with the ``CuraSceneNode`` methods Cura calls on sliceable nodes (``isOutsideBuildArea``,
    ``getPrintingExtruder``, ``getDiffuseColor``, ...) taken over from Cura's class of the running
    version, the build-plate filter of ``isVisible``/``isSelectable``, and its own ``__deepcopy__``
    (multiplying the model copies its regions as regions). It keeps its ``SettingOverrideDecorator``
    (``infill_mesh``, its density), so CuraEngine and the Delaunay pass see it as before.
    """
    global _REGION_NODE_CLASS
    if _REGION_NODE_CLASS is not None:
        return _REGION_NODE_CLASS
    from copy import deepcopy

    from cura.CuraApplication import CuraApplication
    from cura.Scene.CuraSceneNode import CuraSceneNode
    from cura.Settings.SettingOverrideDecorator import SettingOverrideDecorator
    from UM.Scene.SceneNode import SceneNode

    def on_active_plate(node) -> bool:
        plate = CuraApplication.getInstance().getMultiBuildPlateModel().activeBuildPlate
        return node.callDecoration("getBuildPlateNumber") == plate

    # Plain attributes CuraSceneNode.__init__ adds to SceneNode's (``_outside_buildarea``, and what
    # later versions add), with their initial values.
    probe, plain = CuraSceneNode(no_setting_override=True), SceneNode()
    extra_attributes = {
        key: value for key, value in vars(probe).items()
        if key not in vars(plain) and isinstance(value, (bool, int, float, str, type(None)))
    }

    class DensityRegionNode(SceneNode):
        def __init__(self, parent=None, visible: bool = True, name: str = "", no_setting_override: bool = False):
            super().__init__(parent=parent, visible=visible, name=name)
            for key, value in extra_attributes.items():
                setattr(self, key, value)
            self._outside_buildarea = False
            if not no_setting_override:
                self.addDecorator(SettingOverrideDecorator())

        def isVisible(self) -> bool:
            return super().isVisible() and on_active_plate(self)

        def isSelectable(self) -> bool:
            return super().isSelectable() and on_active_plate(self)

        def __deepcopy__(self, memo):
            copy = DensityRegionNode(no_setting_override=True)  # the decorators are copied below
            copy.setTransformation(self.getLocalTransformation())
            copy.setMeshData(self._mesh_data)
            copy.setVisible(deepcopy(self._visible, memo))
            copy.source_mime_type = deepcopy(self.source_mime_type, memo)
            copy._selectable = deepcopy(self._selectable, memo)
            copy._name = deepcopy(self._name, memo)
            for key in ("_delaunay_region_shape", "_delaunay_region_size"):
                if hasattr(self, key):
                    setattr(copy, key, getattr(self, key))
            for decorator in self._decorators:
                copy.addDecorator(deepcopy(decorator, memo))
            for child in self._children:
                copy.addChild(deepcopy(child, memo))
            self.calculateBoundingBoxMesh()
            return copy

    for name, value in vars(CuraSceneNode).items():
        if name.startswith("__") or name in vars(DensityRegionNode) or not callable(value):
            continue
        code = getattr(value, "__code__", None)
        if code is None or "__class__" in code.co_freevars:
            continue  # a method calling super() works on CuraSceneNode instances only
        setattr(DensityRegionNode, name, value)
    DensityRegionNode.__qualname__ = DensityRegionNode.__name__
    _REGION_NODE_CLASS = DensityRegionNode
    return DensityRegionNode


def _build_mesh(shape: str, size: float):
    triangles = shape_triangles(shape, size)
    builder = MeshBuilder()
    builder.setVertices(triangles.reshape(-1, 3).astype(np.float32))
    builder.calculateNormals(fast=True)
    return builder.build()


class DensityRegionTool(PaintToolMixin, Tool):
    """Left-toolbar tool: a click on the selected model adds a density region there."""

    def __init__(self):
        super().__init__()
        self._shortcut_key = Qt.Key.Key_D if QT_MAJOR == 6 else Qt.Key_D
        preferences = _app().getPreferences()
        preferences.addPreference(PREF_SHAPE, "sphere")
        preferences.addPreference(PREF_SIZE, 10.0)
        preferences.addPreference(PREF_DENSITY, 60.0)
        preferences.addPreference(PREF_FEATHER, 0.0)
        self._selected_region = ""
        self._selection_pass = None
        self.setExposedProperties(
            "Shape", "Size", "Density", "Feather", "ModelName", "BaseDensity", "DelaunayEnabled",
            "Regions", "SelectedRegion",
        )
        # As in Cura's support blocker: the first click after the selection was cleared only
        # selects, otherwise the user could never leave the tool.
        self._had_selection = False
        self._skip_press = False
        self._selection_timer = QTimer()
        self._selection_timer.setInterval(0)
        self._selection_timer.setSingleShot(True)
        self._selection_timer.timeout.connect(self._afterSelectionChange)
        Selection.selectionChanged.connect(self._onSelectionChanged)
        # Undo/redo and Per Model Settings change the region list behind our back.
        self._refresh_timer = QTimer()
        self._refresh_timer.setInterval(150)
        self._refresh_timer.setSingleShot(True)
        self._refresh_timer.timeout.connect(self.propertyChanged.emit)
        _scene().sceneChanged.connect(self._onSceneChanged)
        self._initPaint()  # paint mode: paint_tool.py

    # -- exposed properties (QML: UM.ActiveTool.properties.getValue("Name")) ------------------

    def getShape(self) -> str:
        shape = str(_app().getPreferences().getValue(PREF_SHAPE))
        return shape if shape in SHAPES else "sphere"

    def setShape(self, shape) -> None:
        shape = str(shape)
        if shape not in SHAPES:
            Logger.log("w", "DelaunayInfill: unknown region shape %r", shape)
            return
        _app().getPreferences().setValue(PREF_SHAPE, shape)
        self.propertyChanged.emit()

    def getSize(self) -> float:
        return clamp_size_mm(_app().getPreferences().getValue(PREF_SIZE))

    def setSize(self, size) -> None:
        try:
            _app().getPreferences().setValue(PREF_SIZE, clamp_size_mm(size))
        except (TypeError, ValueError):
            Logger.log("w", "DelaunayInfill: ignoring region size %r", size)
        self.propertyChanged.emit()

    def getDensity(self) -> float:
        return clamp_density_percent(_app().getPreferences().getValue(PREF_DENSITY))

    def setDensity(self, density) -> None:
        try:
            _app().getPreferences().setValue(PREF_DENSITY, clamp_density_percent(density))
        except (TypeError, ValueError):
            Logger.log("w", "DelaunayInfill: ignoring region density %r", density)
        self.propertyChanged.emit()

    def getFeather(self) -> float:
        return region_feather_mm()

    def setFeather(self, feather) -> None:
        try:
            value = min(100.0, max(0.0, float(feather)))
        except (TypeError, ValueError):
            return
        if value == self.getFeather():
            return
        _app().getPreferences().setValue(PREF_FEATHER, value)
        self.propertyChanged.emit()
        model = self._selectedModel()
        if model is not None:  # the processed G-code depends on it: slice again
            _scene().sceneChanged.emit(model)

    def getModelName(self) -> str:
        model = self._selectedModel()
        return model.getName() if model is not None else ""

    def getBaseDensity(self) -> float:
        model = self._selectedModel()
        return _node_density_percent(model) if model is not None else float("nan")

    def getDelaunayEnabled(self) -> bool:
        model = self._selectedModel()
        stack = _stack(model)
        if stack is None:
            return False
        try:
            return bool(stack.getProperty("delaunay_infill_enabled", "value"))
        except Exception:
            return False

    def getRegions(self) -> list:
        """The selected model's regions as a list of dicts for the panel's list view."""
        model = self._selectedModel()
        if model is None:
            return []
        rows = []
        for index, node in enumerate(self._regionsOf(model)):
            shape, size = _node_shape_and_size(node)
            number = region_number(node.getName())
            rows.append({
                "name": node.getName(),
                "label": str(number) if number is not None else f"M{index + 1}",
                "number": number if number is not None else -1,
                "shape": shape,
                "size": round(size, 2),
                "density": round(_node_density_percent(node), 2),
                "own": number is not None,
                "selected": node.getName() == self._selected_region or Selection.isSelected(node),
            })
        return rows

    def getSelectedRegion(self) -> str:
        return self._selected_region

    def setSelectedRegion(self, name) -> None:
        self.selectRegion(name)

    # -- actions (QML: UM.ActiveTool.triggerAction / triggerActionWithData) -------------------

    def addRegion(self, model=None, position=None, shape=None, size=None, density=None):
        """Add a region to `model` (default: the selected model), undoably.

        Parameters
        ----------
        model : SceneNode, optional
        position : UM.Math.Vector or sequence of 3 floats, optional
            World (scene) position of the region's centre in mm; default the
            centre of the model's bounding box.
        shape, size, density : optional
            Default: the panel's current choice (size mm, density percent).

        Returns
        -------
        The new region node (:func:`region_node_class`), or None when there is no model to add to.
        """
        from cura.CuraApplication import CuraApplication
        from cura.Operations.SetParentOperation import SetParentOperation
        from cura.Scene.BuildPlateDecorator import BuildPlateDecorator
        from cura.Scene.SliceableObjectDecorator import SliceableObjectDecorator

        model = model if model is not None else self._selectedModel()
        if model is None or not is_model_node(model):
            Logger.log("w", "DelaunayInfill: select one model to add a density region to")
            return None
        shape = shape if shape in SHAPES else self.getShape()
        size = clamp_size_mm(size if size is not None else self.getSize())
        density = clamp_density_percent(density if density is not None else self.getDensity())
        if position is None:
            position = model.getBoundingBox().center
        elif not isinstance(position, Vector):
            position = Vector(*(float(v) for v in position))

        node = region_node_class()()  # not a CuraSceneNode: see region_node_class
        node.setName(region_name(next_region_number(n.getName() for n in DepthFirstIterator(_scene().getRoot()))))
        node.setSelectable(True)
        node.setCalculateBoundingBox(True)
        node.setMeshData(_build_mesh(shape, size))
        node.calculateBoundingBoxMesh()
        node._delaunay_region_shape = shape
        node._delaunay_region_size = size
        node.addDecorator(BuildPlateDecorator(CuraApplication.getInstance().getMultiBuildPlateModel().activeBuildPlate))
        node.addDecorator(SliceableObjectDecorator())
        extruder = model.callDecoration("getActiveExtruder")
        if extruder:
            node.callDecoration("setActiveExtruder", extruder)

        _set_setting(node, "infill_mesh", True, user_state=False)
        for key, value in INFILL_MESH_OVERRIDES.items():
            _set_setting(node, key, value, user_state=False)
        # Newer regions win where they overlap, in CuraEngine too (Delaunay off).
        _set_setting(node, "infill_mesh_order", 1 + region_number(node.getName()), user_state=True)
        _set_setting(node, "infill_sparse_density", density, user_state=True)

        operation = GroupedOperation()
        # Add at the root first so the region keeps its own scale, then parent it to the model.
        operation.addOperation(AddSceneNodeOperation(node, _scene().getRoot()))
        operation.addOperation(SetParentOperation(node, model))
        operation.addOperation(TranslateOperation(node, position, set_position=True))
        operation.push()
        _scene().sceneChanged.emit(node)
        Logger.log("i", "DelaunayInfill: added %s (%s %.1f mm, %.1f %%) to %s at %s",
                   node.getName(), shape, size, density, model.getName(), position)
        self._selected_region = node.getName()
        self.propertyChanged.emit()
        return node

    def addRegionAtCentre(self) -> None:
        """Panel button: add a region at the centre of the selected model."""
        self.addRegion()

    def removeRegion(self, name) -> bool:
        """Delete the region named `name` (or numbered `name`), undoably."""
        node = self._findRegion(name)
        if node is None:
            return False
        RemoveSceneNodeOperation(node).push()
        if self._selected_region == node.getName():
            self._selected_region = ""
        _scene().sceneChanged.emit(node)
        self.propertyChanged.emit()
        return True

    def editRegion(self, data) -> bool:
        """Change a region: `data` is a mapping with "name" and any of "density", "size", "shape"."""
        data = _as_mapping(data)
        node = self._findRegion(data.get("name"))
        if node is None:
            Logger.log("w", "DelaunayInfill: no density region %r", data.get("name"))
            return False
        try:
            if "density" in data and data["density"] not in (None, ""):
                _set_setting(node, "infill_sparse_density", clamp_density_percent(data["density"]), user_state=True)
                _scene().sceneChanged.emit(node)
            shape, size = _node_shape_and_size(node)
            new_shape = str(data.get("shape") or shape)
            new_size = clamp_size_mm(data["size"]) if data.get("size") not in (None, "") else size
            if new_shape != shape or abs(new_size - size) > 1e-9:
                if new_shape not in SHAPES:
                    raise ValueError(f"unknown shape {new_shape!r}")
                _SetRegionMeshOperation(node, new_shape, new_size).push()
        except (TypeError, ValueError) as error:
            Logger.log("w", "DelaunayInfill: cannot edit %s: %s", node.getName(), error)
            return False
        self.propertyChanged.emit()
        return True

    def selectRegion(self, name) -> None:
        """Select the region in the viewport (so the list row and the highlighted mesh match)."""
        node = self._findRegion(name)
        self._selected_region = node.getName() if node is not None else ""
        if node is not None:
            Selection.clear()
            Selection.add(node)
        self.propertyChanged.emit()

    # -- events ----------------------------------------------------------------------------------

    def event(self, event):
        super().event(event)
        painted = self._paintEvent(event)  # paint/erase mode (paint_tool.py)
        if painted is not None:
            return painted
        if event.type != Event.MousePressEvent or MouseEvent.LeftButton not in event.buttons:
            return False
        if not self._controller.getToolsEnabled():
            return False
        if self._skip_press:
            self._skip_press = False
            return False
        if self._selection_pass is None:
            self._selection_pass = _app().getRenderer().getRenderPass("selection")
        picked = _scene().findObject(self._selection_pass.getIdAtPosition(event.x, event.y))
        if picked is None:
            return False
        if is_region_node(picked):
            self._selected_region = picked.getName()
            self.propertyChanged.emit()
            return False
        if not is_model_node(picked):
            return False
        position = self._pickedPosition(event.x, event.y)
        if position is None:
            return False
        self.addRegion(picked, position)
        return True

    def _pickedPosition(self, x: float, y: float):
        """World position under the cursor (normalized view coordinates)."""
        renderer = _app().getRenderer()
        picking = renderer.getRenderPass("picking_selected")  # Cura 5.11+: kept up to date by Cura
        if picking is None:
            from cura.PickingPass import PickingPass

            camera = _scene().getActiveCamera()
            picking = PickingPass(camera.getViewportWidth(), camera.getViewportHeight())
            picking.render()
        if picking.getPickedDepth(x, y) <= 0:
            return None
        return picking.getPickedPosition(x, y)

    def getRequiredExtraRenderingPasses(self) -> list:
        """Uranium 5.11+: render the selected objects' depth for picking."""
        return ["picking_selected"]

    def _onSelectionChanged(self):
        if Selection.hasSelection() != self._had_selection:
            self._selection_timer.start()
        selected = Selection.getSelectedObject(0)
        if selected is not None and is_region_node(selected):
            self._selected_region = selected.getName()
        self._updateEnabled()
        self.propertyChanged.emit()

    def _afterSelectionChange(self):
        has_selection = Selection.hasSelection()
        self._skip_press = not has_selection and self._had_selection
        self._had_selection = has_selection

    def _onSceneChanged(self, node):
        if node is not None and (is_region_node(node) or is_model_node(node)):
            self._refresh_timer.start()

    def _updateEnabled(self):
        selected = Selection.getAllSelectedObjects()
        enabled = len(selected) == 1 and (is_model_node(selected[0]) or is_region_node(selected[0]))
        self._controller.toolEnabledChanged.emit(self._plugin_id, enabled)

    # -- lookups ---------------------------------------------------------------------------------

    def _selectedModel(self):
        node = Selection.getSelectedObject(0)
        if node is None:
            return None
        if is_region_node(node):
            parent = node.getParent()
            if parent is not None and is_model_node(parent):
                return parent
            overlapping = [m for m in self._models() if _boxes_overlap(m, node)]
            return overlapping[0] if overlapping else None
        return node if is_model_node(node) else None

    def _models(self):
        return [node for node in DepthFirstIterator(_scene().getRoot()) if is_model_node(node)]

    def _regionsOf(self, model) -> list:
        """`model`'s regions: its own children, then free modifiers overlapping it."""
        regions = [node for node in region_nodes() if node.getParent() is model]
        regions += [
            node for node in region_nodes()
            if not is_model_node(node.getParent()) and _boxes_overlap(model, node)
        ]
        by_name = {node.getName(): node for node in regions}
        stubs = [
            SceneRegion(name, 0.0, np.zeros((0, 3, 3)), region_number(name), mesh_order=_node_mesh_order(node))
            for name, node in by_name.items()
        ]
        return [by_name[r.name] for r in order_regions(stubs)]

    def _findRegion(self, name):
        if name is None:
            return None
        name = str(name)
        if name.isdigit():
            name = region_name(int(name))
        return next((node for node in region_nodes() if node.getName() == name), None)


def _boxes_overlap(a, b) -> bool:
    box_a, box_b = a.getBoundingBox(), b.getBoundingBox()
    if box_a is None or box_b is None:
        return False
    return box_a.intersectsBox(box_b) != box_a.IntersectionResult.NoIntersection


def _as_mapping(data) -> dict:
    """QML hands a JS object over as a dict (PyQt5/6) or a QJSValue; accept both."""
    if hasattr(data, "toVariant"):
        data = data.toVariant()
    if isinstance(data, dict):
        return {str(k): v for k, v in data.items()}
    raise TypeError(f"expected an object with a name, got {data!r}")
