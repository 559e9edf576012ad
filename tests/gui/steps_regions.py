"""Steps for the density-region GUI test, run inside a real Cura by the GUI driver.

Each public function is called as ``function(ctx, **args)`` on Cura's main
thread (``{"do": "step", "file": ..., "function": ..., "args": {...}}``); a
generator yields waits (seconds, or ``ctx.wait_until(...)`` tuples).  What the
test asserts on is written with ``ctx.record(key, value)`` into the status JSON.
Coordinates in arguments and records are G-code millimetres.
"""

from __future__ import annotations

import sys

import numpy as np


def _plugin_module(name: str):
    """A module of the installed DelaunayInfill plugin (as Cura imported it)."""
    for module_name, module in list(sys.modules.items()):
        if module_name.endswith("DelaunayInfill.cura." + name):
            return module
    raise RuntimeError(f"the DelaunayInfill plugin's {name} module is not loaded")


def _tool(ctx):
    tool = ctx.app.getController().getTool("DelaunayInfill")
    if tool is None:
        raise RuntimeError("Cura has no 'DelaunayInfill' tool: the Density regions tool did not load")
    return tool


def _frame(ctx):
    stack = ctx.app.getGlobalContainerStack()
    return (
        float(stack.getProperty("machine_width", "value")),
        float(stack.getProperty("machine_depth", "value")),
        bool(stack.getProperty("machine_center_is_zero", "value")),
    )


def _model_point(ctx, model: str, offset, z):
    """G-code point: `offset` (dx, dy mm) from the model's bounding-box centre, at G-code height `z`."""
    shapes = _plugin_module("region_shapes")
    box = ctx.node(model).getBoundingBox()
    centre = shapes.scene_to_gcode([box.center.x, box.center.y, box.center.z], *_frame(ctx))
    return [float(centre[0] + offset[0]), float(centre[1] + offset[1]), float(z)]


def _to_scene(ctx, gcode_point):
    from UM.Math.Vector import Vector

    shapes = _plugin_module("region_shapes")
    x, y, z = shapes.gcode_to_scene(np.asarray(gcode_point, dtype=float), *_frame(ctx))
    return Vector(float(x), float(y), float(z))


def select_tool(ctx, model: str):
    """Select `model` and make Density regions the active tool (its panel opens)."""
    from UM.Scene.Selection import Selection

    node = ctx.node(model)
    Selection.clear()
    Selection.add(node)
    yield 0.3
    ctx.app.getController().setActiveTool(_tool(ctx))
    yield 0.7
    active = ctx.app.getController().getActiveTool()
    if active is not _tool(ctx):
        raise RuntimeError(f"the active tool is {active!r}, not Density regions")
    ctx.record("tool_metadata", _plugin_module("region_tool").tool_metadata())


def add_regions(ctx, model: str, regions: list):
    """Add regions through the tool's Python API.

    `regions`: [{shape, size, density, offset: [dx, dy], z}] with the centre
    `offset` mm from the model's centre (G-code X/Y) at G-code height `z`.
    """
    tool = _tool(ctx)
    node = ctx.node(model)
    for spec in regions:
        centre = _model_point(ctx, model, spec["offset"], spec["z"])
        region = tool.addRegion(node, _to_scene(ctx, centre), spec["shape"], spec["size"], spec["density"])
        if region is None:
            raise RuntimeError(f"addRegion refused {spec}")
        ctx.log(f"added {region.getName()} via the Python API")
        yield 0.3


