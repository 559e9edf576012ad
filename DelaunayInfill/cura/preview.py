"""Cura's Preview (layer view) from the processed G-code, not CuraEngine's original.

CuraEngine streams its own paths to Cura, and Cura's ``ProcessSlicedLayersJob``
turns them into the layer data Preview draws; after the Delaunay pass that
data still shows Cura's infill.  This module rebuilds the layer data from the
processed G-code (every move, typed by ``;TYPE:``) and swaps it into the
engine's layer node, whichever of the two finishes first.

The first half is pure numpy (:func:`parse_gcode_paths`), testable without
Cura; the second half (:class:`PreviewUpdater`, :func:`install`) touches
Cura and runs on its main thread except for the parse-and-build job.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

#: ``cura.LayerPolygon`` line-type ids (the same from 4.13 to 5.11; 8/9 were renamed in 5.11,
#: their numbers kept).
LINE_TYPE_IDS = {
    "NONE": 0,
    "WALL-OUTER": 1,
    "WALL-INNER": 2,
    "SKIN": 3,
    "SUPPORT": 4,
    "SKIRT": 5,
    "FILL": 6,
    "SUPPORT-INFILL": 7,
    "SUPPORT-INTERFACE": 10,
    "PRIME-TOWER": 11,
}
TRAVEL = 8  # MoveCombingType (≤ 5.10) / MoveUnretractedType (5.11+)
TRAVEL_RETRACTED = 9  # MoveRetractionType / MoveRetractedType
INFILL = LINE_TYPE_IDS["FILL"]

PROCESSED_MARKER = ";DELAUNAYINFILL_PROCESSED"

# One token per interesting line; findall runs in C over a whole chunk.
_TOKEN = re.compile(
    r"^(?:"
    r"(G0|G1)(?![0-9.])([^;\n]*)"  # 1 move, 2 its parameters
    r"|;TYPE:([^\r\n]*)"  # 3 feature type
    r"|;LAYER:(-?\d+)"  # 4 layer number
    r"|G92(?![0-9.])([^;\n]*)"  # 5 G92 parameters
    r"|(M82|M83)(?![0-9])"  # 6 extrusion mode
    r"|T(\d+)"  # 7 tool change
    r"|(G10|G11)(?![0-9.])"  # 8 firmware retract / unretract
    r"|(G90|G91)(?![0-9.])"  # 9 absolute / relative positioning
    r"|(;TIME_ELAPSED:)"  # 10 end of a layer plan
    r")",
    re.M,
)
_AXES = "XYZEF"
_AXIS_VALUE = {axis: re.compile(r"^(?:[^\n]*?[ \t]" + axis + r"([-+]?[0-9.]+))?[^\n]*$", re.M) for axis in _AXES}


@dataclass
class LayerPaths:
    """All moves of one extruder in one layer, as one polyline.

    Attributes
    ----------
    number : int
        The ``;LAYER:`` number.
    extruder : int
    z : float
        Layer height above the plate, mm (the Z of its first extrusion).
    thickness : float
        Layer thickness, mm.
    points : ndarray, float32, shape (n + 1, 3)
        Polyline vertices in G-code coordinates X, Y, Z (mm).
    types : ndarray, uint8, shape (n,)
        ``LayerPolygon`` type of each segment (see :data:`LINE_TYPE_IDS`, travel 8/9).
    widths : ndarray, float32, shape (n,)
        Line width per segment, mm (travel: 0.1).
    thicknesses : ndarray, float32, shape (n,)
        Line thickness per segment, mm (travel: 0).
    feedrates : ndarray, float32, shape (n,)
        mm/s.
    """

    number: int
    extruder: int
    z: float
    thickness: float
    points: np.ndarray = field(repr=False)
    types: np.ndarray = field(repr=False)
    widths: np.ndarray = field(repr=False)
    thicknesses: np.ndarray = field(repr=False)
    feedrates: np.ndarray = field(repr=False)

    @property
    def segment_count(self) -> int:
        return int(len(self.types))

    def length_of(self, line_type: int) -> float:
        """Total XY length (mm) of the segments of `line_type`."""
        seg = np.diff(self.points[:, :2].astype(float), axis=0)
        return float(np.hypot(seg[:, 0], seg[:, 1])[self.types == line_type].sum())


@dataclass
class _MotionState:
    """Machine state carried from one G-code chunk to the next."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    e: float = 0.0
    f: float = 1800.0  # mm/min
    relative_e: bool = False
    relative_xyz: bool = False
    extruder: int = 0
    type_id: int = 0
    layer: int | None = None
    retracted: bool = False
    layer_z: dict = field(default_factory=dict)  # layer number -> z of its first extrusion


