"""Turn Cura's settings (a ``SceneSnapshot``) into the G-code pass's settings.

Pure Python (no Cura import), so it runs in the worker thread and in tests.
The pass's API is documented in docs/gcode.md: ``process_gcode(layers,
settings, regions, progress, cancel)`` with ``ProcessSettings`` /
``MeshSettings`` / ``Region``.  Cura reports densities and flows in percent;
the pass takes fractions.
"""

from __future__ import annotations

import math

VOLUMETRIC_FLAVORS = ("UltiGCode", "RepRap (Volumetric)")


def _number(value, default=None):
    try:
        number = float(value)
    except (TypeError, ValueError):
        return default
    return number if math.isfinite(number) else default


def _fraction(percent, default=None):
    number = _number(percent)
    return default if number is None else number / 100.0


def raft_z_offset(snapshot) -> float:
    """How far CuraEngine lifts the model above the plate for a raft, mm (0 without raft).

    The G-code's model layers 1, 2, ... print at scene height + raft thickness
    + air gap - ``layer_0_z_overlap`` (layer 0 sits the overlap higher); the
    regions' triangles are in scene heights, so they are lifted by this much
    to slice at the G-code's layer heights.  Checked against CuraEngine 4.13.
    """
    glob = snapshot.global_values
    if str(glob.get("adhesion_type") or "") != "raft":
        return 0.0
    position = int(_number(glob.get("adhesion_extruder_nr"), 0.0))
    values = snapshot.extruder_values.get(position) or next(iter(snapshot.extruder_values.values()), {})
    thickness = (
        _number(values.get("raft_base_thickness"), 0.0)
        + _number(values.get("raft_interface_layers"), 1.0) * _number(values.get("raft_interface_thickness"), 0.0)
        + _number(values.get("raft_surface_layers"), 0.0) * _number(values.get("raft_surface_thickness"), 0.0)
    )
    return thickness + _number(values.get("raft_airgap"), 0.0) - _number(values.get("layer_0_z_overlap"), 0.0)


def _lifted(triangles, dz: float):
    """Triangles (t, 3, 3) mm moved up by `dz` mm (a copy)."""
    import numpy as np

    out = np.array(triangles, dtype=float)
    out[..., 2] += dz
    return out


def _primary_model(snapshot):
    """The enabled model whose seed, layout and extruder drive the pass."""
    models = sorted((m for m in snapshot.meshes if m.enabled and not m.is_region), key=lambda m: m.name)
    return models[0] if models else None


def _infill_fraction(values: dict) -> float | None:
    """The density Cura's infill prints at: its density times the infill line multiplier, at most 1."""
    density = _fraction(values.get("infill_sparse_density"))
    multiplier = _number(values.get("infill_multiplier"), 1.0) or 1.0
    return None if density is None else min(1.0, density * max(1.0, multiplier))


def build_settings(snapshot):
    """``(ProcessSettings, [Region])`` for the pass, from Cura's values.

    Every mesh in the scene is listed: enabled ones are processed with their
    own density, line width, speed and overlap; the others are left exactly
    as Cura made them (``process_unlisted_meshes=False``).
    """
    from ..gcode import MeshSettings, ProcessSettings, Region

    primary = _primary_model(snapshot)
    if primary is None:
        raise ValueError("no model has Delaunay variable infill turned on")
    glob = snapshot.global_values
    extruder = snapshot.extruder_values.get(primary.extruder_nr) or next(iter(snapshot.extruder_values.values()), {})

    meshes = {}
    regions = []
    lift = raft_z_offset(snapshot)
    for mesh in snapshot.meshes:
        values = mesh.values
        density = _infill_fraction(values)
        settings = MeshSettings(
            enabled=bool(mesh.enabled),
            density=density,
            line_width=_number(values.get("infill_line_width")),
            speed=_number(values.get("speed_infill")),
            infill_overlap=_number(values.get("infill_overlap_mm")),
        )
        if mesh.is_region:
            settings.region_density = density
            if snapshot.scene_regions is None and mesh.enabled and mesh.triangles is not None and density is not None:
                regions.append(Region(density, triangles=_lifted(mesh.triangles, lift), name=mesh.name))
        meshes[mesh.name] = settings
    if snapshot.scene_regions is not None:
        enabled_names = {m.name for m in snapshot.meshes if m.enabled}
        regions = [
            Region(float(r.density), triangles=_lifted(r.triangles, lift), name=r.name)
            for r in snapshot.scene_regions
            if r.name in enabled_names
        ]
    if getattr(snapshot, "painted_sets", None):  # painted sets come last: they win where they overlap
        from .paint import painted_regions

        enabled_models = {m.name for m in snapshot.meshes if m.enabled and not m.is_region}
        regions += painted_regions(snapshot.painted_sets, enabled_models, lift)

    hop = _number(extruder.get("retraction_hop"), 0.0) if extruder.get("retraction_hop_enabled") else 0.0
    acceleration = _number(glob.get("machine_acceleration"), 3000.0)
    if glob.get("acceleration_enabled"):
        acceleration = _number(primary.values.get("acceleration_infill"), acceleration)
    jerk = _number(glob.get("machine_max_jerk_xy"), 20.0)
    if glob.get("jerk_enabled"):
        jerk = _number(primary.values.get("jerk_infill"), jerk)
    flavor = str(glob.get("machine_gcode_flavor") or "")
    # Cura combines the infill of this many layers into one (Infill Layer Thickness over the layer height)
    thickness, height = _number(primary.values.get("infill_sparse_thickness")), _number(glob.get("layer_height"))
    infill_layers = max(1, int(round(thickness / height))) if thickness and height and height > 0 else None
    settings = ProcessSettings(
        density=_infill_fraction(primary.values),
        line_width=_number(primary.values.get("infill_line_width")),
        infill_overlap=_number(primary.values.get("infill_overlap_mm")),
        speed=_number(primary.values.get("speed_infill")),
        # Cura's FILL E/mm already includes its infill flow; the pass keeps that E/mm.
        flow=1.0,
        seed=int(_number(primary.values.get("delaunay_infill_seed"), 0.0)),
        layout=str(primary.values.get("delaunay_infill_layout") or "seamless"),
        infill_pattern=str(primary.values.get("infill_pattern") or "") or None,
        gradual_infill_steps=int(_number(primary.values.get("gradual_infill_steps"), 0.0)),
        infill_layers=infill_layers,
        infill_support=bool(primary.values.get("infill_support_enabled")),
        infill_wall_lines=int(_number(primary.values.get("infill_wall_line_count"), 0.0)),
        meshes=meshes,
        process_unlisted_meshes=False,
        filament_diameter=_number(extruder.get("material_diameter")),
        volumetric_e=flavor in VOLUMETRIC_FLAVORS if flavor else None,
        relative_e=bool(glob.get("relative_extrusion")) if glob.get("relative_extrusion") is not None else None,
        retraction_amount=_number(extruder.get("retraction_amount")) if extruder.get("retraction_enable") else 0.0,
        retraction_retract_speed=_number(extruder.get("retraction_retract_speed")),
        retraction_prime_speed=_number(extruder.get("retraction_prime_speed")),
        retraction_hop=hop,
        retraction_min_travel=_number(extruder.get("retraction_min_travel")),
        combing=str(glob.get("retraction_combing") or "all") != "off",  # every other mode combs in infill
        combing_max_distance=max(0.0, _number(extruder.get("retraction_combing_max_distance"), 0.0)),
        # Only a "yes" is certain: some flavours (UltiGCode) use G10/G11 regardless; the pass sees them.
        firmware_retraction=True if glob.get("machine_firmware_retract") else None,
        travel_speed=_number(extruder.get("speed_travel")),
        acceleration=acceleration,
        jerk=max(0.0, jerk),
        # width (mm) over which region densities blend into their surroundings (the tool's feather)
        feather=max(0.0, _number(getattr(snapshot, "feather_mm", 0.0), 0.0)),
    )
    return settings, regions


