"""DelaunayInfill.curaengine: definition merging and setting-formula evaluation.

Most tests use a small hand-written definition set, so they pin the rules
(inheritance, overrides, extruder precedence, formulas, per-mesh dependents)
without Cura installed; the ones marked ``engine`` use Cura 4.13's real
fdmprinter definitions.
"""

from __future__ import annotations

import json

import pytest

from DelaunayInfill import curaengine as ce


def _write(folder, name, document):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.def.json").write_text(json.dumps(document))


@pytest.fixture
def tiny(tmp_path):
    """fdmprinter <- my_printer, with extruder my_extruder."""
    defs, extruders = tmp_path / "definitions", tmp_path / "extruders"
    _write(defs, "fdmprinter", {
        "name": "FDM", "metadata": {},
        "settings": {
            "machine": {"type": "category", "children": {
                "machine_width": {"type": "float", "default_value": 100},
                "material_diameter": {"type": "float", "default_value": 2.85},
            }},
            "infill": {"type": "category", "children": {
                "line_width": {"type": "float", "default_value": 0.4},
                "infill_sparse_density": {"type": "float", "default_value": 20, "children": {
                    "infill_line_distance": {"type": "float", "default_value": 2,
                                             "value": "0 if infill_sparse_density == 0 else line_width * 100 / infill_sparse_density * (2 if infill_pattern == 'grid' else 1)"},
                }},
                "infill_pattern": {"type": "enum", "default_value": "grid"},
                "wall_count": {"type": "int", "default_value": 2, "value": "max(1, round(wall_thickness / line_width))"},
                "wall_thickness": {"type": "float", "default_value": 0.8},
                "top_layers": {"type": "int", "default_value": 8,
                               "value": "math.ceil(round(top_thickness / resolveOrValue('layer_height'), 4))"},
                "top_thickness": {"type": "float", "default_value": 0.8},
                "layer_height": {"type": "float", "default_value": 0.1},
                "all_widths": {"type": "float", "default_value": 0, "value": "max(extruderValues('line_width'))"},
                "first_layer": {"type": "float", "default_value": 0.3, "resolve": "min(extruderValues('layer_height'))"},
                "listy": {"type": "float", "default_value": 0, "value": "sum([line_width for _ in range(3)])"},
                "broken": {"type": "float", "default_value": 7, "value": "no_such_setting * 2"},
                "speed_print": {"type": "float", "default_value": 50},
            }},
        },
    })
    _write(defs, "my_printer", {
        "inherits": "fdmprinter", "metadata": {"machine_extruder_trains": {"0": "my_extruder"}},
        "overrides": {"machine_width": {"default_value": 235}, "layer_height": {"default_value": 0.2}},
    })
    _write(extruders, "fdmextruder", {"name": "ext", "metadata": {}, "settings": {}})
    _write(extruders, "my_extruder", {
        "inherits": "fdmextruder", "metadata": {},
        "overrides": {"material_diameter": {"default_value": 1.75}},
    })
    return tmp_path


def test_inheritance_overrides_and_extruder_precedence(tiny):
    defs = ce.Definitions("my_printer", resources=tiny)
    stack = ce.SettingStack(defs, {})
    assert stack.value("machine_width") == 235.0
    assert stack.value("material_diameter") == 1.75  # the extruder definition wins
    assert defs.extruder_id == "my_extruder"
    assert defs.fdmprinter_path.endswith("fdmprinter.def.json")
    assert "infill_line_distance" in defs.keys and "infill" not in defs.properties  # categories are not settings


