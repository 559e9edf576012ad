"""Steps for the painted-density GUI test, run inside a real Cura by the GUI driver.

Called as ``function(ctx, **args)`` on Cura's main thread (see driver.py); generators yield waits.
The panel helpers (``_qml_object``, ``_type_into``, ``choose_in_combobox``, ``select_tool``) come
from steps_regions.py next to this file.  Coordinates in arguments are G-code millimetres.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location("delaunay_gui_steps_regions_for_paint",
                                               str(Path(__file__).resolve().parent / "steps_regions.py"))
regions = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(regions)

select_tool = regions.select_tool


def _paint_tool_module():
    return regions._plugin_module("paint_tool")


def _rows(ctx):
    return [[r["label"], r["density"], r["depth"], r["faces"]] for r in regions._tool(ctx).getPaintSets()]


def setup_paint(ctx, brush: float, density: float, depth: float):
    """Through the panel: choose Paint in the mode box, type the brush size, density and depth."""
    tool = regions._tool(ctx)
    qt = regions._qt()
    window = ctx.app.getMainWindow()

    def laid_out():  # the panel opens with the tool; its list is laid out a moment later
        obj = regions._qml_object(ctx, "paintMode")
        if obj is None:
            return False
        item = qt["sip"].cast(obj, qt["QQuickItem"])
        corner = item.mapToScene(qt["QPointF"](0, 0))
        return item.isVisible() and item.width() > 0 and 0 < corner.y() < window.height() - 3 * item.height()

    yield ctx.wait_until(laid_out, 10, "the panel's paint mode box on the screen")
    yield 1.0
    yield from regions.choose_in_combobox(ctx, "paintMode", 1)
    for name, value in (("brushSize", brush), ("paintDensity", density), ("paintDepth", depth)):
        yield ctx.wait_until(lambda n=name: regions._qml_object(ctx, n) is not None, 10, f"the panel's {name}")
        regions._type_into(ctx, regions._qml_object(ctx, name), f"{value:g}")
        yield 0.3
    ctx.record("paint_setup", {"mode": tool.getPaintMode(), "brush": tool.getBrushSize(),
                               "density": tool.getPaintDensity(), "depth": tool.getPaintDepth()})


def _pixel(ctx, gcode_point):
    """Screen pixel (X display) of a G-code point, through Cura's camera."""
    try:
        from PyQt6.QtCore import QPoint
    except ImportError:
        from PyQt5.QtCore import QPoint
    point = regions._to_scene(ctx, gcode_point)
    camera = ctx.app.getController().getScene().getActiveCamera()
    clip = camera.getProjectionMatrix().getData() @ camera.getInverseWorldTransformation().getData() @ np.array(
        [point.x, point.y, point.z, 1.0])
    ndc_x, ndc_y = clip[0] / clip[3], clip[1] / clip[3]
    window = ctx.app.getMainWindow()
    local = QPoint(int(round((ndc_x + 1.0) / 2.0 * window.width())), int(round((1.0 - ndc_y) / 2.0 * window.height())))
    screen = window.mapToGlobal(local)
    return [screen.x(), screen.y()]


def _xdotool(ctx, args):
    """Run xdotool (real X pointer events) without blocking Cura's event loop."""
    command = shutil.which("xdotool")
    if command is None:
        raise RuntimeError("xdotool is not installed (apt-get install xdotool)")
    process = subprocess.Popen([command, *[str(a) for a in args]], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               env=dict(os.environ))
    yield ctx.wait_until(lambda: process.poll() is not None, 60, "xdotool")
    if process.returncode != 0:
        raise RuntimeError(f"xdotool failed: {process.stderr.read().decode(errors='replace')}")