def run_pipeline(layers, snapshot, progress=None, cancel=None):
    """Run the G-code pass on Cura's list of G-code chunks.

    Parameters
    ----------
    layers : list of str
        Cura's ``gcode_dict[plate]`` (a copy; it is not modified).
    snapshot : SceneSnapshot
        Cura's settings.
    progress : callable(float) or None
        Called with 0..1 now and then.
    cancel : callable() -> bool or None
        Polled between layers; processing stops when it returns True.

    Returns
    -------
    (list of str, ProcessReport)
    """
    from .. import process_gcode

    settings, regions = build_settings(snapshot)
    return process_gcode(list(layers), settings, regions=regions, progress=progress, cancel=cancel)


def failed_layers(report) -> list:
    """Layer numbers that kept Cura's infill (empty when all went well)."""
    return list(getattr(report, "failed_layers", None) or [])


def kept_message(report) -> str | None:
    """What the user is told of Cura's infill kept where the new infill could not be confirmed (None: nothing)."""
    parts = []
    kept_mm = _number(getattr(report, "cura_infill_kept_mm", None), 0.0)
    layers = int(_number(getattr(report, "layers_with_cura_infill_kept", None), 0.0))
    if kept_mm > 0:
        parts.append(f"Cura's own infill lines were kept in {layers} layer(s) ({kept_mm:.0f} mm of line): where "
                     "the walls and skin did not confirm an infill area, or a part is too small for the "
                     "Delaunay pattern.")
    parts += [f"{w[0].upper()}{w[1:]}." if not w.endswith(".") else w for w in getattr(report, "warnings", None) or []]
    return " ".join(parts) or None


def adjusted_estimates(times_per_feature: dict, material_amounts: list, report, snapshot):
    """Cura's per-feature times and material volumes, corrected for the new infill.

    Parameters
    ----------
    times_per_feature : dict
        Cura's ``printDurationMessage`` times (s) by feature ("infill", ...).
    material_amounts : list of float
        Cura's material volume per extruder, mm³.
    report : ProcessReport
        The pass's report (time and filament before and after).
    snapshot : SceneSnapshot
        For the infill extruder and its filament diameter.

    Returns
    -------
    (dict, list) or None
        None when the report has no usable figures.
    """
    time_before = _number(getattr(report, "time_before_s", None))
    time_after = _number(getattr(report, "time_after_s", None))
    filament_before = _number(getattr(report, "filament_before_mm", None))
    filament_after = _number(getattr(report, "filament_after_mm", None))
    if None in (time_before, time_after, filament_before, filament_after):
        return None
    times = dict(times_per_feature)
    times["infill"] = max(0.0, _number(times.get("infill"), 0.0) + (time_after - time_before))
    amounts = list(material_amounts)
    primary = _primary_model(snapshot)
    nr = primary.extruder_nr if primary is not None else 0
    if 0 <= nr < len(amounts):
        delta = filament_after - filament_before
        flavor = str(snapshot.global_values.get("machine_gcode_flavor") or "")
        if flavor not in VOLUMETRIC_FLAVORS:
            diameter = _number((snapshot.extruder_values.get(nr) or {}).get("material_diameter"), 1.75)
            delta *= math.pi * (diameter / 2.0) ** 2  # mm of filament -> mm³
        amounts[nr] = max(0.0, amounts[nr] + delta)
    return times, amounts
