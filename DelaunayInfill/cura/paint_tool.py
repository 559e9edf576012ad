"""Paint mode of the "Density regions" tool: paint density sets on a model's faces (Cura side).

``PaintToolMixin`` is mixed into ``region_tool.DensityRegionTool``.  In paint mode a left-button
drag over the selected model paints every triangle within the brush radius of the point under
the cursor (erase mode takes them off every set); one stroke is one undoable operation.

Picking is a ray–triangle test in numpy against the model's world mesh, from the camera ray
(``Camera.getRay``), not Uranium's face selection: ``SelectionPass.getFaceIdAtPosition`` needs
``Selection.setFaceSelectMode(True)``, which turns the whole selection pass into a face pass of
the selected objects (no object ids any more, so clicks beside the model and on regions stop
working) and makes Cura's selection tool toggle a "selected face" on every click; the face id
alone gives no point for the brush either.  The ray test gives both, the same in Cura 4.13 and
5.x, and picks only the selected model.

A model's painting lives in ``node.metadata[paint.METADATA_KEY]`` as JSON (face indices in the
node's own mesh order).  Cura's 3MF writer (4.13 and 5.x, ``ThreeMFWriter._convertUMNodeToSavitarNode``)
saves every ``node.metadata`` entry as object metadata and its reader puts unknown entries back
into ``node.metadata`` (as a Savitar ``MetadataEntry``, whose ``.value`` is read here).

While the tool is active each painted set shows on its model in the set's colour: an overlay node
per set (the painted triangles moved a little along their normals) at the scene root, following
the model's world transformation; it is not sliceable, not selectable, has no bounding box and is
on no build plate, so Cura neither slices, lists, saves nor measures it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from UM.Application import Application
from UM.Event import Event, MouseEvent
from UM.Logger import Logger
from UM.Operations.Operation import Operation
from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator
from UM.Scene.SceneNodeDecorator import SceneNodeDecorator

from . import paint
from .region_shapes import scene_to_gcode

PREF_BRUSH = "delaunay_infill/paint_brush_mm"
PREF_PAINT_DENSITY = "delaunay_infill/paint_density"
PREF_PAINT_DEPTH = "delaunay_infill/paint_depth_mm"
PREF_EXPORT_FOLDER = "delaunay_infill/paint_export_folder"

PAINT_PROPERTIES = ("PaintMode", "BrushSize", "PaintDensity", "PaintDepth", "PaintSets", "ActivePaintSet",
                    "PaintStatus", "ExportFolder", "ExportName")

OVERLAY_OFFSET_MM = 0.12  # how far above the surface the painted faces are drawn
#: how far (normalized view units, -1..1 across the view) the pointer may move before a press is a drag
CLICK_SLOP = 0.006


def _app():
    return Application.getInstance()


def _scene():
    return _app().getController().getScene()


def _machine_frame():
    stack = _app().getGlobalContainerStack()
    if stack is None:
        return 0.0, 0.0, True
    return (float(stack.getProperty("machine_width", "value")), float(stack.getProperty("machine_depth", "value")),
            bool(stack.getProperty("machine_center_is_zero", "value")))


# -- a node's painting -------------------------------------------------------------------------------

_parsed: dict = {}  # id(node) -> (text, PaintData) so the JSON is read once per change


def face_count(node) -> int:
    mesh = node.getMeshData() if node is not None else None
    if mesh is None:
        return 0
    return int(mesh.getFaceCount()) if mesh.hasIndices() else int(mesh.getVertexCount()) // 3


def _metadata_text(node):
    metadata = getattr(node, "metadata", None)
    if not isinstance(metadata, dict) or paint.METADATA_KEY not in metadata:
        return None
    value = metadata[paint.METADATA_KEY]
    if not isinstance(value, str):  # read back from a 3MF file: a Savitar MetadataEntry
        value = str(getattr(value, "value", value))
        metadata[paint.METADATA_KEY] = value
    return value


def node_paint(node) -> paint.PaintData | None:
    """The model's painting, or None (nothing painted, or saved for another mesh: then logged once)."""
    text = _metadata_text(node)
    if not text:
        return None
    hit = _parsed.get(id(node))
    if hit is not None and hit[0] == text:
        return hit[1].copy() if hit[1] is not None else None
    try:
        data = paint.PaintData.from_json(text, face_count(node))
    except (ValueError, TypeError) as error:
        Logger.log("w", "DelaunayInfill: ignoring the painting of %s: %s", node.getName(), error)
        data = None
    _parsed[id(node)] = (text, data)
    return data.copy() if data is not None else None