def test_formulas_follow_user_settings(tiny):
    defs = ce.Definitions("my_printer", resources=tiny)
    assert ce.SettingStack(defs, {}).value("infill_line_distance") == pytest.approx(4.0)
    assert ce.SettingStack(defs, {"infill_sparse_density": "50"}).value("infill_line_distance") == pytest.approx(1.6)
    stack = ce.SettingStack(defs, {"infill_sparse_density": 50, "infill_pattern": "lines"})
    assert stack.value("infill_line_distance") == pytest.approx(0.8)
    assert ce.SettingStack(defs, {"infill_sparse_density": 0}).value("infill_line_distance") == 0
    stack = ce.SettingStack(defs, {"wall_thickness": 1.2, "top_thickness": 1.0})
    assert stack.value("wall_count") == 3 and isinstance(stack.value("wall_count"), int)
    assert stack.value("top_layers") == 5
    # a user value wins over the formula; a "=formula" user value is evaluated
    assert ce.SettingStack(defs, {"infill_line_distance": 3}).value("infill_line_distance") == 3.0
    assert ce.SettingStack(defs, {"top_layers": "=top_thickness / 0.1"}).value("top_layers") == 8


def test_cura_formula_functions_and_comprehensions(tiny):
    defs = ce.Definitions("my_printer", resources=tiny)
    stack = ce.SettingStack(defs, {"line_width": 0.5})
    assert stack.value("all_widths") == 0.5
    assert stack.value("listy") == pytest.approx(1.5)  # names inside a comprehension resolve too
    assert stack.resolved("first_layer") == 0.2  # resolve formula on the global stack
    assert ce.SettingStack(defs, {"first_layer": 0.15}).resolved("first_layer") == 0.15


def test_a_broken_formula_falls_back_to_the_default_with_a_warning(tiny):
    stack = ce.SettingStack(ce.Definitions("my_printer", resources=tiny), {})
    assert stack.value("broken") == 7.0
    assert any("broken" in w for w in stack.warnings)


def test_per_mesh_settings_carry_their_dependents(tiny):
    resolved = ce.resolve_settings({"infill_sparse_density": 20}, [("a.stl", {}), ("box.stl", {"infill_sparse_density": 60})],
                                   printer="my_printer", resources=tiny, defaults={})
    assert resolved.meshes[0] == ("a.stl", {})
    box = resolved.meshes[1][1]
    assert box["infill_sparse_density"] == 60.0
    assert box["infill_line_distance"] == pytest.approx(0.4 * 100 / 60 * 2)
    assert "speed_print" not in box and "wall_count" not in box
    assert resolved.global_values["infill_line_distance"] == pytest.approx(4.0)


def test_unknown_settings_are_refused(tiny):
    with pytest.raises(ce.CuraEngineError, match="unknown Cura setting"):
        ce.resolve_settings({"infil_density": 20}, printer="my_printer", resources=tiny, defaults={})
    with pytest.raises(ce.CuraEngineError, match="per-mesh"):
        ce.resolve_settings({}, [("a.stl", {"nope": 1})], printer="my_printer", resources=tiny, defaults={})
    with pytest.raises(ce.CuraEngineError, match="no Cura definition named 'nope'"):
        ce.Definitions("nope", resources=tiny)


def test_engine_arguments_repeat_extruder_settings_after_e0(tiny):
    resolved = ce.resolve_settings({"speed_print": 40}, [("a.stl", {}), ("b.stl", {"infill_sparse_density": 60})],
                                   printer="my_printer", resources=tiny, defaults={})
    args = ce.engine_arguments(resolved)
    assert args[:2] == ["-j", str(tiny / "definitions" / "fdmprinter.def.json")]
    e0 = args.index("-e0")
    assert "material_diameter=1.75" in args[:e0] and "material_diameter=1.75" in args[e0:]
    assert "speed_print=40" in args[e0:]
    la, lb = args.index("a.stl"), args.index("b.stl")
    assert args[la - 1] == "-l" and args[lb - 1] == "-l" and e0 < la < lb
    assert "infill_sparse_density=60" in args[lb:] and "infill_sparse_density=60" not in args[la:lb]
    assert "--next" not in args


def test_engine_text_formats():
    assert ce._engine_text(True) == "true" and ce._engine_text(False) == "false"
    assert ce._engine_text(20.0) == "20" and ce._engine_text(0.1 + 0.2) == repr(0.1 + 0.2)
    assert ce._engine_text([[-20, 10], [10, 10]]) == "[[-20, 10], [10, 10]]"
    assert ce._engine_text("RepRap (Marlin/Sprinter)") == "RepRap (Marlin/Sprinter)"