def _column(values: np.ndarray) -> np.ndarray:
    """Strings to floats, '' → NaN."""
    out = np.full(values.shape, np.nan)
    present = values != ""
    if present.any():
        out[present] = values[present].astype(float)
    return out


def _ffill(values: np.ndarray, start: float) -> np.ndarray:
    """Forward-fill NaNs (the value before the first entry is `start`)."""
    filled = np.concatenate([[start], values])
    index = np.where(np.isnan(filled), 0, np.arange(len(filled)))
    np.maximum.accumulate(index, out=index)
    return filled[index][1:]


def _axis_values(params: np.ndarray) -> dict:
    """Per-row X, Y, Z, E, F values (NaN where absent) of move/G92 parameter strings."""
    joined = "\n".join(params.tolist())
    out = {}
    for axis in _AXES:
        found = _AXIS_VALUE[axis].findall(joined)
        out[axis] = _column(np.asarray(found[: len(params)], dtype=str)) if len(params) else np.zeros(0)
    return out


def _type_id(name: str) -> int:
    return LINE_TYPE_IDS.get(name.strip().upper(), 0)


def parse_gcode_paths(chunks, *, filament_diameter: float = 1.75, volumetric_e: bool | None = None):
    """Every layer's moves of Cura G-code, as polylines for the layer view.

    Parameters
    ----------
    chunks : sequence of str
        Cura's in-memory G-code (``scene.gcode_dict[plate]``), or any split of
        a G-code file into strings.
    filament_diameter : float
        mm; turns E (mm of filament) into line widths.
    volumetric_e : bool, optional
        E is mm³ (UltiGCode, RepRap volumetric). Default: from ``;FLAVOR:``.

    Returns
    -------
    list of LayerPaths
        In print order; one entry per (layer, extruder run).
    """
    chunks = list(chunks)
    if volumetric_e is None:
        head = chunks[0][:4000] if chunks else ""
        volumetric_e = bool(re.search(r"^;FLAVOR:(UltiGCode|RepRap \(Volumetric\))", head, re.M))
    e_to_area = 1.0 if volumetric_e else np.pi * (float(filament_diameter) / 2.0) ** 2
    state = _MotionState()
    result: list[LayerPaths] = []
    for chunk in chunks:
        result.extend(_parse_chunk(chunk, state, e_to_area))
    return _merge_runs(result)