def set_node_paint(node, data: paint.PaintData | None) -> None:
    """Store `data` on the node (None or no set: the painting is removed)."""
    if data is None or not data.sets:
        node.metadata.pop(paint.METADATA_KEY, None)
        _parsed.pop(id(node), None)
        return
    text = data.to_json()
    node.metadata[paint.METADATA_KEY] = text
    _parsed[id(node)] = (text, data.copy())
    ensure_carrier(node)


class PaintCarrierDecorator(SceneNodeDecorator):
    """Carries a model's painting into its copies (Cura's "Multiply Selected").

    Uranium's ``SceneNode.__deepcopy__`` and Cura's ``CuraSceneNode.__deepcopy__`` (4.13 and 5.x)
    copy a node's mesh, transformation, name and decorators, but not ``node.metadata``, where the
    painting lives, so a copy came out unpainted.  Decorators are deep-copied and then handed
    their new node (``addDecorator`` calls ``setNode``): this one's copy takes the painting's
    JSON along and writes it into the new node's metadata.  The copy shares the mesh, so the
    face indices hold.  It has no decorations of its own (``callDecoration`` finds nothing here).
    """

    def __init__(self, carried: str | None = None):
        super().__init__()
        self._carried = carried

    def setNode(self, node) -> None:
        super().setNode(node)
        metadata = getattr(node, "metadata", None)
        if self._carried and isinstance(metadata, dict) and paint.METADATA_KEY not in metadata:
            metadata[paint.METADATA_KEY] = self._carried
        self._carried = None

    def __deepcopy__(self, memo):
        return type(self)(_metadata_text(self._node) if self._node is not None else None)


def ensure_carrier(node) -> None:
    """Give a painted model the decorator that carries its painting into copies (once)."""
    if not any(isinstance(d, PaintCarrierDecorator) for d in node.getDecorators()):
        node.addDecorator(PaintCarrierDecorator())


def local_triangles(node) -> np.ndarray:
    mesh = node.getMeshData()
    if mesh is None:
        return np.zeros((0, 3, 3))
    return paint.mesh_triangles(mesh.getVertices(), mesh.getIndices() if mesh.hasIndices() else None)


def world_triangles(node) -> np.ndarray:
    return paint.transform_triangles(node.getWorldTransformation().getData(), local_triangles(node))


def collect_painted(nodes, global_values: dict | None = None) -> list:
    """The painted sets of `nodes` as :class:`paint.PaintedSnapshot` (main thread; plain data out)."""
    if global_values:
        frame = (float(global_values.get("machine_width") or 0.0), float(global_values.get("machine_depth") or 0.0),
                 bool(global_values.get("machine_center_is_zero")))
    else:
        frame = _machine_frame()
    out = []
    for node in nodes:
        data = node_paint(node)
        if not data:
            continue
        try:
            out += paint.painted_snapshots(node.getName(), data, scene_to_gcode(world_triangles(node), *frame))
        except ValueError as error:
            Logger.log("w", "DelaunayInfill: %s", error)
    return out


class PaintOperation(Operation):
    """One undoable change of a model's painting (a stroke, a set's edit or deletion)."""

    def __init__(self, node, before, after, description: str = ""):
        super().__init__()
        self._node = node
        self._edit = paint.PaintEdit(before, after, self._apply, description)

    def _apply(self, data) -> None:
        set_node_paint(self._node, data)
        overlays = _overlays()
        if overlays is not None:
            overlays.update(self._node)
        _scene().sceneChanged.emit(self._node)  # the processed G-code depends on it: slice again

    def undo(self) -> None:
        self._edit.undo()

    def redo(self) -> None:
        self._edit.redo()

    def __repr__(self) -> str:
        return f"PaintOperation({self._node.getName()}: {self._edit.description})"