def test_missing_engine_and_definitions_give_clear_errors(monkeypatch, tmp_path):
    with pytest.raises(ce.CuraEngineError, match="apt-get install cura-engine"):
        ce.find_curaengine("definitely-not-a-curaengine")
    monkeypatch.setattr(ce, "_RESOURCE_DIRS", ())
    monkeypatch.setenv("CURA_RESOURCES", str(tmp_path))
    with pytest.raises(ce.CuraEngineError, match="apt-get install cura"):
        ce.find_resources()
    from DelaunayInfill import models

    models.write_stl(tmp_path / "x.stl", models.cube())
    with pytest.raises(ce.CuraEngineError, match="apt-get install cura"):
        ce.slice_models([(str(tmp_path / "x.stl"), {})], {}, tmp_path / "o.gcode", engine="definitely-not-a-curaengine")
    with pytest.raises(ce.CuraEngineError, match="model file not found"):
        ce.slice_models([(str(tmp_path / "y.stl"), {})], {}, tmp_path / "o.gcode")
    assert not (tmp_path / "o.gcode").exists()


def test_start_gcode_fields_are_filled(tiny):
    stack = ce.SettingStack(ce.Definitions("my_printer", resources=tiny), {"speed_print": 42})
    text = ce._expand_start_end_gcode("G1 F{speed_print}\n; {machine_width, 0} {not_a_setting}", stack)
    assert text == "G1 F42\n; 235 {not_a_setting}"


def test_one_at_a_time_groups_models_and_keeps_modifiers_with_their_model(tiny):
    defs = ce.Definitions("my_printer", resources=tiny)
    resolved = ce.ResolvedSettings({"print_sequence": "one_at_a_time"}, {},
                                   [("a.stl", {}), ("box.stl", {"infill_mesh": True}), ("b.stl", {})], defs)
    assert ce.mesh_groups(resolved) == [[0, 1], [2]]
    args = ce.engine_arguments(resolved)
    assert args.index("--next") > args.index("box.stl") and args.index("--next") < args.index("b.stl")


# ---------------------------------------------------------------- Cura 4.13's real definitions


@pytest.mark.engine
def test_real_fdmprinter_formulas():
    resolved = ce.resolve_settings({"infill_sparse_density": 50})
    g = resolved.global_values
    assert g["infill_line_distance"] == pytest.approx(1.6)  # grid: 0.4 * 100 / 50 * 2
    assert g["wall_line_count"] == 2 and g["top_layers"] == 4 and g["bottom_layers"] == 4
    assert g["infill_sparse_thickness"] == pytest.approx(0.2)
    assert g["infill_overlap_mm"] == pytest.approx(0.04)
    assert resolved.extruder_values["material_diameter"] == 1.75
    assert not resolved.warnings
    tri = ce.resolve_settings({"infill_sparse_density": 20, "infill_pattern": "triangles"}).global_values
    assert tri["infill_line_distance"] == pytest.approx(6.0)


@pytest.mark.engine
def test_real_infill_modifier_has_no_walls_or_skin():
    resolved = ce.resolve_settings({}, [("part.stl", {}), ("box.stl", ce.infill_modifier_settings(60))])
    box = resolved.meshes[1][1]
    assert box["infill_mesh"] is True
    assert box["wall_line_count"] == 0 and box["top_layers"] == 0 and box["bottom_layers"] == 0
    assert box["infill_line_distance"] == pytest.approx(0.4 * 100 / 60 * 2)


@pytest.mark.engine
def test_real_printer_chain():
    defs = ce.Definitions("creality_ender3")
    stack = ce.SettingStack(defs, {})
    assert stack.value("machine_width") > 200
    assert defs.extruder_id != "fdmextruder"
    assert stack.value("material_diameter") == 1.75