def click_region(ctx, model: str, offset: list, z: float, shape: str, size: float, density: float):
    """Add a region the way a user does: set the panel's values, then click the model.

    The click is a real Qt mouse press/release posted to Cura's main window at
    the pixel where the model's surface point `offset` (dx, dy mm from the
    model's centre) at G-code height `z` appears.
    """
    try:
        from PyQt6.QtCore import QEvent, QPointF, Qt
        from PyQt6.QtGui import QMouseEvent
        from PyQt6.QtWidgets import QApplication

        left, none, no_mod = Qt.MouseButton.LeftButton, Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier
        press, release = QEvent.Type.MouseButtonPress, QEvent.Type.MouseButtonRelease
    except ImportError:
        from PyQt5.QtCore import QEvent, QPointF, Qt
        from PyQt5.QtGui import QMouseEvent
        from PyQt5.QtWidgets import QApplication

        left, none, no_mod = Qt.LeftButton, Qt.NoButton, Qt.NoModifier
        press, release = QEvent.MouseButtonPress, QEvent.MouseButtonRelease

    tool = _tool(ctx)
    tool.setShape(shape)
    tool.setSize(size)
    tool.setDensity(density)
    before = {n.getName() for n in _plugin_module("region_tool").region_nodes()}

    camera = ctx.app.getController().getScene().getActiveCamera()
    at = _model_point(ctx, model, offset, z)
    ctx.record("click_target", at)
    point = _to_scene(ctx, at)
    clip = camera.getProjectionMatrix().getData() @ camera.getInverseWorldTransformation().getData() @ np.array(
        [point.x, point.y, point.z, 1.0]
    )
    ndc_x, ndc_y = clip[0] / clip[3], clip[1] / clip[3]
    window = ctx.app.getMainWindow()
    px = (ndc_x + 1.0) / 2.0 * window.width()
    py = (1.0 - ndc_y) / 2.0 * window.height()
    ctx.record("click_pixel", [round(px, 1), round(py, 1), window.width(), window.height()])
    position = QPointF(px, py)
    for kind in (press, release):
        event = QMouseEvent(kind, position, left, left if kind == press else none, no_mod)
        QApplication.sendEvent(window, event)
        yield 0.2

    def added():
        return {n.getName() for n in _plugin_module("region_tool").region_nodes()} - before

    yield ctx.wait_until(lambda: bool(added()), 10, "a region placed by the click")
    names = sorted(added())
    ctx.log(f"the click added {names}")
    ctx.record("clicked_regions", names)
    yield 0.3
    ctx.record("rows_after_click", [(row["label"], row["selected"]) for row in tool.getRegions()])


def record_regions(ctx, model: str, key: str = "regions"):
    """Record the regions (G-code geometry, densities) and what the panel lists."""
    region_tool = _plugin_module("region_tool")
    tool = _tool(ctx)
    out = []
    for region in region_tool.collect_scene_regions():
        lo, hi = region.bounds()
        out.append({
            "name": region.name,
            "number": region.number,
            "shape": region.shape,
            "size": region.size,
            "density": region.density,
            "parent": region.parent,
            "min": lo.tolist(),
            "max": hi.tolist(),
        })
    ctx.record(key, out)
    ctx.record(key + ":panel", {
        "model": tool.getModelName(),
        "base_density": tool.getBaseDensity(),
        "rows": tool.getRegions(),
    })
    stack = ctx.node(model).callDecoration("getStack")
    ctx.record("infill_line_width", float(stack.getProperty("infill_line_width", "value")))
    ctx.record("base_density", float(stack.getProperty("infill_sparse_density", "value")))
    if False:
        yield


def check_undo(ctx):
    """Undo the last region, check it is gone, redo it, check it is back."""
    region_tool = _plugin_module("region_tool")
    before = sorted(n.getName() for n in region_tool.region_nodes())
    stack = ctx.app.getOperationStack()
    stack.undo()
    yield 0.3
    after_undo = sorted(n.getName() for n in region_tool.region_nodes())
    stack.redo()
    yield 0.3
    after_redo = sorted(n.getName() for n in region_tool.region_nodes())
    ctx.record("undo", {"before": before, "after_undo": after_undo, "after_redo": after_redo})


def check_preview(ctx, timeout_s: float = 60, key: str = "preview"):
    """Wait until Preview shows the processed G-code; record its infill length per layer.

    Recorded: ``preview`` = {"layers": {";LAYER: number": [preview FILL mm,
    processed G-code FILL mm, preview FILL segments, processed FILL segments]}}
    so the test can tell whether the layer view holds the processed paths or
    CuraEngine's original ones.
    """
    preview = _plugin_module("preview")
    from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

    def layer_node():
        for node in DepthFirstIterator(ctx.app.getController().getScene().getRoot()):
            if node.callDecoration("getLayerData") is not None:
                return node
        return None

    def shown():
        updater = preview._updater
        return updater is not None and updater._shown is not None and layer_node() is not None

    yield ctx.wait_until(shown, timeout_s, "Preview rebuilt from the processed G-code")
    data = layer_node().callDecoration("getLayerData")
    preview_fill = {}
    for index, layer in data.getLayers().items():
        total, count = 0.0, 0
        for polygon in layer.polygons:
            points = np.asarray(polygon.data, dtype=float)
            types = np.asarray(polygon.types).reshape(-1)
            seg = np.diff(points[:, [0, 2]], axis=0)
            total += float(np.hypot(seg[:, 0], seg[:, 1])[types == preview.INFILL].sum())
            count += int((types == preview.INFILL).sum())
        preview_fill[int(index)] = (total, count)
    paths = preview.parse_gcode_paths(ctx.gcode_list())
    index_of = preview.layer_index_map(run.number for run in paths)
    gcode_fill = {}
    for run in paths:
        length, count = gcode_fill.get(run.number, (0.0, 0))
        gcode_fill[run.number] = (length + run.length_of(preview.INFILL), count + int((run.types == preview.INFILL).sum()))
    ctx.record(key, {
        "layers": {
            str(n): [preview_fill.get(index_of[n], (0.0, 0))[0], gcode_fill[n][0],
                     preview_fill.get(index_of[n], (0.0, 0))[1], gcode_fill[n][1]]
            for n in sorted(gcode_fill)
        },
    })