# -- the overlay -------------------------------------------------------------------------------------

_OVERLAYS = None


def _overlays():
    return _OVERLAYS


_OVERLAY_CLASS = None


def _overlay_class():
    global _OVERLAY_CLASS
    if _OVERLAY_CLASS is not None:
        return _OVERLAY_CLASS
    from UM.Scene.SceneNode import SceneNode

    class PaintOverlayNode(SceneNode):
        """The painted faces of one set, drawn in the set's colour (not sliced, selected or measured)."""

        shader = None

        def __init__(self, parent=None, **kwargs):
            super().__init__(parent=parent, **kwargs)
            self.model = None
            self.number = 0
            self.color = [1.0, 0.0, 0.0, 1.0]
            self.setSelectable(False)
            self.setCalculateBoundingBox(False)

        def render(self, renderer) -> bool:
            if not self.isVisible() or self.getMeshData() is None:
                return True
            cls = type(self)
            if cls.shader is None:
                from UM.Resources import Resources
                from UM.View.GL.OpenGL import OpenGL

                cls.shader = OpenGL.getInstance().createShaderProgram(Resources.getPath(Resources.Shaders, "object.shader"))
                cls.shader.addBinding("u_diffuseColor", "delaunay_paint_color")
                cls.shader.setUniformValue("u_ambientColor", [0.35, 0.35, 0.35, 1.0])
            renderer.queueNode(self, shader=cls.shader, uniforms={"delaunay_paint_color": self.color})
            return True

        def __deepcopy__(self, memo):  # never copied with a model (it is not the model's child)
            return type(self)()

    _OVERLAY_CLASS = PaintOverlayNode
    return PaintOverlayNode


class PaintOverlays:
    """The overlay nodes of every painted model, kept in step with the models' paintings."""

    def __init__(self):
        self._by_model: dict = {}  # id(model) -> (model, text, [overlay nodes])
        self._visible = False

    def _connect(self, model) -> None:
        model.transformationChanged.connect(self._onTransformation)

    def _onTransformation(self, model) -> None:
        entry = self._by_model.get(id(model))
        if entry is None:
            return
        for overlay in entry[2]:
            overlay.setTransformation(model.getWorldTransformation())

    def _remove(self, key) -> None:
        model, _, overlays = self._by_model.pop(key)
        try:
            model.transformationChanged.disconnect(self._onTransformation)
        except Exception:
            pass
        for overlay in overlays:
            parent = overlay.getParent()
            if parent is not None:
                parent.removeChild(overlay)

    def update(self, model) -> None:
        """Rebuild `model`'s overlays if its painting changed."""
        from UM.Mesh.MeshBuilder import MeshBuilder

        text = _metadata_text(model) or ""
        entry = self._by_model.get(id(model))
        if entry is not None and entry[0] is model and entry[1] == text:
            return
        if entry is not None:
            self._remove(id(model))
        data = node_paint(model)
        overlays = []
        if data:
            triangles = local_triangles(model)
            scale = abs(float(np.linalg.det(model.getWorldTransformation().getData()[:3, :3]))) ** (1.0 / 3.0) or 1.0
            cls = _overlay_class()
            for s in data.sets:
                if not len(s.faces):
                    continue
                builder = MeshBuilder()
                vertices = paint.overlay_triangles(triangles, s.faces, OVERLAY_OFFSET_MM / scale)
                builder.setVertices(vertices.reshape(-1, 3).astype(np.float32))
                builder.calculateNormals(fast=True)
                overlay = cls()
                overlay.setName(f"DelaunayPaint_{model.getName()}_{s.number}")
                overlay.model, overlay.number = model, s.number
                overlay.color = list(paint.set_color(s.number))
                overlay.setMeshData(builder.build())
                overlay.setTransformation(model.getWorldTransformation())
                overlay.setVisible(self._visible)
                _scene().getRoot().addChild(overlay)
                overlays.append(overlay)
        self._by_model[id(model)] = (model, text, overlays)
        if entry is None:
            self._connect(model)

    def sync(self) -> None:
        """Overlays for every painted model in the scene; none for models that are gone."""
        models = {id(n): n for n in DepthFirstIterator(_scene().getRoot())
                  if n.callDecoration("isSliceable") and isinstance(getattr(n, "metadata", None), dict)}
        for key in list(self._by_model):
            if key not in models or self._by_model[key][0] is not models[key]:
                self._remove(key)
        for model in models.values():
            if _metadata_text(model) is not None:
                ensure_carrier(model)  # a model read from a project: its copies keep the painting
            if _metadata_text(model) is not None or id(model) in self._by_model:
                self.update(model)

    def setVisible(self, visible: bool) -> None:
        self._visible = bool(visible)
        for _, _, overlays in self._by_model.values():
            for overlay in overlays:
                overlay.setVisible(self._visible)

    def nodes(self) -> list:
        return [o for _, _, overlays in self._by_model.values() for o in overlays]