def _parse_chunk(text: str, state: _MotionState, e_to_area: float) -> list:
    tokens = _TOKEN.findall(text)
    if not tokens:
        return []
    t = np.asarray(tokens, dtype=str)
    move, move_params, type_name, layer_no, g92_params, mode, tool, firmware, positioning, layer_end = t.T
    rows = len(t)
    # G91 (relative positioning, E included on Marlin) only occurs in start/end G-code: its moves
    # are left out of the view and do not move the tracked position.
    pos_rel = np.where(positioning == "G91", 1.0, np.where(positioning == "G90", 0.0, np.nan))
    relative_xyz = _ffill(pos_rel, 1.0 if state.relative_xyz else 0.0) > 0.5
    is_move = (move != "") & ~relative_xyz
    # a bare "G92" has empty parameters, indistinguishable from "no G92"; it sets nothing we track
    is_g92 = g92_params != ""

    params = np.where(is_move, move_params, np.where(is_g92, g92_params, ""))
    axis = _axis_values(params)

    # layer number, type, extruder, extrusion mode: forward-filled state;
    # after ;TIME_ELAPSED: (the layer's end) moves belong to no layer until the next ;LAYER:
    layer_marks = _column(layer_no)
    layer_marks[layer_end != ""] = np.inf
    layer = _ffill(layer_marks, np.nan if state.layer is None else float(state.layer))
    layer[np.isinf(layer)] = np.nan
    type_ids = np.full(rows, np.nan)
    has_type = type_name != ""
    if has_type.any():
        names, inverse = np.unique(type_name[has_type], return_inverse=True)
        type_ids[has_type] = np.array([_type_id(name) for name in names], dtype=float)[inverse]
    type_ids = _ffill(type_ids, float(state.type_id))
    extruder = _ffill(_column(tool), float(state.extruder))
    mode_rel = np.where(mode == "M83", 1.0, np.where(mode == "M82", 0.0, np.nan))
    relative = (_ffill(mode_rel, 1.0 if state.relative_e else 0.0) > 0.5) | relative_xyz

    # positions (moves and G92 set them; G92 does not move the head)
    x = _ffill(np.where(is_move | is_g92, axis["X"], np.nan), state.x)
    y = _ffill(np.where(is_move | is_g92, axis["Y"], np.nan), state.y)
    z = _ffill(np.where(is_move | is_g92, axis["Z"], np.nan), state.z)
    feed = _ffill(np.where(is_move, axis["F"], np.nan), state.f)

    # E: relative moves give deltas directly; absolute E is forward-filled across moves and G92
    e_given = np.where(is_move | is_g92 | ((move != "") & relative_xyz), axis["E"], np.nan)
    e_abs_src = np.where(~relative | is_g92, e_given, np.nan)
    e_abs = _ffill(e_abs_src, state.e)
    prev_abs = np.concatenate([[state.e], e_abs[:-1]])
    delta_e = np.where(relative, np.nan_to_num(e_given), e_abs - prev_abs)
    delta_e = np.where(is_move, delta_e, 0.0)

    prev_x = np.concatenate([[state.x], x[:-1]])
    prev_y = np.concatenate([[state.y], y[:-1]])
    prev_z = np.concatenate([[state.z], z[:-1]])
    xy_len = np.hypot(x - prev_x, y - prev_y)
    moved = is_move & ((xy_len > 1e-9) | (np.abs(z - prev_z) > 1e-9))

    # retraction state: E-only moves with negative/positive E, G10/G11
    e_only = is_move & ~moved & (np.abs(delta_e) > 1e-9)
    event = np.full(rows, np.nan)
    event[e_only & (delta_e < 0)] = 1.0
    event[e_only & (delta_e > 0)] = 0.0
    event[firmware == "G10"] = 1.0
    event[firmware == "G11"] = 0.0
    retracted = _ffill(event, 1.0 if state.retracted else 0.0) > 0.5

    extruding = moved & (delta_e > 1e-9) & (xy_len > 1e-9)
    seg_type = np.where(extruding, type_ids, np.where(retracted, TRAVEL_RETRACTED, TRAVEL)).astype(np.uint8)

    # carry the state over to the next chunk
    state.x, state.y, state.z = float(x[-1]), float(y[-1]), float(z[-1])
    state.e, state.f = float(e_abs[-1]), float(feed[-1])
    state.relative_e = bool((_ffill(mode_rel, 1.0 if state.relative_e else 0.0) > 0.5)[-1])
    state.relative_xyz = bool(relative_xyz[-1])
    state.extruder = int(extruder[-1])
    state.type_id = int(type_ids[-1])
    state.retracted = bool(retracted[-1])
    state.layer = None if np.isnan(layer[-1]) else int(layer[-1])

    keep = moved & ~np.isnan(layer)
    if not keep.any():
        return []
    idx = np.flatnonzero(keep)
    k_layer = layer[idx].astype(int)
    k_ext = extruder[idx].astype(int)
    # split into runs of (layer, extruder)
    change = np.flatnonzero((np.diff(k_layer) != 0) | (np.diff(k_ext) != 0)) + 1
    bounds = np.concatenate([[0], change, [len(idx)]])
    out = []
    for start, stop in zip(bounds[:-1], bounds[1:]):
        rows_run = idx[start:stop]
        number = int(k_layer[start])
        ext_rows = rows_run[extruding[rows_run]]
        if number not in state.layer_z and len(ext_rows):
            state.layer_z[number] = float(z[ext_rows[0]])
        layer_z = state.layer_z.get(number, float(z[rows_run[0]]))
        lower = [v for k, v in state.layer_z.items() if v < layer_z - 1e-6]
        thickness = layer_z - max(lower) if lower else layer_z
        thickness = thickness if thickness > 1e-6 else 0.2
        points = np.empty((len(rows_run) + 1, 3), dtype=np.float32)
        first = rows_run[0]
        points[0] = (prev_x[first], prev_y[first], prev_z[first])
        points[1:, 0], points[1:, 1], points[1:, 2] = x[rows_run], y[rows_run], z[rows_run]
        types = seg_type[rows_run]
        is_travel = (types == TRAVEL) | (types == TRAVEL_RETRACTED)
        length = np.maximum(xy_len[rows_run], 1e-9)
        widths = np.where(is_travel, 0.1, delta_e[rows_run] * e_to_area / (length * thickness))
        widths = np.clip(widths, 0.05, 3.0).astype(np.float32)
        thick = np.where(is_travel, 0.0, thickness).astype(np.float32)
        out.append(
            LayerPaths(
                number=number,
                extruder=int(k_ext[start]),
                z=layer_z,
                thickness=float(thickness),
                points=points,
                types=types,
                widths=widths,
                thicknesses=thick,
                feedrates=(feed[rows_run] / 60.0).astype(np.float32),
            )
        )
    return out