def drag_paint(ctx, model: str, points: list, z: float, screenshot: str = ""):
    """Paint with a real mouse drag: press on the model at the first point, move through the others, release.

    `points` are (dx, dy) mm from the model's centre (G-code X/Y) on the surface at G-code height `z`.
    The pointer is moved by xdotool (X events, through Qt and Cura's mouse device to the tool). With
    `screenshot`, the screen is captured while the button is still held (painting in progress).
    """
    gcode = [regions._model_point(ctx, model, p, z) for p in points]
    pixels = [_pixel(ctx, p) for p in gcode]
    ctx.record("drag_pixels", pixels)
    stack = ctx.app.getOperationStack()
    ops_before = len(stack.getOperations())
    args = ["mousemove", *pixels[0], "sleep", "0.4", "mousedown", "1", "sleep", "0.3"]
    for px, py in pixels[1:]:
        args += ["mousemove", px, py, "sleep", "0.25"]
    yield from _xdotool(ctx, args)
    yield 1.0
    during = _rows(ctx)
    if screenshot:
        subprocess.run(["/usr/bin/import", "-window", "root", screenshot], check=True, timeout=60)
    yield from _xdotool(ctx, ["mouseup", "1", "sleep", "0.3", "mousemove", 5, 5])
    yield 0.8
    ctx.record("drag", {"during": during, "after": _rows(ctx), "operations": len(stack.getOperations()) - ops_before,
                        "last_operation": repr(stack.getOperations()[-1]) if stack.getOperations() else ""})