def record_estimates(ctx):
    """Record the print time and material Cura's UI shows, and the processed header's."""
    estimates = _plugin_module("estimates")
    info = ctx.app.getPrintInformation()
    header = estimates.header_totals(ctx.gcode_list()[0])
    ctx.record("estimates", {
        "ui_time_s": int(info.currentPrintTime),
        "ui_material_m": [float(v) for v in info.materialLengths],
        "header_time_s": header.time_s,
        "header_filament_m": header.filament_m,
    })
    if False:
        yield


def show_single_layer(ctx, layer: int):
    """Preview: show only layer `layer` (both ends of the layer range), so one layer's infill is visible."""
    from UM.PluginRegistry import PluginRegistry

    view = PluginRegistry.getInstance().getPluginObject("SimulationView")
    yield ctx.wait_until(lambda: view.getMaxLayers() > 0, 60, "the layer view's data")
    layer = min(int(layer), view.getMaxLayers())
    view.setLayer(layer)
    view.setMinimumLayer(layer)
    yield 1.0


def _qml_object(ctx, name: str, within: str = "regionList"):
    """A QML object of Cura's main window by objectName (the tool panel's fields and buttons).

    Repeater delegates are only in the visual tree (``childItems``), not among the
    window's QObject children, so the tool panel's list is walked visually.
    """
    try:
        from PyQt6 import sip
        from PyQt6.QtCore import QObject
        from PyQt6.QtQuick import QQuickItem
    except ImportError:
        from PyQt5 import sip
        from PyQt5.QtCore import QObject
        from PyQt5.QtQuick import QQuickItem
    window = ctx.app.getMainWindow()
    found = window.findChild(QObject, name)
    if found is not None:
        return found
    region_list = window.findChild(QObject, within)  # the list whose delegates are looked through
    pending = [region_list] if region_list is not None else []
    while pending:
        obj = pending.pop()
        if obj.objectName() == name:
            return obj
        pending.extend(obj.children())
        if obj.inherits("QQuickItem"):
            pending.extend(sip.cast(obj, QQuickItem).childItems())
    return None


def _qt():
    """The Qt names the panel steps need, from PyQt6 or PyQt5."""
    try:
        from PyQt6 import sip
        from PyQt6.QtCore import QEvent, QPointF, Qt
        from PyQt6.QtGui import QKeyEvent, QMouseEvent
        from PyQt6.QtQuick import QQuickItem
        from PyQt6.QtWidgets import QApplication

        names = dict(left=Qt.MouseButton.LeftButton, none=Qt.MouseButton.NoButton,
                     no_mod=Qt.KeyboardModifier.NoModifier, key_return=Qt.Key.Key_Return,
                     press=QEvent.Type.MouseButtonPress, release=QEvent.Type.MouseButtonRelease,
                     move=QEvent.Type.MouseMove, key_press=QEvent.Type.KeyPress, key_release=QEvent.Type.KeyRelease)
    except ImportError:
        from PyQt5 import sip
        from PyQt5.QtCore import QEvent, QPointF, Qt
        from PyQt5.QtGui import QKeyEvent, QMouseEvent
        from PyQt5.QtQuick import QQuickItem
        from PyQt5.QtWidgets import QApplication

        names = dict(left=Qt.LeftButton, none=Qt.NoButton, no_mod=Qt.NoModifier, key_return=Qt.Key_Return,
                     press=QEvent.MouseButtonPress, release=QEvent.MouseButtonRelease,
                     move=QEvent.MouseMove, key_press=QEvent.KeyPress, key_release=QEvent.KeyRelease)
    names.update(sip=sip, QPointF=QPointF, QKeyEvent=QKeyEvent, QMouseEvent=QMouseEvent,
                 QQuickItem=QQuickItem, QApplication=QApplication)
    return names