# -- the tool's paint mode ----------------------------------------------------------------------------


class PaintToolMixin:
    """Paint mode, painted sets and their panel API, for ``DensityRegionTool``."""

    def _initPaint(self) -> None:
        global _OVERLAYS
        try:
            from PyQt6.QtCore import QTimer
        except ImportError:  # pragma: no cover - Cura 4.13
            from PyQt5.QtCore import QTimer
        preferences = _app().getPreferences()
        preferences.addPreference(PREF_BRUSH, 6.0)
        preferences.addPreference(PREF_PAINT_DENSITY, 60.0)
        preferences.addPreference(PREF_PAINT_DEPTH, 4.0)
        preferences.addPreference(PREF_EXPORT_FOLDER, os.path.expanduser("~"))
        self._paint_mode = "place"
        self._active_paint_set = 0  # 0: the next stroke starts a new set
        self._stroke = None
        self._press = None  # a press on the model not yet moved: a click or the start of a drag
        self._paint_status = ""
        self.setExposedProperties(*self.getExposedProperties(), *PAINT_PROPERTIES)
        _OVERLAYS = self._paint_overlays = PaintOverlays()
        self._paint_sync_timer = QTimer()
        self._paint_sync_timer.setInterval(200)
        self._paint_sync_timer.setSingleShot(True)
        self._paint_sync_timer.timeout.connect(self._paintSync)
        _scene().sceneChanged.connect(self._onPaintSceneChanged)
        controller = _app().getController()
        controller.activeToolChanged.connect(self._updateOverlayVisibility)
        controller.activeViewChanged.connect(self._updateOverlayVisibility)

    # -- properties --
    def getPaintMode(self) -> str:
        return self._paint_mode

    def setPaintMode(self, mode) -> None:
        mode = str(mode)
        if mode not in paint.MODES:
            Logger.log("w", "DelaunayInfill: unknown paint mode %r", mode)
            return
        self._paint_mode = mode
        self.propertyChanged.emit()

    def getBrushSize(self) -> float:
        try:
            return paint.clamp(_app().getPreferences().getValue(PREF_BRUSH), paint.MIN_BRUSH_MM, paint.MAX_BRUSH_MM, "brush")
        except (TypeError, ValueError):
            return 6.0

    def setBrushSize(self, size) -> None:
        try:
            _app().getPreferences().setValue(PREF_BRUSH, paint.clamp(size, paint.MIN_BRUSH_MM, paint.MAX_BRUSH_MM, "brush size"))
        except (TypeError, ValueError):
            Logger.log("w", "DelaunayInfill: ignoring brush size %r", size)
        self.propertyChanged.emit()

    def getPaintDensity(self) -> float:
        try:
            return paint.clamp(_app().getPreferences().getValue(PREF_PAINT_DENSITY), 0.0, 100.0, "density")
        except (TypeError, ValueError):
            return 60.0

    def setPaintDensity(self, density) -> None:
        try:
            _app().getPreferences().setValue(PREF_PAINT_DENSITY, paint.clamp(density, 0.0, 100.0, "density"))
        except (TypeError, ValueError):
            Logger.log("w", "DelaunayInfill: ignoring paint density %r", density)
        self.propertyChanged.emit()

    def getPaintDepth(self) -> float:
        try:
            return paint.clamp(_app().getPreferences().getValue(PREF_PAINT_DEPTH), paint.MIN_DEPTH_MM, paint.MAX_DEPTH_MM, "depth")
        except (TypeError, ValueError):
            return 4.0

    def setPaintDepth(self, depth) -> None:
        try:
            _app().getPreferences().setValue(PREF_PAINT_DEPTH, paint.clamp(depth, paint.MIN_DEPTH_MM, paint.MAX_DEPTH_MM, "depth"))
        except (TypeError, ValueError):
            Logger.log("w", "DelaunayInfill: ignoring paint depth %r", depth)
        self.propertyChanged.emit()

    def getExportFolder(self) -> str:
        """The save dialog's start folder: where the last export went (a ``file:`` URL for QML)."""
        folder = str(_app().getPreferences().getValue(PREF_EXPORT_FOLDER) or os.path.expanduser("~"))
        if not os.path.isdir(folder):
            folder = os.path.expanduser("~")
        return Path(os.path.abspath(folder)).as_uri()

    def getActivePaintSet(self) -> int:
        return int(self._active_paint_set)

    def setActivePaintSet(self, number) -> None:
        self.selectPaintSet(number)

    def getPaintStatus(self) -> str:
        return self._paint_status

    def getPaintSets(self) -> list:
        """The selected model's painted sets as rows for the panel."""
        model = self._selectedModel()
        data = node_paint(model) if model is not None else None
        if not data:
            return []
        return [{
            "number": s.number,
            "label": f"P{s.number}",
            "density": round(s.density, 2),
            "depth": round(s.depth, 2),
            "faces": int(len(s.faces)),
            "color": paint.set_color_hex(s.number),
            "active": s.number == self._active_paint_set,
        } for s in data.sets]

    # -- actions --
    def newPaintSet(self) -> None:
        """The next stroke starts a new set (with the panel's density and depth)."""
        self._active_paint_set = 0
        if self._paint_mode != "paint":
            self._paint_mode = "paint"
        self.propertyChanged.emit()

    def selectPaintSet(self, number) -> None:
        try:
            self._active_paint_set = int(number)
        except (TypeError, ValueError):
            self._active_paint_set = 0
        self.propertyChanged.emit()

    def _changePainting(self, model, after, description: str) -> bool:
        before = node_paint(model)
        operation = PaintOperation(model, before, after, description)
        if not operation._edit.changes:
            return False
        operation.push()
        self.propertyChanged.emit()
        return True

    def editPaintSet(self, data) -> bool:
        """Change a painted set: `data` has "number" and any of "density" (%), "depth" (mm). Undoable."""
        from .region_tool import _as_mapping

        data = _as_mapping(data)
        model = self._selectedModel()
        painting = node_paint(model) if model is not None else None
        target = painting.get(data.get("number", -1)) if painting else None
        if target is None:
            Logger.log("w", "DelaunayInfill: no painted set %r", data.get("number"))
            return False
        try:
            if data.get("density") not in (None, ""):
                target.density = paint.clamp(data["density"], 0.0, 100.0, "density")
            if data.get("depth") not in (None, ""):
                target.depth = paint.clamp(data["depth"], paint.MIN_DEPTH_MM, paint.MAX_DEPTH_MM, "depth")
        except (TypeError, ValueError) as error:
            Logger.log("w", "DelaunayInfill: cannot edit painted set %s: %s", target.number, error)
            return False
        return self._changePainting(model, painting, f"edit set {target.number}")

    def removePaintSet(self, number) -> bool:
        """Delete a painted set of the selected model (undoable)."""
        model = self._selectedModel()
        painting = node_paint(model) if model is not None else None
        if not painting or not painting.remove_set(number):
            return False
        if self._active_paint_set == int(number):
            self._active_paint_set = 0
        return self._changePainting(model, painting, f"delete set {number}")

    def getExportName(self) -> str:
        """The export's suggested file name for the highlighted set: ``<model>_paint<n>.stl``."""
        model = self._selectedModel()
        name = os.path.splitext(model.getName())[0] if model is not None else ""
        return f"{name or 'model'}_paint{max(self._active_paint_set, 1)}.stl"

    def exportPaintSet(self, number, chosen):
        """Write the selected model as MODEL.stl (G-code coordinates) and set `number` as FACES.json.

        `chosen` is what the panel's save dialog gives (a ``file:`` URL, or a path): ``X.stl``
        writes ``X.stl`` and ``X.faces.json``.  Its folder becomes the dialog's next start.
        Returns the two paths (also shown in the panel), or None.
        """
        model = self._selectedModel()
        painting = node_paint(model) if model is not None else None
        target = painting.get(number) if painting else None
        if target is None:
            self._paint_status = f"Nothing to export: no painted set P{number}"
            self.propertyChanged.emit()
            return None
        try:
            stl, faces = paint.export_paths(paint.local_path(chosen))
            os.makedirs(os.path.dirname(stl) or ".", exist_ok=True)
            paint.export_painting(stl, faces, scene_to_gcode(world_triangles(model), *_machine_frame()), target.faces)
        except (OSError, ValueError) as error:
            self._paint_status = f"Could not export: {error}"
            self.propertyChanged.emit()
            return None
        _app().getPreferences().setValue(PREF_EXPORT_FOLDER, os.path.dirname(stl))
        self._paint_status = (f"Wrote {stl} and {os.path.basename(faces)}: --paint "
                              f"{os.path.basename(stl)}:{os.path.basename(faces)}:{target.density:g}:{target.depth:g}")
        self.propertyChanged.emit()
        return stl, faces

    def exportChosenPaintSet(self, data):
        """Panel: the save dialog's choice, ``{"number": n, "file": url}`` (triggerActionWithData); the paths or None."""
        from .region_tool import _as_mapping

        data = _as_mapping(data)
        try:
            number = int(data.get("number", 0))
        except (TypeError, ValueError):
            number = 0
        return self.exportPaintSet(number, str(data.get("file") or ""))

    def paintStroke(self, model, world_points, erase: bool = False, brush: float | None = None, view_direction=None):
        """Paint (or erase) along world points on `model` as one undoable stroke (Python API and tests)."""
        if not self._startStroke(model, erase):
            return False
        for point in world_points:
            self._brushAt(np.asarray(point, dtype=float), view_direction, None, brush)
        return self._finishStroke()

    # -- strokes --
    def _startStroke(self, model, erase: bool) -> bool:
        before = node_paint(model)
        count = face_count(model)
        working = before.copy() if before is not None else paint.PaintData(count)
        number = self._active_paint_set
        if not erase and working.get(number) is None:
            number = working.add_set(self.getPaintDensity(), self.getPaintDepth()).number
        self._stroke = {"model": model, "before": before, "data": working, "number": number, "erase": erase,
                        "triangles": paint.outward(world_triangles(model)), "last": None, "changed": False}
        _app().getController().toolOperationStarted.emit(self)
        return True

    def _brushAt(self, point, view_direction, hit_face, brush=None) -> None:
        stroke = self._stroke
        radius = 0.5 * float(brush if brush is not None else self.getBrushSize())
        points = [point] if stroke["last"] is None else paint.stroke_points(stroke["last"], point, radius)
        faces = np.unique(np.concatenate([
            paint.brush_faces(stroke["triangles"], p, radius, view_direction=view_direction) for p in points]
            + ([np.array([hit_face], dtype=np.int64)] if hit_face is not None else [])))
        stroke["last"] = point
        if stroke["erase"]:
            changed = stroke["data"].erase(faces)
        else:
            changed = stroke["data"].paint(stroke["number"], faces)
        if changed:
            stroke["changed"] = True
            model = stroke["model"]
            set_node_paint(model, stroke["data"])  # shown at once; the operation is pushed at the end
            self._paint_overlays.update(model)
            self.propertyChanged.emit()  # the panel's face counts follow the stroke

    def _finishStroke(self) -> bool:
        stroke, self._stroke = self._stroke, None
        if stroke is None:
            return False
        _app().getController().toolOperationStopped.emit(self)
        model, after = stroke["model"], stroke["data"]
        if stroke["erase"]:
            after.drop_empty()
        elif after.get(stroke["number"]) is not None and not len(after.get(stroke["number"]).faces):
            after.remove_set(stroke["number"])
        operation = PaintOperation(model, stroke["before"], after, "erase" if stroke["erase"] else f"paint set {stroke['number']}")
        if not operation._edit.changes:
            set_node_paint(model, stroke["before"])
            self._paint_overlays.update(model)
            return False
        operation.push()
        if not stroke["erase"]:
            self._active_paint_set = stroke["number"]
        self.propertyChanged.emit()
        return True

    def _pickOnModel(self, model, x: float, y: float):
        """(world point, face, ray direction) under normalized view coordinates, or None."""
        camera = _scene().getActiveCamera()
        if camera is None:
            return None
        ray = camera.getRay(x, y)
        origin = np.array([ray.origin.x, ray.origin.y, ray.origin.z], dtype=float)
        direction = np.array([ray.direction.x, ray.direction.y, ray.direction.z], dtype=float)
        triangles = self._stroke["triangles"] if self._stroke is not None else world_triangles(model)
        hit = paint.ray_hit(origin, direction, triangles)
        if hit is None:
            return None
        face, _, point = hit
        return point, face, direction / max(np.linalg.norm(direction), 1e-300)

    def _paintEvent(self, event):
        """Handle a mouse event in paint/erase mode: True (used), or None (not a paint event).

        A press on the model is held until the pointer moves more than :data:`CLICK_SLOP`: then
        it is a drag and paints (or erases) from the press point on.  Released where it was
        pressed it is a click: in paint mode a click on a painted face selects that face's set
        (the next drag paints into it) and paints nothing; a click on an unpainted face, or any
        click in erase mode, paints (erases) one brush dab there.
        """
        if self._paint_mode == "place":
            return None
        if event.type == Event.MousePressEvent and MouseEvent.LeftButton in event.buttons:
            if not self._controller.getToolsEnabled():
                return None
            model = self._selectedModel()
            if model is None:
                return None
            picked = self._pickOnModel(model, event.x, event.y)
            if picked is None:
                return None
            self._press = {"model": model, "x": event.x, "y": event.y, "picked": picked}
            return True
        if self._stroke is None and self._press is None:
            return None
        if event.type == Event.MouseMoveEvent:
            if self._stroke is None:
                if max(abs(event.x - self._press["x"]), abs(event.y - self._press["y"])) <= CLICK_SLOP:
                    return True  # still a click
                self._startPressedStroke()
            picked = self._pickOnModel(self._stroke["model"], event.x, event.y)
            if picked is not None:
                self._brushAt(picked[0], picked[2], picked[1])
            else:
                self._stroke["last"] = None  # off the model: do not join the next point to this one
            return True
        if event.type == Event.MouseReleaseEvent:
            if self._stroke is None:
                self._click(self._press)
            else:
                self._finishStroke()
            self._press = None
            return True
        return None

    def _startPressedStroke(self) -> None:
        """Start a stroke with a dab where the held press was."""
        press = self._press
        self._startStroke(press["model"], self._paint_mode == "erase")
        point, face, direction = press["picked"]
        self._brushAt(point, direction, face)

    def _click(self, press) -> None:
        """A click on the model: select the clicked face's set (paint mode), else one dab."""
        if press is None:
            return
        painting = node_paint(press["model"])
        number = painting.set_of_face(press["picked"][1]) if painting and self._paint_mode == "paint" else 0
        if number:
            self.selectPaintSet(number)
            return
        self._startPressedStroke()
        self._finishStroke()

    # -- keeping overlays in step --
    def _onPaintSceneChanged(self, node) -> None:
        if node is not None and isinstance(node, _overlay_class()):
            return
        self._paint_sync_timer.start()

    def _paintSync(self) -> None:
        try:
            self._paint_overlays.sync()
            self._updateOverlayVisibility()
        except Exception:
            Logger.logException("w", "DelaunayInfill: could not update the painted faces' overlay")

    def _updateOverlayVisibility(self) -> None:
        controller = _app().getController()
        view = controller.getActiveView()
        solid = view is None or getattr(view, "getPluginId", lambda: "SolidView")() == "SolidView"
        visible = controller.getActiveTool() is self and solid
        if visible:
            self._paint_overlays.sync()
        self._paint_overlays.setVisible(visible)