def record_paint(ctx, model: str, key: str):
    """Record the model's painting (saved form), the panel's rows, the overlays and the sizes Cura shows."""
    module = _paint_tool_module()
    node = ctx.node(model)
    data = module.node_paint(node)
    overlays = [o for o in module._overlays().nodes()] if module._overlays() is not None else []
    from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

    root = ctx.app.getController().getScene().getRoot()
    sliceable = sorted(n.getName() for n in DepthFirstIterator(root) if n.callDecoration("isSliceable"))
    box = node.getBoundingBox()
    tri = module.world_triangles(node)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    top = np.flatnonzero((normals[:, 1] > 0.99) & (tri[:, :, 1].min(axis=1) > box.top - 1e-3)).tolist()
    ctx.record(key, {
        "json": json.loads(data.to_json()) if data else None,
        "faces": [s.faces.tolist() for s in data.sets] if data else [],
        "face_count": module.face_count(node),
        "top_faces": top,
        "rows": _rows(ctx),
        "overlays": [{"name": o.getName(), "visible": o.isVisible(), "selectable": o.isSelectable(),
                      "sliceable": bool(o.callDecoration("isSliceable")), "box": o.getBoundingBox() is not None,
                      "faces": o.getMeshData().getVertexCount() // 3, "color": o.color} for o in overlays],
        "sliceable": sliceable,
        "size": [box.width, box.height, box.depth],
        "scene_size": _scene_size(ctx),
        "centre": regions._model_point(ctx, model, [0.0, 0.0], 0.0),
        "infill_line_width": float(node.callDecoration("getStack").getProperty("infill_line_width", "value")),
    })
    if False:
        yield


def _scene_size(ctx):
    """What Cura shows under the object list (the scene's bounding box), mm."""
    info = getattr(ctx.app, "getSceneBoundingBoxString", None)
    return info() if callable(info) else None


def undo_redo_paint(ctx, model: str):
    """Undo the last stroke, then redo it; record the rows after each."""
    stack = ctx.app.getOperationStack()
    out = {"before": _rows(ctx)}
    stack.undo()
    yield 0.5
    out["undone"] = _rows(ctx)
    stack.redo()
    yield 0.5
    out["redone"] = _rows(ctx)
    ctx.record("paint_undo", out)


def erase_and_undo(ctx, model: str, point: list, z: float, brush: float):
    """Erase around one point through the tool's Python API, then undo it."""
    tool = regions._tool(ctx)
    centre = regions._to_scene(ctx, regions._model_point(ctx, model, point, z))
    out = {"before": _rows(ctx)}
    tool.paintStroke(ctx.node(model), [[centre.x, centre.y, centre.z]], erase=True, brush=brush)
    yield 0.5
    out["erased"] = _rows(ctx)
    ctx.app.getOperationStack().undo()
    yield 0.5
    out["undone"] = _rows(ctx)
    ctx.record("paint_erase", out)


def edit_in_panel(ctx, label: str, density: float, depth: float):
    """Type a density and a depth into a painted set's row (then undo the density and type it again)."""
    def row_field(name):
        return regions._qml_object(ctx, name, within="paintList")

    out = {"before": _rows(ctx)}
    yield 0.6
    for name, value in (("paintDensityField" + label, density), ("paintDepthField" + label, depth)):
        yield ctx.wait_until(lambda n=name: row_field(n) is not None, 10, f"the panel's {name}")
        regions._type_into(ctx, row_field(name), f"{value:g}")
        yield 0.6
    out["edited"] = _rows(ctx)
    ctx.app.getOperationStack().undo()  # the depth
    yield 0.5
    ctx.app.getOperationStack().undo()  # the density
    yield 0.5
    out["undone"] = _rows(ctx)
    ctx.app.getOperationStack().redo()
    ctx.app.getOperationStack().redo()
    yield 0.5
    out["redone"] = _rows(ctx)
    ctx.record("paint_edit", out)


def set_paint_values(ctx, label: str, density: float, depth: float):
    """Set a painted set's density and depth through the tool's action (as the panel's row does)."""
    tool = regions._tool(ctx)
    tool.editPaintSet({"number": int(label.lstrip("P")), "density": density, "depth": depth})
    yield 0.3


def click_select_set(ctx, model: str, point: list, z: float):
    """With "New set" active, a real mouse click (no drag) on a painted face: its set is selected, nothing painted."""
    tool = regions._tool(ctx)
    tool.newPaintSet()
    yield 0.3
    stack = ctx.app.getOperationStack()
    out = {"active_before": tool.getActivePaintSet(), "rows_before": _rows(ctx), "ops_before": len(stack.getOperations())}
    px, py = _pixel(ctx, regions._model_point(ctx, model, point, z))
    yield from _xdotool(ctx, ["mousemove", px, py, "sleep", "0.4", "click", "1", "sleep", "0.3", "mousemove", 5, 5])
    yield 0.8
    out.update(active_after=tool.getActivePaintSet(), rows_after=_rows(ctx), ops_after=len(stack.getOperations()))
    ctx.record("paint_click", out)


def export_paint(ctx, model: str, number: int, path: str, screenshot: str = ""):
    """Export through the panel: its Export button opens a save dialog; the chosen file goes to the tool.

    The button is clicked (a real mouse event on it), the dialog is seen open and cancelled; then the
    tool's slot is driven with `path` as a file URL, exactly what the dialog's accept hands over.
    """
    try:
        from PyQt6.QtCore import QMetaObject, QUrl
    except ImportError:
        from PyQt5.QtCore import QMetaObject, QUrl
    tool = regions._tool(ctx)
    tool.selectPaintSet(number)
    yield 0.5
    button = regions._qml_object(ctx, "exportPaintSet")
    dialog = regions._qml_object(ctx, "exportDialog")
    out = {"button": button is not None, "dialog": dialog is not None}
    if button is not None and dialog is not None:
        regions._click(ctx, button)
        yield ctx.wait_until(lambda: bool(dialog.property("visible")), 20, "the export dialog open")
        yield 1.0
        if screenshot:
            subprocess.run(["/usr/bin/import", "-window", "root", screenshot], check=True, timeout=60)
        out["opened"] = bool(dialog.property("visible"))
        out["number"] = dialog.property("number")
        out["save_mode"] = dialog.property("savesFile")  # Qt 6: fileMode SaveFile; Qt 5: not selectExisting
        out["title"] = dialog.property("title")
        QMetaObject.invokeMethod(dialog, "reject")
        yield 1.0
        out["closed"] = not bool(dialog.property("visible"))
    paths = tool.exportChosenPaintSet({"number": number, "file": QUrl.fromLocalFile(path).toString()})
    yield 0.3
    stem = os.path.splitext(path)[0]
    out.update(paths=[stem + ".stl", stem + ".faces.json"], status=tool.getPaintStatus(),
               folder=tool.getExportFolder(), name=tool.getExportName(), returned=paths)
    ctx.record("paint_export", out)


def _painted_models(ctx, model: str) -> list:
    return [n for n in ctx.nodes() if n.getName() == model]


def multiply_and_mirror(ctx, model: str):
    """Cura's Multiply Selected (one copy, the menu's CuraActions.multiplySelection), then mirror the copy upside down."""
    from UM.Math.Vector import Vector
    from UM.Operations.MirrorOperation import MirrorOperation
    from UM.Scene.Selection import Selection

    module = _paint_tool_module()
    (original,) = _painted_models(ctx, model)
    Selection.clear()
    Selection.add(original)
    yield 0.3
    actions = getattr(ctx.app, "_cura_actions", None)
    if actions is None:
        raise RuntimeError("Cura has no CuraActions")
    actions.multiplySelection(1)
    from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

    def copies():
        root = ctx.app.getController().getScene().getRoot()
        return [n for n in DepthFirstIterator(root) if n is not original and n.getMeshData() is not None
                and n.getMeshData() is original.getMeshData()]

    for _ in range(60):
        if copies():
            break
        yield 0.5
    root = ctx.app.getController().getScene().getRoot()
    ctx.record("multiply_nodes", [[type(n).__name__, n.getName(), bool(n.callDecoration("isSliceable")),
                                   type(n.getParent()).__name__ if n.getParent() else None,
                                   [type(d).__name__ for d in n.getDecorators()]] for n in DepthFirstIterator(root)])
    if not copies():
        raise RuntimeError("no multiplied copy in the scene")
    yield 2.0  # arranged
    (copy,) = copies()
    out = {"copy_json": json.loads(module.node_paint(copy).to_json()) if module.node_paint(copy) else None,
           "original_json": json.loads(module.node_paint(original).to_json()) if module.node_paint(original) else None,
           "shares_mesh": copy.getMeshData() is original.getMeshData()}
    MirrorOperation(copy, Vector(1, -1, 1), mirror_around_center=True).push()
    yield 2.0
    Selection.clear()
    Selection.add(original)
    yield 0.5
    for key, node in (("original", original), ("copy", copy)):
        box = node.getBoundingBox()
        tri = module.world_triangles(node)
        data = module.node_paint(node)
        painted = tri[data.sets[0].faces] if data else np.zeros((0, 3, 3))
        out[key] = {"centre": regions._plugin_module("region_shapes").scene_to_gcode(
                        [box.center.x, box.center.y, box.center.z], *regions._frame(ctx)).tolist(),
                    "painted_height": [float(painted[:, :, 1].min()), float(painted[:, :, 1].max())] if len(painted) else None,
                    "bottom": float(box.bottom), "top": float(box.top)}
    out["overlays"] = sorted(o.getName() for o in module._overlays().nodes())
    ctx.record("multiply", out)


def save_project(ctx, path: str):
    """Save the scene as a Cura project (.3mf) through Cura's workspace writer, as File > Save Project does."""
    from UM.Mesh.MeshWriter import MeshWriter

    handler = ctx.app.getWorkspaceFileHandler()
    writer = handler.getWriterByMimeType("application/vnd.ms-package.3dmanufacturing-3dmodel+xml")
    if writer is None:
        raise RuntimeError("Cura has no project writer")
    root = ctx.app.getController().getScene().getRoot()
    with open(path, "wb") as stream:
        ok = writer.write(stream, [root], MeshWriter.OutputMode.BinaryMode)
    if ok is False:
        raise RuntimeError(f"the project writer failed: {writer.getInformation()}")
    ctx.log(f"saved project {path} ({os.path.getsize(path)} bytes)")
    yield 0.5


def open_project(ctx, path: str, model: str):
    """Open a project as a user does (File > Open, "Open as project", the summary dialog's Open button)."""
    try:
        from PyQt6.QtCore import QUrl
    except ImportError:
        from PyQt5.QtCore import QUrl
    from UM.Scene.Selection import Selection

    Selection.clear()
    ctx.app.getController().setActiveTool(None)
    old = [n for n in ctx.nodes() if n.getName() == model]
    reader = ctx.app.getWorkspaceFileHandler().getReaderForFile(path)
    ctx.app.readLocalFile(QUrl.fromLocalFile(path), project_mode="open_as_project", add_to_recent_files=False)
    dialog = getattr(reader, "_dialog", None)
    yield ctx.wait_until(lambda: dialog is not None and bool(getattr(dialog, "_visible", False)), 60,
                         "the project summary dialog")
    yield 1.0
    dialog.onOkButtonClicked()  # its Open button

    def loaded():
        nodes = [n for n in ctx.nodes() if n.getName() == model]
        return bool(nodes) and all(n not in old for n in nodes)

    yield ctx.wait_until(loaded, 60, "the project's model in the scene")
    yield 2.0


def panel_geometry(ctx, names: list, key: str = "paint_panel_geometry"):
    """Record where the paint section's controls are (scene x, y, width, height, visible)."""
    qt = regions._qt()
    window = ctx.app.getMainWindow()
    out = {"window": [window.width(), window.height()]}
    for name in names:
        obj = regions._qml_object(ctx, name)
        if obj is None:
            out[name] = None
            continue
        item = qt["sip"].cast(obj, qt["QQuickItem"])
        corner = item.mapToScene(qt["QPointF"](0, 0))
        out[name] = [round(corner.x()), round(corner.y()), round(item.width()), round(item.height()), item.isVisible()]
    ctx.record(key, out)
    if False:
        yield