def _click(ctx, obj) -> None:
    """A real mouse click (press + release) on the middle of a QML item."""
    qt = _qt()
    item = qt["sip"].cast(obj, qt["QQuickItem"])
    centre = item.mapToScene(qt["QPointF"](item.width() / 2, item.height() / 2))
    window = ctx.app.getMainWindow()
    for kind in (qt["press"], qt["release"]):
        buttons = qt["left"] if kind == qt["press"] else qt["none"]
        qt["QApplication"].sendEvent(window, qt["QMouseEvent"](kind, centre, qt["left"], buttons, qt["no_mod"]))


def _type_into(ctx, obj, text: str) -> None:
    """Focus a text field by clicking it, replace its text and press Return (as a user does)."""
    qt = _qt()
    _click(ctx, obj)
    obj.setProperty("text", text)
    window = ctx.app.getMainWindow()
    for kind in (qt["key_press"], qt["key_release"]):
        qt["QApplication"].sendEvent(window, qt["QKeyEvent"](kind, qt["key_return"], qt["no_mod"], "\r"))


def use_panel(ctx, region: str, density: float):
    """Drive the panel's own QML controls: type a density into region `region`'s row, press
    Add (a region at the model's centre), then delete that new region with its ✕ button.

    Records ``panel_use``: the region rows after each step.
    """
    region_tool = _plugin_module("region_tool")
    tool = _tool(ctx)

    def rows():
        return [(row["label"], row["shape"], row["density"]) for row in tool.getRegions()]

    def laid_out(name):
        obj = _qml_object(ctx, name)
        if obj is None:
            return False
        qt = _qt()
        item = qt["sip"].cast(obj, qt["QQuickItem"])
        corner = item.mapToScene(qt["QPointF"](0, 0))
        return item.isVisible() and item.width() > 0 and corner.x() > 0 and corner.y() > 0

    def wait_for(name):
        # the list is rebuilt 150 ms after any scene change: let it settle before clicking into it
        return ctx.wait_until(lambda: laid_out(name), 10, f"the panel's {name}")

    yield 0.6

    steps = {"start": rows()}
    yield wait_for("densityField" + region)
    _type_into(ctx, _qml_object(ctx, "densityField" + region), f"{density:g}")
    yield 0.5
    steps["edited"] = rows()

    yield 0.6
    before = {n.getName() for n in region_tool.region_nodes()}
    yield wait_for("addRegionButton")
    _click(ctx, _qml_object(ctx, "addRegionButton"))
    yield ctx.wait_until(lambda: len(region_tool.region_nodes()) > len(before), 10, "the region added by the Add button")
    added = sorted({n.getName() for n in region_tool.region_nodes()} - before)
    steps["added"] = rows()
    number = added[0].rsplit("_", 1)[1]
    yield wait_for("deleteRegion" + number)
    _click(ctx, _qml_object(ctx, "deleteRegion" + number))
    yield ctx.wait_until(lambda: len(region_tool.region_nodes()) == len(before), 10, "the region deleted by its button")
    yield 0.5
    steps["deleted"] = rows()
    ctx.record("panel_use", steps)
    # move the pointer off the panel so no tooltip stays in the screenshots
    qt = _qt()
    window = ctx.app.getMainWindow()
    away = qt["QPointF"](window.width() - 20.0, window.height() / 2.0)
    move = qt["QMouseEvent"](qt["move"], away, qt["none"], qt["none"], qt["no_mod"])
    qt["QApplication"].sendEvent(window, move)


def edit_region(ctx, name: str, density: float):
    """Change a region's density through the tool (what the panel's field does)."""
    if not _tool(ctx).editRegion({"name": name, "density": density}):
        raise RuntimeError(f"editRegion refused {name}")
    yield 0.5