def _merge_runs(runs: list) -> list:
    """Join consecutive runs of the same layer and extruder (a layer split over chunks)."""
    merged: list[LayerPaths] = []
    for run in runs:
        last = merged[-1] if merged else None
        if last is not None and last.number == run.number and last.extruder == run.extruder:
            gap_free = np.allclose(last.points[-1], run.points[0])
            if gap_free:
                last.points = np.concatenate([last.points, run.points[1:]])
                last.types = np.concatenate([last.types, run.types])
                last.widths = np.concatenate([last.widths, run.widths])
                last.thicknesses = np.concatenate([last.thicknesses, run.thicknesses])
                last.feedrates = np.concatenate([last.feedrates, run.feedrates])
                continue
        merged.append(run)
    return merged


def layer_index_map(numbers) -> dict:
    """``;LAYER:`` number → Preview layer index, as Cura's ``ProcessSlicedLayersJob`` numbers them.

    The lowest layer becomes 0; raft layers (negative numbers) come first
    and the model's layers follow right after them.
    """
    unique = sorted(set(int(n) for n in numbers))
    if not unique:
        return {}
    lowest = unique[0]
    negatives = sum(1 for n in unique if n < 0)
    mapping = {}
    for n in unique:
        index = n - lowest
        if n >= 0 and negatives:
            index += lowest + negatives
        mapping[n] = index
    return mapping


def cura_points(points: np.ndarray) -> np.ndarray:
    """G-code X, Y, Z (mm) → the layer node's local axes (x, y up, z = -Y)."""
    out = np.empty((len(points), 3), dtype=np.float32)
    out[:, 0] = points[:, 0]
    out[:, 1] = points[:, 2]
    out[:, 2] = -points[:, 1]
    return out


# -- Cura side --------------------------------------------------------------------------------


def build_layer_data(paths, material_color_map, line_type_brightness: float = 1.0):
    """A ``cura.LayerData`` mesh from :func:`parse_gcode_paths` output (needs Cura)."""
    from cura.LayerDataBuilder import LayerDataBuilder
    from cura.LayerPolygon import LayerPolygon

    builder = LayerDataBuilder()
    index_of = layer_index_map(p.number for p in paths)
    for run in paths:
        if run.segment_count == 0:
            continue
        index = index_of[run.number]
        builder.addLayer(index)
        builder.setLayerHeight(index, run.z * 1000.0)  # µm, as CuraEngine sends it
        builder.setLayerThickness(index, run.thickness * 1000.0)
        polygon = LayerPolygon(
            run.extruder,
            run.types.reshape(-1, 1).copy(),
            cura_points(run.points),
            run.widths.reshape(-1, 1),
            run.thicknesses.reshape(-1, 1),
            run.feedrates.reshape(-1, 1),
        )
        polygon.buildCache()
        builder.getLayer(index).polygons.append(polygon)
    return builder.build(material_color_map, line_type_brightness)


def _material_colors(application):
    """(extruders, 4) RGBA colours as ProcessSlicedLayersJob picks them."""
    stack = application.getGlobalContainerStack()
    extruders = list(stack.extruderList) if stack is not None else []
    colors = np.zeros((max(1, len(extruders)), 4), dtype=np.float32)
    colors[:] = (0.88, 0.88, 0.0, 1.0)
    for position, extruder in enumerate(extruders):
        code = extruder.material.getMetaDataEntry("color_code", default="#e0e000") if extruder.material else "#e0e000"
        try:
            colors[position] = [int(code[1:3], 16) / 255, int(code[3:5], 16) / 255, int(code[5:7], 16) / 255, 1.0]
        except (TypeError, ValueError, IndexError):
            pass
    return colors


def _filament_settings(application):
    stack = application.getGlobalContainerStack()
    diameter = 1.75
    try:
        diameter = float(stack.extruderList[0].getProperty("material_diameter", "value"))
    except Exception:
        pass
    return diameter


