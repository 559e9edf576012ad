"""A throw-away Cura 4.13 or 5.0 profile that starts straight into the main window.

Cura shows its welcome wizard only while no printer is active, and "What's
new" only when ``last_run_version`` is older than the running version, so a
profile with one printer and the current version skips both.  The printer is
a Creality Ender-3 with the containers Cura 4.13 itself stores for it.

Layout under ``home`` (Cura X.Y on Linux, X.Y = 4.13 or 5.0):
``.config/cura/X.Y/cura.cfg`` (preferences), ``.local/share/cura/X.Y/``
(``machine_instances/``, ``extruders/``, ``user/``, ``definition_changes/``,
``plugins/``, ``cura.log``).  Cura 5.0 stores the Ender-3 with the same
container ids as 4.13; only the container format (``setting_version``) differs.
"""

from __future__ import annotations

import urllib.parse
import uuid
from pathlib import Path

CURA_SERIES = "4.13"  # the default version
#: Cura version -> (container format ``setting_version``, ``last_run_version`` that skips "What's new")
VERSIONS = {"4.13": (19, "4.13.0"), "5.0": (20, "5.0.0")}
SETTING_VERSION = VERSIONS[CURA_SERIES][0]
PREFERENCES_VERSION = 7  # the same in 4.13 and 5.0

ENDER3 = {
    "name": "Creality Ender-3",
    "definition": "creality_ender3",
    "extruder_definition": "creality_base_extruder_0",
    "global_quality": "base_global_standard",
    "quality": "base_0.4_PLA_standard",
    "material": "generic_pla_175_creality_ender3",
    "variant": "creality_ender3_0.4",
}


def _series(version: str) -> str:
    if version not in VERSIONS:
        raise ValueError(f"no profile layout for Cura {version!r}; known: {', '.join(VERSIONS)}")
    return version


def data_dir(home: Path, version: str = CURA_SERIES) -> Path:
    return Path(home) / ".local" / "share" / "cura" / _series(version)


def config_dir(home: Path, version: str = CURA_SERIES) -> Path:
    return Path(home) / ".config" / "cura" / _series(version)


def plugins_dir(home: Path, version: str = CURA_SERIES) -> Path:
    return data_dir(home, version) / "plugins"


def _file_name(container_id: str) -> str:
    return urllib.parse.quote_plus(container_id)  # how Cura names container files


def _ini(sections: dict) -> str:
    return "".join(
        f"[{section}]\n" + "".join(f"{key} = {value}\n" for key, value in values.items()) + "\n"
        for section, values in sections.items()
    )


def seed_profile(home: Path, *, width: int = 1600, height: int = 1000, preferences: dict | None = None,
                 version: str = CURA_SERIES) -> Path:
    """Write a Cura 4.13 or 5.0 profile with an active Ender-3 under `home`.

    Parameters
    ----------
    home : Path
        Used as $HOME for Cura.
    width, height : int
        Main window size in pixels (placed at 0, 0).
    preferences : dict or None
        Extra ``{"section/key": value}`` preferences.
    version : {"4.13", "5.0"}
        The Cura whose folders and container format to write.

    Returns
    -------
    Path
        Cura's data folder in that profile.
    """
    setting_version, run_version = VERSIONS[_series(version)]
    machine = ENDER3
    name = machine["name"]
    extruder_id = f"{machine['extruder_definition']} #1"
    prefs = {
        "general": {
            "version": PREFERENCES_VERSION,
            "last_run_version": run_version,
            "accepted_user_agreement": "True",
            "auto_slice": "False",
            "window_left": 0,
            "window_top": 0,
            "window_width": width,
            "window_height": height,
        },
        "cura": {
            "active_machine": name,
            "active_mode": 1,  # the Custom print settings panel, not Recommended
            "categories_expanded": "infill",
        },
        "view": {"settings_visible": "True"},
        "info": {"asked_send_slice_info": "True", "send_slice_info": "False"},
        "metadata": {"setting_version": setting_version},
    }
    for key, value in (preferences or {}).items():
        section, _, entry = key.partition("/")
        prefs.setdefault(section, {})[entry] = value

    config = config_dir(home, version)
    data = data_dir(home, version)
    for folder in (config, data / "machine_instances", data / "extruders", data / "user",
                   data / "definition_changes", data / "plugins"):
        folder.mkdir(parents=True, exist_ok=True)
    (config / "cura.cfg").write_text(_ini(prefs), encoding="utf-8")
    (config / "plugins.json").write_text('{"disabled": [], "to_install": {}, "to_remove": []}', encoding="utf-8")

    stack_meta = {"setting_version": setting_version}
    (data / "machine_instances" / f"{_file_name(name)}.global.cfg").write_text(_ini({
        "general": {"version": 5, "name": name, "id": name},
        "metadata": {**stack_meta, "type": "machine", "group_id": uuid.uuid4()},
        "containers": {0: f"{name}_user", 1: "empty_quality_changes", 2: "empty_intent",
                       3: machine["global_quality"], 4: "empty_material", 5: "empty_variant",
                       6: f"{name}_settings", 7: machine["definition"]},
    }), encoding="utf-8")
    (data / "extruders" / f"{_file_name(extruder_id)}.extruder.cfg").write_text(_ini({
        "general": {"version": 5, "name": "Extruder 1", "id": extruder_id},
        "metadata": {**stack_meta, "type": "extruder_train", "position": 0, "machine": name},
        "containers": {0: f"{extruder_id}_user", 1: "empty_quality_changes", 2: "empty_intent",
                       3: machine["quality"], 4: machine["material"], 5: machine["variant"],
                       6: f"{extruder_id}_settings", 7: machine["extruder_definition"]},
    }), encoding="utf-8")
    instances = (
        ("user", f"{name}_user", machine["definition"], {"machine": name}),
        ("user", f"{extruder_id}_user", machine["definition"], {"extruder": extruder_id}),
        ("definition_changes", f"{name}_settings", machine["definition"], {}),
        ("definition_changes", f"{extruder_id}_settings", machine["extruder_definition"], {}),
    )
    for kind, container_id, definition, extra in instances:
        (data / kind / f"{_file_name(container_id)}.inst.cfg").write_text(_ini({
            "general": {"version": 4, "name": container_id, "definition": definition},
            "metadata": {"type": kind, **stack_meta, **extra},
            "values": {},
        }), encoding="utf-8")
    return data