def edit_shape_and_undo(ctx, name: str, shape: str, size: float):
    """Change a region's shape and size (the panel's row fields), then undo it.

    Records ``shape_edit``: (shape, size, world extent) before, after the edit, after the undo.
    """
    region_tool = _plugin_module("region_tool")
    tool = _tool(ctx)

    def state():
        node = next(n for n in region_tool.region_nodes() if n.getName() == name)
        row = next(r for r in tool.getRegions() if r["name"] == name)
        box = node.getBoundingBox()
        return [row["shape"], row["size"], round(float(max(box.width, box.height, box.depth)), 2)]

    steps = {"before": state()}
    if not tool.editRegion({"name": name, "shape": shape, "size": size}):
        raise RuntimeError("editRegion refused the change")
    yield 0.5
    steps["edited"] = state()
    ctx.app.getOperationStack().undo()
    yield 0.5
    steps["undone"] = state()
    ctx.record("shape_edit", steps)


def record_sizes(ctx, model: str, key: str):
    """Record the size Cura reports: the scene's (under the object list), the model's box, the Scale tool's.

    Cura recomputes the scene's size 100 ms after a change (a timer: on a busy machine later, so the
    step waits until Cura shows a size at all); then it waits a moment more for it to settle.
    """
    from UM.Scene.Selection import Selection

    yield ctx.wait_until(lambda: not str(ctx.app.getSceneBoundingBoxString).startswith("0.0 x 0.0 x 0.0"), 30,
                         "Cura's scene size under the object list")
    yield 1.0
    node = ctx.node(model)
    box = node.getBoundingBox()
    Selection.clear()
    Selection.add(node)
    yield 0.3
    scale = ctx.app.getController().getTool("ScaleTool")
    ctx.record(key, {
        "scene": ctx.app.getSceneBoundingBoxString,
        "model": [round(float(box.width), 2), round(float(box.height), 2), round(float(box.depth), 2)],
        "scale_tool": [round(float(scale.getObjectWidth()), 2), round(float(scale.getObjectHeight()), 2),
                       round(float(scale.getObjectDepth()), 2)] if scale is not None else None,
        "region_classes": sorted({type(n).__name__ for n in _plugin_module("region_tool").region_nodes()}),
    })


def _item(ctx, obj):
    qt = _qt()
    return qt["sip"].cast(obj, qt["QQuickItem"])


def _panel(ctx):
    panel = _qml_object(ctx, "densityRegionsPanel")
    if panel is None:
        raise RuntimeError("the Density regions panel is not in the window")
    return _item(ctx, panel)


def panel_layout(ctx, key: str = "panel_layout"):
    """Record where the panel's controls are, against the panel's own width (scene pixels).

    Every visible item inside the panel with a size is measured; ``outside`` lists the ones
    whose box reaches past the panel's left or right edge (more than half a pixel).  Also
    recorded: which of Cura's styled controls the fields and buttons are (a property only
    Cura's own control has), the theme's default font and em size.
    """
    qt = _qt()
    yield 0.8
    panel = _panel(ctx)
    origin = panel.mapToScene(qt["QPointF"](0, 0))
    left, right = origin.x(), origin.x() + panel.width()
    outside, measured = [], 0
    pending = list(panel.childItems())
    while pending:
        item = pending.pop()
        pending.extend(item.childItems())
        if not item.isVisible() or item.width() <= 0 or item.height() <= 0:
            continue
        corner = item.mapToScene(qt["QPointF"](0, 0))
        x0, x1 = corner.x(), corner.x() + item.width()
        if item.inherits("QQuickText"):
            # a label's box may be wider than its text (Cura.ComboBox's label reaches left past its
            # box, behind its padding): what counts is where the text is painted
            pad_left, pad_right = float(item.property("leftPadding") or 0), float(item.property("rightPadding") or 0)
            x0 = corner.x() + pad_left
            x1 = x0 + min(float(item.property("contentWidth") or 0), item.width() - pad_left - pad_right)
        measured += 1
        if x0 < left - 0.5 or x1 > right + 0.5:
            chain, parent = [], item.parentItem()
            while parent is not None and parent is not panel and len(chain) < 4:
                chain.append(parent.objectName() or parent.metaObject().className())
                parent = parent.parentItem()
            text = item.property("text") if item.inherits("QQuickText") else None
            outside.append([item.objectName() or item.metaObject().className(), round(x0, 1), round(x1, 1),
                            text, chain])

    def styled(name, prop):
        obj = _qml_object(ctx, name)
        return obj is not None and obj.property(prop) is not None

    theme_font = None
    try:
        from UM.Qt.Bindings.Theme import Theme

        theme = Theme.getInstance()
        theme_font = {"point_size": theme.getFont("default").pointSize(), "em": theme.getSize("line").height()}
    except Exception as error:  # the record says why
        theme_font = {"error": repr(error)}
    ctx.record(key, {
        "panel": [round(left, 1), round(right, 1), round(panel.height(), 1)],
        "measured": measured,
        "outside": outside,
        "styled": {
            "newShape": styled("newShape", "defaultTextOnEmptyModel"),  # Cura.ComboBox
            "newSize": styled("newSize", "leftIcon"),  # Cura.TextField
            "densityField1": styled("densityField1", "leftIcon"),
            "addRegionButton": styled("addRegionButton", "fixedWidthMode"),  # Cura.ActionButton
            "deleteRegion1": styled("deleteRegion1", "iconSource"),  # UM.SimpleButton
        },
        "font": theme_font,
    })