class PreviewUpdater:
    """Keeps Cura's layer view in step with the processed G-code.

    The processed G-code arrives through the extension's processed-callback;
    the engine's layer node appears when Cura's own layer job finishes (only
    while Preview is open). Whichever comes last triggers the rebuild.
    """

    def __init__(self, application):
        self._application = application
        self._pending = None  # (plate, gcode list) to show
        self._shown = None  # (id of the list, id of the node) already shown
        self._job = None
        from UM.Qt.QtApplication import QtApplication  # noqa: F401  (Cura is running)

        try:
            from PyQt6.QtCore import QTimer
        except ImportError:
            from PyQt5.QtCore import QTimer
        self._timer = QTimer()
        self._timer.setSingleShot(True)
        self._timer.setInterval(250)
        self._timer.timeout.connect(self._apply)
        controller = application.getController()
        controller.getScene().sceneChanged.connect(self._onSceneChanged)
        controller.activeViewChanged.connect(self._timer.start)

    # called by the extension after each write-back (main thread)
    def onProcessed(self, plate, gcode_list, report=None) -> None:
        self._pending = (plate, gcode_list)
        self._shown = None
        self._timer.start()

    def _onSceneChanged(self, node) -> None:
        if self._pending is not None and self._job is None:
            self._timer.start()

    def _layerNode(self, plate):
        from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

        for node in DepthFirstIterator(self._application.getController().getScene().getRoot()):
            if node.callDecoration("getLayerData") is None:
                continue
            if node.callDecoration("getGCodeList") is not None:  # a G-code file the user opened
                continue
            node_plate = node.callDecoration("getBuildPlateNumber")
            if node_plate is None or node_plate == plate:
                return node
        return None

    def _apply(self) -> None:
        if self._pending is None or self._job is not None:
            return
        plate, gcode_list = self._pending
        scene = self._application.getController().getScene()
        current = getattr(scene, "gcode_dict", {}).get(plate)
        if current is not gcode_list or not gcode_list or PROCESSED_MARKER not in gcode_list[0]:
            self._pending = None  # a new slice replaced it
            return
        node = self._layerNode(plate)
        if node is None:
            return  # Cura has not built its layer view yet; sceneChanged will call again
        key = (id(gcode_list), id(node), id(node.callDecoration("getLayerData")))
        if self._shown == key:
            return
        from UM.Job import Job

        updater = self

        class _BuildJob(Job):
            def run(self_job):
                paths = parse_gcode_paths(list(gcode_list), filament_diameter=self_job.diameter)
                Job.yieldThread()
                self_job.setResult(build_layer_data(paths, self_job.colors, self_job.brightness))

        job = _BuildJob()
        job.diameter = _filament_settings(self._application)
        job.colors = _material_colors(self._application)
        job.brightness = 0.5 if self._compatibilityMode() else 1.0
        job.node, job.key, job.gcode_list = node, key, gcode_list
        job.finished.connect(updater._onBuilt)
        self._job = job
        job.start()

    def _compatibilityMode(self) -> bool:
        try:
            from UM.View.GL.OpenGLContext import OpenGLContext

            return bool(OpenGLContext.isLegacyOpenGL()) or bool(
                self._application.getPreferences().getValue("view/force_layer_view_compatibility_mode")
            )
        except Exception:
            return False

    def _onBuilt(self, job) -> None:
        from UM.Logger import Logger

        self._job = None
        if job.hasError() or job.getResult() is None:
            Logger.log("e", "DelaunayInfill: could not rebuild the layer view: %r", job.getError())
            return
        pending = self._pending
        if pending is None or pending[1] is not job.gcode_list:
            self._timer.start()
            return
        node = self._layerNode(pending[0])
        if node is not job.node:  # the layer node was replaced meanwhile: build again for the new one
            self._timer.start()
            return
        from cura.LayerDataDecorator import LayerDataDecorator

        decorator = node.getDecorator(LayerDataDecorator)
        if decorator is None:
            return
        decorator.setLayerData(job.getResult())
        self._shown = (id(job.gcode_list), id(node), id(job.getResult()))
        view = self._application.getController().getActiveView()
        if view is not None and hasattr(view, "resetLayerData"):
            view.resetLayerData()
        self._application.getController().getScene().sceneChanged.emit(node)
        Logger.log("i", "DelaunayInfill: Preview shows the processed G-code")


_updater = None


def install(extension) -> None:
    """Hook the layer-view rebuild into the extension's processed-G-code callbacks."""
    global _updater
    from UM.Application import Application

    _updater = PreviewUpdater(Application.getInstance())
    extension.addProcessedCallback(_updater.onProcessed)
