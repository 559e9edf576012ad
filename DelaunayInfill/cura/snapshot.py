"""Read what the G-code pass needs from Cura's scene and setting stacks.

Runs on Cura's main thread (setting stacks and scene nodes are not thread
safe) and returns plain data, so the background job never touches Cura.
Every value is Cura's own, resolved through the node's per-object stack,
which falls through to the right extruder stack (``limit_to_extruder``) and
then the global stack; nothing is re-guessed here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: Read from each mesh's own stack (per object, per extruder via limit_to_extruder).
MESH_KEYS = (
    "delaunay_infill_enabled",
    "delaunay_infill_seed",
    "delaunay_infill_layout",
    "infill_sparse_density",
    "infill_multiplier",
    "infill_line_width",
    "infill_line_distance",
    "infill_overlap_mm",
    "infill_pattern",
    "gradual_infill_steps",
    "infill_sparse_thickness",
    "infill_support_enabled",
    "infill_wall_line_count",
    "speed_infill",
    "acceleration_infill",
    "jerk_infill",
    "infill_material_flow",
    "material_flow",
    "infill_wipe_dist",
    "infill_extruder_nr",
    "infill_mesh",
    "cutting_mesh",
    "support_mesh",
    "anti_overhang_mesh",
)

#: Read from the stack of the extruder that prints the infill.
EXTRUDER_KEYS = (
    "material_diameter",
    "machine_nozzle_size",
    "retraction_enable",
    "retraction_amount",
    "retraction_retract_speed",
    "retraction_prime_speed",
    "retraction_extra_prime_amount",
    "retraction_min_travel",
    "retraction_hop_enabled",
    "retraction_hop",
    "retraction_hop_only_when_collides",
    "speed_z_hop",
    "speed_travel",
    "acceleration_travel",
    "travel_avoid_distance",
    "retraction_combing_max_distance",
    # raft: how far CuraEngine lifts the model (read from the adhesion extruder)
    "raft_base_thickness",
    "raft_interface_thickness",
    "raft_interface_layers",  # Cura 5.x; Cura 4.13 prints one interface layer
    "raft_surface_layers",
    "raft_surface_thickness",
    "raft_airgap",
    "layer_0_z_overlap",
)

#: Read from the global stack.
GLOBAL_KEYS = (
    "machine_width",
    "machine_depth",
    "machine_height",
    "machine_center_is_zero",
    "machine_gcode_flavor",
    "machine_firmware_retract",
    "relative_extrusion",
    "retraction_combing",
    "acceleration_enabled",
    "layer_height",
    "print_sequence",
    "machine_extruder_count",
    "machine_acceleration",
    "machine_max_jerk_xy",
    "jerk_enabled",
    "adhesion_type",
    "adhesion_extruder_nr",
)


@dataclass
class MeshSnapshot:
    """One sliceable scene node as the G-code names it (``;MESH:<name>``).

    Attributes
    ----------
    name : str
        ``node.getName()``, which CuraEngine writes after ``;MESH:``.
    values : dict
        MESH_KEYS → Cura's resolved values (density in percent, lengths in mm,
        speeds in mm/s).
    enabled : bool
        Whether the Delaunay pass replaces this mesh's infill.
    is_region : bool
        True for an ``infill_mesh`` modifier (a density region).
    extruder_nr : int
        The extruder that prints this mesh's infill.
    bounds : tuple of float or None
        (xmin, ymin, zmin, xmax, ymax, zmax) in G-code coordinates, mm.
    triangles : ndarray or None
        Modifier triangles in G-code coordinates, shape (t, 3, 3), mm;
        only for regions.
    """

    name: str
    values: dict
    enabled: bool = False
    is_region: bool = False
    extruder_nr: int = 0
    bounds: tuple | None = None
    triangles: object = None


@dataclass
class SceneSnapshot:
    """Everything the background job needs, as plain data."""

    global_values: dict = field(default_factory=dict)
    extruder_values: dict = field(default_factory=dict)  # extruder nr -> {key: value}
    meshes: list = field(default_factory=list)  # MeshSnapshot, one per sliceable node
    ambiguous_names: list = field(default_factory=list)  # names shared by nodes that disagree
    #: Density regions in application order (later wins), from the region tool when it is
    #: installed (``region_tool.collect_scene_regions``); None: use the meshes' own triangles.
    scene_regions: list | None = None
    feather_mm: float = 0.0
    #: Painted density sets of the models (``paint.PaintedSnapshot``, G-code coordinates), scene order.
    painted_sets: list = field(default_factory=list)

    @property
    def enabled_meshes(self) -> list:
        return [m for m in self.meshes if m.enabled]


def _property(stack, key: str):
    try:
        return stack.getProperty(key, "value")
    except Exception:  # a key this Cura version does not know
        return None


def _scene_to_gcode(vertices, global_values: dict):
    """Cura scene coordinates (Y up, Z towards the front) → G-code X, Y, Z (mm)."""
    import numpy as np

    v = np.asarray(vertices, dtype=float)
    out = np.empty_like(v)
    out[..., 0] = v[..., 0]
    out[..., 1] = -v[..., 2]
    out[..., 2] = v[..., 1]
    if not global_values.get("machine_center_is_zero"):
        out[..., 0] += float(global_values.get("machine_width") or 0.0) / 2.0
        out[..., 1] += float(global_values.get("machine_depth") or 0.0) / 2.0
    return out


def _node_triangles(node, global_values: dict):
    """The node's triangles in G-code coordinates, shape (t, 3, 3), or None."""
    mesh = node.getMeshData()
    if mesh is None:
        return None
    transformed = mesh.getTransformed(node.getWorldTransformation())
    vertices = transformed.getVertices()
    if vertices is None or len(vertices) == 0:
        return None
    indices = transformed.getIndices()
    if indices is not None and len(indices):
        vertices = vertices[indices.reshape(-1)]
    vertices = vertices[: len(vertices) // 3 * 3].reshape(-1, 3, 3)
    return _scene_to_gcode(vertices, global_values)


def _bounds(triangles) -> tuple | None:
    if triangles is None or len(triangles) == 0:
        return None
    flat = triangles.reshape(-1, 3)
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    return (float(lo[0]), float(lo[1]), float(lo[2]), float(hi[0]), float(hi[1]), float(hi[2]))


def _overlaps(a: tuple | None, b: tuple | None) -> bool:
    if a is None or b is None:
        return False
    return all(a[i] <= b[i + 3] and b[i] <= a[i + 3] for i in range(3))


def sliceable_nodes(scene, build_plate: int = 0) -> list:
    """Scene nodes that CuraEngine slices on `build_plate` (models and modifiers)."""
    from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

    nodes = []
    for node in DepthFirstIterator(scene.getRoot()):
        if not node.callDecoration("isSliceable") or not node.getMeshData():
            continue
        plate = node.callDecoration("getBuildPlateNumber")
        if plate is not None and plate != build_plate:
            continue
        nodes.append(node)
    return nodes


def take_snapshot(application, build_plate: int = 0) -> SceneSnapshot:
    """Read the global, extruder and per-object settings of every sliceable node.

    A region (``infill_mesh``) takes part when its own setting is on or when
    it overlaps a model whose setting is on: its FILL replaces that model's
    infill inside the region.
    """
    global_stack = application.getGlobalContainerStack()
    snapshot = SceneSnapshot()
    if global_stack is None:
        return snapshot
    snapshot.global_values = {key: _property(global_stack, key) for key in GLOBAL_KEYS}
    for position, extruder in enumerate(global_stack.extruderList):
        snapshot.extruder_values[position] = {key: _property(extruder, key) for key in EXTRUDER_KEYS}
    if not snapshot.extruder_values:
        snapshot.extruder_values[0] = {key: _property(global_stack, key) for key in EXTRUDER_KEYS}

    scene = application.getController().getScene()
    for node in sliceable_nodes(scene, build_plate):
        stack = node.callDecoration("getStack") or global_stack
        values = {key: _property(stack, key) for key in MESH_KEYS}
        if values.get("cutting_mesh") or values.get("support_mesh") or values.get("anti_overhang_mesh"):
            continue  # these print no infill of their own
        extruder_nr = _infill_extruder(node, values, global_stack)
        is_region = bool(values.get("infill_mesh"))
        triangles = _node_triangles(node, snapshot.global_values)
        snapshot.meshes.append(
            MeshSnapshot(
                name=node.getName(),
                values=values,
                enabled=bool(values.get("delaunay_infill_enabled")),
                is_region=is_region,
                extruder_nr=extruder_nr,
                bounds=_bounds(triangles),
                triangles=triangles if is_region else None,
            )
        )
    models = [m for m in snapshot.meshes if not m.is_region and m.enabled]
    for region in (m for m in snapshot.meshes if m.is_region and not m.enabled):
        region.enabled = any(_overlaps(region.bounds, model.bounds) for model in models)
    _resolve_duplicate_names(snapshot)
    _collect_tool_regions(snapshot)
    _collect_painted_sets(snapshot, scene, build_plate)
    return snapshot


def _collect_painted_sets(snapshot: SceneSnapshot, scene, build_plate: int) -> None:
    """The models' painted sets (``paint_tool.collect_painted``); none when painting is unavailable."""
    try:
        from . import paint_tool

        snapshot.painted_sets = paint_tool.collect_painted(sliceable_nodes(scene, build_plate), snapshot.global_values)
    except Exception:
        from UM.Logger import Logger

        Logger.logException("w", "DelaunayInfill: could not read the painted density sets")
        snapshot.painted_sets = []


def _collect_tool_regions(snapshot: SceneSnapshot) -> None:
    """Regions as the density-region tool orders them, when that tool is installed."""
    try:
        from . import region_tool
    except ImportError:
        return
    try:
        snapshot.scene_regions = list(region_tool.collect_scene_regions())
        snapshot.feather_mm = float(region_tool.region_feather_mm())
    except Exception:
        from UM.Logger import Logger

        Logger.logException("w", "DelaunayInfill: could not read the density regions; using the modifier meshes")
        snapshot.scene_regions = None


def _infill_extruder(node, values: dict, global_stack) -> int:
    try:
        nr = int(values.get("infill_extruder_nr"))
    except (TypeError, ValueError):
        nr = -1
    if nr >= 0:
        return nr
    position = node.callDecoration("getActiveExtruderPosition")
    try:
        return int(position) if position is not None else 0
    except (TypeError, ValueError):
        return 0


def _resolve_duplicate_names(snapshot: SceneSnapshot) -> None:
    """Nodes sharing a name share one ``;MESH:`` label: they must agree."""
    by_name: dict[str, list] = {}
    for mesh in snapshot.meshes:
        by_name.setdefault(mesh.name, []).append(mesh)
    for name, meshes in by_name.items():
        if len(meshes) > 1 and len({m.enabled for m in meshes}) > 1:
            snapshot.ambiguous_names.append(name)
            for mesh in meshes:
                mesh.enabled = False
