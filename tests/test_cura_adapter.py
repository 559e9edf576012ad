"""Cura's values (a SceneSnapshot) → the G-code pass's settings, and the estimate correction.

Pure Python: DelaunayInfill/cura/adapter.py and snapshot.py's data classes need no Cura.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from DelaunayInfill.cura.adapter import adjusted_estimates, build_settings, failed_layers, kept_message
from DelaunayInfill.cura.snapshot import MeshSnapshot, SceneSnapshot
from DelaunayInfill.gcode import ProcessReport


def _model(name, enabled=True, density=20, **values):
    base = {"infill_sparse_density": density, "infill_line_width": 0.4, "speed_infill": 50, "infill_overlap_mm": 0.04,
            "delaunay_infill_seed": 3, "delaunay_infill_layout": "paper", "acceleration_infill": 1500}
    return MeshSnapshot(name=name, values={**base, **values}, enabled=enabled)


def _snapshot(meshes, **glob):
    return SceneSnapshot(
        global_values={"machine_width": 235, "machine_depth": 235, "machine_gcode_flavor": "RepRap (Marlin/Sprinter)",
                       "relative_extrusion": False, "machine_acceleration": 500, **glob},
        extruder_values={0: {"material_diameter": 1.75, "retraction_enable": True, "retraction_amount": 5,
                             "retraction_retract_speed": 45, "retraction_prime_speed": 40, "speed_travel": 150,
                             "retraction_hop_enabled": True, "retraction_hop": 0.4, "retraction_min_travel": 1.5},
                         1: {"material_diameter": 2.85, "retraction_enable": False, "retraction_amount": 8}},
        meshes=meshes,
    )


def test_cura_values_become_fractions_and_per_mesh_settings():
    snapshot = _snapshot([_model("star.stl", density=35, infill_line_width=0.5), _model("cube.stl", enabled=False)])
    settings, regions = build_settings(snapshot)
    assert settings.density == pytest.approx(0.35) and settings.line_width == 0.5
    assert settings.seed == 3 and settings.layout == "paper" and settings.flow == 1.0
    assert settings.process_unlisted_meshes is False
    assert settings.meshes["star.stl"].enabled and settings.meshes["star.stl"].density == pytest.approx(0.35)
    assert settings.meshes["cube.stl"].enabled is False  # listed, so the pass leaves it exactly as Cura made it
    assert (settings.retraction_amount, settings.retraction_hop, settings.retraction_min_travel) == (5, 0.4, 1.5)
    assert settings.travel_speed == 150 and settings.filament_diameter == 1.75
    assert settings.volumetric_e is False and settings.relative_e is False
    assert settings.acceleration == 500  # acceleration control off: the machine's
    assert regions == []
    settings.validate()


def test_the_infill_extruder_drives_retraction_and_filament():
    star = _model("star.stl")
    star.extruder_nr = 1
    settings, _ = build_settings(_snapshot([star], machine_gcode_flavor="UltiGCode", acceleration_enabled=True))
    assert settings.filament_diameter == 2.85
    assert settings.retraction_amount == 0.0  # retraction off on that extruder
    assert settings.volumetric_e is True
    assert settings.acceleration == 1500


def test_regions_come_from_enabled_modifiers_in_gcode_coordinates():
    triangles = np.zeros((12, 3, 3))
    triangles[:, :, 0] = 100.0
    region = MeshSnapshot(name="DelaunayRegion_1", values={"infill_sparse_density": 60, "infill_mesh": True},
                          enabled=True, is_region=True, triangles=triangles)
    ignored = MeshSnapshot(name="elsewhere", values={"infill_sparse_density": 5, "infill_mesh": True},
                           enabled=False, is_region=True, triangles=triangles)
    settings, regions = build_settings(_snapshot([_model("star.stl"), region, ignored]))
    assert [r.name for r in regions] == ["DelaunayRegion_1"]
    assert regions[0].density == pytest.approx(0.6)
    assert settings.meshes["DelaunayRegion_1"].region_density == pytest.approx(0.6)
    assert settings.meshes["elsewhere"].enabled is False


def test_nothing_enabled_is_refused():
    with pytest.raises(ValueError, match="no model"):
        build_settings(_snapshot([_model("star.stl", enabled=False)]))


def test_estimates_are_corrected_by_the_report():
    report = ProcessReport(time_before_s=1000.0, time_after_s=1100.0, filament_before_mm=2000.0,
                           filament_after_mm=1900.0, failed_layers=[7, 9])
    times, amounts = adjusted_estimates({"infill": 300.0, "inset_0": 500.0}, [5000.0], report,
                                        _snapshot([_model("star.stl")]))
    assert times == {"infill": 400.0, "inset_0": 500.0}
    assert amounts[0] == pytest.approx(5000.0 - 100.0 * math.pi * 0.875**2)
    assert failed_layers(report) == [7, 9]
    assert adjusted_estimates({}, [], object(), _snapshot([_model("star.stl")])) is None


def test_regions_are_lifted_by_the_raft():
    """A raft lifts the model (layers >= 1) by raft thickness + air gap - layer 0 overlap; regions follow."""
    raft = {"raft_base_thickness": 0.3, "raft_interface_thickness": 0.2, "raft_surface_layers": 2,
            "raft_surface_thickness": 0.1, "raft_airgap": 0.3, "layer_0_z_overlap": 0.15}
    triangles = np.zeros((12, 3, 3))
    region = MeshSnapshot(name="DelaunayRegion_1", values={"infill_sparse_density": 60, "infill_mesh": True},
                          enabled=True, is_region=True, triangles=triangles)
    snapshot = _snapshot([_model("star.stl"), region], adhesion_type="raft", adhesion_extruder_nr=1)
    snapshot.extruder_values[1].update(raft)
    _, regions = build_settings(snapshot)
    assert regions[0].triangles[..., 2] == pytest.approx(0.3 + 0.2 + 0.2 + 0.3 - 0.15)
    assert triangles[..., 2].max() == 0.0  # the scene's own array is untouched
    snapshot.extruder_values[1]["raft_interface_layers"] = 3  # Cura 5: several interface layers
    assert build_settings(snapshot)[1][0].triangles[..., 2] == pytest.approx(0.3 + 0.6 + 0.2 + 0.3 - 0.15)
    snapshot.global_values["adhesion_type"] = "brim"
    assert build_settings(snapshot)[1][0].triangles[..., 2] == pytest.approx(0.0)


def test_combing_follows_cura_s_combing_mode():
    star = _model("star.stl")
    assert build_settings(_snapshot([star]))[0].combing is True  # Cura's default mode combs
    for mode, combs in (("off", False), ("all", True), ("noskin", True), ("infill", True)):
        assert build_settings(_snapshot([star], retraction_combing=mode))[0].combing is combs
    snapshot = _snapshot([star])
    snapshot.extruder_values[0]["retraction_combing_max_distance"] = 30
    assert build_settings(snapshot)[0].combing_max_distance == 30


def test_the_time_estimate_takes_cura_s_jerk():
    star = _model("star.stl", jerk_infill=8)
    assert build_settings(_snapshot([star]))[0].jerk == 20.0  # fdmprinter's default
    assert build_settings(_snapshot([star], machine_max_jerk_xy=10))[0].jerk == 10.0
    assert build_settings(_snapshot([star], machine_max_jerk_xy=10, jerk_enabled=True))[0].jerk == 8.0


def test_cura_s_infill_pattern_reaches_the_pass():
    settings, _ = build_settings(_snapshot([_model("star.stl", infill_pattern="lightning")]))
    assert settings.infill_pattern == "lightning"
    settings, _ = build_settings(_snapshot([_model("star.stl")]))
    assert settings.infill_pattern is None


def test_the_message_tells_where_cura_s_infill_was_kept():
    assert kept_message(ProcessReport()) is None
    text = kept_message(ProcessReport(cura_infill_kept_mm=123.4, layers_with_cura_infill_kept=7,
                                      warnings=["Cura's lightning infill kept: choose another pattern"]))
    assert "7 layer(s)" in text and "123 mm" in text
    assert text.endswith("Cura's lightning infill kept: choose another pattern.")


def test_the_infill_line_multiplier_multiplies_the_density():
    settings, _ = build_settings(_snapshot([_model("star.stl", density=20, infill_multiplier=2)]))
    assert settings.density == pytest.approx(0.4) and settings.meshes["star.stl"].density == pytest.approx(0.4)


def test_cura_s_gradual_infill_steps_reach_the_pass():
    settings, _ = build_settings(_snapshot([_model("star.stl", gradual_infill_steps=2)]))
    assert settings.gradual_infill_steps == 2
    settings, _ = build_settings(_snapshot([_model("star.stl")]))
    assert settings.gradual_infill_steps == 0


def test_cura_s_infill_layer_thickness_reaches_the_pass_as_layers():
    settings, _ = build_settings(_snapshot([_model("star.stl", infill_sparse_thickness=0.4)], layer_height=0.2))
    assert settings.infill_layers == 2
    settings, _ = build_settings(_snapshot([_model("star.stl", infill_sparse_thickness=0.2)], layer_height=0.2))
    assert settings.infill_layers == 1
    settings, _ = build_settings(_snapshot([_model("star.stl")]))
    assert settings.infill_layers is None  # (then the pass reads the G-code's footer and extrusion)


def test_cura_s_infill_as_support_reaches_the_pass():
    settings, _ = build_settings(_snapshot([_model("star.stl", infill_support_enabled=True)]))
    assert settings.infill_support is True
    settings, _ = build_settings(_snapshot([_model("star.stl")]))
    assert settings.infill_support is False


def test_cura_s_infill_wall_line_count_reaches_the_pass():
    settings, _ = build_settings(_snapshot([_model("star.stl", infill_wall_line_count=2)]))
    assert settings.infill_wall_lines == 2
    settings, _ = build_settings(_snapshot([_model("star.stl")]))
    assert settings.infill_wall_lines == 0