def _qobject_children(obj, class_part: str) -> list:
    """QObject descendants of `obj` whose class name contains `class_part` (QQuickPopup is no PyQt type)."""
    from importlib import import_module

    core = import_module(_qt()["QPointF"].__module__)
    return [child for child in obj.findChildren(core.QObject) if class_part in child.metaObject().className()]


def choose_in_combobox(ctx, name: str, index: int):
    """Pick entry `index` of the panel's combo box `name` as a user does: open it, click the entry.

    Emits the combo box's ``activated(index)``, i.e. runs the panel's handler.
    """
    qt = _qt()
    yield ctx.wait_until(lambda: _qml_object(ctx, name) is not None, 10, f"the panel's {name}")
    combo = _qml_object(ctx, name)
    _click(ctx, combo)
    yield 0.6
    popups = [p for p in _qobject_children(combo, "Popup") if p.inherits("QQuickPopup") and p.property("visible")]
    if not popups:
        raise RuntimeError(f"{name}: a click did not open its list")
    entries = []
    for view in _qobject_children(popups[0], "ListView"):
        if not view.inherits("QQuickListView") or not isinstance(view, qt["QQuickItem"]):
            continue  # e.g. the ListView attached objects of the delegates
        pending = list(view.childItems())
        while pending:
            item = pending.pop()
            pending.extend(item.childItems())
            if item.inherits("QQuickAbstractButton") and item.isVisible():  # ItemDelegate
                entries.append(item)
    entries.sort(key=lambda item: item.mapToScene(qt["QPointF"](0, 0)).y())
    if len(entries) <= index:
        raise RuntimeError(f"{name}: its open list has {len(entries)} entries, not {index + 1}")
    _click(ctx, entries[index])
    yield 0.6


def panel_comboboxes(ctx, region: str = "1"):
    """Use the panel's combo boxes: the shape of the next region, then a region's shape (undone).

    Records ``panel_comboboxes``: the tool's shape and the rows' shapes after each step.
    """
    tool = _tool(ctx)

    def rows():
        return [[row["label"], row["shape"]] for row in tool.getRegions()]

    out = {"shape_before": tool.getShape()}
    yield from choose_in_combobox(ctx, "newShape", 1)
    out["shape_chosen"] = tool.getShape()
    out["rows_before"] = rows()
    yield from choose_in_combobox(ctx, "shapeField" + region, 2)
    out["rows_edited"] = rows()
    ctx.app.getOperationStack().undo()
    yield 0.5
    out["rows_undone"] = rows()
    tool.setShape(out["shape_before"])
    ctx.record("panel_comboboxes", out)


def copy_model(ctx, model: str, key: str = "model_copy"):
    """Deep-copy the model as Cura's Multiply and Copy/Paste do; record what its regions became."""
    from copy import deepcopy

    node = ctx.node(model)
    copy = deepcopy(node)
    children = []
    for child in copy.getChildren():
        stack = child.callDecoration("getStack")
        children.append({
            "class": type(child).__name__,
            "name": child.getName(),
            "infill_mesh": bool(stack.getProperty("infill_mesh", "value")) if stack else None,
            "density": float(stack.getProperty("infill_sparse_density", "value")) if stack else None,
            "shape": getattr(child, "_delaunay_region_shape", None),
        })
    ctx.record(key, {"class": type(copy).__name__, "children": children})
    if False:
        yield
